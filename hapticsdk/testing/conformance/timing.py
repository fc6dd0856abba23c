"""The kit's clocks and time budgets: simulated device time booked per rule, the clocks
bound at import, the servo period the timing rules assume, the share of it one command or
one tick may take, and the fastest-of-n timer the timing rules use."""

from __future__ import annotations

import math
import threading
import time
from typing import Any, Callable






_SIM = threading.local()
#: the kit's own clock, bound at import: the dimension determinism rule moves the
#: ``time`` module's clocks to other epochs while a renderer ticks
_monotonic = time.monotonic
_perf_counter = time.perf_counter


def _sim_advance(dt: float) -> None:
    """Book ``dt`` s of simulated device time to the rule running in this thread (its time
    limit grows by :data:`RULE_TIME_FACTOR` x ``dt``)."""
    box = getattr(_SIM, "box", None)
    if box is not None:
        box[0] += dt


#: servo period the timing rules assume (s)
KIT_PERIOD_S = 1e-3
#: share of the period one actuator command may take (the loop runs several per tick)
COMMAND_BUDGET = 0.25
#: share of the period one renderer tick may take
TICK_BUDGET = 0.25
#: calls timed per timing rule (the fastest counts)
TIMING_CALLS = 25
#: wall time (s) a timing rule goes on sampling while the fastest call is over budget
TIMING_WINDOW_S = 1.0


def _fastest(fn: Callable[[], Any], n: int = TIMING_CALLS, budget_s: float | None = None) -> float:
    """The fastest of ``n`` timed calls; while that is over ``budget_s``, calls go on for
    up to ``TIMING_WINDOW_S`` of wall time: on a busy machine the fastest call is the
    one that was not preempted, and a longer sample finds it (a call that is slow
    every time stays slow)."""
    best = math.inf
    end = None
    i = 0
    while True:
        t0 = _perf_counter()
        fn()
        t1 = _perf_counter()
        best = min(best, t1 - t0)
        i += 1
        if i < n:
            continue
        if budget_s is None or best <= budget_s:
            return best
        end = end if end is not None else t1 + TIMING_WINDOW_S
        if t1 >= end:
            return best
