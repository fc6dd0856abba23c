"""Actuator.still_driving judges a read-back against rest, force and amplitude alike,
within readback_tolerance: half a declared step for a drive record, one step for a
reported output (docs: ActuatorLimits)."""

from __future__ import annotations

from typing import ClassVar

import pytest

from hapticsdk.devices.actuators import Actuator, ActuatorLimits
from hapticsdk.perception.dimensions import ChannelCommand


class _Held(Actuator):
    """Reports whatever the test sets as its output; stop() does not change it."""
    name: ClassVar[str] = "test-held"
    channel: ClassVar[str] = "force"
    accepts: ClassVar[dict[str, str]] = {"force_n": "N"}
    limits = ActuatorLimits(max_force_n=4.0, force_resolution_n=0.01)
    held = ChannelCommand("force", force_n=0.0)

    def _command(self, cmd: ChannelCommand) -> None:
        pass

    def _stop(self) -> None:
        pass

    def _read_back(self) -> ChannelCommand:
        return self.held


@pytest.mark.parametrize("source,step_share", [("drive", 0.5), ("output", 1.0)])
def test_a_force_left_on_is_named_and_one_within_the_step_is_rest(source, step_share):
    act = _Held().open()
    act.stop()  # what the render checks: after the final stop, before close
    act.readback_source = source  # type: ignore[misc]
    act.held = ChannelCommand("force", force_n=0.0)
    assert act.still_driving() is None
    tol = step_share * 0.01
    act.held = ChannelCommand("force", force_n=-0.9 * tol)  # within the share of one step
    assert act.still_driving() is None
    act.held = ChannelCommand("force", force_n=-1.5 * tol)
    assert act.still_driving() is not None and act.still_driving().startswith("force ")
    act.held = ChannelCommand("force", force_n=2.5)
    assert "force 2.5 N" == act.still_driving()
    act.close()
