"""The simulated piezo and voice coil keep a bounded window of their drive waveform
(issue 27: a live session's memory must stay flat for an hour at 1 kHz).

Not a timing or RSS test: the actuators are driven tick by tick for simulated seconds,
and what they hold (arrays, their bytes, the length of every container) is counted by
walking their attributes. After the window has filled, running longer must not change
the count; the waveform kept is the tail of everything written, sample for sample, at least
``keep_s`` seconds of it and at most one block more.
"""

from __future__ import annotations

import random
from collections.abc import Mapping

import numpy as np
import pytest

from hapticsdk.perception.dimensions import ChannelCommand

virtual = pytest.importorskip("hapticsdk_roughness.virtual")
voicecoil = pytest.importorskip("hapticsdk_hardness.voicecoil")
sinks = pytest.importorskip("hapticsdk_hardness.sinks")

PERIOD = 0.001  # the servo's 1 kHz tick


def held(obj, depth: int = 4, seen: set | None = None) -> tuple[int, int, int]:
    """(arrays, their bytes, total container length) reachable from ``obj``'s attributes."""
    seen = set() if seen is None else seen
    if id(obj) in seen or depth < 0:
        return 0, 0, 0
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        return 1, obj.nbytes, 0
    n_arr = n_bytes = n_len = 0
    if isinstance(obj, Mapping):
        items = list(obj.values())
        n_len += len(items)
    elif isinstance(obj, (list, tuple, set, frozenset)) or type(obj).__name__ == "deque":
        items = list(obj)
        n_len += len(items)
    elif hasattr(obj, "__dict__") and type(obj).__module__.split(".")[0].startswith("hapticsdk"):
        items = list(vars(obj).values())
    else:
        return 0, 0, 0
    for v in items:
        a, b, c = held(v, depth - 1, seen)
        n_arr, n_bytes, n_len = n_arr + a, n_bytes + b, n_len + c
    return n_arr, n_bytes, n_len


def _drive(act, ticks: int, t0: int = 0) -> None:
    rng = random.Random(ticks)
    for k in range(t0, t0 + ticks):
        # a changing drive, as a sliding finger gives (amplitudes within both devices' full scale)
        f, a = 80.0 + 40.0 * rng.random(), (0.0 if k % 97 < 5 else 0.8 * rng.random())
        act.command(ChannelCommand("vibration", None, f, a), now=k * PERIOD)
        act.step(PERIOD)


def _coil(keep, monkeypatch):
    monkeypatch.setattr(sinks, "BUFFER_KEEP_S", keep)  # the default "buffer" sink's window
    return voicecoil.VoiceCoilVirtual()


@pytest.mark.parametrize("make", [
    lambda keep, mp: virtual.PiezoVirtual(keep_s=keep),
    _coil,
], ids=["piezo-virtual", "voicecoil-virtual"])
def test_storage_stops_growing_once_the_window_is_full(make, monkeypatch):
    keep = 0.05  # s: 50 ticks
    act = make(keep, monkeypatch).open()
    _drive(act, 100)  # twice the window
    after_2 = held(act)
    _drive(act, 400, 100)  # ten times the window
    after_10 = held(act)
    assert after_10 == after_2, f"storage grew from {after_2} to {after_10} (arrays, bytes, container length)"


def _is_tail(short, long_, keep_n, block_n):
    assert keep_n <= short.size <= keep_n + block_n
    assert np.array_equal(short, long_[-short.size:])


def test_the_piezo_keeps_the_tail_of_its_waveform():
    short, long_ = virtual.PiezoVirtual(keep_s=0.05).open(), virtual.PiezoVirtual(keep_s=10.0).open()
    for act in (short, long_):
        _drive(act, 300)
    t_s, v_s = short.waveform()
    t_l, v_l = long_.waveform()
    assert v_l.size == long_.samples_total  # 300 ticks < 10 s: all of it
    _is_tail(v_s, v_l, int(0.05 * short.fs), int(PERIOD * short.fs) + 1)
    assert np.array_equal(t_s, t_l[-t_s.size:])


def test_the_voice_coil_buffer_keeps_the_tail_of_its_waveform(monkeypatch):
    short, long_ = _coil(0.05, monkeypatch).open(), _coil(10.0, monkeypatch).open()
    for act in (short, long_):
        _drive(act, 300)
    y_s, y_l = short.sink.samples(), long_.sink.samples()
    assert y_l.size == long_.samples_written
    _is_tail(y_s, y_l, int(0.05 * short.fs), int(PERIOD * short.fs) + 1)
