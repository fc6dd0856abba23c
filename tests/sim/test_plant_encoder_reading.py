"""PlantBatch's encoder: the start position is the one given (mm), and the reading is it
rounded to the nearest multiple of each cell's resolution (exact where that is 0)."""

import numpy as np
import pytest

from hapticsdk.sim.arm import ArmParams
from hapticsdk.sim.finger import FingerParams
from hapticsdk.sim.plant import PlantBatch


def test_start_reading_is_the_start_position_rounded_to_the_resolution():
    res = [0.055, 0.055, 0.0]
    arms = [ArmParams(encoder_resolution_mm=r) for r in res]
    plant = PlantBatch([1e-3] * 3, arms, [FingerParams()] * 3, np.array([-0.1, 0.1, -0.1]))
    # -0.1 / 0.055 = -1.82 -> nearest count -2 -> -0.11 mm; +0.1 -> +1.82 -> 2 -> +0.11 mm
    # (nearest, not truncated towards either side); no encoder: -0.1 itself.
    # 1e-12 mm: float rounding of the mm <-> m conversions only
    assert plant.measured_mm() == pytest.approx([-0.11, 0.11, -0.1], abs=1e-12)
    assert plant.y == pytest.approx([-1e-4, 1e-4, -1e-4], abs=1e-15)
