"""Every file the SDK writes is replaced atomically (issue 13.5): SIGKILL mid-write, a tiny
file-size limit, concurrent writers with a reader, a symbolic link in the calibration
folder, a failing WAV sink."""

from __future__ import annotations

import os
import random
import resource
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

from hapticsdk.calibration import PiezoTable, VoiceCoilCalibration, load_calibration, read_calibration
from hapticsdk.calibration.store import save_calibration
from hapticsdk.errors import FileWriteError
from hapticsdk.plugins import registry


def _table(scale: float, source: str, nf: int = 80, nv: int = 40) -> PiezoTable:
    """A plausible piezo table of about 60 kB of JSON."""
    f = np.linspace(20.0, 400.0, nf)
    v = np.linspace(0.0, 100.0, nv)
    acc = scale * (0.01 + np.outer(1.0 + f / 400.0, v / 100.0))
    return PiezoTable(frequencies_hz=f, voltages_v=v, acceleration=acc, generated=True, source=source)


CHILD = textwrap.dedent("""
    import sys, numpy as np
    from pathlib import Path
    from hapticsdk.calibration import PiezoTable
    from hapticsdk.calibration.store import save_calibration
    from hapticsdk.training.recordings import write_trial_file, COLUMNS
    d = Path(sys.argv[1])
    f = np.linspace(20.0, 400.0, 80); v = np.linspace(0.0, 100.0, 40)
    n = 10000
    i = 0
    while True:
        i += 1
        acc = (i % 7 + 1) * (0.01 + np.outer(1.0 + f / 400.0, v / 100.0))
        save_calibration(PiezoTable(f, v, acc, generated=True, source=f"round {i}"), path=d / "piezo-any.json")
        cols = {c: np.full(n, float(i)) for c in COLUMNS[:-1]}
        cols["phase"] = np.array(["press"] * n)
        write_trial_file(d / "trial.csv", cols)
        if i == 1:
            print("ready", flush=True)
""")


def test_sigkill_mid_write_leaves_the_old_or_the_new_file(tmp_path):
    from hapticsdk.training.recordings import read_trial_file

    script = tmp_path / "child.py"
    script.write_text(CHILD)
    rng = random.Random(13)
    for _ in range(5):
        p = subprocess.Popen([sys.executable, str(script), str(tmp_path)], stdout=subprocess.PIPE, text=True)
        assert p.stdout.readline().strip() == "ready"
        time.sleep(rng.uniform(0.0, 0.4))
        p.send_signal(signal.SIGKILL)
        p.wait(10)
        cal = read_calibration(tmp_path / "piezo-any.json")  # parses, validates: whole
        assert cal.source.startswith("round ")
        cols = read_trial_file(tmp_path / "trial.csv")
        assert len(cols["time_s"]) == 10000 and np.unique(cols["time_s"]).size == 1
        assert not np.isnan(cols["acc_z"]).any()


def _limit_fsize(nbytes: int):
    def pre() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, nbytes))
    return pre


@pytest.mark.parametrize("argv", [["calibrate", "answers", "{out}", "--people", "30"],
                                  ["plan", "S7", "-o", "{out}"]])
def test_file_size_limit_keeps_the_old_file_and_exits_2(tmp_path, tmp_path_factory, argv):
    out = tmp_path / "out.file"
    cache = tmp_path_factory.mktemp("cache")
    out.write_text("old content\n")
    # an empty cache folder: the caches' own writes (the model's and the solver's .npz) also
    # meet the limit, whatever this machine's cache holds
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", HAPTICSDK_CACHE_DIR=str(cache))
    r = subprocess.run([sys.executable, "-m", "hapticsdk", *[a.format(out=out) for a in argv]],
                       capture_output=True, text=True, env=env, timeout=120, preexec_fn=_limit_fsize(2048))
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert r.stderr.startswith(f"hapticsdk: error: {out}: "), r.stderr
    assert "Traceback" not in r.stderr
    assert out.read_text() == "old content\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.file"]  # no temporary file left
    assert not [p for p in cache.rglob("*.tmp")]                                     # nor in the cache


def test_concurrent_writers_and_a_reader_never_see_a_partial_file(tmp_path):
    tables = [_table(1.0, "writer A"), _table(2.0, "writer B")]
    save_calibration(tables[0], tmp_path)
    stop = threading.Event()
    errors: list[BaseException] = []

    def writer(t: PiezoTable) -> None:
        try:
            while not stop.is_set():
                save_calibration(t, tmp_path)
        except BaseException as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=writer, args=(t,)) for t in tables]
    for t in threads:
        t.start()
    seen = {}
    try:
        for _ in range(30):
            got = load_calibration("piezo", directory=tmp_path)
            assert got.origin == "file-any" and not got.skipped, got.to_dict()
            seen[got.calibration.source] = seen.get(got.calibration.source, 0) + 1
    finally:
        stop.set()
        for t in threads:
            t.join(30)
    assert not errors
    assert set(seen) <= {"writer A", "writer B"}
    assert [p.name for p in tmp_path.iterdir()] == ["piezo-any.json"]


def test_a_symlink_in_the_calibration_folder_is_replaced_not_followed(tmp_path):
    cal_dir = tmp_path / "cal"
    cal_dir.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    link = cal_dir / "voicecoil-any.json"
    link.symlink_to(victim)
    path = save_calibration(VoiceCoilCalibration(source="mine"), cal_dir)
    assert path == link and not link.is_symlink() and link.is_file()
    assert victim.read_text() == "precious"
    assert read_calibration(link).source == "mine"


def test_write_into_a_missing_folder_is_a_file_write_error(tmp_path):
    from hapticsdk.compiler import compile_scene
    from hapticsdk.scene import Scene
    plan = compile_scene(Scene.for_material({"roughness": 0.5}))
    with pytest.raises(FileWriteError) as ei:
        plan.save(tmp_path / "nowhere" / "plan.json")
    assert str(tmp_path / "nowhere") in str(ei.value)


@pytest.mark.skipif("voicecoil-virtual" not in registry("actuator"), reason="hapticsdk-hardness not installed")
def test_wav_sink_replaces_the_file_only_when_complete(tmp_path):
    import errno
    import wave

    from hapticsdk.perception.dimensions import ChannelCommand
    from hapticsdk_hardness.voicecoil import VoiceCoilVirtual

    path = tmp_path / "coil.wav"
    path.write_bytes(b"old")

    def play(coil: VoiceCoilVirtual, ticks: int) -> None:
        for k in range(ticks):
            coil.command(ChannelCommand("coil", frequency_hz=100.0, amplitude=0.8), now=k * 1e-3)
            coil.step(1e-3)

    coil = VoiceCoilVirtual(sink=f"wav:{path}", sample_rate_hz=8000.0).open()
    play(coil, 50)
    assert path.read_bytes() == b"old"  # nothing replaced while playing
    real = coil.sink._w.writeframes

    def full(data: bytes) -> None:
        real(data[: len(data) // 2])
        raise OSError(errno.ENOSPC, "No space left on device")
    coil.sink._w.writeframes = full
    with pytest.raises(OSError):
        play(coil, 1)
    coil.close()
    assert path.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["coil.wav"]

    coil = VoiceCoilVirtual(sink=f"wav:{path}", sample_rate_hz=8000.0).open()
    play(coil, 50)
    coil.close()
    with wave.open(str(path), "rb") as w:
        assert w.getnframes() == 400 and w.getframerate() == 8000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["coil.wav"]


def test_a_killed_writers_temporary_file_is_removed_by_the_next_write(tmp_path):
    """SIGKILL between mkstemp and the rename leaves ``.<name>.<random>.tmp``; the next
    write of that file (under the directory's lock) removes it, so killed writers do not
    pile up copies. Files that only look similar are left alone."""
    from hapticsdk.fileio import atomic_write_text

    target = tmp_path / "cal.json"
    child = textwrap.dedent("""
        import sys
        from hapticsdk.fileio import atomic_writer
        with atomic_writer(sys.argv[1], "w") as fh:
            fh.write("half")
            fh.flush()
            print("ready", flush=True)
            sys.stdin.read()  # killed here, before the rename
    """)
    p = subprocess.Popen([sys.executable, "-c", child, str(target)], stdout=subprocess.PIPE,
                         stdin=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "ready"
    p.send_signal(signal.SIGKILL)
    p.wait(10)
    orphans = [x.name for x in tmp_path.iterdir() if x.name.endswith(".tmp")]
    assert len(orphans) == 1 and orphans[0].startswith(".cal.json.")
    keep = [".cal.json.tmp", ".cal.json.toolong12.tmp", ".other.json.abcdefgh.tmp", "cal.json.abcdefgh.tmp"]
    for name in keep:
        (tmp_path / name).write_text("not ours")
    atomic_write_text(target, "new")
    assert target.read_text() == "new"
    assert sorted(x.name for x in tmp_path.iterdir()) == sorted(keep + ["cal.json"])


SAVEZ_CHILD = r"""
import sys
import numpy as np
from hapticsdk.errors import FileWriteError
from hapticsdk.fileio import atomic_savez
try:
    atomic_savez(sys.argv[1], compressed=sys.argv[2] == "1", a=np.arange(4096.0), b=np.array("text"))
except FileWriteError as exc:
    print("refused:", exc)
"""


@pytest.mark.parametrize("compressed", ["0", "1"])
def test_a_failed_npz_write_leaves_no_open_archive(tmp_path, compressed):
    """An ``.npz`` that meets a file-size limit is refused with the named error, the old
    file kept, and nothing is printed after it (numpy < 1.25's ``savez`` left its
    ``ZipFile`` to ``__del__``, which printed "Exception ignored ... seek of closed file")."""
    out = tmp_path / "old.npz"
    out.write_bytes(b"old")
    r = subprocess.run([sys.executable, "-c", SAVEZ_CHILD, str(out), compressed], capture_output=True, text=True,
                       timeout=120, preexec_fn=_limit_fsize(2048))
    assert r.returncode == 0 and r.stdout.startswith("refused:"), (r.stdout, r.stderr)
    assert r.stderr == ""
    assert out.read_bytes() == b"old"


def test_atomic_savez_round_trips_what_numpy_savez_writes(tmp_path):
    import zipfile

    import numpy as np

    from hapticsdk.fileio import atomic_savez

    arrays = {"x": np.linspace(0, 1, 7).reshape(7, 1), "n": np.arange(5, dtype=np.int16),
              "s": np.array(json_text := '{"k": 1}'), "e": np.zeros((0, 3)), "cmd/role/f": np.ones(2, bool)}
    for compressed in (False, True):
        atomic_savez(tmp_path / "a.npz", compressed=compressed, **arrays)
        (np.savez_compressed if compressed else np.savez)(tmp_path / "b.npz", **arrays)
        with zipfile.ZipFile(tmp_path / "a.npz") as za, zipfile.ZipFile(tmp_path / "b.npz") as zb:
            assert sorted(za.namelist()) == sorted(zb.namelist())      # numpy's member names
            assert {i.compress_type for i in za.infolist()} == {i.compress_type for i in zb.infolist()}
        with np.load(tmp_path / "a.npz", allow_pickle=False) as a, np.load(tmp_path / "b.npz") as b:
            assert sorted(a.files) == sorted(b.files) == sorted(arrays)
            for k in arrays:
                assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape
                assert np.array_equal(a[k], b[k])
    assert str(np.load(tmp_path / "a.npz")["s"]) == json_text


def test_atomic_savez_refuses_an_array_of_objects(tmp_path):
    """The SDK's readers load ``.npz`` files with ``allow_pickle=False``: an array that only
    pickling could store is refused by name, and no file is written."""
    import numpy as np

    from hapticsdk.fileio import atomic_savez

    with pytest.raises(FileWriteError, match="'tags'"):
        atomic_savez(tmp_path / "a.npz", x=np.zeros(3), tags=np.array([{"k": 1}, None], dtype=object))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
@pytest.mark.parametrize("old_mode", [0o600, 0o640, 0o664, 0o755])
def test_a_replaced_file_keeps_its_permissions_and_a_new_one_follows_the_umask(tmp_path, old_mode):
    """mkstemp makes its file 0600; the replacement gets the permission bits of the file
    it replaces (a user's 0640 stays readable by the group, a private 0600 stays
    private), and a new file 0644 less the process's umask, as open() would make it."""
    from hapticsdk.fileio import atomic_write_bytes
    old = tmp_path / "kept.bin"
    old.write_bytes(b"old")
    os.chmod(old, old_mode)
    atomic_write_bytes(old, b"new")
    assert old.read_bytes() == b"new" and (os.stat(old).st_mode & 0o777) == old_mode
    mask = os.umask(0o027)
    try:
        new = tmp_path / "fresh.bin"
        atomic_write_bytes(new, b"x")
        assert (os.stat(new).st_mode & 0o777) == 0o644 & ~0o027
    finally:
        os.umask(mask)


def test_the_output_check_names_a_directory_and_a_dangling_link(tmp_path):
    """check_output_path: a directory is refused by name; with overwrite=False a symbolic
    link whose target does not exist is refused too (writing would create the target
    through it), and atomic_writer refuses a directory before creating a temporary file."""
    from hapticsdk.fileio import atomic_write_bytes, check_output_path
    d = tmp_path / "adir"
    d.mkdir()
    with pytest.raises(FileWriteError, match="is a directory"):
        check_output_path(d)
    with pytest.raises(FileWriteError, match="is a directory"):
        atomic_write_bytes(d, b"x")
    assert sorted(os.listdir(tmp_path)) == ["adir"]
    link = tmp_path / "link.json"
    link.symlink_to(tmp_path / "nowhere.json")
    with pytest.raises(FileWriteError, match="exists already"):
        check_output_path(link, overwrite=False)
    assert check_output_path(link) == link   # overwriting is allowed: the link is replaced


def test_a_refused_json_or_npz_names_the_path_when_no_field_is_given(tmp_path):
    from hapticsdk.fileio import atomic_savez, atomic_write_json
    p = tmp_path / "doc.json"
    with pytest.raises(FileWriteError) as ei:
        atomic_write_json(p, {"x": float("nan")})
    assert ei.value.field == str(p) and not p.exists()
    q = tmp_path / "a.npz"
    with pytest.raises(FileWriteError) as ei:
        atomic_savez(q, a=np.array([object()], dtype=object))
    assert ei.value.field == str(q) and not q.exists()


@pytest.mark.parametrize("writer", ["bytes", "check"])
def test_a_device_or_pipe_at_the_target_is_refused_and_left_in_place(tmp_path, writer):
    """A write replaces its target whole, so a target that is not a regular file (a named
    pipe here; a device such as /dev/null is the same case) is refused by name before
    anything is written, and stays what it was. (Replacing /dev/null, as root, removed the
    machine's /dev/null.)"""
    import stat as st

    from hapticsdk.fileio import atomic_write_bytes, check_output_path
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    with pytest.raises(FileWriteError, match="not a regular file"):
        if writer == "bytes":
            atomic_write_bytes(fifo, b"data")
        else:
            check_output_path(fifo)
    assert st.S_ISFIFO(os.lstat(fifo).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe"]   # no temporary file left


def test_the_cli_refuses_a_pipe_as_its_output_with_status_2(tmp_path):
    fifo = tmp_path / "out.json"
    os.mkfifo(fifo)
    r = subprocess.run([sys.executable, "-m", "hapticsdk", "export", "S7", "-o", str(fifo)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert "not a regular file" in r.stderr
    assert os.path.exists(fifo) and not os.path.isfile(fifo)
