"""``hapticsdk plan --compare-paper``: the leave-out decisions on the paper's 8 evaluated
samples against its significant removals (section 5.1), and the plan figure's labels."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hapticsdk.plugins import registry

needs_hardness = pytest.mark.skipif("hardness" not in registry("dimension"),
                                    reason="hapticsdk-hardness not installed")

# the paper, section 5.1: removals with a significant realism difference to "All"
PAPER = {("S1", "roughness"), ("S7", "roughness"), ("S13", "roughness"), ("S14", "roughness"),
         ("S16", "roughness"), ("S2", "hardness"), ("S12", "hardness"), ("S13", "hardness"),
         ("S14", "hardness"), ("S16", "hardness"), ("S20", "hardness")}


@needs_hardness
def test_compare_paper_counts_and_explains_every_disagreement(capsys):
    from hapticsdk.cli import main
    assert main(["plan", "--compare-paper", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    rows = out["rows"]
    assert len(rows) == 16 and {r["sample"] for r in rows} == {"S1", "S2", "S7", "S12", "S13", "S14", "S16", "S20"}
    agree = 0
    for r in rows:
        sig = (r["sample"], r["dimension"]) in PAPER
        assert r["paper_significant"] == sig
        ok = (r["plan"] == "keep") == sig
        agree += ok
        assert r["agrees"] == ok
        if not ok:
            assert r["explanation"] and not r["explanation"].startswith("agrees")
        # the conservative rule: a drop has its whole interval below the threshold
        if r["plan"] == "drop":
            assert r["interval_percent"][1] < r["threshold_percent"]
    assert out["agree"] == agree
    assert out["contradictions"] == sum(r["plan"] == "drop" and r["paper_significant"] for r in rows)
    assert "GENERATED" in out["note"]
    assert main(["plan", "--compare-paper"]) == 0
    text = capsys.readouterr().out
    assert f"agreement: {agree} of 16" in text and "GENERATED" in text


def test_compare_paper_takes_no_scene():
    from hapticsdk.cli import main
    assert main(["plan", "S7", "--compare-paper"]) != 0


def test_plan_figure_labels_do_not_overlap():
    pytest.importorskip("matplotlib")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from hapticsdk.plotting import _place_labels
    # a crowded cluster (S9/S17/S2 and S13/S21 sit this close in the library)
    rng = np.random.default_rng(4)
    pts = [(f"S{i}", 0.1 + 0.03 * rng.random(), 0.4 + 0.03 * rng.random()) for i in range(1, 9)]
    fig, ax = plt.subplots(figsize=(6, 6))
    ax.scatter([p[1] for p in pts], [p[2] for p in pts])
    ax.set_xlim(-0.05, 1.05)
    ax.set_ylim(-0.05, 1.05)
    _place_labels(ax, pts)
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    from matplotlib.text import Text
    boxes = [Text.get_window_extent(t, r) for t in ax.texts]   # the labels, without leader lines
    assert len(boxes) == len(pts)
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            assert not boxes[i].overlaps(boxes[j]), (ax.texts[i].get_text(), ax.texts[j].get_text())
    plt.close(fig)


@needs_hardness
def test_plan_text_says_units_and_counts_in_words(capsys):
    from hapticsdk.cli import main
    assert main(["plan", "S7"]) == 0
    text = capsys.readouterr().out
    assert "max 1 1" not in text and "drive up to 1 x full scale" in text   # the voice coil's 0..1 drive
    assert "drive up to 50 V" in text
    assert "over 1 feature vectors" not in text
    assert "at its recorded features and at those features solved onto the target" in text
