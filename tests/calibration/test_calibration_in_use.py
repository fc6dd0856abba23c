"""Saved calibrations are used by rendering (issue 13.6) and a bad file in the calibration
directory never crashes or hangs ``doctor`` / ``calibrate list`` (issue 13.7)."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from hapticsdk.calibration import VoiceCoilCalibration, generate_answers, list_calibrations, load_calibration
from hapticsdk.calibration.store import ENV_DIR, save_calibration
from hapticsdk.plugins import registry

needs_hardness = pytest.mark.skipif("hardness" not in registry("dimension"), reason="hapticsdk-hardness not installed")


def _cli(args: list[str], cal_dir: Path, timeout: float = 120) -> subprocess.CompletedProcess:
    env = dict(os.environ, **{ENV_DIR: str(cal_dir), "HAPTICSDK_DEVICE_CONFIG": str(cal_dir / "none.json")})
    env.pop("HAPTICSDK_DEVICE_OPTIONS", None)
    return subprocess.run([sys.executable, "-m", "hapticsdk", *args], capture_output=True, text=True,
                          env=env, timeout=timeout)


@needs_hardness
def test_render_uses_the_saved_voicecoil_calibration(tmp_path, monkeypatch):
    cal_dir = tmp_path / "cal"
    # answers of an observer whose coil feels 1.5 times stiffer than the paper's formula (7)
    paper = VoiceCoilCalibration.paper()
    ans = generate_answers(lambda f: 1.5 * paper.gs_coil(f), people=10, repeats=2, seed=3)
    answers = ans.to_csv(tmp_path / "answers.csv")
    r = _cli(["calibrate", "voicecoil", str(answers), "--save", "--json"], cal_dir)
    assert r.returncode == 0, r.stderr
    saved = Path(json.loads(r.stdout)["saved"])
    assert saved.parent == cal_dir and saved.is_file()
    digest = hashlib.sha256(saved.read_bytes()).hexdigest()

    r = _cli(["render", "--hardness", "0.9", "--seconds", "0.05", "--json"], cal_dir)
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    cal = rep["calibrations"]["hardness"]
    assert cal["file"] == str(saved) and cal["sha256"] == digest and cal["origin"] == "file-any"
    assert str(saved) in cal["source"]
    # the coil frequency follows the saved curve, not the paper's
    rend = rep["renderers"]["hardness"]
    fitted = VoiceCoilCalibration.from_dict(json.loads(saved.read_text()))
    want, _ = fitted.frequency_for(rend["coil_stiffness_n_per_mm"])
    paper_f, _ = paper.frequency_for(rend["coil_stiffness_n_per_mm"])
    assert rend["coil_frequency_hz"] == pytest.approx(want, rel=1e-9)
    assert abs(want - paper_f) > 5.0  # 1.5x stiffer per Hz: a clearly lower frequency

    # the plan records it too
    from hapticsdk.compiler import compile_scene
    from hapticsdk.scene import Scene
    monkeypatch.setenv(ENV_DIR, str(cal_dir))
    plan = compile_scene(Scene.for_material({"hardness": 0.9}, importance={"enabled": False})).to_dict()
    rec = next(iter(plan["materials"].values()))["calibrations"]["hardness"]
    assert rec["file"] == str(saved) and rec["sha256"] == digest


@needs_hardness
def test_render_says_when_no_calibration_is_saved(tmp_path):
    r = _cli(["render", "--hardness", "0.9", "--seconds", "0.05", "--json"], tmp_path / "empty")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    cal = rep["calibrations"]["hardness"]
    assert cal["origin"] == "default" and cal["file"] is None and cal["sha256"] is None
    assert "no voicecoil calibration file saved" in cal["source"]
    assert rep["renderers"]["hardness"]["calibration"]["source"] == "paper formula (7)"


def test_render_uses_a_saved_piezo_table(tmp_path, monkeypatch):
    if "roughness" not in registry("dimension"):
        pytest.skip("hapticsdk-roughness not installed")
    from hapticsdk.calibration import PiezoTable
    from hapticsdk.compiler import compile_scene
    from hapticsdk.runtime.render import render_plan
    from hapticsdk.scene import Scene
    from hapticsdk_roughness.table import resolve_table

    base = resolve_table(None)
    mine = PiezoTable(frequencies_hz=base.frequencies_hz, voltages_v=base.voltages_v,
                      acceleration=np.asarray(base.acceleration) * 2.0, generated=False, source="bench test")
    path = save_calibration(mine, tmp_path)
    monkeypatch.setenv(ENV_DIR, str(tmp_path))
    plan = compile_scene(Scene.for_material({"roughness": 0.5}))
    assert plan.material().calibrations["roughness"]["file"] == str(path)
    rep = render_plan(plan, seconds=0.05)
    rec = rep.calibrations["roughness"]
    assert rec["file"] == str(path) and rec["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert "changed_since_plan" not in rec
    # the renderer looked V_out up in the saved table
    rend = rep.renderers["roughness"]
    assert rend["table_source"] == "bench test" and rend["table_generated"] is False
    assert rend["v_out_v"] == pytest.approx(mine.voltage_for(rend["Fpeak_hz"], rend["AFpeak_m_s2"])[0])
    # the file changes after compiling: the render uses the new one and says so
    save_calibration(PiezoTable(frequencies_hz=base.frequencies_hz, voltages_v=base.voltages_v,
                                acceleration=np.asarray(base.acceleration) * 3.0, generated=False,
                                source="bench test 2"), tmp_path)
    rec2 = render_plan(plan, seconds=0.05).calibrations["roughness"]
    assert rec2["sha256"] != rec["sha256"] and rec2["changed_since_plan"]["sha256"] == rec["sha256"]


# -- issue 13.7: unreadable files are skipped, named, never block -----------------------

def _good(d: Path) -> Path:
    return save_calibration(VoiceCoilCalibration(coefficients=(0.0002, 0.01, -0.3), source="good"), d)


def _bad_files(d: Path) -> dict[str, str]:
    """name -> what the skip message must say."""
    (d / "bad-utf8.json").write_bytes(b'{"kind": "voicecoil", "source": "\xff\xfe"}')
    (d / "deep.json").write_text("[" * 5000 + "]" * 5000)
    os.mkfifo(d / "fifo.json")
    (d / "dir.json").mkdir()
    os.symlink("/dev/zero", d / "zero.json")
    ragged = {"schema_version": 1, "kind": "piezo", "serial": None, "generated": False, "source": "x",
              "frequencies_hz": [50.0, 100.0], "voltages_v": [0.0, 10.0, 20.0],
              "acceleration_m_s2": [[0.0, 1.0, 2.0], [0.0, 1.0]]}
    (d / "ragged.json").write_text(json.dumps(ragged))
    return {"bad-utf8.json": "UTF-8", "deep.json": "nested", "fifo.json": "not a regular file",
            "dir.json": "directory", "zero.json": "not a regular file", "ragged.json": ""}


def _with_deadline(fn, seconds: float = 20.0):
    out: list = []
    t = threading.Thread(target=lambda: out.append(fn()), daemon=True)
    t.start()
    t.join(seconds)
    assert not t.is_alive(), "blocked on a file of the calibration directory"
    return out[0]


def test_bad_files_are_skipped_and_named(tmp_path, caplog):
    good = _good(tmp_path)
    expect = _bad_files(tmp_path)
    entries = _with_deadline(lambda: list_calibrations(tmp_path))
    by_name = {e.path.name: e for e in entries}
    assert set(by_name) == set(expect) | {good.name}
    assert by_name[good.name].error is None and by_name[good.name].sha256
    for name, word in expect.items():
        err = by_name[name].error
        assert err and word in err, (name, err)
    loaded = _with_deadline(lambda: load_calibration("voicecoil", directory=tmp_path))
    assert loaded.path == good and loaded.calibration.source == "good"
    assert str(tmp_path / "ragged.json") in load_calibration("piezo", directory=tmp_path).skipped
    warned = " ".join(r.getMessage() for r in caplog.records)
    for name in expect:
        assert name in warned


def test_cli_list_and_doctor_survive_bad_files(tmp_path):
    good = _good(tmp_path)
    expect = _bad_files(tmp_path)
    r = _cli(["calibrate", "list", "--json"], tmp_path, timeout=60)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    errs = {Path(f["path"]).name: f["error"] for f in out["files"]}
    assert all(errs[n] for n in expect) and errs[good.name] is None
    vc = next(u for u in out["in_use"] if u["kind"] == "voicecoil")
    assert vc["file"] == str(good)
    r = _cli(["doctor", "--json"], tmp_path, timeout=120)
    assert r.returncode in (0, 1), r.stderr
    assert "Traceback" not in r.stderr
    text = r.stdout
    for n in expect:
        assert n in text
