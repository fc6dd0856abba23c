"""Export of solved materials to .hjif and back: identical numbers, the written subset
validates against schemas/hjif.schema.json, and the CLI commands work end to end."""

from __future__ import annotations

import json

import pytest
from hjif_docs import plan_for

from hapticsdk.cli import main
from hapticsdk.interop.hjif_export import export_plan, write_hjif
from hapticsdk.interop.hjif_import import sdk_materials, split_description
from hapticsdk.interop.hjif_model import parse_hjif, read_hjif
from hapticsdk.schemas_io import validate


def _plan(material: str):
    return plan_for(material)


@pytest.fixture(scope="module")
def hard_plan():
    """S20 (GS above the arm's 2.3 N/mm: stiffness, voice coil and texture)."""
    return _plan("S20")


def test_export_reimports_to_identical_numbers(hard_plan, tmp_path):
    path = write_hjif(export_plan(hard_plan), tmp_path / "s20.hjif")
    mats = sdk_materials(read_hjif(path))
    mp = hard_plan.material("S20")
    m = mats["S20"]
    assert m["features"] == mp.features  # exact float equality, every feature
    assert m["targets"] == mp.targets
    assert m["solve"]["error"] == mp.solve["error"] and m["solve"]["intensities"] == mp.solve["intensities"]
    assert m["solve"]["method"] == mp.solve["method"] and m["solve"]["seed"] == mp.solve["seed"]
    parts = m["parts"]
    assert set(parts) == {"stiffness", "coil", "texture"}
    gs, fpk, afpk = mp.features["GS"], mp.features["Fpeak"], mp.features["AFpeak"]
    assert gs > 2.3
    # the values the perceptions carry equal the metadata, bit for bit
    assert parts["stiffness"]["GS_n_per_mm"] == gs and parts["stiffness"]["GS_from_content"] == gs
    assert parts["texture"]["Fpeak_hz"] == fpk and parts["texture"]["AFpeak_m_s2"] == afpk
    assert parts["texture"]["AFpeak_from_content"] == afpk
    assert parts["texture"]["Fpeak_keyframe_hz"] == round(fpk)
    assert parts["texture"]["v_ref_mm_s"] == 80.0 and parts["texture"]["v_gate_mm_s"] == 20.0
    from hapticsdk_hardness.dimension import HardnessRenderer
    r = HardnessRenderer(gs)
    assert parts["coil"]["coil_frequency_hz"] == r.coil_frequency_hz
    assert parts["coil"]["coil_stiffness_n_per_mm"] == r.coil_stiffness_n_per_mm
    assert parts["coil"]["coil_frequency_keyframe_hz"] == round(r.coil_frequency_hz)
    assert parts["stiffness"]["arm_stiffness_n_per_mm"] == 2.3


def test_written_file_follows_the_schema_and_the_reference_structure(hard_plan, tmp_path):
    path = write_hjif(export_plan(hard_plan, date="2024-05-06"), tmp_path / "s20.hjif")
    raw = json.loads(path.read_text(encoding="utf-8"))
    validate(raw, "hjif")
    assert [p["perception_modality"] for p in raw["perceptions"]] == ["Stiffness", "Vibrotactile",
                                                                      "Vibrotactile Texture"]
    assert raw["timescale"] == 1000 and raw["version"] == "2023" and raw["profile"] == "Main"
    for p in raw["perceptions"]:
        for ch in p["channels"]:
            for b in ch["bands"]:
                for e in b["effects"]:
                    for k in e.get("keyframes", []) + [k for lib in p["effect_library"] for k in lib["keyframes"]]:
                        # the reference reader only keeps integer frequency_modulation values
                        assert isinstance(k.get("frequency_modulation", 0), int)
    # the model writes back exactly what it read
    h = read_hjif(path)
    assert parse_hjif(json.loads(h.to_json())).to_dict() == h.to_dict() == raw


def test_description_carries_human_text_then_metadata(hard_plan):
    h = export_plan(hard_plan)
    text, meta = split_description(h.description)
    assert "S20" in text and "GENERATED" in text
    assert meta["format"] == "hapticsdk-hjif" and meta["generated_data"] is True
    text, meta = split_description(h.perceptions[1].description)
    assert "voice coil" in text and meta["role"] == "coil"


def test_soft_material_has_no_coil_perception():
    plan = _plan("S7")
    h = export_plan(plan)
    assert plan.material("S7").features["GS"] < 2.3
    assert [p.perception_modality for p in h.perceptions] == ["Stiffness", "Vibrotactile Texture"]


def test_cli_export_from_plan_file_import_and_play(hard_plan, tmp_path, capsys):
    plan_path = tmp_path / "plan.json"
    plan_path.write_text(hard_plan.to_json(), encoding="utf-8")
    out = tmp_path / "s20.hjif"
    assert main(["export", str(plan_path), "--format", "hjif", "-o", str(out), "--json"]) == 0
    exp = json.loads(capsys.readouterr().out)
    assert exp["saved"] == str(out) and [p["modality"] for p in exp["perceptions"]][0] == "Stiffness"
    assert main(["import", str(out), "--json", "--synth"]) == 0
    imp = json.loads(capsys.readouterr().out)
    assert imp["sdk_materials"]["S20"]["features"] == hard_plan.material("S20").features
    assert [u["path"] for u in imp["not_played"]] == ["perceptions[0]"]
    assert main(["play", str(out), "--seconds", "0.2", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert set(rep["actuators"]) == {"piezo-virtual", "voicecoil-virtual"}
    assert rep["not_played"][0]["path"] == "perceptions[0]" and "Stiffness" in rep["not_played"][0]["what"]


def test_cli_export_refuses_a_missing_directory_before_solving(tmp_path, capsys):
    code = main(["export", "S7", "-o", str(tmp_path / "nope" / "x.hjif")])
    assert code == 2 and "does not exist" in capsys.readouterr().err


def test_write_reads_the_file_back_and_keeps_the_old_one_when_the_reader_refuses(hard_plan, tmp_path):
    from hapticsdk.errors import FileWriteError

    out = tmp_path / "x.hjif"
    hfile = export_plan(hard_plan)
    write_hjif(hfile, out)
    old = out.read_bytes()
    # content the SDK's reader refuses (a keyframe position out of range) is not written
    hfile.perceptions[0].channels[0].bands[0].effects[0].keyframes[-1].relative_position = -5
    with pytest.raises(FileWriteError, match="read it back"):
        write_hjif(hfile, out)
    assert out.read_bytes() == old
    assert [f.name for f in tmp_path.iterdir()] == ["x.hjif"]  # no temporary file left
