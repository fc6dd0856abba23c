"""One version story: the core's version, each distribution's ``__version__`` and the
first-party plugins' range on the core agree (issue 29)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib")
from packaging.requirements import Requirement  # noqa: E402  (pytest's own dependency)

ROOT = Path(__file__).resolve().parents[2]
FIRST_PARTY = ["hapticsdk-onnx", "hapticsdk-ga", "hapticsdk-hardness", "hapticsdk-roughness"]


def _project(path: Path) -> dict:
    return tomllib.loads(path.read_text())["project"]


def _core_version() -> str:
    return _project(ROOT / "pyproject.toml")["version"]


def test_core_version_matches_the_package_and_the_changelog():
    import hapticsdk
    v = _core_version()
    assert hapticsdk.__version__ == v
    text = (ROOT / "CHANGELOG.md").read_text()
    assert re.search(rf"^## \[{re.escape(v)}\]", text, re.M), f"CHANGELOG.md has no section for {v}"


@pytest.mark.parametrize("dist", FIRST_PARTY)
def test_first_party_plugins_require_the_current_minor(dist):
    core = _core_version()
    proj = _project(ROOT / "plugins" / dist / "pyproject.toml")
    assert proj["version"] == core, "first-party distributions are released together"
    reqs = [Requirement(r) for r in proj["dependencies"]]
    (req,) = [r for r in reqs if r.name == "hapticsdk"]
    assert req.specifier.contains(core), f"{dist}: {req} excludes the core {core}"
    major, minor = (int(x) for x in core.split(".")[:2])
    assert not req.specifier.contains(f"{major}.{minor + 1}.0"), f"{dist}: {req} admits the next minor"
    init = ROOT / "plugins" / dist / "src" / dist.replace("-", "_") / "__init__.py"
    m = re.search(r'^__version__ = "([^"]+)"', init.read_text(), re.M)
    assert m is None or m.group(1) == core
