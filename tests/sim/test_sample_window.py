"""Simulated waveforms keep a bounded window (issue 30, item 4: a live session's memory
does not grow with its length)."""

import numpy as np
import pytest

from hapticsdk.plugins import registry
from hapticsdk.sim.samples import SampleWindow


@pytest.mark.parametrize("seed", range(12))
def test_window_keeps_the_newest_samples_and_at_least_keep(seed):
    rng = np.random.default_rng(seed)
    keep = int(rng.integers(1, 400))
    w = SampleWindow(keep)
    written = []
    for _ in range(int(rng.integers(1, 300))):
        b = rng.standard_normal(int(rng.integers(0, 12)))
        w.append(b)
        written.extend(b)
    got = w.samples()
    assert w.total == len(written)
    # the newest samples, in order; at least keep of them (all when fewer were written),
    # and no more than keep plus one block
    assert got.tolist() == written[len(written) - got.size:]
    assert got.size >= min(keep, len(written)) and got.size < keep + 12
    assert len(w) == got.size
    w.clear()
    assert w.total == 0 and w.samples().size == 0


def test_window_without_keep_keeps_everything_and_refuses_bad_keep():
    w = SampleWindow()
    for i in range(100):
        w.append(np.full(3, float(i)))
    assert w.samples().size == 300
    for bad in (0, -5, True):
        with pytest.raises(ValueError):
            SampleWindow(bad)


@pytest.mark.parametrize("name", ["voicecoil-virtual", "piezo-virtual"])
def test_simulated_vibration_actuators_hold_a_bounded_waveform(name):
    """Ten minutes at 1 kHz of a simulated actuator keep what 60 s hold (not 10 min)."""
    acts = registry("actuator")
    if name not in acts:
        pytest.skip(f"{name} not installed")
    from hapticsdk.perception.dimensions import ChannelCommand
    # the piezo synthesises period_s of waveform per command
    a = acts.load(name)(**({"period_s": 0.05} if name == "piezo-virtual" else {}))
    a.open()
    try:
        fs = a.fs
        for k in range(600_000 // 50):   # 600 s in steps of 50 ms (the per-tick blocks x 50)
            a.command(ChannelCommand("vibration", frequency_hz=200.0, amplitude=0.1), now=k * 0.05)
            a.step(0.05)
        kept = a.sink.samples() if hasattr(a, "sink") else a.waveform()[1]
        assert 60 * fs <= kept.size <= 60 * fs + 0.05 * fs + 1
    finally:
        a.close()
