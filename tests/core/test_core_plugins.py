import sys
import textwrap

import pytest

from hapticsdk import plugins
from hapticsdk.errors import PluginError, UnknownPluginError


@pytest.fixture
def fake_dists(tmp_path, monkeypatch):
    """Two fake installed distributions: one good, one whose module raises on import."""
    (tmp_path / "good_mod.py").write_text("class Thing:\n    pass\n")
    (tmp_path / "bad_mod.py").write_text("raise RuntimeError('boom at import')\n")
    for dist, mod in (("goodplug", "good_mod:Thing"), ("badplug", "bad_mod:Thing")):
        info = tmp_path / f"{dist}-1.2.3.dist-info"
        info.mkdir()
        (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 1.2.3\n")
        (info / "entry_points.txt").write_text(textwrap.dedent(f"""
            [hapticsdk.solvers]
            {dist}-solver = {mod}
            """))
    monkeypatch.syspath_prepend(str(tmp_path))
    plugins.refresh()
    yield
    sys.modules.pop("good_mod", None)
    sys.modules.pop("bad_mod", None)
    monkeypatch.undo()
    plugins.refresh()


def test_listing_does_not_import(fake_dists):
    rows = plugins.list_plugins(["solver"])
    names = {r["name"]: r for r in rows}
    assert names["goodplug-solver"]["distribution"] == "goodplug"
    assert names["goodplug-solver"]["version"] == "1.2.3"
    assert "good_mod" not in sys.modules and "bad_mod" not in sys.modules


def test_broken_plugin_reported_by_name_without_stopping_others(fake_dists):
    rows = {r["name"]: r for r in plugins.list_plugins(["solver"], check=True)}
    assert rows["goodplug-solver"]["error"] is None
    assert "badplug-solver" in rows["badplug-solver"]["error"]
    assert "boom at import" in rows["badplug-solver"]["error"]
    with pytest.raises(PluginError, match="badplug"):
        plugins.load("solver", "badplug-solver")
    assert plugins.load("solver", "goodplug-solver").__name__ == "Thing"


def test_unknown_name_lists_valid_ones(fake_dists):
    with pytest.raises(UnknownPluginError) as e:
        plugins.load("solver", "nope")
    assert "goodplug-solver" in str(e.value) and e.value.plugin == "nope"


def test_in_process_registration_and_unknown_kind():
    reg = plugins.registry("model")
    reg.register("tmp-model", object)
    try:
        assert reg.load("tmp-model") is object
        assert "tmp-model" in reg.names()
    finally:
        reg.unregister("tmp-model")
    with pytest.raises(PluginError):
        plugins.registry("nonsense")


def test_hook_failures_are_isolated():
    from hapticsdk.hookspecs import hookimpl

    class Good:
        @hookimpl
        def hapticsdk_materials(self):
            return [{"name": "X1", "intensities": {"hardness": 0.5}}]

    class Bad:
        @hookimpl
        def hapticsdk_materials(self):
            raise ValueError("bad plugin")

    pm = plugins.PluginManager()
    pm.register(Good(), name="good")
    pm.register(Bad(), name="bad")
    out = pm.call_safely("hapticsdk_materials")
    assert out == [[{"name": "X1", "intensities": {"hardness": 0.5}}]]
    assert "bad plugin" in pm.failures["bad"]


def test_info_reads_metadata_once_and_again_after_refresh(fake_dists, tmp_path):
    """A distribution's metadata is read once per name (compile asks for it per group),
    and read again after ``refresh()``: an upgraded distribution shows its new version."""
    reg = plugins.registry("solver")
    assert reg.info("goodplug-solver").version == "1.2.3"
    info_dir = tmp_path / "goodplug-1.2.3.dist-info"
    (info_dir / "METADATA").write_text("Metadata-Version: 2.1\nName: goodplug\nVersion: 9.9.9\n")
    assert reg.info("goodplug-solver").version == "1.2.3"  # cached until a refresh
    plugins.refresh()
    assert plugins.registry("solver").info("goodplug-solver").version == "9.9.9"
