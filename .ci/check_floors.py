"""Dependency floors: `.ci/floors.txt` pins, for every dependency the distributions of
this repository declare, the lowest version their `>=` bounds allow; every distribution
declares that same bound (so the floor run tests each distribution's floor).

    python .ci/check_floors.py            # floors.txt == declared lower bounds
    python .ci/check_floors.py --installed  # ... and this environment has exactly them

Used by `.ci/run` (second pass, oldest allowed versions) and by
`tests/packaging/test_packaging.py`.
"""

from __future__ import annotations

import re
import sys
from importlib import metadata
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    tomllib = None  # type: ignore[assignment]

ROOT = Path(__file__).resolve().parents[1]
FLOORS = ROOT / ".ci" / "floors.txt"
PYPROJECTS = [ROOT / "pyproject.toml", *sorted((ROOT / "plugins").glob("*/pyproject.toml")),
              ROOT / "examples" / "hapticsdk-warmth" / "pyproject.toml"]
FIRST_PARTY = re.compile(r"^hapticsdk(-[a-z]+)?$")
REQ = re.compile(r"^\s*([A-Za-z0-9_.-]+)\s*(?:\[[^\]]*\])?\s*(.*)$")


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _version_class() -> type:
    try:
        from packaging.version import Version
    except ModuleNotFoundError:  # a fresh venv: pip's own copy
        from pip._vendor.packaging.version import Version
    return Version


def declared_bounds() -> dict[str, dict[str, str]]:
    """package -> {pyproject path: its `>=` bound} over every distribution here."""
    out: dict[str, dict[str, str]] = {}
    for pp in PYPROJECTS:
        proj = tomllib.loads(pp.read_text())["project"]
        reqs = list(proj.get("dependencies", []))
        for extra in proj.get("optional-dependencies", {}).values():
            reqs.extend(extra)
        for req in reqs:
            m = REQ.match(req.split(";")[0])
            assert m, req
            name, spec = _norm(m.group(1)), m.group(2)
            if FIRST_PARTY.match(name):
                continue
            low = re.search(r">=\s*([0-9][0-9A-Za-z.]*)", spec)
            if low is None:
                raise SystemExit(f"{pp.relative_to(ROOT)}: {req!r} has no lower bound")
            out.setdefault(name, {})[str(pp.relative_to(ROOT))] = low.group(1)
    return out


def declared_floors() -> dict[str, str]:
    """package -> the highest `>=` bound any distribution here declares for it."""
    Version = _version_class()
    return {name: max(b.values(), key=Version) for name, b in declared_bounds().items()}


def pinned_floors() -> dict[str, str]:
    """package -> version pinned with `==` in floors.txt."""
    out: dict[str, str] = {}
    for line in FLOORS.read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            name, _, ver = line.partition("==")
            out[_norm(name)] = ver.strip()
    return out


def problems(installed: bool = False) -> list[str]:
    Version = _version_class()
    errs = []
    declared, pinned = declared_floors(), pinned_floors()
    for name in sorted(set(declared) | set(pinned)):
        if name not in pinned:
            errs.append(f"{name}: declared >= {declared[name]} but not pinned in floors.txt")
        elif name not in declared:
            if name != "setuptools":
                errs.append(f"{name}: pinned in floors.txt but declared by no distribution")
        elif Version(pinned[name]) != Version(declared[name]):
            errs.append(f"{name}: floors.txt pins {pinned[name]}, the declared lower bound is {declared[name]}")
    # one floor per package: a distribution declaring a lower bound than the one tested
    # would allow versions no CI run has seen
    for name, bounds in sorted(declared_bounds().items()):
        for where, low in sorted(bounds.items()):
            if name in pinned and Version(low) != Version(pinned[name]):
                errs.append(f"{where}: {name}>={low}, but the tested floor is {pinned[name]}")
    if installed:
        for name, ver in sorted(pinned.items()):
            try:
                have = metadata.version(name)
            except metadata.PackageNotFoundError:
                continue  # declared by an extra that requirements-dev.txt does not install
            if Version(have) != Version(ver):
                errs.append(f"{name}: installed {have}, floor {ver}")
    return errs


if __name__ == "__main__":
    if tomllib is None:
        raise SystemExit("check_floors.py needs Python 3.11+ (tomllib)")
    errs = problems(installed="--installed" in sys.argv)
    for e in errs:
        print("floors:", e, file=sys.stderr)
    if not errs:
        print(f"floors: {len(pinned_floors())} floors match the declared lower bounds"
              + (" and the installed versions" if "--installed" in sys.argv else ""))
    sys.exit(1 if errs else 0)
