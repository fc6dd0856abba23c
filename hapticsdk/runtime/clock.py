"""Clocks for the servo loop: the machine's monotonic clock with a hybrid
sleep-then-spin wait, and a simulated clock for deterministic timing tests.

A clock has ``now() -> float`` (s), ``wait_until(deadline)`` and ``work(tick, seconds)``;
``work`` is where a simulated clock charges the compute time of a tick (and any stall
injected by a test). On the real clock the compute has already taken real time, so
``work`` does nothing.
"""

from __future__ import annotations

import time
from typing import Mapping


class MonotonicClock:
    """``time.perf_counter`` with a hybrid wait: sleep while more than ``spin_s`` remains
    (sleeping half the remaining time each round), then busy-wait to the deadline."""

    simulated = False

    def __init__(self, spin_s: float = 200e-6) -> None:
        self.spin_s = float(spin_s)

    def now(self) -> float:
        return time.perf_counter()

    def wait_until(self, deadline: float) -> None:
        pc = time.perf_counter
        while True:
            remaining = deadline - pc()
            if remaining <= self.spin_s:
                break
            time.sleep(max(remaining - self.spin_s, 0.0) * 0.5 if remaining > 2 * self.spin_s
                       else remaining - self.spin_s)
        while pc() < deadline:
            pass

    def work(self, tick: int, seconds: float) -> None:
        """Real time already passed while the tick computed."""


class SimulatedClock:
    """A clock that only moves when told to: ``wait_until`` jumps to the deadline and
    ``work`` charges a fixed compute cost per tick plus any injected stall.

    Args:
        compute_s: simulated compute time of every tick (s).
        stalls: tick index -> extra seconds that tick takes (a late tick).
        wake_latency_s: how late every wake-up is (s), like a scheduler's latency.
    """

    simulated = True

    def __init__(self, *, compute_s: float = 20e-6, stalls: Mapping[int, float] | None = None,
                 wake_latency_s: float = 0.0, start: float = 0.0) -> None:
        self.t = float(start)
        self.compute_s = float(compute_s)
        self.stalls = dict(stalls or {})
        self.wake_latency_s = float(wake_latency_s)

    def now(self) -> float:
        return self.t

    def wait_until(self, deadline: float) -> None:
        if deadline > self.t:
            self.t = deadline + self.wake_latency_s

    def work(self, tick: int, seconds: float) -> None:
        self.t += self.compute_s + self.stalls.get(tick, 0.0)
