"""The stability map's colour tells cells apart over the whole range a run produces: an
undamped wall without the controller delivers ~100x the passive spring's force, so a
0..1 scale painted every such cell alike (review G)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from hapticsdk import plotting  # noqa: E402


def _cells(ratios):
    return [{"stiffness_n_per_mm": K, "period_s": 1e-3, "damping_ns_per_m": 0.0, "finger": "f",
             "controller": False, "delivered_vs_passive_ratio": r, "energy_to_user_j": 1e-5, "stable": True}
            for K, r in zip((0.1, 2.3, 100.0, 1e4), ratios)]


@pytest.mark.parametrize("ratios", [(1.0, 6.7, 80.0, 180.0), (0.0, 0.03, 0.9, 1.0), (1e-4, 0.5, 2.0, 2500.0)])
def test_every_ratio_has_its_own_colour_and_1_is_inside_the_scale(monkeypatch, ratios):
    kept = []
    monkeypatch.setattr(plotting, "save_figure", lambda fig, path, **kw: kept.append(fig))
    plotting.plot_stability({"cells": _cells(ratios), "energy_tolerance_j": 1e-4}, "unused.png")
    fig = kept[0]
    try:
        (ax,) = [a for a in fig.axes if a.get_title().startswith("damping")]
        im = ax.get_images()[0]
        rgba = im.to_rgba(np.asarray(im.get_array(), float))[0]        # one row: T = 1 ms
        colours = {tuple(np.round(c, 6)) for c in rgba}
        assert len(colours) == len(ratios), ratios                       # no two cells alike
        n = im.norm
        assert n.vmin <= 0.1 and n.vmax >= 10.0                          # 1 sits inside the scale
        pos = [r for r in ratios if r > 0]
        assert n.vmin <= min(pos) and max(pos) <= n.vmax                 # nothing clipped
    finally:
        import matplotlib.pyplot as plt
        plt.close(fig)
