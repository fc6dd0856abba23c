"""Figures (need the optional ``matplotlib``: the ``plot`` extra, ``pip install -e '.[plot]'`` in a checkout).

* :func:`plot_render`: a render's servo log -- normal force against penetration (every
  tick, the mean per penetration bin, the fitted slope and the target slope), the probe's
  motion, and one panel per vibration channel that was driven (drive amplitude in that
  actuator's unit, drive frequency). Channels that were never driven and dimensions the
  plan left out are listed under the figure instead of being drawn as empty panels.
* :func:`plot_stability`: ``hapticsdk bench stability``'s cells: energy to the user on a
  log axis and the delivered force ratio per controller, and the SDK controller against
  the best passive peer (:func:`plot_stability_cells`); an older matrix result as a
  stiffness x period map (:func:`plot_stability_matrix`).
* :func:`plot_plan`: a compiled plan's materials in intensity space, with what was left
  out of each and why.
* :func:`plot_paper_comparison`: leave-out decisions on the paper's 8 evaluated samples
  against its findings.

Every figure is written atomically (:func:`save_figure`).
"""

from __future__ import annotations

import re
import textwrap
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from .errors import HapticSDKError, ValidationError


def _pyplot() -> Any:
    try:
        import matplotlib
    except ImportError:
        from .install_hints import pip_hint
        raise HapticSDKError(f"plotting needs matplotlib: {pip_hint('hapticsdk', 'plot')}") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


#: name Scene.for_material gives intensity targets: "hardness 0.8, roughness 0.3"
_TARGETS_NAME = re.compile(r"[A-Za-z_][\w-]* [0-9.eE+-]+(, [A-Za-z_][\w-]* [0-9.eE+-]+)*")


def describe_material(name: str) -> str:
    """Title text for a rendered material: ``material S7 "fabric on EVA" (GENERATED
    library data)`` for a library material, ``targets hardness 0.8, roughness 0.3`` for
    intensity targets."""
    if _TARGETS_NAME.fullmatch(name):
        return f"targets {name}"
    try:
        from .perception.materials import load_library
        lib = load_library()
        m = lib.get(name)
    except Exception:  # not a library material (a scene's own name)
        return f"material {name}"
    gen = " (GENERATED library data)" if getattr(lib, "generated", False) else ""
    return f'material {m.name} "{m.label}"{gen}'


def _limits(report: Any, role: str) -> dict[str, Any]:
    """The ``limits`` of the actuator that served ``role`` (from the report's devices)."""
    name = (getattr(report, "actuators", {}) or {}).get(role)
    dev = (getattr(report, "devices", {}) or {}).get(name) or {}
    return dict(dev.get("limits") or {})


def _unit_label(unit: str) -> str:
    return {"V": "V", "1": "fraction of full scale", "": "drive units"}.get(unit, unit)


def force_penetration_summary(pen_mm: np.ndarray, force_n: np.ndarray, *, bins: int = 10
                              ) -> dict[str, Any]:
    """Over the ticks in contact (penetration > 0): the least-squares slope through the
    origin (N/mm), and per penetration bin the centre (mm), mean and standard deviation of
    the force (N) and the tick count (empty bins dropped)."""
    pen = np.asarray(pen_mm, float)
    f = np.asarray(force_n, float)
    c = pen > 0
    out: dict[str, Any] = {"n_contact": int(c.sum()), "slope_n_per_mm": float("nan"),
                           "centre_mm": np.zeros(0), "mean_n": np.zeros(0), "std_n": np.zeros(0),
                           "count": np.zeros(0, int)}
    if not c.any():
        return out
    y, fc = pen[c], f[c]
    out["slope_n_per_mm"] = float(np.dot(y, fc) / np.dot(y, y))
    edges = np.linspace(0.0, float(y.max()), bins + 1)
    idx = np.clip(np.digitize(y, edges) - 1, 0, bins - 1)
    count = np.bincount(idx, minlength=bins)
    s1 = np.bincount(idx, weights=fc, minlength=bins)
    s2 = np.bincount(idx, weights=fc * fc, minlength=bins)
    keep = count > 0
    mean = s1[keep] / count[keep]
    var = np.maximum(s2[keep] / count[keep] - mean ** 2, 0.0)
    out.update(centre_mm=0.5 * (edges[:-1] + edges[1:])[keep], mean_n=mean, std_n=np.sqrt(var),
               count=count[keep])
    return out


def plot_render(report: Any, path: str | Path) -> Path:
    """Save a figure of ``report`` (a render report with a servo ``loop`` log) to ``path``."""
    plt = _pyplot()
    loop = getattr(report, "loop", report)
    log = getattr(loop, "log", None) or {}
    if "t" not in log:
        raise HapticSDKError("the report has no servo log to plot")
    t = np.asarray(log["t"])
    pen = np.asarray(log["penetration_mm"])
    force = np.asarray(log.get("force_n", np.zeros_like(t)))
    vel = np.asarray(log["velocity_mm_s"])
    # drive-amplitude channels: the log keeps every field of every role, so a role that was
    # sent forces (the force channel, drawn in the force panel) is not one of them
    roles = sorted(r for r in (k[: -len(".amplitude")] for k in log if k.endswith(".amplitude"))
                   if not np.isfinite(np.asarray(log.get(f"{r}.force_n", [np.nan]), float)).any())
    driven = [r for r in roles if np.any(np.asarray(log[f"{r}.amplitude"]) != 0)]
    idle = [r for r in roles if r not in driven]

    notes = []
    for r in idle:
        act = (getattr(report, "actuators", {}) or {}).get(r, "?")
        notes.append(f"{r} ({act}): never driven in this run (amplitude 0 throughout), not drawn.")
    for d in getattr(report, "dropped", []) or []:
        notes.append(f"left out {d.get('dimension')}: {d.get('reason')}")
    note_lines = [ln for n in notes for ln in textwrap.wrap(n, 150)]

    n_rows = 2 if driven else 1
    fig_h = 4.6 * n_rows + 0.5 + 0.2 * len(note_lines)
    fig = plt.figure(figsize=(12, fig_h))
    gs = fig.add_gridspec(n_rows, 2 if len(driven) <= 2 else len(driven))
    ncol = gs.ncols
    fig.suptitle(f"hapticsdk render of {describe_material(str(getattr(report, 'material', '')))}",
                 fontsize=12)

    # -- force against penetration ------------------------------------------------
    a = fig.add_subplot(gs[0, : ncol // 2])
    lim = _limits(report, "force")
    k_max = lim.get("max_stiffness_n_per_mm")
    f_max = lim.get("max_force_n")
    summ = force_penetration_summary(pen, force)
    c = pen > 0
    a.plot(pen[c], force[c], ".", ms=2, color="0.65", label=f"each tick in contact ({summ['n_contact']})")
    if summ["count"].size:
        a.errorbar(summ["centre_mm"], summ["mean_n"], yerr=summ["std_n"], fmt="o-", color="C0", ms=4,
                   capsize=2, lw=1.2, label="mean per penetration bin (+- 1 sd)")
    top = float(pen[c].max()) if c.any() else 1.0
    y = np.linspace(0.0, top, 50)
    if np.isfinite(summ["slope_n_per_mm"]):
        a.plot(y, summ["slope_n_per_mm"] * y, "-", color="C3", lw=1.5,
               label=f"fitted slope {summ['slope_n_per_mm']:.2f} N/mm (least squares through 0)")
    gsf = (getattr(report, "features", {}) or {}).get("GS")
    if gsf is not None:
        k_t = min(gsf, k_max) if k_max else gsf
        target = k_t * y if not f_max else np.minimum(k_t * y, f_max)
        extra = f" (GS {gsf:.2f} capped at the arm's {k_max:g})" if k_max and gsf > k_max else ""
        a.plot(y, target, "k--", lw=1.2, label=f"target slope {k_t:.2f} N/mm{extra}")
    a.axhline(0.0, color="0.8", lw=0.6)
    a.set_xlabel("penetration (mm)")
    a.set_ylabel("normal force on the arm (N)")
    a.set_title("hardness: force against penetration", fontsize=10)
    a.legend(fontsize=8, loc="upper left", framealpha=0.9)

    # -- probe motion ---------------------------------------------------------------
    a = fig.add_subplot(gs[0, ncol // 2:])
    h1 = a.plot(t, np.abs(vel[:, 0]), color="C0", label="|v_x| sliding speed (mm/s)")
    h2 = a.axhline(20.0, color="r", lw=0.8, ls=":", label="20 mm/s vibration gate")
    a.set_xlabel("time (s)")
    a.set_ylabel("sliding speed (mm/s)")
    vmax = float(np.abs(vel[:, 0]).max()) if len(vel) else 1.0
    a.set_ylim(0.0, max(vmax, 20.0) * 1.45)   # speed in the lower two thirds ...
    a2 = a.twinx()
    h3 = a2.plot(t, pen, color="C2", lw=0.9, label="penetration (mm, < 0 above the surface)")
    lo, hi = float(pen.min()), float(pen.max())
    a2.set_ylim(lo - 0.9 * (hi - lo + 1e-9), hi + 0.05 * (hi - lo + 1e-9))  # ... penetration above
    a2.set_ylabel("penetration (mm)")
    a.set_title("probe motion", fontsize=10)
    handles = [*h1, h2, *h3]
    a.legend(handles, [h.get_label() for h in handles], fontsize=8, loc="upper center",
             bbox_to_anchor=(0.5, -0.14), ncol=3, frameon=False)

    # -- one panel per driven vibration channel --------------------------------------
    for i, r in enumerate(driven):
        span = slice(i * ncol // len(driven), (i + 1) * ncol // len(driven))
        a = fig.add_subplot(gs[1, span])
        lim = _limits(report, r)
        unit = _unit_label(str(lim.get("amplitude_unit", "")))
        act = (getattr(report, "actuators", {}) or {}).get(r, "?")
        h1 = a.plot(t, log[f"{r}.amplitude"], color="C1", lw=1.0, label=f"drive ({unit})")
        a.set_xlabel("time (s)")
        a.set_ylabel(f"drive ({unit})")
        handles = list(h1)
        fk = f"{r}.frequency_hz"
        fr = np.asarray(log.get(fk, np.zeros(0)), float)
        if fr.size:
            fr = np.where(np.asarray(log[f"{r}.amplitude"]) != 0, fr, np.nan)  # frequency while driven
        if fr.size and np.nanmax(np.nan_to_num(fr, nan=0.0)) > 0:  # a channel without frequency: none drawn
            a2 = a.twinx()
            handles += a2.plot(t, fr, color="C4", lw=1.0, ls="--", label="drive frequency (Hz, while driven)")
            a2.set_ylabel("drive frequency (Hz)")
            if np.isfinite(fr).any():  # from 0, so a constant frequency reads as one
                a2.set_ylim(0.0, float(np.nanmax(fr)) * 1.25)
        a.set_title(f"{r} channel ({act})", fontsize=10)
        a.legend(handles, [h.get_label() for h in handles], fontsize=8, loc="upper center",
                 bbox_to_anchor=(0.5, -0.14), ncol=2, frameon=False)

    bottom = (0.15 + 0.2 * len(note_lines)) / fig_h
    if note_lines:
        fig.text(0.01, 0.01, "\n".join(note_lines), fontsize=8, va="bottom", ha="left", family="monospace")
    fig.tight_layout(rect=(0.0, bottom, 1.0, 0.96), h_pad=2.5)
    out = Path(path)
    save_figure(fig, out, dpi=90)
    return out


def _cells_grid(cells: Sequence[Mapping[str, Any]], damping: float, controller: bool
                ) -> tuple[list[float], list[float], np.ndarray, np.ndarray, np.ndarray]:
    """K values, T values, and (T x K) arrays of the worst delivered force ratio (against
    min(K, K_pass) x penetration), the largest energy to the user (J) and stability over
    fingers, for one damping."""
    sel = [c for c in cells if c["damping_ns_per_m"] == damping and bool(c["controller"]) == controller]
    ks = sorted({float(c["stiffness_n_per_mm"]) for c in sel})
    ts = sorted({float(c["period_s"]) for c in sel})
    ratio = np.full((len(ts), len(ks)), np.nan)
    energy = np.full((len(ts), len(ks)), np.nan)
    stable = np.ones((len(ts), len(ks)), bool)
    for c in sel:
        i, j = ts.index(float(c["period_s"])), ks.index(float(c["stiffness_n_per_mm"]))
        r = float(c.get("delivered_vs_passive_ratio", c.get("delivered_force_ratio", np.nan)))
        ratio[i, j] = r if np.isnan(ratio[i, j]) else np.nanmin([ratio[i, j], r])
        energy[i, j] = np.nanmax([energy[i, j], float(c["energy_to_user_j"])])
        stable[i, j] &= bool(c["stable"])
    return ks, ts, ratio, energy, stable


def plot_stability(result: Mapping[str, Any], path: str | Path) -> Path:
    """Save ``hapticsdk bench stability``'s result as a figure: the per-controller cells
    (``run_grid`` / ``run_random``, with ``mode``) go to :func:`plot_stability_cells`; an
    older matrix (``StabilityResult.to_dict()``) to :func:`plot_stability_matrix`."""
    if "mode" in result:
        return plot_stability_cells(result, path)
    return plot_stability_matrix(result, path)


#: Energies below this (J) are drawn at it on the log axis (a display floor, marked).
ENERGY_FLOOR_J = 1e-9


def plot_stability_cells(result: Mapping[str, Any], path: str | Path) -> Path:
    """Three panels over the same cells: (1) the energy each controller gave the user, one
    dot per cell on a log axis (energies below :data:`ENERGY_FLOOR_J` drawn at it), the goal
    as a line and the count within it; (2) the delivered force ratio ``F / (K x pen)`` over
    the contact ticks, one dot per cell, the median marked; (3) the SDK controller's ratio
    against the best peer that stayed within the energy goal in the same cell, coloured by
    the cell's period."""
    plt = _pyplot()
    cells = list(result["cells"])
    if not cells:
        raise HapticSDKError("the stability result has no cells to plot")
    names = list(cells[0]["results"])
    goal = float(result["summary"]["energy_bound_j"])
    rng = np.random.default_rng(0)   # horizontal jitter only
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.2))
    a0, a1, a2 = axes
    within: list[str] = []
    for i, name in enumerate(names):
        e = np.array([c["results"][name]["energy_to_user_j"] for c in cells])
        d = np.array([c["results"][name]["delivered_ratio"] for c in cells])
        x = i + rng.uniform(-0.3, 0.3, e.size)
        a0.scatter(x, np.maximum(e, ENERGY_FLOOR_J), s=4, alpha=0.4)
        within.append(f"{name}\n{int((e <= goal).sum())}/{e.size}")
        ok = np.isfinite(d)
        a1.scatter(x[ok], d[ok], s=4, alpha=0.4)
        if ok.any():
            a1.plot([i - 0.35, i + 0.35], [np.median(d[ok])] * 2, color="black", lw=2)
            a1.text(i, 1.04, f"median\n{np.median(d[ok]):.2f}", ha="center", fontsize=7)
    a0.axhline(goal, color="red", lw=1)
    a0.set_yscale("log")
    a0.set_ylim(ENERGY_FLOOR_J / 2, None)
    # eight lanes: the names turned so that they do not run into each other
    a0.set_xticks(range(len(names)), within, fontsize=7, rotation=30, ha="right")
    a0.set_xlabel("controller, cells within the bound")
    a0.set_ylabel(f"max energy given to the user (J, log; < {ENERGY_FLOOR_J:g} drawn at it)")
    a0.set_title(f"energy to the user per cell (red: bound {goal * 1e3:g} mJ)", fontsize=10)
    a1.set_xticks(range(len(names)), names, fontsize=8, rotation=30, ha="right")
    a1.set_ylim(-0.03, 1.16)
    a1.set_ylabel("delivered force / (K x penetration), contact ticks")
    a1.set_title("delivered force ratio per cell (bar: median)", fontsize=10)
    if "sdk" in names:
        from .benchmarks.stability_random import cell_verdicts
        best = np.array([cell_verdicts(c)["best_passive_peer_ratio"] for c in cells])
        mine = np.array([c["results"]["sdk"]["delivered_ratio"] for c in cells])
        per = np.array([c["period_s"] for c in cells]) * 1e3
        ok = np.isfinite(best) & np.isfinite(mine)
        sc = a2.scatter(best[ok], mine[ok], c=per[ok], s=6, cmap="viridis", norm=_lognorm(per[ok]))
        a2.plot([0, 1], [0, 1], color="gray", lw=1)
        a2.plot([0, 1], [0, 0.95], color="gray", lw=1, ls="--")
        a2.set_xlabel("best passive peer's delivered ratio (popc / eb / vc within the bound)")
        a2.set_ylabel("sdk delivered ratio (damping measured hands off)")
        # the lines named in the title: a legend box would sit on cells in any corner
        a2.set_title(f"sdk against the best passive peer ({int(ok.sum())} cells with one)\n"
                     "solid line: equal; dashed: 95 % of the peer (the goal)", fontsize=9)
        cb = fig.colorbar(sc, ax=a2, label="period T (ms, log)")
        from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter
        # plain numbers of ms at 1, 2, 5 per decade (not "6 x 10^0")
        cb.ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        cb.ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        cb.ax.yaxis.set_minor_formatter(NullFormatter())
    mode = result.get("mode", "")
    fig.suptitle(f"stiff virtual walls, {len(cells)} {mode} cells on a simulated arm (generated data; "
                 "exact zero-order hold, energy from the raw state)", fontsize=11)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 0.94))
    out = Path(path)
    save_figure(fig, out, dpi=90)
    return out


def _lognorm(v: np.ndarray) -> Any:
    from matplotlib.colors import LogNorm
    lo = float(np.min(v)) if v.size else 0.1
    hi = float(np.max(v)) if v.size else 1.0
    return LogNorm(vmin=lo, vmax=max(hi, lo * 1.0001))


def plot_stability_matrix(result: Mapping[str, Any], path: str | Path) -> Path:
    """Save ``hapticsdk bench stability``'s matrix (``StabilityResult.to_dict()``) as a
    figure: for each damping (columns) and controller on/off (rows), a stiffness x period
    map coloured by the delivered force ratio against the stiffest passive spring,
    ``delivered_vs_passive_ratio`` (worst finger; 1 = min(K, K_pass) x penetration
    delivered), with the largest energy given to the user (mJ) written in each cell and
    unstable cells outlined in red. The colour scale is logarithmic, whole decades from
    at most 0.1 to at least 10 and wide enough for every cell (an undamped wall without
    the controller delivers a hundred times the passive spring's force: a 0..1 scale
    painted every cell alike); a ratio of 0 is drawn at the bottom of the scale."""
    plt = _pyplot()
    from matplotlib.colors import LogNorm
    from matplotlib.patches import Rectangle

    cells = list(result["cells"])
    if not cells:
        raise HapticSDKError("the stability result has no cells to plot")
    dampings = sorted({float(c["damping_ns_per_m"]) for c in cells})
    ctrl = sorted({bool(c["controller"]) for c in cells}, reverse=True)
    grids = {(on, b): _cells_grid(cells, b, on) for on in ctrl for b in dampings}
    every = np.concatenate([g[2].ravel() for g in grids.values()])
    pos = every[np.isfinite(every) & (every > 0)]
    lo_d = np.floor(np.log10(min(0.1, pos.min()))) if pos.size else -1.0
    hi_d = np.ceil(np.log10(max(10.0, pos.max()))) if pos.size else 1.0
    v_lo = float(10.0 ** lo_d)
    norm = LogNorm(vmin=v_lo, vmax=float(10.0 ** hi_d))
    fig, axes = plt.subplots(len(ctrl), len(dampings), figsize=(4.6 * len(dampings), 3.9 * len(ctrl) + 1.2),
                             squeeze=False)
    tol_mj = float(result.get("energy_tolerance_j", np.nan)) * 1e3
    im = None
    for r, on in enumerate(ctrl):
        for col, b in enumerate(dampings):
            a = axes[r, col]
            ks, ts, ratio, energy, stable = grids[(on, b)]
            im = a.imshow(np.where(ratio > 0, ratio, v_lo), origin="lower", cmap="viridis", norm=norm,
                          aspect="auto")
            for i in range(len(ts)):
                for j in range(len(ks)):
                    e = energy[i, j] * 1e3
                    txt = f"{e:.0f}" if e >= 10 else (f"{e:.2g}" if e >= 0.01 else "0")
                    shade = ratio[i, j]
                    a.text(j, i, txt, ha="center", va="center", fontsize=7,
                           color="black" if np.isfinite(shade) and norm(max(shade, v_lo)) > 0.6 else "white")
                    if not stable[i, j]:
                        a.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, ec="red", lw=2.0))
            a.set_xticks(range(len(ks)), [f"{k:g}" for k in ks], rotation=45, fontsize=8)
            a.set_yticks(range(len(ts)), [f"{t * 1e3:g}" for t in ts], fontsize=8)
            a.set_xlabel("wall stiffness K (N/mm)")
            a.set_ylabel("servo period T (ms)")
            a.set_title(f"damping b = {b:g} Ns/m, controller {'on' if on else 'off'}", fontsize=10)
    fig.suptitle("stability matrix of a virtual wall on the simulated Omni (generated data)\n"
                 "colour = delivered force / (min(K, K_pass) x penetration), worst finger; "
                 "number = largest energy given to the user (mJ)\n"
                 f"red outline = unstable (energy > {tol_mj:g} mJ or force after release)", fontsize=10)
    fig.tight_layout(rect=(0.0, 0.0, 0.86, 0.93))
    cax = fig.add_axes((0.875, 0.12, 0.015, 0.7))
    fig.colorbar(im, cax=cax, label="delivered / (min(K, K_pass) x penetration), log scale\n"
                 "(1: the passive spring's force)")
    out = Path(path)
    save_figure(fig, out, dpi=90)
    return out


def _place_labels(ax: Any, pts: Sequence[tuple[str, float, float]], fontsize: float = 7.0) -> None:
    """Annotate each point with its name where the label overlaps no other label and no
    marker: eight offsets tried in turn, then further out with a leader line (greedy;
    each candidate's extent is measured as drawn)."""
    from matplotlib.text import Text
    fig = ax.figure
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    to_px = fig.dpi / 72.0
    xy = ax.transData.transform(np.array([[x, y] for _, x, y in pts])) if pts else np.zeros((0, 2))
    marker_r = 3.7 * to_px   # radius of a size-55 marker (sqrt(55) pt across)
    taken: list[Any] = []

    def hits(bb: Any, own: int) -> bool:
        if any(bb.overlaps(o) for o in taken):
            return True
        near = ((xy[:, 0] > bb.x0 - marker_r) & (xy[:, 0] < bb.x1 + marker_r)
                & (xy[:, 1] > bb.y0 - marker_r) & (xy[:, 1] < bb.y1 + marker_r))
        near[own] = False   # the label's own marker: the offset keeps it clear
        return bool(near.any())

    dirs = [(1, 1), (1, -1), (-1, 1), (-1, -1), (1, 0), (-1, 0), (0, 1), (0, -1)]
    for k, (name, x, y) in enumerate(pts):
        placed = None
        for reach in (4.0, 12.0, 22.0, 34.0, 48.0):
            for dx, dy in dirs:
                ha = "left" if dx > 0 else ("right" if dx < 0 else "center")
                va = "bottom" if dy > 0 else ("top" if dy < 0 else "center")
                arrow = {"arrowstyle": "-", "lw": 0.5, "color": "0.5"} if reach > 4.0 else None
                t = ax.annotate(name, (x, y), textcoords="offset points", xytext=(dx * reach, dy * reach),
                                fontsize=fontsize, ha=ha, va=va, arrowprops=arrow)
                t.update_positions(r)
                bb = Text.get_window_extent(t, r)   # the text alone, not its leader line
                if not hits(bb, k):
                    placed = bb
                    break
                t.remove()
            if placed is not None:
                break
        if placed is None:   # crowded everywhere: at the first offset, drawn anyway
            t = ax.annotate(name, (x, y), textcoords="offset points", xytext=(4, 4), fontsize=fontsize)
            t.update_positions(r)
            placed = Text.get_window_extent(t, r)
        taken.append(placed)


def _plan_line(name: str, m: Mapping[str, Any]) -> list[str]:
    """Text lines for one material of a plan figure: what it renders or leaves out, with
    the loss interval against the threshold."""
    out = []
    dropped = m.get("dropped", [])
    if not dropped:
        out.append(f"{name:<6} renders {', '.join(m.get('dimensions', []))}")
    for d in dropped:
        iv, thr = d.get("loss_interval_percent"), d.get("threshold_percent")
        loss = d.get("predicted_loss_percent")
        if iv is not None and thr is not None:
            why = f"loss {iv[0]:.1f}-{iv[1]:.1f} % < {thr:g} %"
        elif loss is not None and thr is not None:
            why = f"loss {loss:.1f} % < {thr:g} %"
        else:
            why = textwrap.shorten(str(d.get("reason", "")), 40)
        rep = (d.get("replacement") or {}).get("renderer")
        out.append(f"{name:<6} left out {d['dimension']}: {why}" + (f", replaced by {rep}" if rep else ""))
    for dim, e in (m.get("importance") or {}).items():
        lo, hi = e["interval_percent"]
        if e.get("decision") == "keep" and lo < e["threshold_percent"] <= hi:
            out.append(f"{'':<6}   kept {dim}: loss {lo:.1f}-{hi:.1f} % straddles {e['threshold_percent']:g} %")
    return out


def plot_plan(plan: Any, path: str | Path) -> Path:
    """Save a compiled plan (a ``RenderPlan`` or its ``to_dict()``) as a figure: each
    material at its target intensities (the first two dimensions named; with one
    dimension, one row per material), its marker saying which dimensions were left out,
    and beside the plot one line per material: what was left out, why (the loss interval
    against the threshold), what replaces it, and what was kept because its interval
    straddles the threshold."""
    plt = _pyplot()
    if hasattr(plan, "to_dict"):
        plan = plan.to_dict()
    mats = plan["materials"]
    mats = mats if isinstance(mats, Mapping) else {m["name"]: m for m in mats}
    if not mats:
        raise HapticSDKError("the plan has no materials to plot")
    dims: list[str] = []
    for m in mats.values():
        for d in m.get("targets", {}):
            if d not in dims:
                dims.append(d)
    dx = dims[0]
    dy = dims[1] if len(dims) > 1 else None
    groups: dict[tuple[str, ...], list[tuple[str, float, float]]] = {}
    lines: list[str] = []
    for i, (name, m) in enumerate(mats.items()):
        tg = m.get("targets", {})
        key = tuple(d["dimension"] for d in m.get("dropped", []))
        y = float(tg.get(dy, np.nan)) if dy else float(i)
        groups.setdefault(key, []).append((name, float(tg.get(dx, np.nan)), y))
        lines += _plan_line(name, m)
    fig_h = max(6.0, 0.19 * len(lines) + 1.8, (0.3 * len(mats) + 1.8) if not dy else 0.0)
    fig, (a, t) = plt.subplots(1, 2, figsize=(13, fig_h), gridspec_kw={"width_ratios": [1.0, 0.85]})
    style = [("o", "C0", True), ("s", "C1", False), ("D", "C3", False), ("^", "C2", False), ("v", "C4", False)]
    allpts: list[tuple[str, float, float]] = []
    for gi, (key, pts) in enumerate(sorted(groups.items(), key=lambda kv: (len(kv[0]), kv[0]))):
        marker, color, filled = style[gi % len(style)]
        label = "every dimension rendered" if not key else "left out: " + ", ".join(key)
        a.scatter([p[1] for p in pts], [p[2] for p in pts], s=55, marker=marker, zorder=3,
                  facecolors=color if filled else "white", edgecolors=color, linewidths=1.5,
                  label=f"{label} ({len(pts)})")
        allpts += pts
    a.set_xlim(-0.05, 1.05)
    a.set_xlabel(f"target {dx} intensity (0..1)")
    if dy:
        a.set_ylim(-0.05, 1.05)
        a.set_ylabel(f"target {dy} intensity (0..1)")
    else:   # one dimension: one row per material, named on the axis (no labels to collide)
        a.set_ylim(len(mats) - 0.5, -0.5)
        a.set_yticks(range(len(mats)))
        a.set_yticklabels(list(mats))
        a.set_ylabel("material (one row each)")
    a.grid(alpha=0.3)
    a.legend(fontsize=8, loc="upper left", bbox_to_anchor=(0.0, -0.1), ncol=2, frameon=False)
    a.set_title("materials at their target intensities", fontsize=10)
    t.axis("off")
    t.text(0.0, 1.0, "\n".join(lines), va="top", ha="left", fontsize=8, family="monospace",
           transform=t.transAxes)
    t.set_title("what each material renders; what is left out, why, and what replaces it", fontsize=10)
    model = next((d.get("importance_model") for m in mats.values() for d in m.get("dropped", [])
                  if d.get("importance_model")), None)
    gen = any(m.get("source") == "library" for m in mats.values())
    fig.suptitle(f"render plan of scene {plan.get('scene', '')}"
                 + (f": a dimension is left out when importance model '{model}' puts its whole 80 % "
                    "realism-loss interval below the threshold" if model else "")
                 + ("\n(library materials: GENERATED data)" if gen else ""), fontsize=11)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 0.93))
    if dy:
        _place_labels(a, allpts)
    out = Path(path)
    save_figure(fig, out, dpi=90)
    return out


def plot_paper_comparison(cmp: Mapping[str, Any], path: str | Path) -> Path:
    """Save :func:`hapticsdk.compiler.paper_findings.compare_with_paper`'s result as a
    figure: per evaluated sample and removal, the 80 % loss interval against the
    threshold, coloured by the paper's finding, the plan's decision as the marker."""
    plt = _pyplot()
    rows = list(cmp["rows"])
    if not rows:
        raise HapticSDKError("no evaluated sample to plot")
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), sharey=True)
    for ax, dim in zip(axes, ("roughness", "hardness")):
        rs = [r for r in rows if r["dimension"] == dim]
        for i, r in enumerate(rs):
            lo, hi = r["interval_percent"]
            col = "C3" if r["paper_significant"] else "C0"
            ax.plot([lo, hi], [i, i], color=col, lw=5, alpha=0.55, solid_capstyle="butt")
            ax.plot([r["median_percent"]], [i], marker="o" if r["plan"] == "keep" else "X", ms=8,
                    color="black" if r["agrees"] else "C1", zorder=3)
        thr = rs[0]["threshold_percent"] if rs else 10.0
        ax.axvline(thr, color="0.3", ls="--", lw=1)
        ax.set_yticks(range(len(rs)))
        ax.set_yticklabels([r["sample"] for r in rs])
        ax.set_ylim(len(rs) - 0.5, -0.5)
        ax.set_xlabel(f"predicted realism loss if {dim} is removed (%), 80 % interval")
        ax.set_title(f"removing {dim}", fontsize=10)
        ax.grid(axis="x", alpha=0.3)
    from matplotlib.lines import Line2D
    handles = [Line2D([], [], color="C3", lw=5, alpha=0.55, label="paper: significant loss"),
               Line2D([], [], color="C0", lw=5, alpha=0.55, label="paper: not significant"),
               Line2D([], [], color="0.3", ls="--", label="threshold"),
               Line2D([], [], marker="o", color="black", ls="", label="plan keeps (median)"),
               Line2D([], [], marker="X", color="black", ls="", label="plan drops (median)"),
               Line2D([], [], marker="o", color="C1", ls="", label="disagrees with the paper")]
    fig.legend(handles=handles, loc="lower center", ncol=6, fontsize=8, frameon=False)
    fig.suptitle(f"leave-out decisions against the paper's findings: {cmp['agree']} of {cmp['total']} agree, "
                 f"{cmp['contradictions']} drop(s) contradicted\n(library samples: GENERATED data anchored to "
                 f"the paper's orderings, not the paper's samples)", fontsize=10)
    fig.tight_layout(rect=(0.0, 0.08, 1.0, 0.9))
    out = Path(path)
    save_figure(fig, out, dpi=90)
    return out


def save_figure(fig: Any, path: str | Path, *, dpi: int = 100, field: str | None = None) -> Path:
    """``fig.savefig`` through :func:`hapticsdk.fileio.atomic_writer` (format from the
    suffix, PNG without one); the figure is closed. A failed write keeps the old file."""
    import matplotlib.pyplot as plt

    from .fileio import atomic_writer
    p = Path(path)
    fmt = p.suffix[1:].lower() or "png"
    known = fig.canvas.get_supported_filetypes()
    if fmt not in known:
        plt.close(fig)
        raise ValidationError(f"cannot write a figure as {fmt!r}; use one of {', '.join(sorted(known))}",
                              field=field or str(p))
    try:
        with atomic_writer(p, "wb", field=field) as fh:
            fig.savefig(fh, format=fmt, dpi=dpi)
    finally:
        plt.close(fig)
    return p
