"""Names that moved keep working for one minor version with a DeprecationWarning naming
the new place (docs/api.md, CHANGELOG "Deprecated")."""

from __future__ import annotations

import importlib
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
]


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
