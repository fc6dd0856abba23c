"""Benchmarks carry their clock, their machine and the ratio to a bare reference taken
in the same run (issue 30, item 5)."""

import math

import pytest

from hapticsdk.benchmarks import reference
from hapticsdk.benchmarks.timing import format_table, run_timing


@pytest.mark.parametrize("clock", sorted(reference.CLOCKS))
def test_bare_reference_is_a_positive_time_with_its_clock(clock):
    r = reference.bare_reference(clock, samples=201)
    assert r["clock"] == clock and r["statistic"] == "median"
    assert 0 < r["bare_loop_us"] < r["empty_call_us"] < 1e3   # a call costs more than a pass
    with pytest.raises(ValueError):
        reference.bare_reference("sundial")


def test_ratios_divide_by_the_reference():
    ref = {"empty_call_us": 0.5, "bare_loop_us": 0.01}
    out = reference.ratios({"median_us": 8.0}, ref)
    assert out == {"median_us/empty_call": 16.0, "median_us/bare_loop": 800.0}
    assert math.isnan(reference.ratios({"x": 1.0}, {"empty_call_us": 0.0, "bare_loop_us": None})["x/empty_call"])


def test_timing_report_has_machine_clock_and_ratio():
    d = run_timing(0.3)
    r = d["reference"]
    assert r["thread_cpu"]["clock"] == "thread_cpu" and r["wall"]["clock"] == "wall"
    assert r["machine_before"]["cpus"] >= 1 and r["machine_after"]["cpu_model"]
    c = d["compute_cpu_us"]
    assert r["ratios_compute_cpu_us"]["median_us/empty_call"] == pytest.approx(
        c["median_us"] / r["thread_cpu"]["empty_call_us"])
    assert r["ratios_compute_us"]["p99_us/empty_call"] == pytest.approx(
        d["compute_us"]["p99_us"] / r["wall"]["empty_call_us"])
    text = format_table([d])
    assert "machine: " in text and "empty call" in text and "thread_cpu clock" in text
