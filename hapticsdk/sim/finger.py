"""Scripted finger trajectories and finger (hand) impedances for simulated runs.

A :class:`Trajectory` gives the *reference* position of the finger over time: where the
finger means to be (mm). A kinematic probe (:class:`~hapticsdk.sim.probe.VirtualProbe`)
follows it exactly; a simulated force arm is pushed towards it through the finger's
impedance (:class:`FingerParams`: mass, spring, damper). Axes follow
:class:`~hapticsdk.actuators.DeviceState`: x is the lateral sliding direction, y the
surface normal with the material surface at y = 0 and its inside at y < 0.

All trajectories are piecewise linear in time, evaluated vectorised with
``np.interp`` (positions in mm, times in s, velocities in mm/s).
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..errors import ValidationError


@dataclass(frozen=True)
class FingerParams:
    """Impedance of the finger holding the stylus (generated presets, not measured).

    Attributes:
        mass_kg: finger mass moving with the stylus (kg).
        stiffness_n_per_m: spring between the intended and actual position (N/m).
        damping_ns_per_m: damper in parallel with it (N*s/m).
    """

    mass_kg: float = 0.01
    stiffness_n_per_m: float = 300.0
    damping_ns_per_m: float = 0.5

    def __post_init__(self) -> None:
        for k in ("mass_kg", "stiffness_n_per_m", "damping_ns_per_m"):
            v = getattr(self, k)
            if not np.isfinite(v) or v < 0:
                raise ValidationError(f"must be finite and >= 0, got {v!r}", field=f"finger.{k}")


#: Finger impedance presets, soft .. stiff grip (assumed values of the order reported for
#: fingertip/hand impedance in the haptics literature; generated, not measured).
FINGERS: dict[str, FingerParams] = {
    "soft": FingerParams(mass_kg=0.005, stiffness_n_per_m=100.0, damping_ns_per_m=0.2),
    "medium": FingerParams(mass_kg=0.01, stiffness_n_per_m=300.0, damping_ns_per_m=0.5),
    "stiff": FingerParams(mass_kg=0.02, stiffness_n_per_m=1000.0, damping_ns_per_m=1.0),
}


def finger(name_or_params: "str | FingerParams") -> FingerParams:
    """Look up a preset by name or pass params through."""
    if isinstance(name_or_params, FingerParams):
        return name_or_params
    try:
        return FINGERS[name_or_params]
    except KeyError:
        raise ValidationError(f"unknown finger {name_or_params!r}; valid: {sorted(FINGERS)}",
                              field="finger") from None


class Trajectory:
    """Piecewise-linear reference path through knots ``(t_s, x_mm, y_mm)``."""

    def __init__(self, knots: Sequence[tuple[float, float, float]], *, name: str = "trajectory") -> None:
        k = np.asarray(knots, float)
        if k.ndim != 2 or k.shape[1] != 3 or k.shape[0] < 2:
            raise ValidationError("knots must be >= 2 rows of (t_s, x_mm, y_mm)", field="knots")
        if not np.isfinite(k).all() or np.any(np.diff(k[:, 0]) <= 0):
            raise ValidationError("knot times must be finite and strictly increasing", field="knots")
        self.t, self.x, self.y = k[:, 0] - k[0, 0], k[:, 1], k[:, 2]
        self.name = name
        self._vx = np.diff(self.x) / np.diff(self.t)
        self._vy = np.diff(self.y) / np.diff(self.t)
        # plain lists for the scalar fast path used once per servo tick
        self._tl = self.t.tolist()
        self._xl = self.x.tolist()
        self._yl = self.y.tolist()
        self._vxl = self._vx.tolist()
        self._vyl = self._vy.tolist()

    def at(self, t: float) -> tuple[float, float, float, float]:
        """Scalar ``(x_mm, y_mm, vx_mm_s, vy_mm_s)`` at time ``t`` (s); cheap (no numpy)."""
        tl = self._tl
        if t < tl[0]:
            return self._xl[0], self._yl[0], 0.0, 0.0
        if t >= tl[-1]:
            return self._xl[-1], self._yl[-1], 0.0, 0.0
        i = bisect_right(tl, t) - 1
        s = t - tl[i]
        vx, vy = self._vxl[i], self._vyl[i]
        return self._xl[i] + vx * s, self._yl[i] + vy * s, vx, vy

    @property
    def duration_s(self) -> float:
        return float(self.t[-1])

    def position(self, t: "float | np.ndarray") -> tuple[np.ndarray, np.ndarray]:
        """Reference (x, y) in mm at times ``t`` (s); held constant after the end."""
        t = np.asarray(t, float)
        return np.interp(t, self.t, self.x), np.interp(t, self.t, self.y)

    def velocity(self, t: "float | np.ndarray") -> tuple[np.ndarray, np.ndarray]:
        """Reference (vx, vy) in mm/s (right derivative; 0 outside the knots)."""
        t = np.asarray(t, float)
        i = np.searchsorted(self.t, t, side="right") - 1
        inside = (i >= 0) & (i < self._vx.size)
        ic = np.clip(i, 0, self._vx.size - 1)
        return np.where(inside, self._vx[ic], 0.0), np.where(inside, self._vy[ic], 0.0)

    def sample(self, period_s: float, duration_s: float | None = None) -> dict[str, np.ndarray]:
        """Reference on the tick grid ``0, T, 2T, ...`` up to the duration."""
        n = int(round((duration_s if duration_s is not None else self.duration_s) / period_s)) + 1
        tt = np.arange(n) * period_s
        x, y = self.position(tt)
        return {"t": tt, "x_mm": x, "y_mm": y}

    def then(self, other: "Trajectory", gap_s: float = 0.0) -> "Trajectory":
        """This path followed by ``other`` (shifted in time; positions as given)."""
        t0 = self.duration_s + max(gap_s, 1e-9)
        knots = list(zip(self.t, self.x, self.y)) + [
            (t0 + t, x, y) for t, x, y in zip(other.t, other.x, other.y)]
        return Trajectory(knots, name=f"{self.name}+{other.name}")


def press_slide(*, depth_mm: float = 2.0, approach_mm: float = 2.0, press_s: float = 0.5,
                hold_s: float = 0.2, speed_mm_s: float = 80.0, slide_s: float = 1.0,
                release_s: float = 0.5, rest_s: float = 0.5, x0_mm: float = 0.0) -> Trajectory:
    """Press into the surface, slide laterally along x, release.

    Starts ``approach_mm`` above the surface, reaches ``-depth_mm`` after ``press_s``,
    holds ``hold_s``, slides at ``speed_mm_s`` (mm/s) for ``slide_s``, holds again,
    returns to ``+approach_mm`` over ``release_s`` and rests ``rest_s``.
    """
    for name, v in (("depth_mm", depth_mm), ("press_s", press_s), ("release_s", release_s)):
        if not np.isfinite(v) or v <= 0:
            raise ValidationError(f"must be > 0, got {v!r}", field=name)
    for name, v in (("approach_mm", approach_mm), ("hold_s", hold_s), ("slide_s", slide_s), ("rest_s", rest_s)):
        if not np.isfinite(v) or v < 0:
            raise ValidationError(f"must be >= 0, got {v!r}", field=name)
    t = 0.0
    k = [(t, x0_mm, approach_mm)]
    t += press_s
    k.append((t, x0_mm, -depth_mm))
    x = x0_mm
    if hold_s > 0:
        t += hold_s
        k.append((t, x, -depth_mm))
    if slide_s > 0:
        t += slide_s
        x += speed_mm_s * slide_s
        k.append((t, x, -depth_mm))
        if hold_s > 0:
            t += hold_s
            k.append((t, x, -depth_mm))
    t += release_s
    k.append((t, x, approach_mm))
    if rest_s > 0:
        t += rest_s
        k.append((t, x, approach_mm))
    return Trajectory(k, name="press-slide")


def taps(*, n: int = 5, depth_mm: float = 1.5, approach_mm: float = 2.0, down_s: float = 0.05,
         up_s: float = 0.05, dwell_s: float = 0.05, pause_s: float = 0.2) -> Trajectory:
    """``n`` taps: down to ``-depth_mm`` in ``down_s``, dwell, up in ``up_s``, pause."""
    if n < 1:
        raise ValidationError("n must be >= 1", field="n")
    t = 0.0
    k = [(t, 0.0, approach_mm)]
    for _ in range(n):
        t += down_s
        k.append((t, 0.0, -depth_mm))
        if dwell_s > 0:
            t += dwell_s
            k.append((t, 0.0, -depth_mm))
        t += up_s
        k.append((t, 0.0, approach_mm))
        if pause_s > 0:
            t += pause_s
            k.append((t, 0.0, approach_mm))
    return Trajectory(k, name="taps")


def quasi_static_press(*, depth_mm: float = 3.0, speed_mm_s: float = 5.0, approach_mm: float = 0.5,
                       hold_s: float = 0.1) -> Trajectory:
    """Slow press and release at ``speed_mm_s`` (< 10 mm/s: quasi-static, goal 7)."""
    s = (approach_mm + depth_mm) / speed_mm_s
    return Trajectory([(0.0, 0.0, approach_mm), (s, 0.0, -depth_mm), (s + hold_s, 0.0, -depth_mm),
                       (2 * s + hold_s, 0.0, approach_mm)], name="quasi-static-press")


def standard_set(duration_s: float = 10.0) -> list[Trajectory]:
    """A set of scripted hand trajectories (press/slide/taps at several speeds and
    depths), each repeated to fill ``duration_s``."""
    out = []
    bases = [press_slide(), press_slide(depth_mm=1.0, press_s=0.2, release_s=0.2, speed_mm_s=150.0),
             press_slide(depth_mm=3.0, press_s=1.0, release_s=1.0, speed_mm_s=40.0),
             taps(), taps(depth_mm=0.8, down_s=0.02, up_s=0.02), quasi_static_press()]
    for b in bases:
        tr = b
        while tr.duration_s < duration_s:
            tr = tr.then(b, gap_s=0.01)
        out.append(tr)
    return out
