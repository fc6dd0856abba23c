"""Figures people read: no empty panels, one unit per axis, legends off the data, the
rendered stiffness readable (binned mean, fitted slope next to the target slope), titles
that say what was rendered; the stability map and the plan figure."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

import hapticsdk as hs  # noqa: E402
from hapticsdk import plotting  # noqa: E402


@pytest.fixture
def figures(monkeypatch):
    """Keep each figure open instead of writing it (``save_figure`` closes it)."""
    kept = []

    def keep(fig, path, **kw):
        kept.append(fig)
        return path

    monkeypatch.setattr(plotting, "save_figure", keep)
    yield kept
    import matplotlib.pyplot as plt
    for f in kept:
        plt.close(f)


def _axes_by_title(fig):
    return {a.get_title(): a for a in fig.axes if a.get_title()}


def test_force_penetration_summary_recovers_the_slope():
    rng = np.random.default_rng(3)
    y = rng.uniform(0.0, 0.5, 4000)
    k, sigma = 1.7, 0.15            # N/mm, N: the spread the issue saw
    f = k * y + rng.normal(0.0, sigma, y.size)
    pen = np.concatenate([y, -rng.uniform(0, 2, 500)])        # ticks above the surface are ignored
    force = np.concatenate([f, rng.normal(0, 5, 500)])
    s = plotting.force_penetration_summary(pen, force, bins=10)
    assert s["n_contact"] == y.size
    # standard error of a least-squares slope through the origin: sigma / sqrt(sum y^2)
    se = sigma / np.sqrt(np.sum(y ** 2))
    assert abs(s["slope_n_per_mm"] - k) < 5 * se
    # each bin's mean is within 5 standard errors of the spring law at the bin's centre
    # (plus the slope change across half a bin width)
    half = 0.5 * 0.5 / 10
    for c, m, n in zip(s["centre_mm"], s["mean_n"], s["count"]):
        assert abs(m - k * c) < 5 * sigma / np.sqrt(n) + k * half


def test_render_figure_with_a_dropped_dimension(figures):
    # S13's intensities (fabric on sponge): GS below the arm's 2.3 N/mm (the voice coil
    # stays idle) and roughness left out by the importance model
    its = {k: round(v, 2) for k, v in hs.load_library().get("S13").intensities.items()}
    rep = hs.render(its, seconds=1.0, seed=1)
    assert [d["dimension"] for d in rep.dropped] == ["roughness"]
    plotting.plot_render(rep, "unused.png")
    fig = figures[-1]
    # the title says intensity targets, not "material"
    assert fig._suptitle.get_text() == (f"hapticsdk render of targets hardness {its['hardness']:g}, "
                                        f"roughness {its['roughness']:g}")
    titles = _axes_by_title(fig)
    assert set(titles) == {"hardness: force against penetration", "probe motion"}  # no empty panel
    notes = " ".join(t.get_text() for t in fig.texts)
    assert "left out roughness" in notes
    assert "coil (voicecoil-virtual): never driven" in notes
    assert "force (" not in notes   # the force role was driven: the log also holds its (zero) amplitude
    # every drawn axis has data on it
    for a in fig.axes:
        assert any(len(ln.get_xdata()) > 1 for ln in a.get_lines()), a.get_title()
    # force panel: binned mean, fitted slope and target slope, all labelled
    labels = titles["hardness: force against penetration"].get_legend_handles_labels()[1]
    assert any(lb.startswith("mean per penetration bin") for lb in labels)
    assert any(lb.startswith("fitted slope ") for lb in labels)
    gs = rep.features["GS"]
    assert gs < 2.3 and any(lb.startswith(f"target slope {gs:.2f} N/mm") for lb in labels)


def test_render_figure_units_and_legends(figures):
    # S8 (leather on rubber): both dimensions kept, GS above the arm's 2.3 N/mm (coil used)
    rep = hs.render("S8", seconds=1.5, seed=0)
    assert set(rep.dimensions) == {"hardness", "roughness"}
    plotting.plot_render(rep, "unused.png")
    fig = figures[-1]
    fig.canvas.draw()
    titles = _axes_by_title(fig)
    assert fig._suptitle.get_text().startswith('hapticsdk render of material S8 "')
    assert "GENERATED" in fig._suptitle.get_text()
    coil = titles["coil channel (voicecoil-virtual)"]
    piezo = titles["vibration channel (piezo-virtual)"]
    # one unit per axis: the piezo in volts, the coil as a fraction of full scale
    assert piezo.get_ylabel() == "drive (V)"
    assert coil.get_ylabel() == "drive (fraction of full scale)"
    for a in fig.axes:
        assert not ("V" in a.get_ylabel() and "0..1" in a.get_ylabel())
    r = fig.canvas.get_renderer()
    # y labels do not run into the figure title
    top_of_axes = max(a.yaxis.label.get_window_extent(r).y1 for a in fig.axes)
    assert top_of_axes < fig._suptitle.get_window_extent(r).y0
    # legends of time panels sit below their axes; the force legend covers no mean point
    for name in ("probe motion", "coil channel (voicecoil-virtual)", "vibration channel (piezo-virtual)"):
        a = titles[name]
        assert a.get_legend().get_window_extent(r).y1 <= a.get_window_extent(r).y0, name
    fa = titles["hardness: force against penetration"]
    box = fa.get_legend().get_window_extent(r)
    mean_line = next(ln for ln in fa.get_lines() if ln.get_marker() == "o")
    pts = fa.transData.transform(np.column_stack([mean_line.get_xdata(), mean_line.get_ydata()]))
    assert not any(box.contains(x, y) for x, y in pts)


def _cell(K, T, b, finger, on, ratio, energy, stable):
    return {"stiffness_n_per_mm": K, "period_s": T, "damping_ns_per_m": b, "finger": finger,
            "controller": on, "delivered_force_ratio": ratio, "energy_to_user_j": energy, "stable": stable}


def test_stability_map_shows_the_worst_finger_and_marks_unstable_cells(figures):
    cells = []
    for K in (1.0, 100.0):
        for T in (1e-3, 4e-3):
            for on in (True, False):
                for finger, r in (("soft", 0.9), ("stiff", 0.4 if K == 100.0 else 0.8)):
                    unstable = (not on) and K == 100.0 and T == 4e-3 and finger == "stiff"
                    cells.append(_cell(K, T, 0.0, finger, on, r if on else 1.0, 0.05 if unstable else 1e-4,
                                       not unstable))
    plotting.plot_stability({"cells": cells, "energy_tolerance_j": 2.5e-3}, "unused.png")
    fig = figures[-1]
    titles = _axes_by_title(fig)
    on = titles["damping b = 0 Ns/m, controller on"]
    img = on.get_images()[0].get_array()
    # rows: T = 1, 4 ms; columns: K = 1, 100 N/mm; colour = the worst finger's ratio
    np.testing.assert_allclose(np.asarray(img), [[0.8, 0.4], [0.8, 0.4]])
    off = titles["damping b = 0 Ns/m, controller off"]
    assert len(off.patches) == 1 and len(on.patches) == 0   # the one unstable cell outlined
    assert {t.get_text() for t in off.texts} >= {"50"}       # its energy, mJ


def test_plan_figure_lists_what_was_left_out_and_why(figures):
    from hapticsdk.compiler import compile_scene
    from hapticsdk.scene import Scene

    plan = compile_scene(Scene.for_material({"hardness": 0.8, "roughness": 0.3}, seed=1))
    plotting.plot_plan(plan, "unused.png")
    fig = figures[-1]
    text = " ".join(t.get_text() for a in fig.axes for t in a.texts)
    d = plan.to_dict()
    (m,) = d["materials"].values()
    (drop,) = m["dropped"]
    lo, hi = drop["loss_interval_percent"]
    assert f"left out roughness: loss {lo:.1f}-{hi:.1f} % < {drop['threshold_percent']:g} %" in text
    scatter = fig.axes[0]
    offsets = np.concatenate([c.get_offsets() for c in scatter.collections if len(c.get_offsets())])
    np.testing.assert_allclose(offsets, [[0.8, 0.3]])


def test_cli_writes_the_figures(tmp_path, monkeypatch):
    from hapticsdk.benchmarks import stability
    from hapticsdk.cli import main

    monkeypatch.setattr(stability, "QUICK_GRID", {"stiffness_n_per_mm": [0.1, 100.0], "period_s": [4e-3],
                                                  "damping_ns_per_m": [0.0], "finger": ["medium"],
                                                  "duration_s": 3.0})
    out = tmp_path / "stab.png"
    assert main(["bench", "stability", "--quick", "--plot", str(out), "--json"]) in (0, 1)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    out = tmp_path / "plan.png"
    assert main(["plan", "S12", "--plot", str(out), "--json"]) in (0, 1)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
