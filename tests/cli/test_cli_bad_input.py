"""No input ends in a traceback (issue 13, item 9).

Every bad input below goes through ``hapticsdk.cli.main([...])`` in-process and must
give exit status 2, a ``hapticsdk: error: <field>: <reason>`` line on stderr naming
the expected field, and no traceback. A few run as real subprocesses (``python -m
hapticsdk``) so the interpreter's own exit path (pipe closed early, usage errors) is
covered too.

The cases are data: each is ``(id, argv, field)`` where ``argv`` may name files made by
the ``files`` fixture as ``{name}``. Output-path cases whose command would run for
minutes (``bench solvers``) pass only because the path is checked before the work.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from hapticsdk.cli import EXIT_BROKEN_PIPE, main

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_ONNX = ROOT / "plugins/hapticsdk-onnx/src/hapticsdk_onnx/models/default.onnx"

BAD_UTF8 = b'{"objects": [{"material": "S7\xff\xfe"}]}'
DEEP = "[" * 5000 + "]" * 5000
DEEP_OBJ = '{"a":' * 5000 + "1" + "}" * 5000


def _write_run(path: Path, header: dict, n: int = 5, **override: np.ndarray) -> Path:
    arrays = {"t": np.arange(n) * 1e-3, "state_t": np.arange(n) * 1e-3, "position_mm": np.zeros((n, 3)),
              "velocity_mm_s": np.zeros((n, 3)), "device_force_n": np.zeros((n, 3)),
              "buttons": np.zeros(n, np.int64), "header_json": np.array(json.dumps(header))}
    arrays.update(override)
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    return path


def _answers(path: Path, freqs: list[float]) -> Path:
    rows = ["person,frequency_hz,spring_n_per_mm,spring_stiffer"]
    for p in range(3):
        for f in freqs:
            for k, s in enumerate((0.3, 0.8, 1.5, 2.1)):
                rows.append(f"{p},{f:g},{s},{int(k >= 2)}")
    path.write_text("\n".join(rows) + "\n")
    return path


def _piezo_csv(path: Path, freqs: list[float], volts: list[float]) -> Path:
    rows = ["frequency_hz,voltage_v,acceleration_m_s2"]
    for f in freqs:
        for i, v in enumerate(volts):
            rows.append(f"{f:g},{v:g},{0.5 * i:g}")
    path.write_text("\n".join(rows) + "\n")
    return path


def _manifest_edit(src: Path, dst: Path, edit) -> Path:
    shutil.copytree(src, dst)
    doc = json.loads((dst / "recordings.json").read_text())
    edit(doc)
    (dst / "recordings.json").write_text(json.dumps(doc))
    return dst


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, str]:
    """Every bad file the cases name, keyed by the ``{name}`` used in argv."""
    from hapticsdk.training.pipeline import generate_feature_dataset

    d = tmp_path_factory.mktemp("bad")
    f: dict[str, Path] = {"dir": d / "adir", "missing_dir": d / "no" / "such"}
    f["dir"].mkdir()
    (d / "bad_utf8.json").write_bytes(BAD_UTF8)
    (d / "deep.json").write_text(DEEP)
    (d / "deep_obj.json").write_text(DEEP_OBJ)
    # parseable by json (under the recursion limit) but deep enough that validating it
    # (or printing the validation error) exhausts the stack: only the depth cap stops it
    deep = 960
    (d / "deep_field.json").write_text('{"objects": [{"material": "S7", "x": ' + "[" * deep + "]" * deep + "}]}")
    (d / "nan.json").write_text('{"objects": [{"material": "S7"}], "settings": {"servo": {"period_s": NaN}}}')
    (d / "empty.json").write_text("")
    (d / "exists.txt").write_text("keep me\n")
    (d / "safety_off.json").write_text(json.dumps(
        {"objects": [{"material": "S7"}],
         "devices": {"force": {"actuator": "omni-virtual", "options": {"safety": "off"}}}}))
    (d / "bad_utf8.csv").write_bytes(b"person,frequency_hz,spring_n_per_mm,spring_stiffer\n0,40,\xff1.5,1\n")
    (d / "quote.csv").write_text('person,frequency_hz,spring_n_per_mm,spring_stiffer\n0,40,"1.5\n')
    # issue 31: safety settings, renderer options and tables a file may not give
    scene = {"objects": [{"material": "S7"}]}
    for name, extra in (("passivity_off", {"settings": {"servo": {"passivity": False}}}),
                        ("gain_3", {"devices": {"vibration": {"actuator": "piezo-virtual", "options": {"gain": 3}}}}),
                        ("ropt_sink", {"settings": {"renderer_options": {"hardness": {"sink": "buffer"}}}}),
                        ("ropt_paper", {"settings": {"renderer_options": {"hardness": {"calibration": "paper"}}}}),
                        ("coil_1e9", {"objects": [{"material": {"name": "hard", "intensities": {"hardness": 1.0}}}],
                                      "devices": {"coil": {"actuator": "voicecoil-virtual",
                                                           "options": {"sample_rate_hz": 1e9}}}})):
        (d / f"{name}.json").write_text(json.dumps({**scene, **extra}))
        f[name] = d / f"{name}.json"
    from hapticsdk.calibration import PiezoTable
    tab = PiezoTable([100.0, 200.0], [0.0, 10.0], [[0.0, 1.0], [0.0, 2.0]]).to_dict()
    tab["frequencies_hz"][1] = "200"
    (d / "piezo_str.json").write_text(json.dumps(tab))
    f["piezo_str"] = d / "piezo_str.json"
    for name in ("bad_utf8.json", "deep.json", "deep_obj.json", "deep_field.json", "nan.json", "empty.json", "exists.txt",
                 "safety_off.json", "quote.csv"):
        f[name.split(".")[0]] = d / name
    f["bad_utf8_csv"] = d / "bad_utf8.csv"
    f["answers_ok"] = _answers(d / "answers_ok.csv", [30, 50, 70, 90, 110])
    f["answers_mhz"] = _answers(d / "answers_mhz.csv", [1e5, 3e5, 6e5, 1e6])
    f["piezo_neg_hz"] = _piezo_csv(d / "piezo_neg.csv", [-100, 50], [0, 10])
    f["piezo_10kv"] = _piezo_csv(d / "piezo_10kv.csv", [100, 200], [0, 10000])
    f["piezo_ok"] = _piezo_csv(d / "piezo_ok.csv", [100, 200], [0, 10, 20])
    if hasattr(os, "mkfifo"):
        os.mkfifo(d / "fifo.json")
        f["fifo"] = d / "fifo.json"
    # run files
    head = {"format": "hapticsdk-run", "version": 1, "period_s": 1e-3}
    f["run_1e9"] = _write_run(d / "run_1e9.npz", {**head, "device": {
        "name": "omni-virtual", "limits": {"max_force_n": 1e9, "max_stiffness_n_per_mm": 2.3}}})
    f["run_nan_limit"] = _write_run(d / "run_nan.npz", {**head, "device": {"limits": {"max_force_n": True}}})
    f["run_strings"] = _write_run(d / "run_str.npz", head, t=np.array(["a", "b", "c", "d", "e"]))
    good = _write_run(d / "run_ok.npz", head).read_bytes()
    (d / "run_trunc.npz").write_bytes(good[: len(good) // 2])
    f["run_trunc"] = d / "run_trunc.npz"
    # recording sets
    ds = d / "ds"
    generate_feature_dataset(ds, 3, n_trials=2, n_raters=2, raw_format="npz")
    f["ds"] = ds
    tr = shutil.copytree(ds, d / "ds_trunc")
    first = sorted((tr / "trials").glob("*.npz"))[0]
    first.write_bytes(first.read_bytes()[:200])
    f["ds_trunc"] = tr
    # a complete archive whose compressed data is damaged in the middle (zlib / CRC errors
    # while reading a member, not when opening the archive)
    mid = shutil.copytree(ds, d / "ds_corrupt")
    victim = sorted((mid / "trials").glob("*.npz"))[0]
    raw = bytearray(victim.read_bytes())
    with zipfile.ZipFile(victim) as z:
        info = z.infolist()[1]
    start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
    for i in range(start + 8, start + min(info.compress_size, 64)):
        raw[i] ^= 0x5A
    victim.write_bytes(bytes(raw))
    f["ds_corrupt"] = mid
    zb = shutil.copytree(ds, d / "ds_badzip")
    (sorted((zb / "trials").glob("*.npz"))[0]).write_bytes(b"PK\x03\x04 not really a zip")
    f["ds_badzip"] = zb
    f["ds_abs"] = _manifest_edit(ds, d / "ds_abs", lambda m: m["trials"][0].update(file="/etc/passwd.npz"))
    f["ds_dotdot"] = _manifest_edit(ds, d / "ds_dotdot",
                                    lambda m: m["trials"][0].update(file="../ds/trials/x.npz"))
    f["ds_ratings_out"] = _manifest_edit(ds, d / "ds_ratings", lambda m: m.update(ratings="../../ratings.json"))
    u8 = shutil.copytree(ds, d / "ds_utf8")
    (u8 / "recordings.json").write_bytes(b"\xff" + (u8 / "recordings.json").read_bytes())
    f["ds_utf8"] = u8
    # a feature data set (no recordings.json) whose trial table is not UTF-8
    ft = d / "ft_utf8"
    ft.mkdir()
    for name in ("dataset.json", "ratings.json"):
        shutil.copy(ds / name, ft / name)
    (ft / "trial_features.csv").write_bytes((ds / "trial_features.csv").read_bytes().replace(b"S1", b"S\xff", 1))
    f["ft_utf8"] = ft
    # a plan whose GS is 1e6 N/mm
    from hapticsdk.compiler import compile_scene
    from hapticsdk.scene import Scene
    plan = compile_scene(Scene.for_material("S7")).to_dict()
    plan["materials"]["S7"]["features"]["GS"] = 1e6
    (d / "plan_gs.json").write_text(json.dumps(plan))
    f["plan_gs"] = d / "plan_gs.json"
    # a model whose df_hz is not a number
    import onnx
    proto = onnx.load(str(DEFAULT_ONNX))
    for e in proto.metadata_props:
        if e.key == "hapticsdk.df_hz":
            e.value = json.dumps("abc")
    onnx.save(proto, str(d / "df_abc.onnx"))
    f["df_abc"] = d / "df_abc.onnx"
    return {k: str(v) for k, v in f.items()}


# (id, argv, field the error line must name[, text its reason must hold])
CASES = [
    # --- numeric arguments (argparse types of hapticsdk.cli.argtypes) -------------------
    ("solve-seed-negative", ["solve", "--hardness", "0.5", "--seed", "-1"], "--seed"),
    ("solve-seed-text", ["solve", "--hardness", "0.5", "--seed", "abc"], "--seed"),
    ("solve-seed-float", ["solve", "--hardness", "0.5", "--seed", "1.5"], "--seed"),
    ("solve-tolerance-nan", ["solve", "--hardness", "0.5", "--tolerance", "nan"], "--tolerance"),
    ("solve-tolerance-negative", ["solve", "--hardness", "0.5", "--tolerance", "-1"], "--tolerance"),
    ("solve-hardness-inf", ["solve", "--hardness", "inf"], "--hardness"),
    ("solve-hardness-true", ["solve", "--hardness", "true"], "--hardness"),
    ("solve-target-text", ["solve", "--target", "hardness=abc"], "targets.hardness"),
    ("solve-target-no-value", ["solve", "--target", "hardness"], "target"),
    ("solve-no-target", ["solve"], "targets"),
    ("solve-model-df-not-number", ["solve", "--hardness", "0.5", "--model", "{df_abc}"], "df_hz"),
    ("solve-model-missing", ["solve", "--hardness", "0.5", "--model", "{missing_dir}/m.onnx"], "solve"),
    ("render-seconds-zero", ["render", "S7", "--seconds", "0"], "--seconds"),
    ("render-seconds-nan", ["render", "S7", "--seconds", "nan"], "--seconds"),
    ("render-seconds-inf", ["render", "S7", "--seconds", "inf"], "--seconds"),
    ("render-seed-negative", ["render", "S7", "--seed", "-5"], "--seed"),
    ("plan-seed-negative", ["plan", "S7", "--seed", "-1"], "--seed"),
    ("plan-threshold-negative", ["plan", "S7", "--threshold", "-5"], "--threshold"),
    ("plan-threshold-nan", ["plan", "S7", "--threshold", "nan"], "--threshold"),
    ("train-seed-negative", ["train", "{ds}", "--out", "{dir}/m.onnx", "--seed", "-1"], "--seed"),
    ("train-folds-negative", ["train", "{ds}", "--out", "{dir}/m.onnx", "--folds", "-1"], "--folds"),
    ("train-restarts-zero", ["train", "{ds}", "--out", "{dir}/m.onnx", "--restarts", "0"], "--restarts"),
    ("generate-samples-zero", ["dataset", "generate", "{dir}/g", "--samples", "0"], "--samples"),
    ("generate-samples-huge", ["dataset", "generate", "{dir}/g", "--samples", "1000000000"], "--samples"),
    ("generate-samples-float", ["dataset", "generate", "{dir}/g", "--samples", "1e3"], "--samples"),
    ("generate-trials-negative", ["dataset", "generate", "{dir}/g", "--trials", "-1"], "--trials"),
    ("growth-sizes-text", ["dataset", "growth", "--sizes", "abc"], "--sizes"),
    ("growth-sizes-empty", ["dataset", "growth", "--sizes", ","], "--sizes"),
    ("growth-sizes-zero", ["dataset", "growth", "--sizes", "23,0"], "--sizes"),
    ("growth-sizes-huge", ["dataset", "growth", "--sizes", "23,99999999"], "--sizes"),
    ("voicecoil-gain-nan", ["calibrate", "voicecoil", "{answers_ok}", "--amplifier-gain", "nan"], "--amplifier-gain"),
    ("voicecoil-gain-negative", ["calibrate", "voicecoil", "{answers_ok}", "--amplifier-gain", "-2"],
     "--amplifier-gain"),
    ("voicecoil-confidence-1.5", ["calibrate", "voicecoil", "{answers_ok}", "--confidence", "1.5"], "--confidence"),
    ("answers-people-zero", ["calibrate", "answers", "{dir}/a.csv", "--people", "0"], "--people"),
    ("answers-seed-negative", ["calibrate", "answers", "{dir}/a.csv", "--seed", "-1"], "--seed"),
    ("cache-unknown-action", ["cache", "frob"], "ACTION", "invalid choice"),
    ("bench-solvers-seeds-zero", ["bench", "solvers", "--seeds", "0"], "--seeds"),
    ("bench-timing-fifo-500", ["bench", "timing", "--fifo-priority", "500"], "--fifo-priority"),
    ("bench-timing-seconds-negative", ["bench", "timing", "--seconds", "-1"], "--seconds"),
    ("bench-live-fifo-word", ["bench", "live", "--fifo-priority", "high"], "--fifo-priority"),
    ("bench-live-fifo-zero", ["bench", "live", "--fifo-priority", "0"], "--fifo-priority"),
    ("bench-timing-pin-cpu-negative", ["bench", "timing", "--pin-cpu", "-1"], "--pin-cpu"),
    ("bench-fidelity-period-zero", ["bench", "fidelity", "--periods", "0"], "--periods"),
    ("unknown-command", ["nosuch"], "COMMAND"),
    ("no-command", [], "COMMAND"),
    ("calibrate-without-kind", ["calibrate"], "KIND"),
    ("bench-without-benchmark", ["bench"], "BENCH"),
    ("dataset-without-command", ["dataset"], "dataset"),
    ("train-missing-out", ["train", "{ds}"], "train"),
    # --- files that are not UTF-8, nested 5000 deep, not JSON, not regular -------------
    ("render-scene-non-utf8", ["render", "--scene", "{bad_utf8}"], "scene", "not UTF-8"),
    ("render-scene-deep", ["render", "--scene", "{deep}"], "scene", "nested 5000 levels"),
    ("render-scene-deep-object", ["render", "--scene", "{deep_obj}"], "scene", "nested 5000 levels"),
    ("render-scene-960-deep-field", ["render", "--scene", "{deep_field}"], "scene", "nested 963 levels"),
    ("render-scene-nan-literal", ["render", "--scene", "{nan}"], "scene.settings.servo.period_s", "NaN"),
    ("render-scene-empty", ["render", "--scene", "{empty}"], "scene"),
    ("render-scene-directory", ["render", "--scene", "{dir}"], "scene", "directory"),
    ("render-scene-fifo", ["render", "--scene", "{fifo}"], "scene", "not a regular file"),
    ("plan-scene-non-utf8", ["plan", "{bad_utf8}"], "scene", "not UTF-8"),
    ("plan-scene-deep", ["plan", "{deep}"], "scene", "nested"),
    ("materials-library-non-utf8", ["materials", "--library", "{bad_utf8}"], "materials", "not UTF-8"),
    ("materials-library-deep", ["materials", "--library", "{deep}"], "materials", "nested"),
    ("voicecoil-answers-non-utf8", ["calibrate", "voicecoil", "{bad_utf8_csv}"], "answers", "not UTF-8"),
    ("voicecoil-answers-unclosed-quote", ["calibrate", "voicecoil", "{quote}"], "answers"),
    ("voicecoil-answers-directory", ["calibrate", "voicecoil", "{dir}"], "answers"),
    ("piezo-measurements-non-utf8", ["calibrate", "piezo", "{bad_utf8_csv}"], "measurements", "not UTF-8"),
    ("piezo-table-deep-json", ["calibrate", "piezo", "{deep}"], "measurements", "nested"),
    ("piezo-table-non-utf8-json", ["calibrate", "piezo", "{bad_utf8}"], "measurements", "not UTF-8"),
    ("features-manifest-non-utf8", ["features", "{ds_utf8}"], "file", "not UTF-8"),
    ("features-npz-truncated", ["features", "{ds_trunc}"], "file", "npz"),
    ("features-npz-bad-zip", ["features", "{ds_badzip}"], "file"),
    ("features-npz-corrupt-member", ["features", "{ds_corrupt}"], "file", "npz"),
    ("train-npz-truncated", ["train", "{ds_trunc}", "--out", "{dir}/m.onnx"], "file"),
    ("train-trial-table-non-utf8", ["train", "{ft_utf8}", "--out", "{dir}/m.onnx"], "file", "not UTF-8"),
    ("replay-truncated", ["replay", "{run_trunc}"], "runlog"),
    ("replay-not-npz", ["replay", "{bad_utf8}"], "runlog"),
    ("replay-string-arrays", ["replay", "{run_strings}"], "runlog.t"),
    ("view-seconds-negative", ["view", "{dir}/scene.json", "--seconds", "-1"], "--seconds"),
    # --- output paths, checked before the work ------------------------------------------
    ("render-plot-missing-dir", ["render", "S7", "--plot", "{missing_dir}/r.png"], "--plot"),
    ("render-plot-directory", ["render", "S7", "--plot", "{dir}"], "--plot"),
    ("plan-output-missing-dir", ["plan", "S7", "-o", "{missing_dir}/p.json"], "--output"),
    ("plan-output-directory", ["plan", "S7", "-o", "{dir}"], "--output"),
    ("voicecoil-out-missing-dir", ["calibrate", "voicecoil", "{answers_ok}", "--out", "{missing_dir}/c.json"],
     "--out"),
    ("voicecoil-out-directory", ["calibrate", "voicecoil", "{answers_ok}", "--out", "{dir}"], "--out"),
    ("voicecoil-save-onto-file", ["calibrate", "voicecoil", "{answers_ok}", "--save", "{exists}"], "--save"),
    ("piezo-out-directory", ["calibrate", "piezo", "{piezo_ok}", "--out", "{dir}"], "--out"),
    ("answers-out-missing-dir", ["calibrate", "answers", "{missing_dir}/a.csv"], "out"),
    ("answers-out-directory", ["calibrate", "answers", "{dir}"], "out"),
    ("generate-onto-file", ["dataset", "generate", "{exists}", "--samples", "2"], "out"),
    ("generate-missing-dir", ["dataset", "generate", "{missing_dir}/g", "--samples", "2"], "out"),
    ("generate-materials-missing-dir", ["dataset", "generate", "{dir}/g2", "--samples", "2", "--materials",
                                        "{missing_dir}/m.json"], "--materials"),
    ("train-out-missing-dir", ["train", "{ds}", "--out", "{missing_dir}/m.onnx"], "--out"),
    ("train-out-directory", ["train", "{ds}", "--out", "{dir}"], "--out"),
    ("bench-solvers-output-missing-dir", ["bench", "solvers", "--quick", "--output", "{missing_dir}/b.json"],
     "--output"),
    ("bench-solvers-plot-directory", ["bench", "solvers", "--quick", "--plot", "{dir}"], "--plot"),
    # --- files that are data: implausible values, options a file may not set -----------
    ("render-scene-safety-off", ["render", "--scene", "{safety_off}", "--seconds", "0.1"], "options.safety"),
    ("voicecoil-curve-1e5-1e6-hz", ["calibrate", "voicecoil", "{answers_mhz}"], "frequency_hz"),
    ("piezo-negative-frequency", ["calibrate", "piezo", "{piezo_neg_hz}"], "frequencies_hz"),
    ("piezo-10kv-column", ["calibrate", "piezo", "{piezo_10kv}"], "voltages_v"),
    ("replay-header-1e9-newton", ["replay", "{run_1e9}"], "limits.max_force_n"),
    ("replay-header-bool-limit", ["replay", "{run_nan_limit}"], "limits.max_force_n"),
    ("features-manifest-absolute-path", ["features", "{ds_abs}"], "trials.0.file"),
    ("features-manifest-dotdot", ["features", "{ds_dotdot}"], "trials.0.file"),
    ("export-plan-gs-1e6", ["export", "{plan_gs}", "-o", "{dir}/x.hjif"], "plan.materials.S7.features.GS"),
    ("export-output-directory", ["export", "S7", "-o", "{dir}"], "output"),
    ("export-seed-negative", ["export", "S7", "-o", "{dir}/x.hjif", "--seed", "-1"], "--seed"),
    ("import-non-utf8", ["import", "{bad_utf8}"], "bad_utf8.json", "UTF-8"),
    ("import-deep", ["import", "{deep}"], "deep.json", "nested"),
    ("play-seconds-nan", ["play", "{deep}", "--seconds", "nan"], "--seconds"),
    ("train-manifest-ratings-outside", ["train", "{ds_ratings_out}", "--out", "{dir}/m.onnx"], "ratings"),
    # --- issue 31: named errors, safety is not data, budgets ------------------------------
    ("render-plot-exe", ["render", "S7", "--plot", "{dir}/out.exe"], "--plot", "'exe'"),
    ("bench-solvers-plot-exe", ["bench", "solvers", "--quick", "--plot", "{dir}/out.exe"], "--plot", "'exe'"),
    ("bench-stability-plot-exe", ["bench", "stability", "--quick", "--plot", "{dir}/out.exe"], "--plot", "'exe'"),
    ("voicecoil-serial-300", ["calibrate", "voicecoil", "{answers_ok}", "--serial", "s" * 300], "--serial", "126"),
    ("piezo-serial-300", ["calibrate", "piezo", "{piezo_ok}", "--serial", "s" * 300], "--serial", "126"),
    ("list-serial-300", ["calibrate", "list", "--serial", "voicecoil=" + "s" * 300], "--serial", "126"),
    ("piezo-table-string-frequency", ["calibrate", "piezo", "{piezo_str}"], "frequencies_hz[1]", "number"),
    ("render-scene-passivity-off", ["render", "--scene", "{passivity_off}", "--seconds", "0.05"],
     "scene.settings.servo.passivity", "privileged"),
    ("render-scene-gain-3", ["render", "--scene", "{gain_3}", "--seconds", "0.05"],
     "scene.devices.vibration.options.gain", "voltage"),
    ("render-scene-renderer-option-sink", ["render", "--scene", "{ropt_sink}", "--seconds", "0.05"],
     "scene.settings.renderer_options.hardness.sink", "unknown option"),
    ("render-scene-calibration-paper", ["render", "--scene", "{ropt_paper}", "--seconds", "0.05"],
     "scene.settings.renderer_options.hardness.calibration", "calibration"),
    ("render-scene-coil-1e9-hz", ["render", "--scene", "{coil_1e9}", "--seconds", "0.05"],
     "actuator_options.coil.sample_rate_hz", "384000"),
    ("render-device-no-equals", ["render", "S7", "--device", "coil"], "device", "ROLE=ACTUATOR"),
    ("render-device-dotted-role", ["render", "S7", "--device", "coil.x=voicecoil-virtual"], "device",
     "ROLE=ACTUATOR"),
    ("render-device-unknown-plugin", ["render", "S7", "--device", "coil=no-such-actuator"], "device",
     "no actuator plugin"),
]


def _argv(argv: list[str], files: dict[str, str]) -> list[str]:
    out = []
    for a in argv:
        if "{fifo}" in a and "fifo" not in files:
            pytest.skip("no FIFOs on this system")
        out.append(a.format(**files))
    return out


def _assert_clean_error(code: int, err: str, field: str, reason: str = "") -> None:
    assert code == 2, err
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.startswith("hapticsdk: error: ")]
    assert len(lines) == 1, err
    rest = lines[0][len("hapticsdk: error: "):]
    # "<field>: <reason>", and the expected field is named in it
    head, sep, why = rest.partition(": ")
    assert sep and head.strip() and why.strip(), lines[0]
    assert field in rest, lines[0]
    assert reason in rest, lines[0]


def test_at_least_45_cases_across_commands():
    assert len(CASES) >= 45
    assert len({c[0] for c in CASES}) == len(CASES)
    commands = {" ".join(c[1][:2] if c[1][:1] in (["calibrate"], ["dataset"], ["bench"]) else c[1][:1])
                for c in CASES if c[1]}
    # every command of `hapticsdk --help` gets bad input (doctor and plugins take none)
    from hapticsdk.cli import build_parser
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    untried = set(sub.choices) - {c.split()[0] for c in commands} - {"doctor", "plugins"}
    assert not untried, untried
    assert len(commands) >= 20, commands


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input_exits_2_with_a_named_field(case, files, capsys):
    _, argv, field, *reason = case
    before = set(os.listdir(files["dir"]))
    code = main(_argv(argv, files))
    err = capsys.readouterr().err
    _assert_clean_error(code, err, field, *reason)
    assert set(os.listdir(files["dir"])) == before, "a refused command wrote a file"


@pytest.mark.parametrize("case_id", ["solve-seed-negative", "render-scene-deep", "replay-header-1e9-newton"])
def test_bad_input_in_a_subprocess(case_id, files):
    _, argv, field, *reason = next(c for c in CASES if c[0] == case_id)
    proc = subprocess.run([sys.executable, "-m", "hapticsdk", *_argv(argv, files)], capture_output=True,
                          text=True, timeout=120)
    _assert_clean_error(proc.returncode, proc.stderr, field, *reason)


def test_json_mode_prints_the_error_object_and_the_line(files, capsys):
    code = main(["render", "--scene", files["deep"], "--json"])
    cap = capsys.readouterr()
    assert code == 2
    out = json.loads(cap.out)
    # the field is the path where the nesting goes too deep (scene[0][0]...)
    assert out["field"].startswith("scene[0][0]") and out["type"] == "ValidationError"
    assert cap.err.startswith("hapticsdk: error: scene[0][0]")


# --- pipe closed early: ``hapticsdk ... | head`` ----------------------------------------
class _ClosedPipe:
    def write(self, s: str) -> int:
        raise BrokenPipeError(32, "Broken pipe")

    def flush(self) -> None:
        raise BrokenPipeError(32, "Broken pipe")


def test_broken_pipe_in_process_exits_quietly(monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdout", _ClosedPipe())
    code = main(["materials"])
    assert code == EXIT_BROKEN_PIPE == 141
    assert "Traceback" not in capsys.readouterr().err


def test_broken_pipe_subprocess_like_head():
    # the reading end is closed before the command writes (start-up takes far longer
    # than closing a descriptor), so its first write meets EPIPE
    proc = subprocess.Popen([sys.executable, "-m", "hapticsdk", "materials", "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == EXIT_BROKEN_PIPE, err
    assert b"Traceback" not in err and b"Exception ignored" not in err, err


# --- a bug (not bad input) gets the last-resort message ------------------------------
def test_unexpected_exception_is_an_internal_error(monkeypatch, capsys):
    import hapticsdk.cli.core as core

    def boom(args):
        raise ZeroDivisionError("simulated bug")

    monkeypatch.setattr(core, "cmd_materials", boom)
    assert main(["materials"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("hapticsdk: internal error: ZeroDivisionError: simulated bug") and "-v" in err
    assert "Traceback" not in err
    assert main(["-v", "materials"]) == 1
    assert "Traceback" in capsys.readouterr().err


def test_truncated_npz_error_names_the_file(files, capsys):
    assert main(["features", files["ds_trunc"]]) == 2
    err = capsys.readouterr().err
    first = sorted((Path(files["ds_trunc"]) / "trials").glob("*.npz"))[0]
    assert first.name in err


def test_api_seed_text_is_a_validation_error():
    from hapticsdk.errors import ValidationError
    from hapticsdk.solvers.problems import solve

    for bad in ("abc", -1, 1.5, True):
        with pytest.raises(ValidationError) as ei:
            solve({"hardness": 0.5, "roughness": 0.5}, seed=bad)
        assert ei.value.field == "seed"


def test_zip_bombs_are_refused_before_decompressing(files, tmp_path, monkeypatch, capsys):
    """A trial or run file that unpacks to more than the cap is refused from the archive's
    directory, before a byte is decompressed (caps lowered here so that a 16 MiB member
    of zeros, 16 kB on disk, stands for a bomb)."""
    import hapticsdk.runlog as runlog
    import hapticsdk.training.recordings as recordings

    monkeypatch.setattr(recordings, "MAX_TRIAL_BYTES", 1 << 20)
    monkeypatch.setattr(runlog, "MAX_RUN_BYTES", 1 << 20)
    ds = Path(shutil.copytree(files["ds"], tmp_path / "ds"))
    trial = sorted((ds / "trials").glob("*.npz"))[0]
    run = tmp_path / "run.npz"
    shutil.copy(files["run_1e9"], run)
    for archive in (trial, run):
        with zipfile.ZipFile(archive, "a", zipfile.ZIP_DEFLATED) as z:
            z.writestr("padding.npy", bytes(16 << 20))
        assert archive.stat().st_size < 1 << 20
    assert main(["features", str(ds)]) == 2
    _assert_clean_error(2, capsys.readouterr().err, "file", "unpacks to")
    assert main(["replay", str(run)]) == 2
    _assert_clean_error(2, capsys.readouterr().err, "runlog", "unpacks to")
