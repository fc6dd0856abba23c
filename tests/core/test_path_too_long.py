"""A path the operating system cannot hold (a name over its NAME_MAX, a path over its
PATH_MAX) is a named error at every reader, writer and command-line argument that takes
a file -- not an OSError ("File name too long") from a ``Path.exists()`` /
``is_dir()`` / ``is_file()`` probe, which pathlib raises for that errno instead of
answering False.

Found by an argument campaign: ``hapticsdk plan S999...`` (300 characters, tried as a
scene file first), ``hapticsdk plan S7 -o aaa...json`` and ``hapticsdk export S7 -o
aaa...`` ended in "internal error: OSError: [Errno 36] File name too long"."""

from __future__ import annotations

import pytest
from core.test_path_arguments import _readers

from hapticsdk.cli import main
from hapticsdk.errors import HapticSDKError

#: one name of 300 bytes (NAME_MAX is 255 on Linux, macOS and Windows file systems), a
#: path of 5000 bytes (Linux PATH_MAX 4096) of short names, a name of 300 two-byte
#: characters (600 bytes: the limit counts the encoded bytes)
LONG = ["a" * 300 + ".json", "d/" * 2500 + "x.json", "\u00e9" * 150 + ".json"]


def _writers():
    from hapticsdk.fileio import atomic_write_json, atomic_write_text, check_output_path
    from hapticsdk.interop.hjif_export import write_hjif
    return {"check_output_path": check_output_path, "atomic_write_text": lambda p: atomic_write_text(p, "x"),
            "atomic_write_json": lambda p: atomic_write_json(p, {}), "write_hjif": lambda p: write_hjif(None, p)}


@pytest.mark.parametrize("name", sorted(_readers()) + sorted(_writers()))
@pytest.mark.parametrize("value", LONG, ids=["name", "path", "utf8"])
def test_a_path_too_long_for_the_system_is_a_named_error(tmp_path, monkeypatch, name, value):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(HapticSDKError):
        {**_readers(), **_writers()}[name](value)


@pytest.mark.parametrize("argv", [
    ["plan", "S" + "9" * 300], ["export", "S" + "9" * 300, "-o", "m.hjif"], ["render", "--scene", "a" * 300 + ".json"],
    ["plan", "S7", "-o", "a" * 300 + ".json"], ["export", "S7", "-o", "a" * 300], ["replay", "a" * 300 + ".npz"],
    ["import", "a" * 300 + ".hjif"], ["play", "a" * 300 + ".ahap"], ["features", "a" * 300],
    ["calibrate", "voicecoil", "a" * 300 + ".csv"], ["materials", "--library", "a" * 300 + ".json"],
    ["dataset", "generate", "a" * 300], ["train", "a" * 300, "--out", "m.onnx"],
    ["calibrate", "piezo", "m.csv", "--save", "a" * 300]])
def test_a_command_given_a_path_too_long_exits_2(tmp_path, monkeypatch, capsys, argv):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HAPTICSDK_CACHE_DIR", str(tmp_path / "cache"))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "internal error" not in err and "hapticsdk: error:" in err


def test_a_manifest_naming_a_trial_file_too_long_is_a_named_error(tmp_path):
    # a recording set is data: its manifest names the trial files
    import json

    from hapticsdk.errors import RecordingError
    from hapticsdk.training.recordings import load_manifest, read_trial_file
    with pytest.raises(RecordingError):
        read_trial_file(tmp_path / ("a" * 300 + ".npz"))
    m = {"schema_version": 1, "format": "hapticsdk-recording", "fs_hz": 1000.0, "accel_unit": "g",
         "lateral_axis": "x", "trials": [{"sample": "S1", "trial": 1, "file": "a" * 300 + ".npz"}]}
    (tmp_path / "recordings.json").write_text(json.dumps(m))
    from hapticsdk.training.extraction import extract_set
    with pytest.raises(RecordingError):
        extract_set(load_manifest(tmp_path))
