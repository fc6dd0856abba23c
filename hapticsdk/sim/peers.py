"""Textbook passivity controllers, vectorised over cells, as peers of
:class:`hapticsdk.passivity.PassivityController` in the stability benchmark.

Each takes the encoder reading ``x_mm``, the period ``T`` (s), the wall's force ``fw`` (N)
and the *declared* device damping (taken at face value, as the textbook does), and
returns the force to command; :func:`commit` records the force actually applied.

* ``plain``: the wall itself, no controller.
* ``popc``: passivity observer / controller (Hannaford & Ryu 2002) with the observer
  paired to the hold (``E += -F_applied(n-1) dx(n)``, Ryu, Kim & Hannaford 2004) and the
  unbounded variable damper ``alpha = -E / (T v^2)``, ``F = F_wall - alpha v``.
* ``eb``: energy bounding (Kim & Ryu 2004/2010, read from the abstract): the energy the
  hold generates in a sample, ``|dF| |dx| / 2``, is kept within what the declared
  physical damping dissipates, ``b dx^2 / T``, i.e. ``|F_n - F_(n-1)| <= 2 b |dx| / T``.
* ``vc``: virtual coupling (Adams & Hannaford 1999) at the Colgate limit: a spring
  ``K_c = 2 b / T`` (no coupling damper) in series with the wall and a massless proxy,
  ``F = K K_c / (K + K_c) x penetration``.
"""

from __future__ import annotations

import numpy as np

PEERS = ("plain", "popc", "eb", "vc")


def state(n: int) -> dict[str, np.ndarray]:
    """Fresh state for ``n`` lanes."""
    z = np.zeros(n)
    return {"E": z.copy(), "x1": z.copy(), "f1": z.copy(), "out": z.copy(), "started": np.zeros(n, bool)}


def step(kind: np.ndarray, st: dict[str, np.ndarray], x_mm: np.ndarray, T: np.ndarray, fw: np.ndarray,
         K_n_per_mm: np.ndarray, pen_mm: np.ndarray, b_declared: np.ndarray) -> np.ndarray:
    """Commanded force (N) of each lane's peer (``kind``: index into :data:`PEERS`)."""
    started = st["started"]
    dq = np.where(started, (x_mm - st["x1"]) * 1e-3, 0.0)
    st["x1"] = np.array(x_mm, float)
    st["started"] = np.ones_like(started)
    # PO/PC
    E = st["E"] - st["f1"] * dq
    st["E"] = E
    v = dq / T
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha = np.where((E < 0) & (v != 0), -E / (T * v * v), 0.0)
    popc = fw - alpha * v
    # energy bounding
    lim = 2.0 * b_declared * np.abs(dq) / T
    prev = st["out"]
    eb = prev + np.clip(fw - prev, -lim, lim)
    # virtual coupling at the Colgate limit
    kc = 2.0 * b_declared / T / 1000.0
    with np.errstate(divide="ignore", invalid="ignore"):
        keff = np.where(K_n_per_mm + kc > 0, K_n_per_mm * kc / (K_n_per_mm + kc), 0.0)
    vc = keff * np.maximum(pen_mm, 0.0)
    out = np.select([kind == 0, kind == 1, kind == 2], [fw, popc, eb], vc)
    st["out"] = out
    return out


def commit(st: dict[str, np.ndarray], f_applied: np.ndarray) -> None:
    """Record the applied forces (N)."""
    st["f1"] = np.array(f_applied, float)
    st["out"] = st["f1"].copy()
