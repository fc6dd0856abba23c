"""A recording stream (``.part``) left by a crashed session may be damaged anywhere: a
header that is not the writer's (missing or wrong ``columns`` / ``roles``, a
``period_s`` that is no period, ``objects`` that map nothing) raises RecordingError
naming the field, for both writers (``.npz`` and ``.h5`` streams) -- not KeyError,
ZeroDivisionError, TypeError, AttributeError or ValueError, and no run file is written
with a period of "x"."""

import json
import struct

import numpy as np
import pytest

from hapticsdk.errors import RecordingError
from hapticsdk.runtime import recording_layout as layout
from hapticsdk.runtime.recorder import MAGIC, load_recording

COLS = layout.columns(["force"])
GOOD = {"columns": COLS, "roles": ["force"], "period_s": 0.001, "objects": {"0": "a"}}
DROP = object()

CASES = [
    ("columns", DROP, "record.columns"), ("columns", [], "record.columns"), ("columns", 5, "record.columns"),
    ("columns", ["a", "b"], "record.columns"), ("roles", DROP, "record.roles"), ("roles", "force", "record.roles"),
    ("roles", ["force", "coil"], "record.columns"), ("roles", ["force", "force"], "record.roles"),
    ("period_s", DROP, "record.period_s"), ("period_s", "x", "record.period_s"),
    ("period_s", None, "record.period_s"), ("period_s", -1, "record.period_s"),
    ("period_s", 10 ** 400, "record.period_s"), ("objects", [1], "record.objects"),
    ("objects", {"x": "a"}, "record.objects"), ("objects", {"0": 5}, "record.objects"),
]


def _header(key, value):
    h = dict(GOOD)
    if value is DROP:
        del h[key]
    else:
        h[key] = value
    return h


def _npz_part(tmp_path, header):
    p = tmp_path / "run.npz.part"
    head = (json.dumps(header) if header is not None else "[1, 2]").encode()
    head += b" " * (-len(head) % 8)
    p.write_bytes(MAGIC + struct.pack("<Q", len(head)) + head + np.arange(3.0 * len(COLS)).tobytes())
    return p


@pytest.mark.parametrize("key, value, field", CASES)
def test_npz_stream_with_a_damaged_header(tmp_path, key, value, field):
    with pytest.raises(RecordingError) as exc:
        load_recording(_npz_part(tmp_path, _header(key, value)))
    assert exc.value.field == field
    assert not (tmp_path / "run.npz").exists()


def test_npz_stream_whose_header_is_no_object(tmp_path):
    with pytest.raises(RecordingError) as exc:
        load_recording(_npz_part(tmp_path, None))
    assert exc.value.field == "record.header"


@pytest.mark.parametrize("key, value, field", CASES)
def test_h5_stream_with_a_damaged_header(tmp_path, key, value, field):
    pytest.importorskip("h5py")
    from hapticsdk.runtime.recorder_h5 import H5Appender

    p = tmp_path / "run.h5.part"
    app = H5Appender(p, GOOD, 4)
    app.append(np.zeros((2, len(COLS))))
    app.close()
    import h5py
    with h5py.File(p, "r+") as f:
        f.attrs["stream_header_json"] = json.dumps(_header(key, value))
    with pytest.raises(RecordingError) as exc:
        load_recording(p)
    assert exc.value.field == field


def test_good_stream_still_loads(tmp_path):
    run = load_recording(_npz_part(tmp_path, GOOD))
    assert run.n_ticks == 3 if hasattr(run, "n_ticks") else run is not None
