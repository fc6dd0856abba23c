"""Live API bounds (issue 31, item 6): intensities are numbers; poses and sizes are finite
and inside the workspace plus margin, in the live session and in scene files."""

from __future__ import annotations

import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.runtime.session import Session
from hapticsdk.scene import Scene
from hapticsdk.scene.bounds import DEFAULT_WORKSPACE_MM, limits

SCENE = {"schema_version": 2, "objects": [{"name": "a", "material": "S7",
                                           "geometry": {"shape": "sphere", "radius_mm": 20}}]}
BOX, MAX_SIZE = limits()


@pytest.fixture(scope="module")
def session():
    s = Session(SCENE, isolation="thread", realtime=False, refine=False)
    yield s
    s.close()


@pytest.mark.parametrize("value", ["0.5", b"0.5", None, True, float("nan"), 1.5, -0.1, [0.5]])
def test_intensities_must_be_numbers_in_0_1(session, value):
    with pytest.raises(ValidationError) as ei:
        session.set_material("a", {"hardness": value})
    assert ei.value.field == "material.hardness"


@pytest.mark.parametrize("pos,axis", [([1e308, 0, 0], 0), ([0, -1e308, 0], 1), ([0, 0, float("inf")], 2),
                                      ([0, BOX[1][1] + 1.0, 0], 1)])
def test_move_and_add_outside_the_workspace_are_refused(session, pos, axis):
    with pytest.raises(ValidationError) as ei:
        session.move_object("a", {"position_mm": pos})
    assert ei.value.field in (f"objects.a.pose.position_mm[{axis}]", f"pose.position_mm[{axis}]"), ei.value.field
    with pytest.raises(ValidationError) as ei:
        session.add_object("b", "S7", {"shape": "sphere", "radius_mm": 10}, {"position_mm": pos})
    assert ei.value.field.endswith(f"position_mm[{axis}]")
    assert "b" not in session.objects


@pytest.mark.parametrize("geometry,key", [({"shape": "sphere", "radius_mm": 1e308}, "radius_mm"),
                                          ({"shape": "box", "half_size_mm": [10, MAX_SIZE * 1.01, 10]},
                                           "half_size_mm[1]")])
def test_sizes_beyond_the_workspace_are_refused(session, geometry, key):
    with pytest.raises(ValidationError) as ei:
        session.add_object("c", "S7", geometry)
    assert ei.value.field == f"objects.c.geometry.{key}"


def test_inside_the_bounds_is_accepted(session):
    session.move_object("a", {"position_mm": [BOX[0][1], 0, 0]})  # the edge of workspace + margin
    session.add_object("d", {"hardness": 0.5}, {"shape": "sphere", "radius_mm": MAX_SIZE})
    assert "d" in session.objects
    session.remove_object("d")


def test_scene_files_have_the_same_bounds():
    big = {**SCENE, "objects": [{**SCENE["objects"][0], "pose": {"position_mm": [0, 0, 1e308]}}]}
    with pytest.raises(ValidationError) as ei:
        Scene.from_dict(big)
    assert ei.value.field == "scene.objects[0].pose.position_mm[2]"
    big = {**SCENE, "objects": [{**SCENE["objects"][0], "geometry": {"shape": "sphere", "radius_mm": 1e9}}]}
    with pytest.raises(ValidationError) as ei:
        Scene.from_dict(big)
    assert ei.value.field == "scene.objects[0].geometry.radius_mm"


def test_margin_is_one_workspace_extent():
    extent = max(hi - lo for lo, hi in DEFAULT_WORKSPACE_MM)
    assert BOX[0] == (DEFAULT_WORKSPACE_MM[0][0] - extent, DEFAULT_WORKSPACE_MM[0][1] + extent)
    box, size = limits(((0, 100), (0, 50), (-10, 10)))
    assert box[1] == (-100, 150) and size == 200
