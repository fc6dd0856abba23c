"""The kinematic probe's documented options: ``loop`` restarts the scripted trajectory
when it ends (default: hold the last point), reopening starts it again from t = 0, and
the probe applies no force whatever it is commanded (read-back 0, a stop clears the
ignored command)."""

import pytest

from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.sim.finger import Trajectory
from hapticsdk.sim.probe import VirtualProbe

# a 1 s ramp from y = 0 to y = -2 mm: at time t inside it, y = -2 t
RAMP = Trajectory([(0.0, 0.0, 0.0), (1.0, 0.0, -2.0)])


def _advance(p, seconds, dt=0.01):
    for _ in range(round(seconds / dt)):
        p.step(dt)


@pytest.mark.parametrize("loop, expected_y", [(True, -0.5), (False, -2.0)])
def test_loop_restarts_the_trajectory_and_no_loop_holds_its_end(loop, expected_y):
    # 1.25 s on a 1 s ramp: a looped probe is 0.25 s into its second pass (y = -0.5);
    # an unlooped one holds the end (y = -2). Tolerance: summing 125 steps of 0.01 s
    # carries float error ~1e-15 s, far below the 1e-9 mm asked.
    p = VirtualProbe(trajectory=RAMP, loop=loop)
    p.open()
    _advance(p, 1.25)
    assert p.read_state().position_mm[1] == pytest.approx(expected_y, abs=1e-9)
    p.close()


def test_reopening_starts_the_trajectory_again():
    p = VirtualProbe(trajectory=RAMP)
    p.open()
    _advance(p, 0.5)
    assert p.read_state().position_mm[1] == pytest.approx(-1.0, abs=1e-9)
    p.close()
    p.open()
    assert p.read_state().position_mm[1] == pytest.approx(0.0, abs=1e-12)
    p.close()


def test_commanded_force_is_ignored_read_back_zero_and_stop_clears_it():
    p = VirtualProbe(trajectory=RAMP)
    p.open()
    for k in range(200):  # the safety layer ramps the command up; the probe keeps what it was sent
        sent = p.command(ChannelCommand("force", force_n=0.7), now=k * 0.01)
    assert sent.force_n > 0 and p.ignored_force_n == sent.force_n
    back = p.read_back()
    assert back is None or back.force_n == 0.0  # it has no motors: it applies nothing
    p.stop()
    assert p.ignored_force_n == 0.0
    p.close()
