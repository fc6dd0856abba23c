"""Scenes and plans given as dicts (not files) are bounded in depth as read_json bounds a
file: 5000 nested levels -- or a dict that holds itself -- raise ValidationError naming
where it goes too deep, not RecursionError from the deep copy, the schema or a repr."""

import json

import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.scene import Scene


def _deep(n, leaf=None):
    x = {} if leaf is None else leaf
    for _ in range(n):
        x = {"a": x}
    return x


def _deepl(n):
    x: list = []
    for _ in range(n):
        x = [x]
    return x


@pytest.mark.parametrize("data, field", [
    ({"objects": [{"material": "S7"}], "settings": {"solver": {"options": _deep(5000)}}},
     "scene.settings.solver.options.a"),
    ({"objects": [{"material": "S7"}], "devices": {"force": {"actuator": "omni-virtual", "options": _deep(5000)}}},
     "scene.devices.force.options.a"),
    ({"objects": [{"material": "S7", "name": _deepl(5000)}]}, "scene.objects[0].name[0]"),
    ({"objects": [{"material": "S7"}], "description": _deepl(5000)}, "scene.description[0]"),
])
def test_deep_scene_dict_is_refused(data, field):
    with pytest.raises(ValidationError) as exc:
        Scene.from_dict(data)
    assert exc.value.field.startswith(field)


def test_deep_or_cyclic_settings_in_code_are_refused():
    with pytest.raises(ValidationError) as exc:
        Scene.for_material("S7", renderer_options={"hardness": _deep(5000)})
    assert exc.value.field.startswith("scene.settings.renderer_options.hardness")
    loop: dict = {}
    loop["again"] = loop
    with pytest.raises(ValidationError):
        Scene.for_material("S7", renderer_options={"hardness": loop})


def test_deep_plan_dict_is_refused():
    from hapticsdk.compiler import compile_scene
    from hapticsdk.plan import RenderPlan

    plan = json.loads(json.dumps(compile_scene(Scene.for_material("S7", solver={"method": "polish"})).to_dict(),
                                 default=str))
    plan["materials"]["S7"]["solve"] = _deep(5000)
    with pytest.raises(ValidationError) as exc:
        RenderPlan.from_dict(plan)
    assert exc.value.field.startswith("plan.materials.S7.solve")


def test_depth_bound_is_that_of_a_file():
    from hapticsdk.schemas_io import MAX_JSON_DEPTH, check_depth

    check_depth(_deep(MAX_JSON_DEPTH - 1), "x")
    with pytest.raises(ValidationError):
        check_depth(_deep(MAX_JSON_DEPTH + 1), "x")
