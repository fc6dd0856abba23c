"""Scripted finger trajectories and finger (hand) impedances for simulated runs.

A :class:`Trajectory` gives the *reference* position of the finger over time: where the
finger means to be (mm). A kinematic probe (:class:`~hapticsdk.sim.probe.VirtualProbe`)
follows it exactly; a simulated force arm is pushed towards it through the finger's
impedance (:class:`FingerParams`: mass, spring, damper). Axes follow
:class:`~hapticsdk.devices.actuators.DeviceState`: x is the lateral sliding direction, y the
surface normal with the material surface at y = 0 and its inside at y < 0.

All trajectories are piecewise linear in time, evaluated vectorised with
``np.interp`` (positions in mm, times in s, velocities in mm/s).

Spatial scenes (:mod:`hapticsdk.scene.geometry`): :func:`walk` builds a 3-D path
(knots ``(t, x, y, z)``) that presses and slides across several surfaces in turn, and
:func:`walk_over` builds that walk from a scene's objects. The kinematic probe follows
all three axes; the simulated Omni keeps y (the normal) through its arm dynamics and
follows x and z kinematically.
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass
from typing import Any, Callable, Sequence

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
    # nobody holds the stylus: the hands-off damping run (hapticsdk calibrate damping
    # --device omni-virtual --device-option finger=none)
    "none": FingerParams(mass_kg=0.0, stiffness_n_per_m=0.0, damping_ns_per_m=0.0),
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
    """Piecewise-linear reference path through knots ``(t_s, x_mm, y_mm)``, or
    ``(t_s, x_mm, y_mm, z_mm)`` for a 3-D path (z: across the sliding direction; 0 for
    3-column knots). :meth:`at` gives (x, y) as always; :meth:`at3` adds z."""

    def __init__(self, knots: "Sequence[Sequence[float]] | np.ndarray", *, name: str = "trajectory") -> None:
        k = np.asarray(knots, float)
        if k.ndim != 2 or k.shape[1] not in (3, 4) or k.shape[0] < 2:
            raise ValidationError("knots must be >= 2 rows of (t_s, x_mm, y_mm) or (t_s, x_mm, y_mm, z_mm)",
                                  field="knots")
        if not np.isfinite(k).all() or np.any(np.diff(k[:, 0]) <= 0):
            raise ValidationError("knot times must be finite and strictly increasing", field="knots")
        self.t, self.x, self.y = k[:, 0] - k[0, 0], k[:, 1], k[:, 2]
        #: True for 4-column knots (a z coordinate was given)
        self.has_z = k.shape[1] == 4
        self.z = k[:, 3] if self.has_z else np.zeros_like(self.x)
        self.name = name
        self._vx = np.diff(self.x) / np.diff(self.t)
        self._vy = np.diff(self.y) / np.diff(self.t)
        self._vz = np.diff(self.z) / np.diff(self.t)
        # plain lists for the scalar fast path used once per servo tick
        self._tl = self.t.tolist()
        self._xl = self.x.tolist()
        self._yl = self.y.tolist()
        self._zl = self.z.tolist()
        self._vxl = self._vx.tolist()
        self._vyl = self._vy.tolist()
        self._vzl = self._vz.tolist()

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

    def at3(self, t: float) -> tuple[float, float, float, float, float, float]:
        """Scalar ``(x_mm, y_mm, z_mm, vx, vy, vz)`` (mm, mm/s) at time ``t`` (s); no numpy."""
        tl = self._tl
        if t < tl[0]:
            return self._xl[0], self._yl[0], self._zl[0], 0.0, 0.0, 0.0
        if t >= tl[-1]:
            return self._xl[-1], self._yl[-1], self._zl[-1], 0.0, 0.0, 0.0
        i = bisect_right(tl, t) - 1
        s = t - tl[i]
        vx, vy, vz = self._vxl[i], self._vyl[i], self._vzl[i]
        return self._xl[i] + vx * s, self._yl[i] + vy * s, self._zl[i] + vz * s, vx, vy, vz

    def z_at(self, t: float) -> tuple[float, float]:
        """Scalar ``(z_mm, vz_mm_s)`` at ``t`` (s); ``(0, 0)`` for a 2-D path."""
        if not self.has_z:
            return 0.0, 0.0
        _, _, z, _, _, vz = self.at3(t)
        return z, vz

    @property
    def duration_s(self) -> float:
        """Length of the trajectory (s)."""
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
        out = {"t": tt, "x_mm": x, "y_mm": y}
        if self.has_z:
            out["z_mm"] = np.interp(tt, self.t, self.z)
        return out

    def then(self, other: "Trajectory", gap_s: float = 0.0) -> "Trajectory":
        """This path followed by ``other`` (shifted in time; positions as given)."""
        t0 = self.duration_s + max(gap_s, 1e-9)
        if self.has_z or other.has_z:
            knots: list = list(zip(self.t, self.x, self.y, self.z)) + [
                (t0 + t, x, y, z) for t, x, y, z in zip(other.t, other.x, other.y, other.z)]
        else:
            knots = list(zip(self.t, self.x, self.y)) + [
                (t0 + t, x, y) for t, x, y in zip(other.t, other.x, other.y)]
        return Trajectory(knots, name=f"{self.name}+{other.name}")

    def repeated(self, more: Callable[[float], bool], gap_s: float = 0.0) -> "Trajectory":
        """This path, then copies of it (each ``gap_s`` after the last one ends) while
        ``more(duration so far)`` holds: the same knots as chaining :meth:`then`, built in
        one pass (chaining copies every knot again per copy: quadratic in their number)."""
        cols = [self.t, self.x, self.y] + ([self.z] if self.has_z else [])
        last = float(self.t[-1])
        offsets = [0.0]
        dur = last
        while more(dur):
            t0 = dur + max(gap_s, 1e-9)
            offsets.append(t0)
            dur = t0 + last
        if len(offsets) == 1:
            return self
        rows = np.concatenate([np.column_stack([off + cols[0]] + cols[1:]) for off in offsets])
        name = "+".join([self.name] * len(offsets)) if len(offsets) <= 8 else f"{self.name} x {len(offsets)}"
        return Trajectory(rows, name=name)


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


# -- walks over the objects of a spatial scene ------------------------------------
Point3 = tuple[float, float, float]


def walk(strokes: Sequence[Sequence[Sequence[float]]], *, press_depth_mm: float = 1.5,
         speed_mm_s: float = 50.0, approach_mm: float = 5.0, press_s: float = 0.3, hold_s: float = 0.1,
         lift_s: float = 0.3, travel_speed_mm_s: float = 150.0, rest_s: float = 0.2,
         clearance_y_mm: float | None = None) -> Trajectory:
    """A 3-D finger path over several surfaces (knots ``(t, x, y, z)``, mm).

    ``strokes`` holds one stroke per object: a list of surface points ``(x, y, z)``
    (mm; 1 point = a press without sliding). For each stroke the finger comes down at
    ``travel_speed_mm_s`` to ``approach_mm`` above the first point, presses to
    ``press_depth_mm`` below it (along -y) in ``press_s``, holds ``hold_s``, slides
    through the remaining points at ``speed_mm_s`` (each ``press_depth_mm`` below the
    surface point, along -y), holds, lifts to ``approach_mm`` above the last point in
    ``lift_s``, rises to the clearance height and travels (straight, at
    ``travel_speed_mm_s``) to above the next stroke. The clearance height is
    ``clearance_y_mm``, default ``approach_mm`` above the highest surface point of all
    strokes, so the finger does not graze other objects between strokes. The path ends
    with ``rest_s`` at the clearance height.

    The press is along the world y axis only (the axis the simulated Omni's arm
    dynamics act on); on a sloped surface the penetration along the surface normal is
    less than ``press_depth_mm``.
    """
    for name, v in (("press_depth_mm", press_depth_mm), ("speed_mm_s", speed_mm_s), ("press_s", press_s),
                    ("lift_s", lift_s), ("travel_speed_mm_s", travel_speed_mm_s)):
        if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
            raise ValidationError(f"must be > 0, got {v!r}", field=name)
    for name, v in (("approach_mm", approach_mm), ("hold_s", hold_s), ("rest_s", rest_s)):
        if not (isinstance(v, (int, float)) and np.isfinite(v) and v >= 0):
            raise ValidationError(f"must be >= 0, got {v!r}", field=name)
    pts: list[list[Point3]] = []
    for i, stroke in enumerate(strokes):
        a = np.asarray(stroke, float)
        if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] < 1 or not np.isfinite(a).all():
            raise ValidationError("a stroke is a list of finite (x, y, z) points (mm)", field=f"strokes[{i}]")
        pts.append([(float(p[0]), float(p[1]), float(p[2])) for p in a])
    if not pts:
        raise ValidationError("at least one stroke is needed", field="strokes")
    top = max(p[1] for s in pts for p in s)
    clear = top + approach_mm if clearance_y_mm is None else float(clearance_y_mm)
    if not np.isfinite(clear) or clear < top:
        raise ValidationError(f"clearance {clear!r} mm is below the highest surface point {top} mm",
                              field="clearance_y_mm")
    knots: list[tuple[float, float, float, float]] = []
    t = 0.0

    def go(x: float, y: float, z: float, dur: float | None = None, speed: float | None = None) -> None:
        nonlocal t
        if knots:
            _, x0, y0, z0 = knots[-1]
            dist = float(np.sqrt((x - x0) ** 2 + (y - y0) ** 2 + (z - z0) ** 2))
            if dur is None:
                dur = dist / float(speed)  # type: ignore[arg-type]
            if dist == 0.0 and dur <= 0.0:
                return
            t += dur
        knots.append((t, x, y, z))

    x0, _, z0 = pts[0][0]
    go(x0, clear, z0)
    for stroke in pts:
        sx, sy, sz = stroke[0]
        go(sx, clear, sz, speed=travel_speed_mm_s)
        go(sx, sy + approach_mm, sz, speed=travel_speed_mm_s)
        go(sx, sy - press_depth_mm, sz, dur=press_s)
        if hold_s > 0:
            go(sx, sy - press_depth_mm, sz, dur=hold_s)
        for px, py, pz in stroke[1:]:
            go(px, py - press_depth_mm, pz, speed=speed_mm_s)
        lx, ly, lz = stroke[-1]
        if hold_s > 0 and len(stroke) > 1:
            go(lx, ly - press_depth_mm, lz, dur=hold_s)
        go(lx, ly + approach_mm, lz, dur=lift_s)
        go(lx, clear, lz, speed=travel_speed_mm_s)
    if rest_s > 0:
        _, lx, ly, lz = knots[-1]
        go(lx, ly, lz, dur=rest_s)
    return Trajectory(knots, name="walk")


def _x_half_extent(shape: Any) -> float:
    """Half extent along world x of an object's top (mm); None-safe for infinite planes."""
    from ..scene.geometry import Box, PlanePatch, Sphere
    if isinstance(shape, Sphere):
        return shape.radius_mm
    m = shape._m  # the shape's local frame (rows), world = m @ local + p
    if isinstance(shape, Box):
        return sum(abs(m[0][j]) * h for j, h in enumerate(shape.half_size_mm))
    if isinstance(shape, PlanePatch) and shape.half_size_mm is not None:
        hx, hz = shape.half_size_mm
        return abs(m[0][0]) * hx + abs(m[0][2]) * hz
    return 20.0  # an infinite plane: slide 2 * 20 * slide_fraction mm


def walk_over(scene: Any, *, press_depth_mm: float = 1.5, speed_mm_s: float = 50.0,
              slide_fraction: float = 0.6, samples: int = 9, **walk_options: Any) -> Trajectory:
    """:func:`walk` over every object of a scene, in the scene's order.

    ``scene`` is a :class:`~hapticsdk.scene.Scene`, a
    :class:`~hapticsdk.scene.geometry.HitTester` or a sequence of shapes. On each object
    the finger presses at the top of the object (found by a vertical ray through its
    pose position, :meth:`~hapticsdk.scene.geometry.Shape.surface_y`) and slides along
    world x across ``slide_fraction`` of the object's x extent (an infinite plane: 40 mm
    times ``slide_fraction``) centred on it, following the surface through ``samples``
    points. Objects whose top is covered by another object, or whose pose position is
    not under their own surface (a wall: normal horizontal), cannot be walked:
    ValidationError naming the object. Other keywords go to :func:`walk`.
    """
    from ..scene.geometry import HitTester, Shape
    if isinstance(scene, HitTester):
        shapes, names = list(scene.shapes), list(scene.names)
    elif hasattr(scene, "hit_tester") and callable(scene.hit_tester):
        ht = scene.hit_tester()
        shapes, names = list(ht.shapes), list(ht.names)
    else:
        shapes = list(scene)
        names = [f"objects[{i}]" for i in range(len(shapes))]
        for i, s in enumerate(shapes):
            if not isinstance(s, Shape):
                raise ValidationError(f"expected a Shape, got {s!r}", field=f"objects[{i}]")
    if not (isinstance(slide_fraction, (int, float)) and 0 <= slide_fraction <= 1):
        raise ValidationError(f"must be in [0, 1], got {slide_fraction!r}", field="slide_fraction")
    if not isinstance(samples, int) or samples < 2:
        raise ValidationError(f"must be an integer >= 2, got {samples!r}", field="samples")
    strokes = []
    for name, shape in zip(names, shapes):
        cx, _, cz = shape.pose.position_mm
        half = slide_fraction * _x_half_extent(shape)
        stroke: list[Point3] = []
        for k in range(samples):
            x = cx - half + 2.0 * half * k / (samples - 1) if half > 0 else cx
            y = shape.surface_y(x, cz)
            if y is not None and (not stroke or x != stroke[-1][0]):
                stroke.append((x, y, cz))
        if not stroke:
            raise ValidationError("no surface above the object's position to press on", field=f"objects.{name}")
        strokes.append(stroke)
    return walk(strokes, press_depth_mm=press_depth_mm, speed_mm_s=speed_mm_s, **walk_options)
