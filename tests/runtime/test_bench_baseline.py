"""``bench timing --baseline REF``: the old code's tick from the same run (issue 30)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import hapticsdk
from hapticsdk.benchmarks import baseline
from hapticsdk.errors import ValidationError

ROOT = Path(hapticsdk.__file__).resolve().parents[1]


def _need_git_checkout() -> None:
    ok = shutil.which("git") is not None and subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True).returncode == 0
    if not ok:
        if os.environ.get("CI") == "true":
            pytest.fail("CI runs from a git checkout with git installed (Debian package git)")
        pytest.skip("needs git (Debian package git) and a git checkout of hapticsdk")


def _run(tick_med, tick_p99, empty):
    return {"tick_cpu_median_us": tick_med, "tick_cpu_p99_us": tick_p99, "empty_call_us": empty, "files": []}


def test_summary_pairs_rounds_and_divides_this_code_by_the_baseline():
    old = [_run(20.0, 40.0, 0.5), _run(30.0, 60.0, 0.5), _run(25.0, 50.0, 0.4)]
    new = [_run(10.0, 30.0, 0.5), _run(12.0, 30.0, 0.5), _run(20.0, 25.0, 0.4)]
    s = baseline.summarise(old, new)
    assert s["ratio_median_per_round"] == [0.5, 0.4, 0.8]
    assert s["ratio_median"] == 0.5                          # median of the paired ratios
    assert s["ratio_p99_per_round"] == [0.75, 0.5, 0.5] and s["ratio_p99"] == 0.5
    assert s["baseline"]["tick_cpu_median_us"] == 25.0 and s["this"]["tick_cpu_median_us"] == 12.0
    assert s["baseline"]["empty_call_us"] == 0.5
    assert s["this"]["median_over_empty_call"] == 12.0 / 0.5


def test_an_unknown_ref_is_a_named_error():
    _need_git_checkout()
    with pytest.raises(ValidationError) as e:
        baseline.run_baseline("no-such-ref-xyz", seconds=0.1, rounds=1)
    assert e.value.field == "--baseline" and "no-such-ref-xyz" in str(e.value)
    with pytest.raises(ValidationError):
        baseline.resolve(ROOT, "--output=/tmp/x")            # an option is not a ref
    with pytest.raises(ValidationError):
        baseline.run_baseline("HEAD", seconds=0.1, rounds=0)


def test_outside_a_checkout_is_a_named_error(tmp_path):
    if shutil.which("git") is None:
        pytest.skip("needs git (Debian package git)")
    with pytest.raises(ValidationError) as e:
        baseline.repository_of(tmp_path)
    assert e.value.field == "--baseline"


def test_a_child_that_imported_code_outside_the_baseline_tree_is_refused(tmp_path):
    """A 'tree' whose package is a link to this code: the child runs, but its files
    resolve outside the tree, which must not pass for the baseline's figure."""
    (tmp_path / "hapticsdk").symlink_to(Path(hapticsdk.__file__).resolve().parent)
    with pytest.raises(RuntimeError, match="instead of the baseline tree"):
        baseline.run_child(tmp_path, 0.05, 0.001)


def test_cli_runs_both_trees_interleaved_and_reports_both_figures_and_the_ratio():
    _need_git_checkout()
    out = subprocess.run([sys.executable, "-m", "hapticsdk", "bench", "timing", "--baseline", "HEAD",
                          "--seconds", "0.2", "--rounds", "2"], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    text = out.stdout
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True).stdout
    assert f"baseline HEAD ({head[:10]})" in text and "this code" in text
    assert "thread_time_ns" in text and "median" in text and "load" in text
    assert "paired by round: median" in text
    assert "goal" not in text.lower()
    # each figure line: tick median / p99 and the empty call, all positive numbers
    for name in ("baseline HEAD", "this code"):
        line = next(ln for ln in text.splitlines() if ln.startswith(name))
        nums = [float(w) for w in line.replace("/", " ").split() if w.replace(".", "", 1).isdigit()]
        assert len(nums) >= 5 and all(n > 0 for n in nums[-5:]), line


def test_cli_refuses_options_the_comparison_does_not_take():
    out = subprocess.run([sys.executable, "-m", "hapticsdk", "bench", "timing", "--baseline", "HEAD",
                          "--realtime"], capture_output=True, text=True, timeout=120)
    assert out.returncode != 0 and "--realtime" in out.stderr


def _live(p50, p99, mx, missed, ref_p99, state):
    return {"jitter": {"p50_us": p50, "p99_us": p99, "max_us": mx, "missed_tick_rate": missed},
            "reference": {"p50_us": 0.0, "p99_us": ref_p99, "missed_tick_rate": 0.0},
            "state_us": state, "state_p99_us": 2 * state, "files": []}


def test_live_summary_pairs_rounds_and_relates_each_tree_to_its_reference_loop():
    old = [_live(1.0, 40.0, 90.0, 0.002, 4.0, 10.0), _live(1.0, 60.0, 80.0, 0.004, 6.0, 12.0)]
    new = [_live(1.0, 20.0, 70.0, 0.001, 4.0, 5.0), _live(1.0, 45.0, 99.0, 0.001, 5.0, 6.0)]
    s = baseline.summarise_live(old, new)
    assert s["ratio_jitter_p99_per_round"] == [0.5, 0.75] and s["ratio_jitter_p99"] == 0.625
    assert s["ratio_state_per_round"] == [0.5, 0.5]
    assert s["baseline"]["jitter"]["p99_us"] == 50.0 and s["this"]["jitter"]["missed_tick_rate"] == 0.001
    assert s["baseline"]["reference"]["p99_us"] == 5.0
    assert s["this"]["jitter_p99_over_reference"] == 32.5 / 4.5


def test_live_cli_refuses_what_the_comparison_does_not_take():
    out = subprocess.run([sys.executable, "-m", "hapticsdk", "bench", "live", "--baseline", "HEAD",
                          "--app-load", "all"], capture_output=True, text=True, timeout=120)
    assert out.returncode != 0 and "--app-load all" in out.stderr


def test_live_cli_runs_both_trees_and_reports_both_sessions():
    """Both trees' children run a live session and a reference loop and the CLI reports
    both. With no application load: a busy application thread (the default) cost each
    child about 5 s of CPU (the main thread waits for the interpreter lock after each of
    its sleeps) and measures nothing this test reads; the loads themselves are tested in
    test_session.py (``test_benchmark_application_load_keeps_a_cpu_busy_until_stopped``)."""
    _need_git_checkout()
    out = subprocess.run([sys.executable, "-m", "hapticsdk", "bench", "live", "--baseline", "HEAD",
                          "--seconds", "0.3", "--rounds", "1", "--record", "none", "--app-load", "none"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    text = out.stdout
    assert "application load none" in text
    assert "baseline HEAD (" in text and "this code" in text and "reference loop" in text
    assert "paired by round: jitter p99" in text and "perf_counter" in text and "goal" not in text.lower()


def test_a_failing_child_is_a_named_error_not_an_internal_one(tmp_path):
    """A child that fails (here: a tree without hapticsdk's benchmarks) is reported with
    its last error line as a BaselineRunError (an SDK error: the CLI prints it as such)."""
    from hapticsdk.errors import HapticSDKError
    (tmp_path / "hapticsdk").mkdir()
    (tmp_path / "hapticsdk" / "__init__.py").write_text("")
    with pytest.raises(baseline.BaselineRunError, match="the baseline tree") as e:
        baseline.run_code(tmp_path, baseline.LIVE, ["process", "none", "0.1", "0.001", "none"])
    assert isinstance(e.value, HapticSDKError)


def test_the_live_benchmark_runs_its_session_with_the_heartbeat_off(monkeypatch, tmp_path):
    """On a loaded machine the application can miss the 250 ms heartbeat; the servo then
    stops and the benchmark ends instead of measuring (the suite failed once on it under
    load). The benchmark's session turns the heartbeat off; the parent-process check stays."""
    import hapticsdk.benchmarks.live as live
    import hapticsdk.runtime.session as session_pkg

    seen = {}

    class Stop(Exception):
        pass

    def fake_session(*args, **kw):
        seen.update(kw)
        raise Stop

    monkeypatch.setattr(session_pkg, "Session", fake_session)
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))   # its recording folder
    with pytest.raises(Stop):
        live.run_session("thread", "none", 0.1, record="none", view=False)
    assert "heartbeat_timeout_s" in seen and seen["heartbeat_timeout_s"] is None
