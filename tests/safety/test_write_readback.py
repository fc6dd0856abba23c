"""What the SDK writes it can read back (issue 31, item 1).

Every writer of a file the SDK reads again hands its reader to
:func:`hapticsdk.fileio.atomic_writer` (``verify=``): the finished temporary file is read
back with the reader's own limits before it replaces anything. Content the reader would
refuse raises :class:`~hapticsdk.fileio.UnreadableWriteError` and the old file stays,
also when the writing process is killed."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from hapticsdk.calibration import VoiceCoilCalibration, load_calibration, save_calibration
from hapticsdk.errors import FileWriteError, ValidationError
from hapticsdk.fileio import UnreadableWriteError, atomic_write_text

BIG = 5 * 1024 * 1024  # above the calibration reader's 4 MiB cap


def test_big_calibration_over_a_good_one_is_refused_and_the_good_one_stays(tmp_path):
    good = save_calibration(VoiceCoilCalibration(serial="A1", source="good"), tmp_path)
    before = good.read_bytes()
    with pytest.raises(UnreadableWriteError) as ei:
        save_calibration(VoiceCoilCalibration(serial="A1", source="x" * BIG), tmp_path)
    assert isinstance(ei.value, FileWriteError) and isinstance(ei.value, ValidationError)
    assert str(good) in str(ei.value) and "bytes" in str(ei.value)
    assert good.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [good.name]  # no temporary file left
    loaded = load_calibration("voicecoil", "A1", directory=tmp_path)
    assert loaded.origin == "file" and loaded.calibration.source == "good"


CHILD = textwrap.dedent("""
    import sys
    from hapticsdk.calibration import VoiceCoilCalibration, save_calibration
    from hapticsdk.errors import FileWriteError
    big = VoiceCoilCalibration(serial="A1", source="x" * (5 * 1024 * 1024))
    print("ready", flush=True)
    while True:
        try:
            save_calibration(big, sys.argv[1])
        except FileWriteError:
            pass
""")


@pytest.mark.parametrize("delay", [0.05, 0.2, 0.5])
def test_sigkill_while_writing_unreadable_content_keeps_the_good_file(tmp_path, delay):
    good = save_calibration(VoiceCoilCalibration(serial="A1", source="good"), tmp_path)
    before = good.read_bytes()
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "ready"
        time.sleep(delay)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=30)
        child.stdout.close()
    assert good.read_bytes() == before
    assert load_calibration("voicecoil", "A1", directory=tmp_path).calibration.source == "good"


def test_atomic_writer_verify_refusal_keeps_the_old_file(tmp_path):
    p = tmp_path / "f.txt"
    p.write_text("old")

    def reader(path):
        raise ValueError(f"{path}: too long")

    with pytest.raises(UnreadableWriteError) as ei:
        atomic_write_text(p, "new", verify=reader)
    assert "<new content>" in str(ei.value) and "too long" in ei.value.reason
    assert p.read_text() == "old" and os.listdir(tmp_path) == ["f.txt"]
    atomic_write_text(p, "new", verify=lambda path: path.read_text() == "new")
    assert p.read_text() == "new"


# ---- every writer/reader pair: the writer hands its reader, with its limits ------------
def _plan_writer(tmp_path):
    from hapticsdk.plan import RenderPlan
    from hapticsdk.compiler import compile_scene
    plan = compile_scene({"objects": [{"material": "S7"}]})
    d = plan.to_dict()
    d["materials"][next(iter(d["materials"]))]["features"]["GS"] = 1e6  # the reader refuses this value
    bad = RenderPlan.from_dict(d, validate=False)
    return (lambda p: plan.save(p)), (lambda p: bad.save(p))


def _runlog_writer(tmp_path, monkeypatch):
    import hapticsdk.runlog as rl
    from hapticsdk.runlog import RunRecorder
    from hapticsdk.devices.actuators import ChannelCommand, DeviceState

    def make(p):
        rec = RunRecorder(p)
        for i in range(20):
            st = DeviceState(position_mm=np.zeros(3), velocity_mm_s=np.zeros(3), t=i * 1e-3)
            rec.record(i * 1e-3, st, {"force": ChannelCommand("force", force_n=0.1)})
        rec.close()
        return p

    def bad(p):
        monkeypatch.setattr(rl, "MAX_RUN_BYTES", 16)  # the reader's cap, below what is written
        return make(p)
    return make, bad


def _trial_writer(suffix):
    def factory(tmp_path, monkeypatch):
        import hapticsdk.training.recordings as rec
        n = 8
        cols = {c: np.zeros(n) for c in rec.COLUMNS}
        cols["phase"] = np.array(["press"] * n)
        cols["time_s"] = np.arange(n) / 1000.0

        def bad(p):
            monkeypatch.setattr(rec, "MAX_TRIAL_BYTES", 16)
            if suffix == ".csv":  # the CSV reader's byte cap, below what is written
                import hapticsdk.schemas_io as sio
                orig = sio.read_csv_rows
                monkeypatch.setattr(sio, "read_csv_rows", lambda *a, **k: orig(*a, **{**k, "max_bytes": 16}))
            rec.write_trial_file(p, cols)
        return (lambda p: rec.write_trial_file(p, cols)), bad
    return factory


def _table_writer(tmp_path, monkeypatch):
    from hapticsdk_roughness import table as tb
    t = tb.resolve_table(None)

    def bad(p):
        import hapticsdk.schemas_io as sio
        orig = sio.read_json
        monkeypatch.setattr(sio, "read_json", lambda *a, **k: orig(*a, **{**k, "max_bytes": 16}))
        tb.save_table(t, p)
    return (lambda p: tb.save_table(t, p)), bad


@pytest.mark.parametrize("name,factory,suffix", [
    ("plan", lambda tmp, mp: _plan_writer(tmp), ".json"),
    ("runlog", _runlog_writer, ".npz"),
    ("trial-npz", _trial_writer(".npz"), ".npz"),
    ("trial-csv", _trial_writer(".csv"), ".csv"),
    ("piezo-table", _table_writer, ".json"),
])
def test_every_writer_reads_back_before_replacing(tmp_path, monkeypatch, name, factory, suffix):
    good_writer, bad_writer = factory(tmp_path, monkeypatch)
    p = tmp_path / f"{name}{suffix}"
    good_writer(p)
    before = p.read_bytes()
    with pytest.raises(ValidationError) as ei:
        bad_writer(p)
    assert isinstance(ei.value, UnreadableWriteError), repr(ei.value)
    assert p.read_bytes() == before
    assert sorted(x.name for x in tmp_path.iterdir()) == [p.name]
