"""Any value at any place of a scene or a render plan ends in a named error or a clean
result, never a raw exception (docs/safety.md, "Non-finite numbers" and "Named errors").

A property test over the class, not samples: hypothesis takes a valid scene (the desk
example, with geometry, poses and intensities) or a valid compiled plan, puts one drawn
value at one drawn place (any node: a leaf, a group, the whole object), and the scene is
read and compiled, the plan read and rendered for 5 ms on the simulated devices. The
values: half of the draws NaN, +-inf, +-10**400, +-1e308, -1, 0, 2**63 or True; the
others None, bools, ints up to 10**30, every float, strings (empty, unicode, NUL, a path, 5000 characters, names the
SDK knows) and lists / objects of them. An error must be a HapticSDKError; a plan
carried ``settings.renderer_options: true`` into the renderer, which raised TypeError.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from json_leaves import nodes, replaced

from hapticsdk.errors import HapticSDKError

ROOT = Path(__file__).resolve().parents[2]
NAMES = ["", "S7", "hardness", "roughness", "force", "vibration", "piezo-virtual", "solver", "servo",
         "renderer_options", "options", "gain", "\x00", "../../etc/passwd", "\u202e", "x" * 5000]

SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-10 ** 30, 10 ** 30), st.just(10 ** 400),
                    st.floats(), st.text(max_size=12), st.sampled_from(NAMES))
#: the numbers this test is about, drawn as often as everything else together
EXTREMES = st.sampled_from([float("nan"), float("inf"), float("-inf"), 10 ** 400, -10 ** 400, 1e308, -1e308,
                            -1, 0, 2 ** 63, True])
VALUES = st.one_of(EXTREMES, st.recursive(SCALARS, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8) | st.sampled_from(NAMES), inner, max_size=4)),
    max_leaves=8))


def _places(data):
    """A strategy for a place in ``data``: first one of its top-level keys (or the whole
    object), then any node under it -- each part of the document gets its share of the
    draws, however many numbers a plan's materials hold."""
    under: dict = {k: [] for k in data}
    for p, _ in nodes(data):
        if p:
            under[p[0]].append(p)
    groups = [[()]] + [under[k] for k in data]
    return st.sampled_from(groups).flatmap(st.sampled_from)


def _put(data, path, value):
    return value if not path else replaced(data, path, value)


def _scene():
    d = json.loads((ROOT / "examples/scenes/desk-spatial.json").read_text())
    d["objects"][1]["intensities"] = {"hardness": 0.7}
    d["settings"]["solver"]["method"] = "polish"   # the quick solver: ~10 ms a compile
    return d


SCENE = _scene()
SCENE_PLACES = _places(SCENE)


def test_the_unchanged_scene_compiles():
    from hapticsdk.compiler import compile_scene
    from hapticsdk.scene import Scene
    assert compile_scene(Scene.from_dict(SCENE)).materials


@settings(max_examples=1000, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(path=SCENE_PLACES, value=VALUES)
def test_any_value_anywhere_in_a_scene(path, value):
    from hapticsdk.compiler import compile_scene
    from hapticsdk.scene import Scene
    try:
        compile_scene(Scene.from_dict(_put(SCENE, path, value)))
    except HapticSDKError:
        pass


@pytest.fixture(scope="module")
def plan_dict():
    from hapticsdk.compiler import compile_scene
    from hapticsdk.scene import Scene
    return compile_scene(Scene.for_material("S7", solver={"method": "polish"})).to_dict()


@pytest.fixture(scope="module")
def plan_places(plan_dict):
    """The places of the plan, listed once (the plan's nodes are the same on every draw)."""
    return _places(plan_dict)


def test_the_unchanged_plan_renders(plan_dict):
    from hapticsdk.runtime.render import render_plan
    render_plan(plan_dict, seconds=0.005)


@settings(max_examples=1500, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(data=st.data(), value=VALUES)
def test_any_value_anywhere_in_a_plan(plan_dict, plan_places, data, value):
    from hapticsdk.runtime.render import render_plan
    path = data.draw(plan_places, label="path")
    try:
        render_plan(_put(plan_dict, path, value), seconds=0.005)
    except HapticSDKError:
        pass


def test_plan_renderer_options_must_be_objects(plan_dict):
    """The case the property test found, named: the plan's settings are checked as the
    scene's are (the plan schema leaves them open)."""
    from hapticsdk.errors import ValidationError
    from hapticsdk.runtime.render import render_plan
    for bad in (True, [None], "x", 1):
        d = replaced(plan_dict, ("settings", "renderer_options"), bad)
        with pytest.raises(ValidationError) as exc:
            render_plan(d, seconds=0.005)
        assert exc.value.field == "plan.settings.renderer_options"
    d = replaced(plan_dict, ("settings", "solver", "tolerance"), 10 ** 400)
    with pytest.raises(ValidationError) as exc:
        render_plan(d, seconds=0.005)
    assert exc.value.field == "plan.settings.solver.tolerance"
