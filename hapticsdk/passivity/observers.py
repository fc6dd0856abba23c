"""Passivity observers of a recorded run: the energy paired with the zero-order hold, and
the textbook one (current force times backward velocity) for comparison."""

from __future__ import annotations

import numpy as np

def zoh_observer_energy(x_mm: np.ndarray, f_applied: np.ndarray) -> np.ndarray:
    """Running ZOH-paired observer energy (J) of a recorded run: ``E_n = -sum F_{k-1} dx_k``."""
    dx = np.diff(np.asarray(x_mm, float)) * 1e-3
    return np.concatenate([[0.0], np.cumsum(-np.asarray(f_applied, float)[:-1] * dx)])


def naive_observer_energy(x_mm: np.ndarray, f_applied: np.ndarray, dt: float) -> np.ndarray:
    """Running textbook observer energy (J): ``E_n = -sum f_k v_k dt`` with the *current*
    force and the backward-difference velocity (blind to the energy of the hold)."""
    v = np.diff(np.asarray(x_mm, float)) * 1e-3 / dt
    return np.concatenate([[0.0], np.cumsum(-np.asarray(f_applied, float)[1:] * v * dt)])
