"""The exact ZOH rows and dissipation Gramians are computed once per distinct (arm,
finger) pair of a batch and shared: arms that differ in one parameter only (here the
damping, as on the fixed grid, whose cells share the arm's mass and the period) must
each get their own. Each row is compared with the same pair's row computed alone."""

import numpy as np
import pytest

from hapticsdk.sim.arm import ArmParams, dissipation_gramians, transition_matrices
from hapticsdk.sim.finger import FingerParams

FINGER = FingerParams()


@pytest.mark.parametrize("rows", [transition_matrices, dissipation_gramians])
@pytest.mark.parametrize("field,values", [("damping_ns_per_m", (0.0, 0.5, 2.0)), ("mass_kg", (0.02, 0.045, 0.1))])
def test_pairs_that_differ_in_one_parameter_get_their_own_rows(rows, field, values):
    arms = [ArmParams(**{field: v}) for v in values]
    together = rows(1e-3, arms, [FINGER] * len(arms))
    for i, a in enumerate(arms):
        alone = rows(1e-3, [a], [FINGER])[0]
        assert np.array_equal(together[i], alone), (field, values[i])
    # and the parameter matters to the rows (else the test could not tell them apart)
    assert not np.array_equal(together[0], together[-1])
