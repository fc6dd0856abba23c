"""``bench/bench_tick_floor.py`` times the least Python that does the work of the
benchmark's servo tick. Its figure means something only while that code does the same
work as ``ServoLoop.tick``: its full floor writes its log row into the loop's ring, and
every logged value of every tick after the warm-up (time, period, penetration, object,
force sent, position, velocity, and each role's force, frequency and amplitude) must equal
the loop's own run of the same scene, bit for bit, except on the ticks whose state the
loop refused (out of range or not finite), where the loop logs object -1 at penetration 0
and the floor -1 mm on object 0. The scene is the benchmark's with, on fixed ticks, a
velocity spike, a position that is not a number and one beyond the position limit (the
device's state read replaced), and tighter force and stiffness limits on the force
channel, so that the spike replacement, the refused states and both force clamps are
compared too. No time is asserted."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from repo_scripts import load_script

pytest.importorskip("hapticsdk_hardness")
pytest.importorskip("hapticsdk_roughness")


def _setup(dev, acts):
    read = dev._read_state
    k = [0]

    def read_state():
        st = read()
        k[0] += 1
        if k[0] % 211 == 100:
            st.vy += 3000.0          # a velocity spike (2000 mm/s a tick is the limit)
        elif k[0] % 307 == 200:
            st.py = math.nan
        elif k[0] % 401 == 300:
            st.px = 5000.0           # beyond the position limit
        return st
    dev._read_state = read_state
    lay = acts["force"].safety
    lay.limits = dataclasses.replace(lay.limits, max_force_n=1.2, max_stiffness_n_per_mm=0.1)


def _logs(seconds=2.0):
    bf = load_script("bench/bench_tick_floor.py")
    loop_log, floor_log = [], []
    bf.run_loop(seconds, log=loop_log, setup=_setup)
    ns = bf.run_floor(seconds, "full", log=floor_log, setup=_setup)
    return bf.WARM, loop_log[0], floor_log[0], ns


def test_the_full_floor_logs_what_the_loop_logs():
    warm, a, b, ns = _logs()
    assert ns.shape == (a.shape[0] - warm,) and (ns > 0).all()
    a, b = a[warm:, :20], b[warm:, :20]   # every column but the three compute times
    refused = a[:, 3] == -1
    assert refused.sum() < 0.05 * len(a)
    keep = ~refused
    same = (a == b) | (np.isnan(a) & np.isnan(b))
    cols = [c for c in range(20) if not same[keep, c].all()]
    assert cols == [], f"columns that differ on accepted ticks: {cols}"
    other = [c for c in range(20) if c not in (2, 3) and not same[refused, c].all()]
    assert other == [], f"columns that differ on refused ticks: {other}"
    # the run renders a wall: contact, a force and both vibration channels; the force
    # clamps bite (the stiffness cap 0.1 N/mm x depth + 1 N, the force limit 1.2 N)
    assert (a[:, 2] > 0).sum() > 100 and a[:, 4].max() > 0.5
    assert np.nanmax(a[:, 16]) > 0 and np.nanmax(a[:, 19]) > 0
    assert np.sum(a[:, 4] == 1.2) > 10
    depth = np.clip(a[:, 2], 0.0, None)
    assert np.sum(np.isclose(a[:, 4], 0.1 * depth + 1.0, rtol=0, atol=1e-12) & (a[:, 4] < 1.2)) > 10
