"""Safety is not data (issue 31, item 2): a scene or plan cannot switch the passivity
controller off or raise a driver's full scale; the user device configuration file and its
folder are refused when someone else could have written them."""

from __future__ import annotations

import copy
import json
import math
import os

import pytest

from hapticsdk.compiler import compile_scene
from hapticsdk.devices.device_options import (ENV_CONFIG, ENV_OPTIONS, PRIVILEGED_SETTINGS, PrivilegedOptionError,
                                      check_data_settings, energy_option_ceilings, trusted_options)
from hapticsdk.errors import ValidationError
from hapticsdk.plugins import registry
from hapticsdk.runtime.render import render_plan
from hapticsdk.scene import Scene
from hapticsdk.schemas_io import validate

ROUGH = {"name": "r", "intensities": {"roughness": 0.6}}


def _scene(**extra):
    return {"objects": [{"name": "o", "material": ROUGH}], **extra}


@pytest.mark.parametrize("value", [False, 0, "false", None, [], {}])
def test_scene_cannot_switch_passivity_off(value):
    sc = _scene(settings={"servo": {"passivity": value}})
    for build in (Scene.from_dict, compile_scene):
        with pytest.raises(PrivilegedOptionError) as ei:
            build(copy.deepcopy(sc))
        assert ei.value.field == "scene.settings.servo.passivity"
        assert "privileged" in str(ei.value)
    # the schema alone says so too (a scene checked by another tool)
    with pytest.raises(ValidationError) as ei:
        validate(sc, "scene")
    assert ei.value.field == "scene.settings.servo.passivity"
    Scene.from_dict(_scene(settings={"servo": {"passivity": True}}))  # the safe value is accepted


def test_plan_cannot_switch_passivity_off_but_code_can():
    plan = compile_scene(_scene()).to_dict()
    assert render_plan(plan, seconds=0.01).fault is None
    for value in (False, 0, None):
        edited = copy.deepcopy(plan)
        edited["settings"].setdefault("servo", {})["passivity"] = value
        with pytest.raises(PrivilegedOptionError) as ei:
            render_plan(edited, seconds=0.01)
        assert ei.value.field == "plan.settings.servo.passivity"
    # the application's code may (and a plan object built in code is still data: refused)
    rep = render_plan(plan, seconds=0.01, passivity=False)
    assert rep.fault is None
    with pytest.raises(ValidationError):
        render_plan(plan, seconds=0.01, passivity="no")


def test_every_privileged_setting_is_checked():
    for path, (safe, _) in PRIVILEGED_SETTINGS.items():
        node = bad = {}
        for part in path[:-1]:
            node = node.setdefault(part, {})
        node[path[-1]] = not safe
        with pytest.raises(PrivilegedOptionError):
            check_data_settings(bad, field="x")


@pytest.mark.parametrize("actuator", ["piezo-virtual", "piezo-serial", "piezo-mcp2221"])
def test_drv2667_gain_above_the_default_is_privileged(actuator):
    if actuator not in registry("actuator"):
        pytest.skip(f"{actuator} not installed (hapticsdk-roughness)")
    cls = registry("actuator").load(actuator)
    default, _ = energy_option_ceilings(cls)["gain"]
    assert default in (0, 1)
    for gain in (default + 1, 3, 3.0, "3", "1", True, float("nan"), float("inf"), None):
        sc = _scene(devices={"vibration": {"actuator": actuator, "options": {"gain": gain}}})
        if isinstance(gain, float) and not math.isfinite(gain):
            # no scene holds a non-finite number: refused when read, by the same field
            with pytest.raises(ValidationError, match="not a finite number") as ei:
                compile_scene(sc)
            assert ei.value.field == "scene.devices.vibration.options.gain", gain
            # and the compiler's ceiling still refuses it in a Scene built past that check
            sc = Scene.from_dict(_scene(devices={"vibration": {"actuator": actuator, "options": {"gain": 0}}}))
            sc.devices["vibration"].options["gain"] = gain
        with pytest.raises(PrivilegedOptionError) as ei:
            compile_scene(sc)
        assert ei.value.field == "scene.devices.vibration.options.gain", gain
        assert "voltage" in str(ei.value)


def test_gain_may_be_lowered_by_a_scene_and_raised_only_by_trusted_sources(tmp_path, monkeypatch):
    plan = compile_scene(_scene(devices={"vibration": {"actuator": "piezo-virtual", "options": {"gain": 0}}}))
    d = plan.to_dict()
    rep = render_plan(d, seconds=0.01)
    assert rep.devices["piezo-virtual"]["gain"] == 0
    d["materials"]["r"]["actuator_options"]["vibration"]["gain"] = 3
    with pytest.raises(PrivilegedOptionError) as ei:
        render_plan(d, seconds=0.01)
    assert ei.value.field == "plan.materials.r.actuator_options.vibration.gain"
    del d["materials"]["r"]["actuator_options"]["vibration"]["gain"]
    # code, environment, configuration file
    assert render_plan(d, seconds=0.01, actuator_options={"vibration": {"gain": 3}}).devices[
        "piezo-virtual"]["gain"] == 3
    monkeypatch.setenv(ENV_OPTIONS, json.dumps({"piezo-virtual": {"gain": 2}}))
    assert render_plan(d, seconds=0.01).devices["piezo-virtual"]["gain"] == 2
    monkeypatch.delenv(ENV_OPTIONS)
    folder = tmp_path / "cfg"
    folder.mkdir(mode=0o755)
    os.chmod(folder, 0o755)
    cfg = folder / "devices.json"
    cfg.write_text(json.dumps({"piezo-virtual": {"gain": 3}}))
    os.chmod(cfg, 0o600)
    monkeypatch.setenv(ENV_CONFIG, str(cfg))
    assert render_plan(d, seconds=0.01).devices["piezo-virtual"]["gain"] == 3


@pytest.mark.parametrize("target,mode,why", [
    ("file", 0o620, "its group"), ("file", 0o602, "others"),
    ("folder", 0o775, "its group"), ("folder", 0o757, "others"), ("folder", 0o1777, "others"),
])
def test_config_file_or_folder_writable_by_others_is_refused(tmp_path, monkeypatch, target, mode, why):
    folder = tmp_path / "cfg"
    folder.mkdir()
    os.chmod(folder, 0o755)
    cfg = folder / "devices.json"
    cfg.write_text(json.dumps({"piezo-virtual": {"gain": 3}}))
    os.chmod(cfg, 0o644)
    monkeypatch.setenv(ENV_CONFIG, str(cfg))
    assert trusted_options("piezo-virtual") == {"gain": 3}
    os.chmod(cfg if target == "file" else folder, mode)
    with pytest.raises(ValidationError) as ei:
        trusted_options("piezo-virtual")
    assert ei.value.field == str(cfg)
    assert f"writable by {why}" in str(ei.value) and ("its folder" in str(ei.value)) == (target == "folder")


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="chown to another user needs root")
@pytest.mark.parametrize("target", ["file", "folder"])
def test_config_owned_by_another_user_is_refused(tmp_path, monkeypatch, target):
    folder = tmp_path / "cfg"
    folder.mkdir()
    os.chmod(folder, 0o755)
    cfg = folder / "devices.json"
    cfg.write_text("{}")
    os.chmod(cfg, 0o644)
    os.chown(cfg if target == "file" else folder, 65534, 65534)
    monkeypatch.setenv(ENV_CONFIG, str(cfg))
    with pytest.raises(ValidationError, match="owned by uid 65534"):
        trusted_options("piezo-virtual")


def test_energy_options_declared_as_any_collection_are_read():
    from hapticsdk.errors import PluginError

    class Base:
        def __init__(self, *, gain=1, boost=0):
            pass

    for decl in (("gain",), ["gain"], {"gain"}, frozenset({"gain"}), {"gain": "full scale"}):
        cls = type("A", (Base,), {"energy_options": decl})
        assert energy_option_ceilings(cls)["gain"][0] == 1, decl
    with pytest.raises(PluginError):  # unreadable: fail closed, never ignored
        energy_option_ceilings(type("B", (Base,), {"energy_options": "gain"}))


@pytest.mark.parametrize("value", ["piezo_table.json", "/etc/passwd", "paper", 3])
def test_scene_or_plan_cannot_name_a_calibration_file_to_read(tmp_path, value):
    """A calibration option (the roughness renderer's piezo ``table``) given as anything
    but an inline object is refused by name, from a scene and from a plan: a string would
    be opened as a path chosen by data. Inline tables and code keep working."""
    table = tmp_path / "piezo_table.json"
    from hapticsdk_roughness.table import generated_table
    table.write_text(json.dumps(generated_table().to_dict()))
    if value == "piezo_table.json":
        value = str(table)   # a real, readable table file: still refused from data
    sc = _scene(settings={"renderer_options": {"roughness": {"table": value}}})
    with pytest.raises(ValidationError) as ei:
        compile_scene(copy.deepcopy(sc))
    assert ei.value.field == "scene.settings.renderer_options.roughness.table"
    plan = compile_scene(_scene())
    plan.settings["renderer_options"] = {"roughness": {"table": value}}
    with pytest.raises(ValidationError) as ei:
        render_plan(plan, seconds=0.01)
    assert ei.value.field == "plan.settings.renderer_options.roughness.table"
    # inline, as an object in the table format, it is data and is used
    inline = _scene(settings={"renderer_options": {"roughness": {"table": generated_table().to_dict()}}})
    assert compile_scene(inline).materials
