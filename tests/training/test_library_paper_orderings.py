"""The shipped library reuses the paper's sample names, so it must agree with what the
paper states about those samples (Li et al. 2022, section 2.2 and Figure 6):

* S1 is made of "soft sponge and leather" and has the softest hardness rating;
* S12 has the hardest hardness rating and the smoothest roughness rating;
* S7 has the roughest roughness rating.

These are checked on the shipped files -- the raters' mean ratings (``ratings.json``),
the library's intensities (``materials.json``) and what the shipped default model
predicts for the library's features -- as strict orderings (no tolerance). Each sample
carries one label in every shipped file. The data are GENERATED; the orderings are
imposed on them by the generator (``hapticsdk.training.generator._paper_anchors``).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "hapticsdk" / "data"
DATASET = DATA / "dataset"
DIMS = ("hardness", "roughness")

#: (dimension, "max"/"min", sample): the orderings the paper states
PAPER_ORDERINGS = (("hardness", "max", "S12"), ("hardness", "min", "S1"),
                   ("roughness", "max", "S7"), ("roughness", "min", "S12"))


def ordering_violations(values: dict[str, dict[str, float]]) -> list[str]:
    """Which of the paper's orderings ``values`` (sample -> dimension -> value) breaks:
    the named sample must be strictly above (max) or below (min) every other sample."""
    out = []
    for dim, kind, name in PAPER_ORDERINGS:
        own = values[name][dim]
        others = {n: v[dim] for n, v in values.items() if n != name}
        rival = (max if kind == "max" else min)(others, key=others.get)
        ok = own > others[rival] if kind == "max" else own < others[rival]
        if not ok:
            out.append(f"{dim} {kind}: {name} {own:.4f} but {rival} {others[rival]:.4f}")
    return out


def _mean_ratings() -> dict[str, dict[str, float]]:
    doc = json.loads((DATASET / "ratings.json").read_text())
    return {s: {d: float(np.mean(v[d])) for d in DIMS} for s, v in doc["ratings"].items()}


def _library() -> list[dict]:
    return json.loads((DATA / "materials.json").read_text())["materials"]


def _model_predictions() -> dict[str, dict[str, float]]:
    from hapticsdk_onnx import load_default
    model = load_default()
    lib = _library()
    G = np.array([[m["features"][f] for f in model.feature_names] for m in lib])
    idx = [model.dimension_names.index(d) for d in DIMS]
    I = np.asarray(model.predict(G))[:, idx]
    return {m["name"]: dict(zip(DIMS, map(float, row))) for m, row in zip(lib, I)}


def test_shipped_files_are_the_papers_23_generated_samples():
    lib = _library()
    assert [m["name"] for m in lib] == [f"S{i}" for i in range(1, 24)]
    assert all(m["generated"] is True for m in lib)
    assert json.loads((DATA / "materials.json").read_text())["generated"] is True
    assert json.loads((DATASET / "ratings.json").read_text()).get("generated") is True


def test_mean_ratings_follow_the_papers_orderings():
    assert ordering_violations(_mean_ratings()) == []


def test_library_intensities_follow_the_papers_orderings():
    values = {m["name"]: dict(m["intensities"]) for m in _library()}
    assert ordering_violations(values) == []
    # the library's intensities are the mean ratings on the 0..1 scale
    means = _mean_ratings()
    for name, v in values.items():
        for d in DIMS:
            assert v[d] == pytest.approx(means[name][d] / 100.0, abs=1e-9)


def test_default_model_predictions_follow_the_papers_orderings():
    assert ordering_violations(_model_predictions()) == []


def test_s1_is_leather_on_sponge_and_every_file_gives_one_label():
    lib = {m["name"]: m for m in _library()}
    s1 = lib["S1"]
    assert (s1["substrate"], s1["texture"], s1["label"]) == ("sponge", "leather", "leather on sponge")
    labels = {n: (m["label"], m["substrate"], m["texture"]) for n, m in lib.items()}
    ds = {s["name"]: (s["label"], s["substrate"], s["texture"])
          for s in json.loads((DATASET / "dataset.json").read_text())["samples"]}
    assert ds == labels
    with open(DATASET / "sample_features.csv", newline="") as fh:
        csv_labels = {r["sample"]: (r["label"], r["substrate"], r["texture"]) for r in csv.DictReader(fh)}
    assert csv_labels == labels
    truth = {s["name"]: (s["label"], s["substrate"], s["texture"])
             for s in json.loads((DATASET / "truth.json").read_text())["samples"]}
    assert truth == labels
    for name, (label, sub, tex) in labels.items():
        assert label == f"{tex} on {sub}", name


# ---------------------------------------------------------------- the checks have teeth
@pytest.mark.parametrize("dim,a,b", [("hardness", "S12", "S20"), ("hardness", "S1", "S5"),
                                     ("roughness", "S7", "S8"), ("roughness", "S12", "S5")])
def test_checker_catches_a_swapped_extreme(dim, a, b):
    """Swapping an anchored sample's value with another sample's breaks an ordering."""
    values = _mean_ratings()
    values[a][dim], values[b][dim] = values[b][dim], values[a][dim]
    assert ordering_violations(values)


def test_checker_catches_a_tie():
    values = _mean_ratings()
    values["S16"]["hardness"] = values["S12"]["hardness"]
    assert ordering_violations(values) == [
        f"hardness max: S12 {values['S12']['hardness']:.4f} but S16 {values['S16']['hardness']:.4f}"]


def test_generator_without_the_anchoring_breaks_the_orderings(monkeypatch):
    """The orderings come from the anchoring, not from chance: the same seed without it
    makes another sample the hardest (S20) and the roughest (S8), as in generator v1."""
    from hapticsdk.training import generator as gen

    def means(specs):
        r = gen.simulate_ratings(specs)
        return {s: {d: float(np.mean(v[d])) for d in DIMS} for s, v in r.values.items()}

    assert ordering_violations(means(gen.make_samples())) == []
    monkeypatch.setattr(gen, "_paper_anchors", lambda specs: specs)
    broken = ordering_violations(means(gen.make_samples()))
    assert any(b.startswith("hardness max: S12") for b in broken)
    assert any(b.startswith("roughness max: S7") for b in broken)
    assert any(b.startswith("roughness min: S12") for b in broken)


def test_generating_parameters_follow_the_orderings_for_every_seed():
    """The anchoring's guarantee is on the generating parameters (the ratings add noise):
    stiffness for hardness, the raters' weighted vibration power for roughness."""
    from hapticsdk.training import generator as gen

    for seed in range(50):
        specs = gen.make_samples(23, seed)
        values = {s.name: {"hardness": s.gs_n_mm,
                           "roughness": s.amplitude_m_s2 ** 2 / 2 * (60.0 / s.fpeak_nominal_hz)
                           + s.rough_rms_m_s2 ** 2} for s in specs}
        assert ordering_violations(values) == [], seed
        assert {s.name: s.label for s in specs}["S1"] == "leather on sponge"
