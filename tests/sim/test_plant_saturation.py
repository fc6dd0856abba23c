"""PlantBatch holds the commanded force saturated at each cell's own force limit, in
both directions (the documented model: ``F`` held over each period and saturated)."""

import numpy as np

from hapticsdk.sim.arm import ArmParams
from hapticsdk.sim.finger import FingerParams
from hapticsdk.sim.plant import PlantBatch


def test_force_is_clipped_to_each_cells_limit_both_ways():
    arms = [ArmParams(max_force_n=1.0), ArmParams(max_force_n=2.5), ArmParams(max_force_n=2.5)]
    plant = PlantBatch([1e-3, 2e-3, 1e-3], arms, [FingerParams()] * 3, 0.0)
    got = plant.step(np.array([10.0, -10.0, 0.4]), np.zeros(3), np.zeros(3))
    assert got.tolist() == [1.0, -2.5, 0.4]  # above, below, and within the limit
