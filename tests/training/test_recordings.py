"""Recording format: round trips, schema validation and broken-recording errors."""

import json
import shutil

import numpy as np
import pytest

from hapticsdk.errors import RecordingError
from hapticsdk.training import extraction, recordings
from hapticsdk.training.recordings import (COLUMNS, load_manifest, load_ratings, read_trial_file,
                                           trial_from_columns, validate_trial, write_trial_file)


def _cols(gen23, i=0):
    return gen23.trials[i].columns("g")


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_trial_file_round_trip_exact(tmp_path, gen23, suffix):
    cols = _cols(gen23)
    p = tmp_path / f"t{suffix}"
    write_trial_file(p, cols)
    back = read_trial_file(p)
    for c in COLUMNS:
        if c == "phase":
            assert list(back[c]) == list(cols[c])
        else:
            np.testing.assert_array_equal(back[c], cols[c])


def test_written_set_extracts_like_memory(small_recordings):
    root, gs = small_recordings
    rs = load_manifest(root)
    ft = extraction.extract_set(rs)
    mem = extraction.extract_trials(gs.trials)
    np.testing.assert_allclose(ft.X, mem.X, rtol=1e-12)
    assert ft.samples == mem.samples
    r = load_ratings(root)
    assert r.dimensions == ("hardness", "roughness") and len(r.raters) == 3


def test_acceleration_unit_conversion(gen23):
    tr = gen23.trials[0]
    cols_g = tr.columns("g")
    cols_ms = tr.columns("m/s^2")
    a = trial_from_columns(cols_g, sample="S1", trial=1, fs_hz=500, accel_unit="g")
    b = trial_from_columns(cols_ms, sample="S1", trial=1, fs_hz=500, accel_unit="m/s^2")
    np.testing.assert_allclose(a.acc, b.acc, rtol=1e-12)
    assert abs(np.median(a.acc[:, 2]) - recordings.G0) < 0.2


def _broken(gen23, **changes):
    cols = {k: np.array(v, copy=True) for k, v in _cols(gen23).items()}
    fs = changes.pop("fs_hz", 500.0)
    for k, fn in changes.items():
        cols[k] = fn(cols[k])
    return trial_from_columns(cols, sample="S1", trial=1, fs_hz=fs, accel_unit="g", source="f.csv",
                              full_scale={"force_n": (0, 15), "acc": (-16, 16)})


@pytest.mark.parametrize("changes, field, words", [
    ({"force_n": lambda a: np.where(np.arange(len(a)) == 50, np.nan, a)}, "force_n", "NaN"),
    ({"acc_x": lambda a: np.where(np.arange(len(a)) == 9, np.inf, a)}, "acc_x", "NaN/Inf"),
    ({"fs_hz": 1000.0, "time_s": lambda t: t / 2}, "fs_hz", "expected 500"),
    ({"time_s": lambda t: t * 2}, "time_s", "does not match"),
    ({"force_n": lambda a: np.full_like(a, 1.0)}, "force_n", "constant"),
    ({"force_n": lambda a: np.where(a > 4.0, 15.0, a)}, "force_n", "clipped"),
    ({"acc_x": lambda a: np.where(np.abs(a) > 0.05, 16.0 * np.sign(a), a)}, "acc_x", "clipped"),
    ({"phase": lambda p: np.where(p == "slide", "slid", p)}, "phase", "phase value"),
])
def test_broken_trials_name_file_and_field(gen23, changes, field, words):
    tr = _broken(gen23, **changes)
    with pytest.raises(RecordingError) as ei:
        validate_trial(tr, expected_fs_hz=500.0)
    assert ei.value.field == field
    assert "f.csv" in str(ei.value) and "trial 1" in str(ei.value) and words in str(ei.value)


def test_short_and_empty_trials(gen23):
    cols = _cols(gen23)
    keep = np.arange(len(cols["time_s"])) < len(cols["time_s"]) - 800  # cut 1.6 s of slide
    short = trial_from_columns({k: v[keep] for k, v in cols.items()}, sample="S1", trial=2, fs_hz=500,
                               accel_unit="g", source="short.npz")
    with pytest.raises(RecordingError, match="too short") as ei:
        extraction.extract_trial(short)
    assert ei.value.field == "phase" and "short.npz" in str(ei.value)
    empty = trial_from_columns({k: v[:0] for k, v in cols.items()}, sample="S1", trial=3, fs_hz=500,
                               source="empty.npz")
    with pytest.raises(RecordingError, match="empty") as ei:
        validate_trial(empty)
    assert ei.value.field == "rows"


def test_broken_files(tmp_path, gen23):
    cols = _cols(gen23)
    p = tmp_path / "missing.csv"
    write_trial_file(p, cols)
    text = p.read_text().splitlines()
    header = text[0].split(",")
    j = header.index("displacement_mm")
    p.write_text("\n".join(",".join(x for i, x in enumerate(l.split(",")) if i != j) for l in text) + "\n")
    with pytest.raises(RecordingError) as ei:
        read_trial_file(p)
    assert ei.value.field == "displacement_mm" and "missing.csv" in str(ei.value)
    e = tmp_path / "empty.csv"
    e.write_text("")
    with pytest.raises(RecordingError) as ei:
        read_trial_file(e)
    assert ei.value.field == "rows" and "empty.csv" in str(ei.value)
    bad = tmp_path / "nan.csv"
    write_trial_file(bad, cols)
    lines = bad.read_text().splitlines()
    parts = lines[30].split(",")
    parts[COLUMNS.index("acc_x")] = "nan"
    lines[30] = ",".join(parts)
    bad.write_text("\n".join(lines) + "\n")
    tr = trial_from_columns(read_trial_file(bad), sample="S9", trial=4, fs_hz=500, source=str(bad))
    with pytest.raises(RecordingError) as ei:
        validate_trial(tr)
    assert ei.value.field == "acc_x" and "nan.csv" in str(ei.value) and "sample S9, trial 4" in str(ei.value)


def test_manifest_schema_and_wrong_rate(small_recordings, tmp_path):
    root, _ = small_recordings
    dst = tmp_path / "rec"
    shutil.copytree(root, dst)
    doc = json.loads((dst / "recordings.json").read_text())
    doc["trials"][1]["fs_hz"] = 250.0
    (dst / "recordings.json").write_text(json.dumps(doc))
    with pytest.raises(RecordingError) as ei:
        extraction.extract_set(load_manifest(dst))
    assert ei.value.field == "fs_hz" and "S1_t02.csv" in str(ei.value)
    del doc["fs_hz"]
    (dst / "recordings.json").write_text(json.dumps(doc))
    with pytest.raises(RecordingError, match="fs_hz"):
        load_manifest(dst)
    doc["fs_hz"] = 500
    doc["accel_unit"] = "furlong"
    (dst / "recordings.json").write_text(json.dumps(doc))
    with pytest.raises(RecordingError) as ei:
        load_manifest(dst)
    assert ei.value.field == "accel_unit"


def test_ratings_validation(small_recordings, tmp_path):
    root, _ = small_recordings
    doc = json.loads((root / "ratings.json").read_text())
    doc["ratings"]["S1"]["hardness"] = doc["ratings"]["S1"]["hardness"][:2]
    (tmp_path / "ratings.json").write_text(json.dumps(doc))
    with pytest.raises(RecordingError) as ei:
        load_ratings(tmp_path)
    assert ei.value.field == "ratings.S1.hardness"
    doc["ratings"]["S1"]["hardness"] = [10, 20, 130]
    (tmp_path / "ratings.json").write_text(json.dumps(doc))
    with pytest.raises(RecordingError, match="130"):
        load_ratings(tmp_path)
