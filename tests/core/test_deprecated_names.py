"""Names that moved keep working for one minor version with a DeprecationWarning naming
the new place (docs/api.md, CHANGELOG "Deprecated")."""

from __future__ import annotations

import importlib
import re
import sys
import warnings

import pytest

MOVED_NAMES = [  # (old module, name, new module)
    ("hapticsdk.scene", "compile_scene", "hapticsdk.compiler"),
    ("hapticsdk.plan", "compile_scene", "hapticsdk.compiler"),
    ("hapticsdk.plan", "api_compatible", "hapticsdk.plugin_api"),
    ("hapticsdk.plan", "check_plugin_api", "hapticsdk.plugin_api"),
    ("hapticsdk.calibration.voicecoil", "VoiceCoilFit", "hapticsdk.calibration.voicecoil_fit"),
    ("hapticsdk.calibration.voicecoil", "fit_voicecoil", "hapticsdk.calibration.voicecoil_fit"),
    ("hapticsdk.doctor", "calibration_dir", "hapticsdk.calibration"),
    ("hapticsdk.training.recordings", "schema_dir", "hapticsdk.schemas_io"),
]

MOVED_MODULES = [  # (old module, new module, a name users imported from it)
    ("hapticsdk.rendering", "hapticsdk.runtime.render", "render_plan"),
    ("hapticsdk.rendering", "hapticsdk.runtime.render", "RenderReport"),
    ("hapticsdk.importance", "hapticsdk.compiler.importance", "PaperRegressionImportance"),
    ("hapticsdk.runtime.limits", "hapticsdk.scene.limits", "check_period"),
    ("hapticsdk.problems", "hapticsdk.solvers.problems", "build_problem"),
    ("hapticsdk.problems", "hapticsdk.solvers.problems", "solve"),
    ("hapticsdk.features", "hapticsdk.perception.features", "Feature"),
    ("hapticsdk.features", "hapticsdk.perception.features", "FeatureSpace"),
    ("hapticsdk.features", "hapticsdk.perception.features", "same_unit"),
    ("hapticsdk.dimensions", "hapticsdk.perception.dimensions", "PerceptionDimension"),
    ("hapticsdk.dimensions", "hapticsdk.perception.dimensions", "ChannelCommand"),
    ("hapticsdk.dimensions", "hapticsdk.perception.dimensions", "declared_roles"),
    ("hapticsdk.models", "hapticsdk.perception.models", "PerceptionModel"),
    ("hapticsdk.models", "hapticsdk.perception.models", "MLPModel"),
    ("hapticsdk.materials", "hapticsdk.perception.materials", "load_library"),
    ("hapticsdk.materials", "hapticsdk.perception.materials", "DEFAULT_LIBRARY"),
    ("hapticsdk.channels", "hapticsdk.perception.channels", "CHANNELS"),
    ("hapticsdk.actuators", "hapticsdk.devices.actuators", "Actuator"),
    ("hapticsdk.actuators", "hapticsdk.devices.actuators", "create_actuator"),
    ("hapticsdk.actuators", "hapticsdk.devices.actuators", "CHANNELS"),
    ("hapticsdk.actuators", "hapticsdk.devices.actuators", "_frozen3"),
    ("hapticsdk.safety", "hapticsdk.devices.safety", "SafetyLayer"),
    ("hapticsdk.safety", "hapticsdk.devices.safety", "declared_limits"),
    ("hapticsdk.device_options", "hapticsdk.devices.device_options", "privileged_options"),
    ("hapticsdk.device_options", "hapticsdk.devices.device_options", "trusted_options"),
]

#: the modules that were flat in hapticsdk/ in 0.1 and moved into a stage's folder in 0.2
#: (old name, new name), with a class of each (the class a pickle names)
MOVED_CLASSES = [("features", "perception.features", "Feature"),
                 ("dimensions", "perception.dimensions", "ChannelCommand"),
                 ("models", "perception.models", "MLPModel"),
                 ("materials", "perception.materials", "Material"),
                 ("actuators", "devices.actuators", "ActuatorLimits"),
                 ("actuators", "devices.actuators", "SensedState"),
                 ("safety", "devices.safety", "SafetySettings"),
                 ("device_options", "devices.device_options", "PrivilegedOptionError")]


@pytest.mark.parametrize("old, name, new", MOVED_NAMES)
def test_moved_name_warns_and_is_the_same_object(old, name, new):
    mod = importlib.import_module(old)
    with pytest.warns(DeprecationWarning, match=f"{new}.{name}"):
        value = getattr(mod, name)
    assert value is getattr(importlib.import_module(new), name)


@pytest.mark.parametrize("old, new, name", MOVED_MODULES)
def test_moved_module_warns_on_import_and_serves_its_names(old, new, name, monkeypatch):
    monkeypatch.delitem(sys.modules, old, raising=False)
    with pytest.warns(DeprecationWarning, match=new.replace(".", r"\.")):
        mod = importlib.import_module(old)
    assert getattr(mod, name) is getattr(importlib.import_module(new), name)


def test_the_old_render_helpers_moved_with_the_module(monkeypatch):
    monkeypatch.delitem(sys.modules, "hapticsdk.rendering", raising=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from hapticsdk.rendering import ConstantForceRenderer
    from hapticsdk.runtime.replacements import ConstantForceRenderer as now
    assert ConstantForceRenderer is now


def test_unknown_names_still_raise_attribute_error():
    import hapticsdk.scene
    with pytest.raises(AttributeError, match="no attribute 'nothing_here'"):
        hapticsdk.scene.nothing_here  # noqa: B018


def test_current_names_do_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        from hapticsdk.compiler import compile_scene  # noqa: F401
        from hapticsdk.runtime.render import render_plan  # noqa: F401
        from hapticsdk.scene import Scene  # noqa: F401


def test_scene_compile_method_warns_and_compiles():
    from hapticsdk.compiler import compile_scene
    from hapticsdk.scene import Scene
    scene = Scene.for_material({"hardness": 0.5}, seed=0)
    with pytest.warns(DeprecationWarning, match=r"hapticsdk\.compiler\.compile_scene"):
        plan = scene.compile()
    assert plan.to_dict()["materials"].keys() == compile_scene(scene).to_dict()["materials"].keys()


def test_every_moved_module_is_tested_here():
    """A shim registered in ``MOVED_MODULES`` has a row above (and a row names a real
    shim): a module moved later is covered by the parametrised test, or this fails."""
    from hapticsdk._deprecation import MOVED_MODULES as registered
    assert {(old, new) for old, new, _ in MOVED_MODULES} == set(registered.items())


@pytest.mark.parametrize("old, new, cls", MOVED_CLASSES)
def test_a_class_pickled_at_its_old_place_still_unpickles(old, new, cls, monkeypatch):
    """0.1 and 0.2 pickles name ``hapticsdk.<old>.<cls>``; unpickling resolves that
    path through the shim (warning) to the class at its new place. Protocol 0's
    ``GLOBAL`` opcode names the module and class as text, the way those pickles do."""
    import pickle
    monkeypatch.delitem(sys.modules, f"hapticsdk.{old}", raising=False)
    with pytest.warns(DeprecationWarning, match=re.escape(f"hapticsdk.{new}")):
        got = pickle.loads(f"chapticsdk.{old}\n{cls}\n.".encode())
    assert got is getattr(importlib.import_module(f"hapticsdk.{new}"), cls)


def test_a_feature_pickled_by_0_1_still_unpickles():
    """A whole ``Feature`` instance pickled when the class lived in ``hapticsdk.features``."""
    import pickle

    from hapticsdk.perception.features import Feature
    blob = pickle.dumps(Feature("GS", "N/mm", 0.1, 2.0), protocol=2)
    assert b"hapticsdk.perception.features" in blob
    old = blob.replace(b"hapticsdk.perception.features", b"hapticsdk.features")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        got = pickle.loads(old)
    assert got == Feature("GS", "N/mm", 0.1, 2.0) and type(got) is Feature


def test_the_top_level_moved_names_do_not_warn():
    """``hs.Feature``, ``hs.PerceptionDimension``, ``hs.Actuator`` ... resolve to the new
    places with no warning (a fresh interpreter: the top level caches what it resolved)."""
    import subprocess
    code = ("import warnings; warnings.simplefilter('error', DeprecationWarning)\n"
            "import hapticsdk as hs\n"
            "names = ['Feature', 'FeatureSpace', 'PerceptionDimension', 'PerceptionModel', "
            "'Material', 'load_library', 'Actuator', 'HapticDevice', 'create_actuator']\n"
            "print(' '.join(getattr(hs, n).__module__ for n in names))\n"
            "print(len(hs.load_library()))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    mods, n = r.stdout.split("\n")[:2]
    assert set(mods.split()) == {f"hapticsdk.perception.{m}" for m in ("features", "dimensions", "models", "materials")
                                 } | {"hapticsdk.devices.actuators"}
    assert int(n) > 0


def test_the_actuator_log_keeps_its_0_1_logger_name(caplog):
    """Users silence or route the actuators' log by the logger name ``hapticsdk.actuators``
    (so does the conformance kit); the module moved, the name did not. A stop that fails
    is logged through that logger."""
    import logging

    from hapticsdk.devices.actuators import create_actuator
    act = create_actuator("voicecoil-virtual")
    act.open()

    def broken() -> None:
        raise OSError("stop failed on purpose")
    act._stop = broken  # type: ignore[method-assign]
    with caplog.at_level(logging.ERROR, logger="hapticsdk.actuators"):
        act.stop()
    del act._stop
    act.close()
    assert [r.name for r in caplog.records if "stop failed on purpose" in r.getMessage()] == ["hapticsdk.actuators"]
