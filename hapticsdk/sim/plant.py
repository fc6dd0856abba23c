"""Many arm + finger cells, each with its own period, advanced together under an exact
zero-order hold, with the energy given to the finger integrated from the raw per-tick
state (independent of any controller's bookkeeping).

Model per cell (SI): ``(m + m_h) y'' = F - b y' + k_h (r - y) + b_h (r' - y')`` with the
force ``F`` held over each period and saturated at the force limit, the finger reference
``r`` linear within a period. The step is ``expm(A T)`` of the augmented state
``[y, v, r, r', F]`` (:func:`hapticsdk.sim.arm.transition_matrices`); the arm damper's
dissipation over a period is ``b z^T G z`` with Van Loan's Gramian
(:func:`hapticsdk.sim.arm.dissipation_gramians`), so the energy integral is exact too:

    ``energy to the finger = sum F_k (y_{k+1} - y_k) - 1/2 m v^2 - sum b z_k^T G z_k``

(motor work minus the arm's kinetic energy minus its damper; the finger starts at rest).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .arm import ArmParams, dissipation_gramians, readings_mm, transition_matrices, zoh_step
from .finger import FingerParams


class PlantBatch:
    """``n`` independent cells; cell ``i`` has its own period, arm and finger.

    ``rows`` maps lanes to cells (several controllers on the same cell share its
    matrices): lane ``j`` simulates cell ``rows[j]``."""

    def __init__(self, periods_s: Sequence[float], arms: Sequence[ArmParams], fingers: Sequence[FingerParams],
                 y0_mm: "np.ndarray | float", rows: "np.ndarray | None" = None) -> None:
        n = len(arms)
        P = np.empty((n, 2, 5))
        G = np.empty((n, 5, 5))
        for i, (T, a, f) in enumerate(zip(periods_s, arms, fingers)):
            P[i] = transition_matrices(float(T), [a], [f])[0]
            G[i] = dissipation_gramians(float(T), [a], [f])[0]
        rows = np.arange(n) if rows is None else np.asarray(rows, int)
        self.rows = rows
        self.P = P[rows]
        self.G = G[rows]
        self.b = np.array([a.damping_ns_per_m for a in arms])[rows]
        self.m = np.array([a.mass_kg for a in arms])[rows]
        self.fmax = np.array([a.max_force_n for a in arms])[rows]
        self.res_mm = np.array([a.encoder_resolution_mm for a in arms])[rows]
        self.y = np.broadcast_to(np.asarray(y0_mm, float), (n,))[rows] * 1e-3
        self.v = np.zeros(rows.size)
        self.motor_work_j = np.zeros(rows.size)
        self.damper_j = np.zeros(rows.size)
        self._z = np.zeros((rows.size, 5))

    def measured_mm(self) -> np.ndarray:
        """Encoder readings (mm): the true position rounded to each cell's resolution."""
        return readings_mm(self.y, self.res_mm)

    def step(self, force_n: np.ndarray, r_mm: np.ndarray, rd_mm_s: np.ndarray, live: "np.ndarray | None" = None
             ) -> np.ndarray:
        """Advance every live lane one of its periods under its held force (saturated);
        returns the applied forces (N). Lanes not live keep their state."""
        f = np.clip(np.nan_to_num(np.asarray(force_n, float)), -self.fmax, self.fmax)
        yv, z = zoh_step(self.P, self._z, self.y, self.v, f, r_mm, rd_mm_s)
        dis = self.b * np.einsum("ni,nij,nj->n", z, self.G, z)
        work = f * (yv[:, 0] - self.y)
        if live is None:
            live = np.ones(f.shape, bool)
        self.damper_j += np.where(live, dis, 0.0)
        self.motor_work_j += np.where(live, work, 0.0)
        self.y = np.where(live, yv[:, 0], self.y)
        self.v = np.where(live, yv[:, 1], self.v)
        return f

    def energy_to_user_j(self) -> np.ndarray:
        """Energy the arm + wall have given to the finger so far (J)."""
        return self.motor_work_j - 0.5 * self.m * self.v ** 2 - self.damper_j
