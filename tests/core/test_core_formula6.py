"""Formula (6) of the paper, checked on hand-picked points: the fitness is the sum of
absolute intensity errors plus (Wv^2 - W^2) when W < Wv = MF^2/(2 GS) and
(P_F^2 - P^2) when P < P_F = AFpeak^2 df, with MF = 3.3 N (the paper's numbers)."""

import numpy as np
import pytest

pytest.importorskip("hapticsdk_hardness")
pytest.importorskip("hapticsdk_roughness")

from hapticsdk.solvers.problems import build_problem  # noqa: E402

MF_N = 3.3


def _fitness_by_hand(problem, x):
    G = problem.full_inputs(np.asarray(x, float)[None])[0]
    f = dict(zip(problem.model.feature_names, G))
    pred = problem.model.predict(G[None])[0]
    idx = [problem.model.dimension_names.index(d) for d in problem.dimensions]
    err = float(np.abs(pred[idx] - problem.targets[0]).sum())
    wv = MF_N ** 2 / (2.0 * f["GS"])
    df = float(problem.model.metadata["df_hz"])
    pf = f["AFpeak"] ** 2 * df
    pen = (wv ** 2 - f["W"] ** 2 if f["W"] < wv else 0.0) + (pf ** 2 - f["P"] ** 2 if f["P"] < pf else 0.0)
    return err, pen


@pytest.mark.parametrize("point", [
    # GS, W, Fpeak, AFpeak, P
    (0.5, 4.0, 100.0, 2.0, 3.0),     # W < Wv = 10.89 mJ: work penalty only
    (2.0, 10.0, 120.0, 3.5, 0.5),    # P < P_F = 4.9: power penalty only
    (0.5, 4.0, 60.0, 3.5, 0.5),      # both
    (2.0, 10.0, 120.0, 1.0, 3.0),    # neither
])
def test_paper_penalty_matches_formula_6(point):
    problem = build_problem({"hardness": 0.4, "roughness": 0.6}, penalty="paper")
    x = problem.space.vector(dict(zip(("GS", "W", "Fpeak", "AFpeak", "P"), point)))
    err, pen = _fitness_by_hand(problem, x)
    got = problem.evaluate(x[None], details=True)
    assert float(got["error"][0]) == pytest.approx(err, rel=1e-9, abs=1e-12)
    assert float(got["fitness"][0]) == pytest.approx(err + pen, rel=1e-9, abs=1e-12)
    assert (float(got["violation"][0]) > 0) == (pen > 0)
