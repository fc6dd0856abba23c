"""What to type to install a missing piece, from where this copy of the SDK was installed.

The core and its first-party plugins are not on the package index: ``pip install
hapticsdk-hardness`` would fail (or find someone else's package). From a source checkout
(this package sits in a folder whose ``plugins/`` holds the plugin distributions) the
hint is an editable install of the checkout's own path; elsewhere it says to install it
from a hapticsdk source checkout. Third-party libraries (pyserial, matplotlib, ...) are
on the index and are named as they are.
"""

from __future__ import annotations

from pathlib import Path

#: the first-party distributions, each in ``plugins/<name>`` of a source checkout
FIRST_PARTY_DISTRIBUTIONS = ("hapticsdk-onnx", "hapticsdk-ga", "hapticsdk-hardness", "hapticsdk-roughness")


def source_checkout() -> Path | None:
    """The source checkout this ``hapticsdk`` was installed from (editable install or run
    in place), or ``None`` (installed from a wheel)."""
    root = Path(__file__).resolve().parent.parent
    if (root / "pyproject.toml").is_file() and (root / "plugins").is_dir():
        return root
    return None


def shown_path(path: Path) -> str:
    """``path`` (resolved) relative to the working directory when it is below it, else
    as it is: how the SDK shows its own folders in hints and help examples."""
    try:
        return str(path.relative_to(Path.cwd().resolve()))
    except (ValueError, OSError):  # not below it; the working directory is gone
        return str(path)


def _quote(arg: str) -> str:
    return f"'{arg}'" if any(c in arg for c in "[] ") else arg


def pip_hint(distribution: str, extra: str | None = None) -> str:
    """The command that installs ``distribution`` (``"hapticsdk"`` for the core) with an
    optional ``extra``; first-party ones from this checkout's path."""
    suffix = f"[{extra}]" if extra else ""
    if distribution == "hapticsdk" or distribution in FIRST_PARTY_DISTRIBUTIONS:
        root = source_checkout()
        sub = "" if distribution == "hapticsdk" else f"plugins/{distribution}"
        if root is not None:
            path = shown_path(root / sub) if sub else shown_path(root)
            return f"pip install -e {_quote(path + suffix)}"
        where = f"{sub}{suffix}" if sub else f".{suffix}"
        return (f"pip install -e {_quote(where)} in a hapticsdk source checkout "
                f"({distribution} is not on the package index)")
    return f"pip install {_quote(distribution + suffix)}"

