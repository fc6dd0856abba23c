"""The solver benchmark's pieces on the synthetic fixture problem (shape of the report,
plot file, CLI wiring). Nothing here asserts a timing."""

import argparse
import json

import numpy as np
import pytest

from hapticsdk.benchmarks import solvers as bench
from hapticsdk.cli.bench_solvers import register_bench


@pytest.fixture
def factory(fx, model):
    def f(T, penalty="paper", **kw):
        return fx.make_problem(np.asarray(T, float), model=model, penalty=penalty, **kw)
    return f


def test_work_precision_and_report_shape(factory, fx, model, tmp_path):
    T = fx.reachable_targets(model, 6, seed=2)
    wp = bench.work_precision(factory, T, "ga", [{"generations": 2, "target_error": 0},
                                                 {"generations": 30, "target_error": 0}], [0, 1])
    assert set(wp) == {"points", "time_to_error"} and len(wp["points"]) == 2
    for pt in wp["points"]:
        assert {"time_s", "cpu_s", "error", "error_p10", "error_p90", "error_max", "failures", "solves"} <= set(pt)
        assert pt["error_p10"] <= pt["error"] <= pt["error_p90"] <= pt["error_max"]
        assert pt["solves"] == 6 * 2 and 0 <= pt["failures"] <= pt["solves"]
    # 2 generations from random starts: some of the 12 solves miss, and the count says so
    assert wp["points"][0]["failures"] > 0
    assert set(wp["time_to_error"]) == {"0.1", "0.01", "0.001"}
    # more generations never give a worse error at the same seeds (elitism)
    assert wp["points"][1]["error"] <= wp["points"][0]["error"]
    ref = bench.reference_errors(factory, np.vstack([T[:2], [[0.0, 0.0]]]))
    assert ref[0] <= 1e-6 and ref[1] <= 1e-6
    peers = bench.run_peers(factory, T[:1], [0])
    assert "ga (ours, one target per call)" in peers and "ga-polish (ours, one target per call)" in peers
    for name in ("numpy-ga", "scipy-de", "lbfgsb-multistart", "pygad", "deap", "pymoo"):
        assert name in peers
    for name in ("numpy-ga", "scipy-de", "lbfgsb-multistart"):   # numpy/scipy only: always run
        pt = peers[name]["points"][0]
        assert pt["error"] <= pt["error_p90"] <= pt["error_max"] and pt["solves"] == 1
        assert pt["error_max"] < 0.5     # a real search, not a random point: reachable target
    rep = {"meta": {"model": "synthetic", "seeds": 2, "python": "3", "numpy": np.__version__},
           "targets_summary": {"reachable": 6}, "solvers": {"ga": wp}, "peers": peers}
    pytest.importorskip("matplotlib")
    out = tmp_path / "wp.png"
    bench.plot(rep, out)
    assert out.stat().st_size > 1000
    json.dumps(rep, default=str)


def test_cli_registration():
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="cmd")
    b = sub.add_parser("bench").add_subparsers(dest="bench_cmd")
    register_bench(b)
    args = parser.parse_args(["bench", "solvers", "--quick", "--json", "--plot", "x.png"])
    assert args.quick and args.json and args.plot == "x.png" and callable(args.func)


def test_material_targets_load():
    names, T = bench.load_material_targets()
    assert len(names) == len(T) and T.shape[1] == 2
    assert np.all((T >= 0) & (T <= 1))


def test_summary_shows_results_not_goal_labels(factory, fx, model):
    T = fx.reachable_targets(model, 3, seed=2)
    wp = bench.work_precision(factory, T, "polish", [{"max_iter": 3, "target_error": 0}], [0])
    rep = {"meta": {"model": "synthetic"}, "targets_summary": {"reachable": 3}, "solvers": {"polish": wp},
           "peers": {"x": {"error": "not installed"}},
           "penalty_forms": {"paper": {"error": 1e-3}, "normalised": {"error": 2e-3}, "lower_error": "paper"},
           "amortised": {"median_us": 3.0, "batch_us_per_target": 0.5, "table_shape": [101, 101, 5],
                         "cpu_us_per_lookup": 2.0, "table_build_cpu_s": 5.0, "table_source": "built",
                         "table_obtain_s": 5.1}}
    text = bench.summary_text(rep)
    assert "goal" not in text.lower() and "max err" in text and "failed" in text
    assert "built in 5.00 s CPU" in text
