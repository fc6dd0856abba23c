"""Live recording (issue 27): the servo streams every tick to disk in chunks; the file
is a run file that replay and the plotting helpers read; a servo killed mid-run leaves a
stream whose complete chunks are recovered."""

import os
import signal
import time

import numpy as np
import pytest

import hapticsdk as hs
from hapticsdk.errors import ServoProcessDied, ValidationError
from hapticsdk.runlog import load_run
from hapticsdk.runtime import recorder as rec
from hapticsdk.sim.finger import Trajectory

PAD = {"schema_version": 1, "name": "pad",
       "objects": [{"name": "pad", "material": {"intensities": {"hardness": 0.9, "roughness": 0.5}}}],
       "devices": {"force": "probe-virtual"},
       "settings": {"solver": {"seed": 0}, "importance": {"enabled": False}}}
#: press 2 mm and slide along x at 40 mm/s (the piezo is driven above its 20 mm/s gate)
SLIDE = Trajectory([(0.0, -20.0, 2.0), (0.2, -20.0, -2.0), (1.2, 20.0, -2.0), (600.0, 20.0, -2.0)])


def _wait(pred, timeout=20.0):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if pred():
            return True
        time.sleep(0.005)
    return False


def test_every_tick_is_recorded_and_replayable(tmp_path):
    path = tmp_path / "run.npz"
    with hs.Session(PAD, trajectory=SLIDE, isolation="thread", realtime=False, record=path) as s:
        assert _wait(lambda: s.state().ticks > 2500)
        summary = s.close()
        loop = s._servo_holder[0].loop
        n = loop.ticks
    assert summary["record_path"] == str(path) and not rec.part_path(path).exists()
    run = load_run(path)
    assert len(run) == n  # every tick, in order, none twice
    assert np.allclose(np.diff(run.t), loop.period_s)
    # the kinematic probe is exactly the trajectory
    for i in (0, 500, n - 1):
        x, y, z, *_ = SLIDE.at3(run.t[i])
        assert run.position_mm[i] == pytest.approx([x, y, z])
    with np.load(path) as z:
        # the servo log's own arrays for the plotting helpers, ids named in the header
        assert z["object_id"].max() == 0 and z["force_n"].max() > 0 and z["vibration.amplitude"].max() > 0
        assert np.array_equal(z["force_n"], z["force_n"])
    assert run.header["meta"]["objects"] == {"0": "pad"}
    assert set(run.roles) == set(s.devices)
    # hapticsdk replay plays it back
    from hapticsdk.cli import main
    assert main(["replay", str(path)]) == 0


def test_a_killed_servo_leaves_its_complete_chunks(tmp_path):
    path = tmp_path / "run.npz"
    with hs.Session(PAD, trajectory=SLIDE, record=path) as s:
        assert _wait(lambda: s.state().ticks > 2.5 * rec.CHUNK_ROWS)
        os.kill(s.servo_pid, signal.SIGKILL)
        with pytest.raises(ServoProcessDied):
            assert _wait(lambda: s.state() is None, 10.0)
    assert not path.exists() and rec.part_path(path).exists()
    run = rec.load_recording(path)
    n = len(run)
    assert n >= 2 * rec.CHUNK_ROWS and n % rec.CHUNK_ROWS == 0
    assert np.all(np.diff(run.t) > 0)
    assert path.exists() and not rec.part_path(path).exists()


def test_record_paths_are_checked(tmp_path):
    with pytest.raises(ValidationError, match="h5py"):
        hs.Session(PAD, record=tmp_path / "run.h5")
    with pytest.raises(ValidationError):
        hs.Session(PAD, record=tmp_path / "run.csv")
