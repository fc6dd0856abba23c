"""Breaking changes of the public API since the last release, with griffe.

    python .ci/api_check.py [--against REF]

Loads ``hapticsdk`` as it is now and at ``REF`` (default: the last release, ``BASELINE``
below; the commit is in every clone of main), lists griffe's breaking changes for the
documented surface (``SURFACE``: the modules ``docs/api.md`` lists; a test keeps the two
equal) and fails on each one that is not announced. Announced means:

* the changed object's dotted path (or a parent's: a module, a class) is named in
  backquotes in a bullet under ``### Removed`` or ``### Deprecated`` of CHANGELOG.md's
  top (unreleased) section or of a ``changes/*.md`` fragment, before any ``->`` (what
  follows it is the new place), or
* its path is a line of ``.ci/api-breaks.txt``: ``dotted.path  reason`` (a reason is
  required).

A deprecation shim keeps the old name importable, so a name moved *with* a shim is no
break at all; a removal or a changed signature is.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: the last release: 0.1.0, main's landing at this commit
BASELINE = "73fd5b9"

#: the documented surface (docs/api.md): public names of these modules
SURFACE = (
    "hapticsdk",
    "hapticsdk.errors", "hapticsdk.perception.features", "hapticsdk.perception.materials",
    "hapticsdk.solvers.problems",
    "hapticsdk.solvers", "hapticsdk.scene", "hapticsdk.compiler", "hapticsdk.plan",
    "hapticsdk.runtime", "hapticsdk.runtime.render", "hapticsdk.runtime.session",
    "hapticsdk.sim.finger", "hapticsdk.calibration", "hapticsdk.interop", "hapticsdk.runlog",
    "hapticsdk.perception.dimensions", "hapticsdk.perception.models", "hapticsdk.devices.actuators",
    "hapticsdk.plugins", "hapticsdk.plugin_api", "hapticsdk.hookspecs", "hapticsdk.devices.device_options",
    "hapticsdk.devices.safety", "hapticsdk.testing",
    # deprecated (shims until 0.3): their removals must stay announced
    "hapticsdk.problems", "hapticsdk.features", "hapticsdk.materials", "hapticsdk.dimensions",
    "hapticsdk.models", "hapticsdk.actuators", "hapticsdk.device_options", "hapticsdk.safety",
)


def in_surface(module: str, path: str) -> bool:
    """Whether the object ``path``, defined (or re-exported) in ``module``, is on the
    documented surface: ``module`` is one of ``SURFACE`` and no part of the path below it
    is private."""
    if module not in SURFACE or not (path == module or path.startswith(module + ".")):
        return False
    rest = path[len(module):].split(".")
    return not any(p.startswith("_") and not p.startswith("__") for p in rest)


def module_of(obj) -> str:  # noqa: ANN001 - a griffe Object or Alias
    """The dotted path of the module that holds ``obj`` (an alias: where it is re-exported)."""
    while obj is not None and not getattr(obj, "is_module", False):
        obj = obj.parent
    return obj.path if obj is not None else ""


def announced_paths() -> dict[str, str]:
    """Dotted paths announced as removed or deprecated, with where they were announced."""
    out: dict[str, str] = {}
    texts = []
    changelog = ROOT / "CHANGELOG.md"
    if changelog.exists():
        # the top version section only: what this release announces
        sections = re.split(r"^## ", changelog.read_text(encoding="utf-8"), flags=re.M)
        if len(sections) > 1:
            texts.append(("CHANGELOG.md", sections[1]))
    for frag in sorted((ROOT / "changes").glob("*.md")):
        if frag.name.lower() != "readme.md":
            texts.append((f"changes/{frag.name}", frag.read_text(encoding="utf-8")))
    for where, text in texts:
        for block in re.split(r"^### ", text, flags=re.M)[1:]:
            title, _, body = block.partition("\n")
            if title.strip().lower() in ("removed", "deprecated"):
                # one bullet each: the old paths in backquotes, before "->" (the new place)
                for bullet in re.split(r"^- ", body, flags=re.M)[1:]:
                    for name in re.findall(r"`([A-Za-z_][\w.]*)`", bullet.split("->")[0]):
                        out[name] = where
    ignore = ROOT / ".ci" / "api-breaks.txt"
    if ignore.exists():
        for n, line in enumerate(ignore.read_text(encoding="utf-8").splitlines(), 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            path, _, reason = line.partition(" ")
            if not reason.strip():
                raise SystemExit(f".ci/api-breaks.txt:{n}: {path} has no reason")
            out[path] = ".ci/api-breaks.txt"
    return out


def is_announced(path: str, announced: dict[str, str]) -> str | None:
    parts = path.split(".")
    for i in range(len(parts), 0, -1):
        where = announced.get(".".join(parts[:i]))
        if where:
            return where
    return None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--against", default=BASELINE, help=f"git reference of the release (default {BASELINE})")
    args = ap.parse_args(argv)
    import griffe

    old = griffe.load_git("hapticsdk", ref=args.against, repo=ROOT, search_paths=["."])
    new = griffe.load("hapticsdk", search_paths=[str(ROOT)])
    announced = announced_paths()
    bad, ok = [], []
    for br in griffe.find_breaking_changes(old, new):
        path = br.obj.path
        if not in_surface(module_of(br.obj), path):
            continue
        where = is_announced(path, announced)
        (ok if where else bad).append((br, where))
    def line(br: griffe.Breakage) -> str:
        return re.sub(r"\x1b\[[0-9;]*m", "", br.explain(style=griffe.ExplanationStyle.ONE_LINE))

    for br, where in ok:
        print(f"announced ({where}): {line(br)}")
    for br, _ in bad:
        print(f"NOT ANNOUNCED: {line(br)}")
    print(f"api check against {args.against}: {len(bad)} unannounced and {len(ok)} announced "
          f"breaking changes on the documented surface ({len(SURFACE)} modules)")
    if bad:
        print("Keep the old name working (hapticsdk/_deprecation.py) or announce the break: "
              "CHANGELOG.md / changes/NN.md under 'Removed' or 'Deprecated', naming it in "
              "backquotes, or a line 'dotted.path  reason' in .ci/api-breaks.txt.")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
