"""The API check's surface is the one docs/api.md documents, and its rules hold (issue 29)."""

from __future__ import annotations

import importlib
import re
import warnings

from repo_scripts import ROOT, load_script


def _api_check():
    return load_script(".ci/api_check.py")


def test_surface_is_the_documented_table():
    table = re.findall(r"^\| `(hapticsdk[\w.]*)` \|", (ROOT / "docs" / "api.md").read_text(), re.M)
    assert sorted(table) == sorted(_api_check().SURFACE)
    from hapticsdk._deprecation import MOVED_MODULES
    for name in table:
        with warnings.catch_warnings():
            if name in MOVED_MODULES:  # a deprecated shim on the surface: warns, by design
                warnings.simplefilter("ignore", DeprecationWarning)
            importlib.import_module(name)


def test_surface_membership():
    ac = _api_check()
    assert ac.in_surface("hapticsdk", "hapticsdk.solve")
    assert ac.in_surface("hapticsdk.runtime.render", "hapticsdk.runtime.render.RenderReport.to_dict")
    assert not ac.in_surface("hapticsdk.runtime.loop", "hapticsdk.runtime.loop.ServoLoop")  # undocumented
    assert not ac.in_surface("hapticsdk.runtime.render", "hapticsdk.runtime.render._jsonable")  # private
    assert not ac.in_surface("hapticsdk.scene.geometry", "hapticsdk.scene.geometry.Box")  # re-exported
    assert ac.in_surface("hapticsdk.scene", "hapticsdk.scene.Box")      # ... here


def test_announced_names_are_old_places_only(tmp_path, monkeypatch):
    ac = _api_check()
    (tmp_path / "changes").mkdir()
    (tmp_path / "CHANGELOG.md").write_text(
        "# Changelog\n\n## [9.9.0] - Unreleased\n\n### Deprecated\n- `a.old`, `a.older` -> `a.new`\n"
        "### Added\n- `a.added`\n\n## [9.8.0]\n\n### Removed\n- `a.last_time`\n")
    (tmp_path / "changes" / "7.md").write_text("### Removed\n- `b.gone`\n")
    monkeypatch.setattr(ac, "ROOT", tmp_path)
    got = ac.announced_paths()
    assert set(got) == {"a.old", "a.older", "b.gone"}
    assert ac.is_announced("a.old.method", got) and not ac.is_announced("a.new", got)
