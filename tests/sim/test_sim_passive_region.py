"""Goal 2: inside the passive region the wall never gives energy to the hand (20 scripted
trajectories x 10 s x 3 stiffnesses x 3 periods, vectorised), and a free decay from
inside the wall never gains energy."""

import numpy as np
import pytest

from hapticsdk.sim.arm import ArmBatch, ArmParams
from hapticsdk.sim.finger import FINGERS, FingerParams, press_slide, taps


def _twenty_trajectories(duration_s=10.0):
    bases = [press_slide(depth_mm=d, speed_mm_s=s, press_s=p, release_s=p, slide_s=0.5, rest_s=0.1)
             for d in (1.0, 3.0, 6.0) for s in (40.0, 150.0) for p in (0.05, 0.4)]
    bases += [taps(n=3, depth_mm=d, down_s=q, up_s=q) for d in (1.0, 4.0) for q in (0.01, 0.05)]
    bases += [press_slide(depth_mm=2.0, speed_mm_s=80.0), taps(), press_slide(depth_mm=8.0, press_s=0.02,
              release_s=0.02), taps(n=10, depth_mm=3.0, down_s=0.01, up_s=0.01, dwell_s=0.01, pause_s=0.03)]
    out = []
    for b in bases:
        tr = b
        while tr.duration_s < duration_s:
            tr = tr.then(b, gap_s=0.01)
        out.append(tr)
    assert len(out) == 20
    return out


@pytest.mark.parametrize("T", [0.5e-3, 1e-3, 2e-3])
def test_no_energy_to_the_hand_inside_the_passive_region(T):
    b = 0.5
    kcrit = 2 * b / T / 1000.0  # N/mm
    trs = _twenty_trajectories()
    cells = [(f * kcrit, tr, fg) for f in (0.1, 0.5, 0.9) for tr in trs for fg in ("soft", "stiff")]
    arm = ArmParams(damping_ns_per_m=b, encoder_resolution_mm=0.0)
    K = np.array([c[0] for c in cells])
    n = int(round(10.0 / T))
    tt = np.arange(n + 1) * T
    R = np.array([c[1].position(tt)[1] for c in cells])
    batch = ArmBatch(T, [arm] * len(cells), [FINGERS[c[2]] for c in cells], y0_mm=R[:, 0], track_energy=True)
    e_max = np.zeros(len(cells))
    pressed = np.zeros(len(cells))
    for k in range(n):
        y = batch.measured_mm()
        f = batch.step(np.where(y < 0, -K * y, 0.0), R[:, k], (R[:, k + 1] - R[:, k]) / T)
        np.maximum(e_max, batch.energy_to_user_j(), out=e_max)
        np.maximum(pressed, f, out=pressed)
    assert e_max.max() <= 1e-6  # min_t W_d >= -1e-6 J
    assert pressed.min() > 0  # every cell actually touched the wall


@pytest.mark.parametrize("T", [0.5e-3, 1e-3, 2e-3])
def test_free_decay_never_gains_energy(T):
    """No hand: start 1 mm inside the wall at rest; total energy 1/2 m v^2 + 1/2 K x+^2 at
    the ticks is non-increasing (to 1e-9 J per tick) over 10 s."""
    b = 0.5
    kcrit = 2 * b / T / 1000.0
    K = np.array([0.1, 0.5, 0.9]) * kcrit
    arm = ArmParams(damping_ns_per_m=b, encoder_resolution_mm=0.0)
    batch = ArmBatch(T, [arm] * 3, [FingerParams(0.0, 0.0, 0.0)] * 3, y0_mm=-1.0)
    n = int(round(10.0 / T))
    def energy():
        pen = np.maximum(-batch.y, 0.0)
        return 0.5 * arm.mass_kg * batch.v ** 2 + 0.5 * K * 1000.0 * pen ** 2
    e_prev = energy()
    worst = -np.inf
    for _ in range(n):
        y = batch.measured_mm()
        batch.step(np.where(y < 0, -K * y, 0.0), np.zeros(3), np.zeros(3))
        e = energy()
        worst = max(worst, float(np.max(e - e_prev)))
        e_prev = e
    assert worst <= 1e-9
