"""The live recorder without a servo: rows added as the servo adds them, in both formats,
closed normally or cut short by a SIGKILL of the writing process (a fork), then read
back with ``load_run`` / ``load_recording``. Fast, and the h5py floor's check."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from hapticsdk.devices.actuators import SensedState
from hapticsdk.runlog import load_run
from hapticsdk.runtime import recorder as rec

CHUNK = 64


@pytest.fixture(params=["npz", "h5"])
def fmt(request):
    if request.param == "h5":
        try:
            import h5py  # noqa: F401
        except ImportError:
            if os.environ.get("CI") == "true":
                raise
            pytest.skip("h5py is not installed (pip install 'hapticsdk[h5]')")
    return request.param


class _Slot:
    def __init__(self, cap: int) -> None:
        self.log_n, self.log_f, self.log_a = np.zeros(cap), np.zeros(cap), np.zeros(cap)


class _Loop:
    """The loop attributes ``LiveRecorder.add`` reads (its log ring holds 8 ticks)."""

    def __init__(self) -> None:
        self.ticks, self._cap = 0, 8
        self.last_t, self.last_force_n, self.last_penetration_mm = 0.0, 0.0, 0.0
        # the servo loop keeps a SensedState (loop.py converts any backend's state)
        self.last_state = SensedState(0.0, (1.0, 2.0, -0.5), (10.0, 0.0, 0.0))
        self._slots = [_Slot(8)]


def _write(path, n: int, *, kill: bool = False):
    r = rec.LiveRecorder(path, ["vibration"], 0.001, objects={0: "pad"}, chunk_rows=CHUNK)
    lp = _Loop()
    for k in range(n):
        lp.ticks, lp.last_t, lp.last_force_n = k + 1, k * 0.001, float(k)
        lp._slots[0].log_a[k % 8] = 0.5 * k
        lp._slots[0].log_f[k % 8] = 100.0 + k
        r.add(lp, 0.0)
    if kill:
        os.kill(os.getpid(), signal.SIGKILL)
    return r.close()


def test_rows_come_back_in_order(tmp_path, fmt):
    path = _write(tmp_path / f"run.{fmt}", 1000)
    run = load_run(path)
    k = np.arange(1000)
    assert len(run) == 1000 and np.array_equal(run.t, k * 0.001)
    assert np.array_equal(run.commands["vibration"]["amplitude"], 0.5 * k)
    assert np.array_equal(run.commands["vibration"]["frequency_hz"], 100.0 + k)
    assert run.header["meta"]["objects"] == {"0": "pad"} and not rec.part_path(path).exists()


def _killed_writer(path) -> None:
    pid = os.fork()
    if pid == 0:  # the child plays the servo and is killed before close()
        try:
            _write(path, 1000, kill=True)
        finally:
            os._exit(1)
    _, status = os.waitpid(pid, 0)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL
    assert rec.part_path(path).exists() and not path.exists()


def test_a_killed_writer_leaves_every_complete_chunk(tmp_path, fmt):
    path = tmp_path / f"run.{fmt}"
    _killed_writer(path)
    run = rec.load_recording(path)
    assert len(run) == 1000 // CHUNK * CHUNK  # the partial last chunk is lost, nothing else
    assert np.array_equal(run.t, np.arange(len(run)) * 0.001)
    assert np.array_equal(run.commands["vibration"]["amplitude"], 0.5 * np.arange(len(run)))
    assert path.exists() and not rec.part_path(path).exists()


def test_replay_recovers_a_cut_short_stream(tmp_path, fmt):
    """``hapticsdk replay run.<fmt>`` when only the stream of a killed writer is left."""
    from hapticsdk.cli import main
    path = tmp_path / f"run.{fmt}"
    _killed_writer(path)
    assert main(["replay", str(path)]) == 0
    assert len(load_run(path)) == 1000 // CHUNK * CHUNK and not rec.part_path(path).exists()
