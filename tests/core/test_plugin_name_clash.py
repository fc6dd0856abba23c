"""Two installed plugins that give one name different objects: the registry does not pick
one (which the scan meets first is an accident of the install order, and for a device
backend the wrong one drives the hardware); it names both, and an in-process
registration still decides."""

from importlib import metadata

import pytest

from hapticsdk import plugins
from hapticsdk.errors import PluginError
from hapticsdk.plugins import GROUPS, Registry


@pytest.fixture
def reg(monkeypatch):
    group = GROUPS["actuator"]
    eps = [metadata.EntryPoint(name="clash-arm", value="vendor_a.arm:Arm", group=group),
           metadata.EntryPoint(name="solo-arm", value="vendor_c.arm:Arm", group=group),
           metadata.EntryPoint(name="clash-arm", value="vendor_b.arm:Arm", group=group),
           # the same target seen twice (one distribution on two path entries): no clash
           metadata.EntryPoint(name="twice-arm", value="vendor_d.arm:Arm", group=group),
           metadata.EntryPoint(name="twice-arm", value="vendor_d.arm:Arm", group=group)]
    monkeypatch.setattr(plugins, "_entry_points", lambda g: list(eps) if g == group else [])
    return Registry("actuator")


def test_a_name_two_plugins_provide_does_not_load_and_names_both(reg):
    assert reg.names() == ["clash-arm", "solo-arm", "twice-arm"]
    assert "clash-arm" in reg
    for call in (reg.load, reg.info):
        with pytest.raises(PluginError) as err:
            call("clash-arm")
        msg = str(err.value)
        assert "vendor_a.arm:Arm" in msg and "vendor_b.arm:Arm" in msg and "register" in msg
        assert err.value.plugin == "clash-arm" and err.value.kind == "actuator"
    assert list(reg.clashes()) == ["clash-arm"]
    assert [i.value for i in reg.clashes()["clash-arm"]] == ["vendor_a.arm:Arm", "vendor_b.arm:Arm"]


def test_the_other_names_are_unaffected(reg):
    # they still resolve (their modules do not exist here: the import error is theirs)
    for name in ("solo-arm", "twice-arm"):
        assert reg.info(name).value.endswith(".arm:Arm")
        with pytest.raises(PluginError, match="failed to import"):
            reg.load(name)


def test_an_in_process_registration_decides(reg):
    class Mine:
        pass
    reg.register("clash-arm", Mine)
    assert reg.load("clash-arm") is Mine
    reg.unregister("clash-arm")
    with pytest.raises(PluginError, match="more than one"):
        reg.load("clash-arm")


def test_two_hook_modules_under_one_name_both_contribute(tmp_path, monkeypatch):
    """Hook modules add to each other (every implementation is called), so two plugins
    that chose one hook name are both registered; before, the second was dropped
    without a word. The same target seen twice, or loaded twice, registers once."""
    import sys

    for mod, material in (("clash_hooks_a", "A1"), ("clash_hooks_b", "B1")):
        (tmp_path / f"{mod}.py").write_text(
            "from hapticsdk.hookspecs import hookimpl\n\n"
            "@hookimpl\n"
            f"def hapticsdk_materials():\n    return [{{'name': '{material}', 'intensities': {{'hardness': 0.5}}}}]\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    group = GROUPS["hooks"]
    eps = [metadata.EntryPoint(name="shared", value="hapticsdk.clash_hooks_a", group=group),
           metadata.EntryPoint(name="shared", value="clash_hooks_b", group=group),
           metadata.EntryPoint(name="shared", value="clash_hooks_b", group=group)]
    # the first under the core's prefix skips the plugin-API check, as a first-party module would
    sys.modules["hapticsdk.clash_hooks_a"] = __import__("clash_hooks_a")
    monkeypatch.setattr(plugins, "_entry_points", lambda g: list(eps) if g == group else [])
    try:
        pm = plugins.PluginManager().load_all().load_all()
        got = sorted(m["name"] for ms in pm.call_safely("hapticsdk_materials") for m in ms)
        assert got == ["A1", "B1"] and not pm.failures
    finally:
        for m in ("hapticsdk.clash_hooks_a", "clash_hooks_a", "clash_hooks_b"):
            sys.modules.pop(m, None)


def test_the_doctor_names_a_clash_as_one(reg, monkeypatch):
    from hapticsdk import doctor

    monkeypatch.setattr(plugins, "registry", lambda kind: reg)
    table, classes = doctor.check_backends()
    assert table["clash-arm"]["reason"].startswith("name clash: ")
    assert "vendor_a.arm:Arm" in table["clash-arm"]["reason"] and not table["clash-arm"]["available"]
    assert table["solo-arm"]["reason"].startswith("plugin failed to import: ")
