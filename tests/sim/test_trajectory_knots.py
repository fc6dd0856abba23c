"""Trajectory knots, from its documented contract: times strictly increasing (a repeated
time is refused), the path's clock starts at its first knot (knots at 5..6 s make a 1 s
path starting at t = 0), the velocity is 0 outside the knots, and ``at`` holds the first
point before the start."""

import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.sim.finger import Trajectory


def test_a_repeated_knot_time_is_refused():
    with pytest.raises(ValidationError):
        Trajectory([(0.0, 0.0, 0.0), (1.0, 0.0, -1.0), (1.0, 0.0, -2.0)])


def test_the_clock_starts_at_the_first_knot():
    tr = Trajectory([(5.0, 0.0, 0.0), (6.0, 10.0, -2.0)])
    assert tr.duration_s == 1.0
    x, y = tr.position(0.5)  # halfway along the single segment
    assert (float(x), float(y)) == (5.0, -1.0)


def test_velocity_is_zero_outside_the_knots_and_the_segment_slope_inside():
    tr = Trajectory([(0.0, 0.0, 0.0), (1.0, 10.0, -2.0)])
    vx, vy = tr.velocity([-0.5, 0.5, 1.5])
    assert vx.tolist() == [0.0, 10.0, 0.0] and vy.tolist() == [0.0, -2.0, 0.0]
    assert tr.at(-0.1) == (0.0, 0.0, 0.0, 0.0)
    assert tr.at(0.0) == (0.0, 0.0, 10.0, -2.0)  # at the first knot: the first segment's slope
