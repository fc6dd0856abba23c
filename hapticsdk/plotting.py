"""Figures of a render (needs the optional ``matplotlib``: ``pip install hapticsdk[plot]``).

:func:`plot_render` draws, from the servo loop's per-tick log, the normal force against
penetration (with the commanded spring law), the vibration commands over time (piezo
voltage envelope and frequency, voice-coil drive), and the probe's sliding speed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .errors import HapticSDKError


def _pyplot() -> Any:
    try:
        import matplotlib
    except ImportError:
        raise HapticSDKError("plotting needs matplotlib: pip install 'hapticsdk[plot]'") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _role_series(a: Any, t: np.ndarray, log: dict, suffix: str, ylabel: str, title: str) -> None:
    """Plot every ``<role><suffix>`` series of the log on axis ``a``."""
    keys = sorted(k for k in log if k.endswith(suffix))
    for key in keys:
        a.plot(t, log[key], label=key[: -len(suffix)])
    a.set_xlabel("time (s)")
    a.set_ylabel(ylabel)
    a.set_title(title)
    if keys:
        a.legend(fontsize=8)


def plot_render(report: Any, path: str | Path) -> Path:
    """Save a 2x2 figure of ``report`` (a render report with a servo ``loop`` log) to ``path``."""
    plt = _pyplot()
    loop = getattr(report, "loop", report)
    log = getattr(loop, "log", None) or {}
    if "t" not in log:
        raise HapticSDKError("the report has no servo log to plot")
    t = np.asarray(log["t"])
    pen = np.asarray(log["penetration_mm"])
    force = np.asarray(log.get("force_n", np.zeros_like(t)))
    vel = np.asarray(log["velocity_mm_s"])
    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    title = f"hapticsdk render of {getattr(report, 'material', '')}"
    fig.suptitle(title)

    a = ax[0, 0]
    a.plot(np.maximum(pen, 0), force, ".", ms=2, label="rendered")
    gs = (getattr(report, "features", {}) or {}).get("GS")
    if gs is not None:
        y = np.linspace(0, max(pen.max(), 1e-3), 50)
        a.plot(y, np.minimum(min(gs, 2.3) * y, 3.3), "k--", lw=1, label=f"min(GS, 2.3 N/mm) * Y, GS = {gs:.2f} N/mm")
    a.set_xlabel("penetration Y (mm)")
    a.set_ylabel("normal force (N)")
    a.set_title("hardness: force against penetration")
    a.legend(fontsize=8)

    _role_series(ax[0, 1], t, log, ".amplitude", "drive amplitude (V for the piezo, 0..1 for the coil)",
                 "vibration drive envelopes")
    _role_series(ax[1, 0], t, log, ".frequency_hz", "drive frequency (Hz)",
                 "vibration frequencies (piezo follows sliding speed)")

    a = ax[1, 1]
    a.plot(t, np.abs(vel[:, 0]), label="|v_x| sliding speed")
    a.axhline(20.0, color="r", lw=0.8, ls=":", label="20 mm/s gate")
    a.set_xlabel("time (s)")
    a.set_ylabel("speed (mm/s)")
    a2 = a.twinx()
    a2.plot(t, pen, "g", lw=0.8, label="penetration")
    a2.set_ylabel("penetration (mm)")
    a.set_title("probe motion")
    a.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out
