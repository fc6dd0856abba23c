"""A real (not simulated) actuator is always driven by a servo paced on the clock: the
plan's ``servo.realtime`` (data) cannot run it unpaced, commands back to back with the
servo's seconds over in a fraction of the wall time. Code may still choose."""

from typing import Any, ClassVar

import pytest

from hapticsdk.devices.actuators import Actuator
from hapticsdk.compiler import compile_scene
from hapticsdk.plugins import registry
from hapticsdk.runtime.render import render_plan


class _RealCoil(Actuator):
    """A stand-in for a real vibration actuator: takes commands, drives nothing."""

    name: ClassVar[str] = "test-real-coil"
    channel: ClassVar[str] = "vibration"
    accepts: ClassVar[dict[str, str]] = {"frequency_hz": "Hz", "amplitude": "V"}
    hapticsdk_api: ClassVar[str] = ">=1,<2"

    def __init__(self, **options: Any) -> None:
        super().__init__(**options)

    def _open(self) -> None:
        pass

    def _command(self, cmd: Any) -> None:
        pass

    def _stop(self) -> None:
        pass

    def _close(self) -> None:
        pass


@pytest.fixture
def real_coil():
    assert not _RealCoil.simulated   # the base's default: real unless declared simulated
    registry("actuator").register("test-real-coil", _RealCoil)
    try:
        yield
    finally:
        registry("actuator").unregister("test-real-coil")


def _plan(actuator: str, realtime: Any) -> dict[str, Any]:
    scene = {"objects": [{"name": "o", "material": {"name": "m", "intensities": {"roughness": 0.5}}}],
             "devices": {"vibration": {"actuator": actuator}}}
    plan = compile_scene(scene).to_dict()
    if realtime is not None:
        plan["settings"].setdefault("servo", {})["realtime"] = realtime
    return plan


@pytest.mark.parametrize("plan_says", [None, False])
def test_a_real_actuator_is_paced_whatever_the_plan_says(real_coil, plan_says):
    rep = render_plan(_plan("test-real-coil", plan_says), seconds=0.05, hooks=False)
    assert rep.loop.realtime is True
    # paced: the servo's 50 ms took at least about that long on the clock (a loop run
    # back to back renders them in well under 10 ms)
    assert rep.wall_s >= 0.04


@pytest.mark.parametrize("plan_says", [None, False])
def test_simulated_devices_keep_the_fast_default(plan_says):
    rep = render_plan(_plan("piezo-virtual", plan_says), seconds=0.05, hooks=False)
    assert rep.loop.realtime is False


def test_code_may_still_choose(real_coil):
    rep = render_plan(_plan("test-real-coil", None), seconds=0.05, hooks=False, realtime=False)
    assert rep.loop.realtime is False
