"""The safety layer's stiffness cap reads the penetration of every kind of state it is
handed (issue 30, round 9): the loop's plain-float ``SensedState`` from its ``py`` (no
property frame), a subclass through its own ``penetration_mm`` (the loop's contact-frame
state in a spatial scene), a plain ``DeviceState`` from its position array, each capped as
``|F| <= k_max * max(penetration, 0) + stiffness_offset_n``."""

from __future__ import annotations

import numpy as np
import pytest

from hapticsdk.devices.actuators import ActuatorLimits, DeviceState, SensedState
from hapticsdk.devices.safety import SafetyLayer
from hapticsdk.perception.dimensions import ChannelCommand

K = 2.0


class _AlongNormal(SensedState):
    """A state whose penetration is along a contact normal, not -y (as the loop's
    ``_ContactState`` in a spatial scene)."""

    __slots__ = ("_pen",)

    @property
    def penetration_mm(self) -> float:
        return self._pen


def _layer() -> SafetyLayer:
    lay = SafetyLayer(ActuatorLimits(max_stiffness_n_per_mm=K), ramp_time_s=0.0)
    lay.reset(0.0)
    lay.observe(SensedState.of(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    lay.filter(ChannelCommand("f", force_n=0.0), 0.0)
    assert lay.phase == "running"
    return lay


def _capped(lay: SafetyLayer, st, t: float) -> float:
    lay.observe(st)
    return lay.filter(ChannelCommand("f", force_n=50.0), t).force_n


@pytest.mark.parametrize("depth", [0.5, 1.5, 0.0, -1.0])
def test_each_kind_of_state_is_capped_at_its_own_penetration(depth):
    lay = _layer()
    off = lay.settings.stiffness_offset_n
    cap = K * max(depth, 0.0) + off
    # the loop's floats: the penetration is -py
    assert _capped(lay, SensedState.of(0.001, 3.0, -depth, 1.0, 0.0, 0.0, 0.0), 0.001) == pytest.approx(cap)
    # a plain DeviceState: from its position array
    st = DeviceState(0.002, np.array([3.0, -depth, 1.0]), np.zeros(3))
    assert _capped(lay, st, 0.002) == pytest.approx(cap)
    # a subclass with its own penetration (here 1 mm deeper than -py): its own is used
    sub = _AlongNormal.of(0.003, 3.0, -depth, 1.0, 0.0, 0.0, 0.0)
    sub._pen = depth + 1.0
    assert _capped(lay, sub, 0.003) == pytest.approx(K * max(depth + 1.0, 0.0) + off)
    assert lay.hits["max_stiffness_n_per_mm"] == 3
