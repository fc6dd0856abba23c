"""A scene built in code (Scene(...), Scene.for_material, hs.render) gets no JSON schema:
its settings, objects and devices are checked in Python with the schema's rules, and every
bad value raises ValidationError naming the field -- no TypeError / AttributeError /
OverflowError, and no value silently taken (realtime="no" is not true, a typo'd key is
not ignored, a seed of 1.7 is not 1). A scene file's too-large ints are named as well."""

import math

import pytest

import hapticsdk as hs
from hapticsdk.errors import ValidationError
from hapticsdk.scene import Scene, SceneObject

S = "scene.settings"
BIG = 10 ** 400


@pytest.mark.parametrize("settings, field", [
    ({"importance": "x"}, f"{S}.importance"),
    ({"importance": {"threshold_percent": BIG}}, f"{S}.importance.threshold_percent"),
    ({"importance": {"threshold_percent": "10"}}, f"{S}.importance.threshold_percent"),
    ({"importance": {"thresholds": "x"}}, f"{S}.importance.thresholds"),
    ({"importance": {"thresholds": {"hardness": "5"}}}, f"{S}.importance.thresholds.hardness"),
    ({"importance": {"thresholds": {"hardness": True}}}, f"{S}.importance.thresholds.hardness"),
    ({"importance": {"thresholds": {"hardness": BIG}}}, f"{S}.importance.thresholds.hardness"),
    ({"importance": {"thresholds": {"hardness": math.nan}}}, f"{S}.importance.thresholds.hardness"),
    ({"importance": {"enabled": "no"}}, f"{S}.importance.enabled"),
    ({"importance": {"model": 5}}, f"{S}.importance.model"),
    ({"importance": {"treshold_percent": 5}}, f"{S}.importance"),
    ({"solver": "x"}, f"{S}.solver"),
    ({"solver": {"options": [1]}}, f"{S}.solver.options"),
    ({"solver": {"tolerance": "0.1"}}, f"{S}.solver.tolerance"),
    ({"solver": {"tolerance": BIG}}, f"{S}.solver.tolerance"),
    ({"solver": {"seed": "1"}}, f"{S}.solver.seed"),
    ({"solver": {"data_support": "no"}}, f"{S}.solver.data_support"),
    ({"solver": {"method": 5}}, f"{S}.solver.method"),
    ({"solver": {"penalty": "x"}}, f"{S}.solver.penalty"),
    ({"solver": {"tolernce": 0.1}}, f"{S}.solver"),
    ({"servo": "x"}, f"{S}.servo"),
    ({"servo": {"period_s": "0.001"}}, f"{S}.servo.period_s"),
    ({"servo": {"period_s": BIG}}, f"{S}.servo.period_s"),
    ({"servo": {"realtime": "no"}}, f"{S}.servo.realtime"),
    ({"servo": {"passivity": "no"}}, f"{S}.servo.passivity"),
    ({"model": 5}, f"{S}.model"),
    ({"dimensions": "hardness"}, f"{S}.dimensions"),
    ({"dimensions": 5}, f"{S}.dimensions"),
    ({"renderer_options": [1]}, f"{S}.renderer_options"),
    ({"renderer_options": {"hardness": "x"}}, f"{S}.renderer_options.hardness"),
    ({"zz": 1}, S),
])
def test_settings_given_in_code_are_checked(settings, field):
    with pytest.raises(ValidationError) as exc:
        Scene(objects=[SceneObject(name="a", material="S7")], settings=settings)
    assert exc.value.field == field


@pytest.mark.parametrize("path, value", [
    (("importance", "threshold_percent"), BIG),
    (("importance", "thresholds", "hardness"), BIG),
])
def test_scene_file_int_beyond_float_range_is_named(path, value):
    # the schema takes 10**400 as a number; it raised TypeError / OverflowError
    settings: dict = {}
    cur = settings
    for k in path[:-1]:
        cur = cur.setdefault(k, {})
    cur[path[-1]] = value
    with pytest.raises(ValidationError) as exc:
        Scene.from_dict({"objects": [{"material": "S7"}], "settings": settings})
    assert exc.value.field == f"{S}." + ".".join(path)


@pytest.mark.parametrize("build, field", [
    (lambda: Scene(objects="abc"), "scene.objects"),
    (lambda: Scene(objects=[5]), "scene.objects[0]"),
    (lambda: Scene(objects=[SceneObject(name=5, material="S7")]), "scene.objects[0].name"),
    (lambda: Scene(objects=[SceneObject(name="a", material="S7", dimensions="hardness")]),
     "scene.objects[0].dimensions"),
    (lambda: Scene(objects=[SceneObject(name="a", material="S7", dimensions=[5])]),
     "scene.objects[0].dimensions[0]"),
    (lambda: Scene(objects=[SceneObject(name="a", material="S7")], settings=[1]), "scene.settings"),
    (lambda: Scene(objects=[SceneObject(name="a", material="S7")], devices=5), "scene.devices"),
    (lambda: Scene.for_material("S7", devices=[1]), "scene.devices"),
    (lambda: Scene.for_material("S7", dimensions="hardness"), "scene.objects[0].dimensions"),
    (lambda: Scene.for_material("S7", dimensions=5), "scene.objects[0].dimensions"),
    (lambda: Scene.for_material("S7", seed="abc"), "seed"),
    (lambda: Scene.for_material("S7", seed=1.7), "seed"),
    (lambda: Scene.for_material("S7", seed=True), "seed"),
    (lambda: Scene.for_material("S7", seed=1, solver="x"), "scene.settings.solver"),
])
def test_objects_devices_and_seed_given_in_code_are_checked(build, field):
    with pytest.raises(ValidationError) as exc:
        build()
    assert exc.value.field == field


@pytest.mark.parametrize("kw, field", [
    ({"seconds": "1"}, "seconds"),
    ({"seconds": BIG}, "seconds"),
    ({"seconds": 0.01, "realtime": "no"}, "realtime"),
    ({"seconds": 0.01, "devices": "x"}, "scene.devices"),
    ({"seconds": 0.01, "seed": "x"}, "seed"),
])
def test_render_arguments_are_checked(kw, field):
    with pytest.raises(ValidationError) as exc:
        hs.render("S7", **kw)
    assert exc.value.field == field


def test_render_plan_flags_are_bools():
    from hapticsdk.compiler import compile_scene
    from hapticsdk.runtime.render import render_plan

    plan = compile_scene(Scene.for_material("S7", solver={"method": "polish"}))
    for flag in ("realtime", "passivity", "hooks", "raise_on_fault"):
        with pytest.raises(ValidationError) as exc:
            render_plan(plan, seconds=0.01, **{flag: "no"})
        assert exc.value.field == flag


def test_good_scene_in_code_still_builds():
    sc = Scene.for_material("S7", dimensions=("hardness",), seed=3, devices={},
                            importance={"thresholds": {"hardness": 5}}, servo={"realtime": False})
    assert sc.settings["solver"]["seed"] == 3 and sc.objects[0].dimensions == ["hardness"]
    assert Scene.for_material("S7", dimensions=[]).objects[0].dimensions is None


@pytest.mark.parametrize("recorder", ["run.npz", 5, object()])
def test_render_plan_recorder_must_record(recorder):
    # the servo called recorder.record every tick and counted each failure as a renderer
    # error: a path or an object without record() recorded nothing, without a word
    from hapticsdk.compiler import compile_scene
    from hapticsdk.runtime.render import render_plan

    plan = compile_scene(Scene.for_material("S7", solver={"method": "polish"}))
    with pytest.raises(ValidationError) as exc:
        render_plan(plan, seconds=0.01, recorder=recorder)
    assert exc.value.field == "recorder"
