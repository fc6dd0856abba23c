"""Every argument of the live session's methods, given each value of one table of bad
values in turn: a HapticSDKError or a clean result, never a raw exception, and the
session keeps running without a fault and stops every actuator on close (docs/safety.md,
"Named errors"). Found by this table: an object name or an event kind that is a list,
a dict or an array (``set_material``, ``move_object``, ``remove_object``, ``off_event``)
raised TypeError (unhashable) from a dict lookup."""

from __future__ import annotations

import numpy as np
import pytest

from hapticsdk.errors import HapticSDKError, ValidationError
from hapticsdk.runtime.session import Session

SCENE = {"schema_version": 2, "objects": [{"name": "a", "material": "S7",
                                           "geometry": {"shape": "sphere", "radius_mm": 20}}]}
BAD = [float("nan"), float("inf"), 10 ** 400, -1, 1e308, True, None, "", "x" * 10000, "\x00", [0.5], {"a": 1},
       {"hardness": float("nan")}, {None: 0.5}, {"hardness": 10 ** 400}, np.array([np.nan]), object(), b"b",
       2 ** 63, 1j]
SPHERE = {"shape": "sphere", "radius_mm": 10}
CALLS = {
    "set_material.object": lambda s, v: s.set_material(v, "S7"),
    "set_material.material": lambda s, v: s.set_material("a", v),
    "set_material.ramp_s": lambda s, v: s.set_material("a", "S7", ramp_s=v),
    "set_material.refine": lambda s, v: s.set_material("a", "S7", refine=v),
    "add_object.name": lambda s, v: s.add_object(v, "S7", SPHERE),
    "add_object.material": lambda s, v: s.add_object("b", v, SPHERE),
    "add_object.geometry": lambda s, v: s.add_object("b", "S7", v),
    "add_object.radius_mm": lambda s, v: s.add_object("b", "S7", {"shape": "sphere", "radius_mm": v}),
    "add_object.pose": lambda s, v: s.add_object("b", "S7", SPHERE, v),
    "move_object.name": lambda s, v: s.move_object(v, {"position_mm": [0, 0, 0]}),
    "move_object.pose": lambda s, v: s.move_object("a", v),
    "move_object.position_mm": lambda s, v: s.move_object("a", {"position_mm": [v, 0, 0]}),
    "remove_object.name": lambda s, v: s.remove_object(v),
    "pause.on": lambda s, v: s.pause(v),
    "on_event.kind": lambda s, v: s.on_event(v, lambda e: None),
    "on_event.callback": lambda s, v: s.on_event("fault", v),
    "off_event.kind": lambda s, v: s.off_event(v, None),
}


@pytest.fixture(scope="module")
def session():
    s = Session(SCENE, isolation="thread", realtime=False, refine=False)
    yield s
    s.close()


@pytest.mark.parametrize("call", list(CALLS))
def test_each_bad_value_is_named(session, call):
    raw = []
    for value in BAD:
        try:
            CALLS[call](session, value)
        except HapticSDKError:
            pass
        except Exception as exc:   # noqa: BLE001 - the test is that none gets here
            raw.append(f"{value!r:.40}: {type(exc).__name__}: {exc}"[:200])
        if call.startswith("add_object"):   # a value accepted: the object goes again
            try:
                session.remove_object("b")
            except ValidationError:
                pass
    assert not raw, "\n".join(raw)


@pytest.mark.parametrize("call, field", [("set_material.object", "object"), ("move_object.name", "object"),
                                         ("remove_object.name", "object"), ("off_event.kind", "kind")])
def test_a_name_that_is_no_string_is_named(session, call, field):
    for value in ([0.5], {"a": 1}, np.array(["a"])):
        with pytest.raises(ValidationError) as exc:
            CALLS[call](session, value)
        assert exc.value.field == field


def test_the_session_runs_on_and_stops_every_actuator():
    s = Session(SCENE, isolation="thread", realtime=False, refine=False)
    for call in CALLS.values():
        for value in BAD:
            try:
                call(s, value)
            except HapticSDKError:
                pass
    s.pause(False)
    report = s.close()
    assert report["report"]["fault"] is None
    assert sorted(report["stopped"]) == sorted(["omni-virtual", "piezo-virtual", "voicecoil-virtual"])
