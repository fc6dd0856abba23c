"""Tick-time and period-jitter statistics of servo runs (all reported in microseconds):
wall-clock and on-CPU compute time per tick, preempted ticks, period jitter."""

from __future__ import annotations

import numpy as np

from ..quantiles import percentile


def _summary(us: np.ndarray) -> tuple[float, float, float, float]:
    """p50, p99, p99.9 and max of ``us`` (NaN when empty)."""
    if us.size == 0:
        return (float("nan"),) * 4
    p50, p99, p999 = percentile(us, [50, 99, 99.9])
    return float(p50), float(p99), float(p999), float(us.max())


def tick_stats(seconds: np.ndarray) -> dict[str, float]:
    """Median, p99, p99.9 and max of per-tick compute times given in seconds (us out)."""
    return dict(zip(("median_us", "p99_us", "p999_us", "max_us"), _summary(np.asarray(seconds, float) * 1e6)))


def jitter_stats(periods_s: np.ndarray, period_s: float) -> dict[str, float]:
    """Statistics of ``|period - T|`` (us) over measured start-to-start periods, and the
    missed-tick rate (fraction of periods longer than 1.5 T)."""
    p = np.asarray(periods_s, float)
    if p.size == 0:
        return {"p50_us": float("nan"), "p99_us": float("nan"), "p999_us": float("nan"),
                "max_us": float("nan"), "missed_tick_rate": float("nan"), "periods": 0}
    p50, p99, p999, mx = _summary(np.abs(p - period_s) * 1e6)
    return {"p50_us": p50, "p99_us": p99, "p999_us": p999, "max_us": mx,
            "missed_tick_rate": float(np.mean(p > 1.5 * period_s)), "periods": int(p.size),
            "mean_period_us": float(p.mean() * 1e6)}


#: a tick whose wall compute time exceeds its on-CPU time by more than this was
#: preempted (the thread was off the CPU: another process ran, or the tick slept)
PREEMPT_THRESHOLD_S = 100e-6


def preemption_stats(wall_s: np.ndarray, cpu_s: np.ndarray,
                     threshold_s: float = PREEMPT_THRESHOLD_S) -> dict[str, float]:
    """Compare each tick's wall compute time with its on-CPU time (both in s).

    Returns ``preempted_ticks`` (ticks with wall - CPU > ``threshold_s``),
    ``preempt_threshold_us``, ``off_cpu_max_us`` (largest wall - CPU of a tick) and
    ``off_cpu_total_ms`` (sum of the positive differences).
    """
    w = np.asarray(wall_s, float)
    c = np.asarray(cpu_s, float)
    if w.shape != c.shape:
        raise ValueError(f"wall and cpu arrays differ in shape: {w.shape} vs {c.shape}")
    if w.size == 0:
        return {"preempted_ticks": 0, "preempt_threshold_us": threshold_s * 1e6,
                "off_cpu_max_us": float("nan"), "off_cpu_total_ms": 0.0}
    gap = w - c
    return {"preempted_ticks": int(np.count_nonzero(gap > threshold_s)), "preempt_threshold_us": threshold_s * 1e6,
            "off_cpu_max_us": float(gap.max() * 1e6), "off_cpu_total_ms": float(np.clip(gap, 0.0, None).sum() * 1e3)}
