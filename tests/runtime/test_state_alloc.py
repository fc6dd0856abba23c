"""``state()`` keeps nothing alive per call beyond its result (issue 27).

Counted with ``sys.getallocatedblocks`` (CPython's live small-object blocks), not timed.
A result that is kept costs exactly what it holds: the named tuple, its two coordinate
tuples and the numbers in it (a CPython float or int > 256 is an object); a result that
is dropped leaves nothing. Anything retained per call (a cache, a list of past states,
a reference cycle) leaves at least one block per call, so the bound of 0.5 blocks per
call over 20 000 calls allows the session's own threads (supervisor, heartbeat, callback
dispatcher) up to 10 000 blocks of their own during the count while still catching it.
"""

from __future__ import annotations

import gc
import sys
import time

import hapticsdk as hs
from hapticsdk.sim.finger import Trajectory

PAD = {"schema_version": 1, "name": "pad",
       "objects": [{"name": "pad", "material": {"intensities": {"hardness": 0.9, "roughness": 0.5}}}],
       "devices": {"force": "probe-virtual"},
       "settings": {"solver": {"seed": 0}, "importance": {"enabled": False}}}
N = 20000


def test_state_retains_nothing_per_call_beyond_its_result():
    finger = Trajectory([(0.0, -20.0, 2.0), (0.2, -20.0, -2.0), (600.0, 20.0, -2.0)])
    with hs.Session(PAD, trajectory=finger) as s:
        t0 = time.monotonic()
        while s.state().ticks < 300 and time.monotonic() - t0 < 30:
            time.sleep(0.01)
        gc.disable()
        try:
            for _ in range(1000):
                s.state()
            b0 = sys.getallocatedblocks()
            for _ in range(N):
                s.state()
            dropped = (sys.getallocatedblocks() - b0) / N
            b0 = sys.getallocatedblocks()
            kept = [s.state() for _ in range(N)]
            per_kept = (sys.getallocatedblocks() - b0) / N
        finally:
            gc.enable()
        st = kept[-1]
    assert dropped < 0.5, f"{dropped:.2f} blocks stay alive per state() call"
    # what a result holds: itself, two coordinate tuples, its floats, ints above CPython's
    # small-int cache; the list slot holding it is a pointer in one array, not a block
    holds = 3 + sum(isinstance(v, float) for v in (*st, *st.position_mm, *st.velocity_mm_s)) + \
        sum(isinstance(v, int) and not isinstance(v, bool) and v > 256 for v in st)
    assert abs(per_kept - holds) < 0.5, f"a kept result costs {per_kept:.2f} blocks, it holds {holds}"
