"""PlantBatch.step's ``live`` mask: a lane not live keeps its whole state (position,
velocity and both energy accounts) while the live lanes advance exactly as they would
alone. Two lanes of the same cell (``rows``), one held back, must therefore differ from
each other and the live one must equal a one-lane plant driven the same way."""

import numpy as np

from hapticsdk.sim.arm import ArmParams
from hapticsdk.sim.finger import FingerParams
from hapticsdk.sim.plant import PlantBatch

ARM = ArmParams(damping_ns_per_m=1.0, encoder_resolution_mm=0.0)
FINGER = FingerParams()


def test_lanes_not_live_keep_their_state_and_books():
    pair = PlantBatch([1e-3], [ARM], [FINGER], -0.5, rows=np.array([0, 0]))
    alone = PlantBatch([1e-3], [ARM], [FINGER], -0.5)
    for k in range(50):  # both lanes run 20 steps, then only lane 0 runs 30 more
        live = np.array([True, k < 20])
        f, r, rd = np.full(2, 1.2), np.full(2, -1.0 - 0.01 * k), np.full(2, -10.0)
        pair.step(f, r, rd, live)
        alone.step(f[:1], r[:1], rd[:1])
        if k == 19:
            frozen = (pair.y[1], pair.v[1], pair.motor_work_j[1], pair.damper_j[1])
    assert (pair.y[1], pair.v[1], pair.motor_work_j[1], pair.damper_j[1]) == frozen
    assert frozen[3] > 0  # the held-back lane had moved: its damper book is not trivially 0
    # the live lane did exactly what a lone plant does (same floats, same operations)
    for a in ("y", "v", "motor_work_j", "damper_j"):
        assert getattr(pair, a)[0] == getattr(alone, a)[0], a
