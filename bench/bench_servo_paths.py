"""The stiff-wall controller through the real servo loop (``ServoLoop``, the simulated Omni
of ``plugins/hapticsdk-hardness``: 45 g, 0.055 mm encoder, 3.3 N; generated data) on motions
and events the stability benchmark does not draw (issue 23). Energy to the finger:
``OmniVirtual.energy_to_user_j`` (motor work on the true positions less the arm's kinetic
energy and damper loss), its largest over the run; a cell fails above 0.1 mJ.

    python bench/bench_servo_paths.py KIND [--cells N] [--seed S] [--axes 3]

KIND (drawn per cell: period, the arm's damping 0-0.5 N s/m declared or measured hands
off, a spring wall of 0.3-50 N/mm, the finger preset, the motion's parameters):

* ``slide``: pressed 0.3-3 mm, sliding across the seam of two abutting boxes and back
  (2-11 crossings at 20-300 mm/s), against one box as wide as both;
* ``taps``: 2-11 taps on the two boxes in turn, against one box;
* ``ball``: sliding back and forth over the top of a ball of 8-40 mm at depth;
* ``nan``, ``switch``, ``pause``, ``delay``, ``moving``: a press and hold on the plane
  (a box for ``moving``) with, during the press or the hold, 1-19 ticks of NaN readings,
  a material 1.5-20 times stiffer switched in, a pause of 1-19 ticks, a force delayed by
  1-3 ticks, or the box moving 0.2-3 mm at 1-20 Hz; each cell run with and without the
  event, and the cells failing with the event only counted;
* ``moving`` also prints the energy in the wall's frame: the energy to the finger less the
  work the box's motion did through the force applied (each move at the mean of the forces
  held before and after it), the scene's work, which the rendering does not bound
  (docs/runtime.md, Passivity, "A moving wall"), with the cells whose probe went past the
  box's middle (its bottom face the nearest: the one-axis turn, docs/runtime.md,
  Passivity, "A turn on a device that renders one axis") counted
  apart, and the median delivered ratio;
* ``thin``: the same presses into a plate of half-thickness 0.2-1.5 mm (a box 40 mm wide),
  so most go past its middle, where the nearest face turns from the top to the bottom and
  the force along -y (a pop-through: the one-axis reading's turn, docs/runtime.md,
  "Positions carried with the object");
* ``plain``: the same presses without any event (the runs the five kinds above compare
  with), with the median delivered ratio ``sum F / sum min(K pen, F_max)`` over the contact
  ticks (F the force sent, pen the loop's penetration).

``--axes 3`` runs the same loop on ``omni3-virtual`` (the simulated Omni with x, y and z
actuated, ``force_axes = (0, 1, 2)``; its exact ``energy_to_user_j``), KIND one of ``face``,
``edge``, ``corner``, ``ball``, ``two``, ``taps``, ``random`` or ``all``: a 3-D finger path about a
spot of the scene (a box's face, edge or corner drawn at random for ``random`` and ``taps``; a
ball of 8-40 mm; the seam of two abutting boxes), knots within a cube of 0.5-5 mm about the
spot and up to 0.3-3 mm inside, at 5-1500 mm/s (log-uniform) in random directions, holds of
0-0.1 s, ``taps`` in and out through the spot; periods 0.25-4 ms, damping 0-0.5 N s/m
declared or measured, walls of 0.3-50 N/mm, the three fingers. Each kind with the controller
on and, as the control, off: cells over 0.1 mJ, the largest, the median delivered ratio
(docs/runtime.md, Passivity, "A normal that turns"). ``moving --axes 3``: the ``random``
paths with the box moved 0.2-3 mm along a random direction at 1-20 Hz from a time drawn in
the first 70% of the path, each cell run with the box still and moving (the controller
on): the world-frame figure, and the energy in the wall's frame as the one-axis ``moving``
computes it, the move's work through the force vector applied (docs/runtime.md, Passivity,
"A moving wall", "Positions carried with the object").

``--start-ramp-s S`` gives the Omni's safety layer a start ramp of S seconds in every kind
but ``ball`` (default: the layer's own, 0.2 s; docs/safety.md): presses and taps start within it, and a spring pressed under
its envelope is active by itself (docs/runtime.md, "Other events in a press, through the
loop").

Statistic: counts of cells over 0.1 mJ and the largest energy; no clock is involved
(simulated time). Figures: docs/runtime.md, Passivity, "A force rendered along one axis",
"A bound per run, not per object", "A tick without a period or a reading", "Other events
in a press, through the loop" and "A moving wall".
"""

from __future__ import annotations

import argparse
import functools
import logging
import sys
from pathlib import Path

import numpy as np

from hapticsdk.devices.safety import SafetyLayer
from hapticsdk.passivity import ControllerSettings
from hapticsdk.runtime import ServoLoop
from hapticsdk.scene.geometry import Box, HitTester, Pose, Sphere
from hapticsdk.sim.finger import Trajectory, press_slide
from hapticsdk_hardness.omni import OmniVirtual
from hapticsdk_hardness.omni3 import Omni3Virtual

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from renderers import Spring  # noqa: E402


#: the safety layer's start ramp (s) of the devices of ``cell``; None: the layer's default
START_RAMP_S = None


@functools.lru_cache(maxsize=None)
def measured_damping(damping):
    """The arm's damping measured hands off (the simulated Omni with no finger)."""
    from hapticsdk.calibration.damping import DampingCalibration, measure_damping
    from hapticsdk.sim.finger import FingerParams

    free = OmniVirtual(finger=FingerParams(0.0, 0.0, 0.0), damping_ns_per_m=damping)
    fit, _, _ = measure_damping(free)
    return DampingCalibration.from_fit(fit, period_s=1e-3, resolution_mm=free.encoder_resolution_mm,
                                       generated=True, source="bench: simulated Omni, hands off")


def traj(rng, kind):
    d = rng.uniform(0.3, 3.0); n = int(rng.integers(2, 12))
    pts = [(0.0, -10.0, 1.0)]; t = 0.0
    if kind == "slide":   # press on A, slide across to B and back n times at depth d
        v = rng.uniform(20, 300)  # mm/s
        t += rng.uniform(0.02, 0.3); pts.append((t, -10.0, -d))
        x = -10.0
        for i in range(n):
            x = 10.0 if x < 0 else -10.0
            t += 20.0 / v; pts.append((t, x, -d))
            t += rng.uniform(0.0, 0.2); pts.append((t, x, -d))
        t += rng.uniform(0.02, 0.3); pts.append((t, x, 1.0))
    else:   # alternate taps on A and B
        x = -10.0
        for i in range(n):
            tin = rng.uniform(0.005, 0.3); hold = rng.uniform(0.0, 0.3); tout = rng.uniform(0.005, 0.3)
            t += tin; pts.append((t, x, -d)); t += hold; pts.append((t, x, -d))
            t += tout; pts.append((t, x, 1.0))
            x = 10.0 if x < 0 else -10.0
            t += 0.05; pts.append((t, x, 1.0))
    t += 0.1; pts.append((t, pts[-1][1], 1.0))
    return Trajectory(pts)

def run(rng, kind, two):
    T = float(rng.choice([0.5e-3, 1e-3, 2e-3, 4e-3]))
    b = float(rng.choice([0.0, 0.25, 0.5]))
    K = float(np.exp(rng.uniform(np.log(0.3), np.log(50))))
    src = rng.choice(["declared", "measured"])
    tr = traj(rng, kind)
    safety = None if START_RAMP_S is None else SafetyLayer(OmniVirtual.limits, ramp_time_s=START_RAMP_S)
    dev = OmniVirtual(trajectory=tr, finger=str(rng.choice(["soft", "medium", "stiff"])), damping_ns_per_m=b,
                      safety=safety)
    st = ControllerSettings.for_device(dev, damping=measured_damping(b)) if src == "measured" else None
    if two:
        a = Box((10.0, 10.0, 10.0), pose=Pose((-10.0, -10.0, 0.0)))
        bb = Box((10.0, 10.0, 10.0), pose=Pose((10.0, -10.0, 0.0)))
        objs = [("A", [Spring(K)]), ("B", [Spring(K)])]; ht = HitTester([("A", a), ("B", bb)])
    else:
        a = Box((20.0, 10.0, 10.0), pose=Pose((0.0, -10.0, 0.0)))
        objs = [("A", [Spring(K)])]; ht = HitTester([("A", a)])
    loop = ServoLoop(dev, (), {"force": dev}, period_s=T, passivity=True, passivity_settings=st,
                     objects=objs, hit_tester=ht)
    loop.start(tr.duration_s)
    worst = -np.inf
    while True:
        more = loop.tick(); worst = max(worst, dev.energy_to_user_j())
        if not more: break
    loop.finish()
    return worst, dict(T=T, b=b, K=K, src=str(src))


def ball_traj(rng):
    R = rng.uniform(8, 40); d = rng.uniform(0.3, 3.0); X = rng.uniform(0.2, 0.9) * R
    v = rng.uniform(20, 300); n = int(rng.integers(2, 8))
    xs = np.linspace(-X, X, 25)
    pts = [(0.0, -X, 1.0 + np.sqrt(R*R - X*X) - R)]; t = rng.uniform(0.02, 0.3)
    def y(x): return np.sqrt(R*R - x*x) - R - d
    pts.append((t, -X, y(-X)))
    seq = xs
    for i in range(n):
        for x in seq[1:]:
            t += (seq[1]-seq[0]) / v if i % 2 == 0 else (seq[0]-seq[1]) / v
            t = abs(t)
            pts.append((t, x, y(x)))
        seq = seq[::-1]
    t += 0.1; pts.append((t, seq[0], y(seq[0]) + d + 1.0)); pts.append((t + 0.1, seq[0], y(seq[0]) + d + 1.0))
    return Trajectory(pts), R

def run_ball(rng):
    T = float(rng.choice([2.5e-4, 5e-4, 1e-3, 2e-3])); b = float(rng.choice([0.0, 0.25, 0.5]))
    K = float(np.exp(rng.uniform(np.log(0.3), np.log(50)))); fing = str(rng.choice(["soft", "medium", "stiff"]))
    tr, R = ball_traj(rng)
    dev = OmniVirtual(trajectory=tr, finger=fing, damping_ns_per_m=b)
    loop = ServoLoop(dev, (), {"force": dev}, period_s=T, passivity=True, objects=[("ball", [Spring(K)])],
                     hit_tester=HitTester([("ball", Sphere(R, pose=Pose((0.0, -R, 0.0))))]))
    loop.start(tr.duration_s); w = -np.inf
    while True:
        more = loop.tick(); w = max(w, dev.energy_to_user_j())
        if not more: break
    loop.finish()
    return w, dict(T=T, b=b, K=round(K, 3), R=round(R, 1), f=fing)


def run_thin(rng):
    """A press and hold into a plate of half-thickness 0.2-1.5 mm (``thin``)."""
    T = float(rng.choice([2.5e-4, 5e-4, 1e-3, 2e-3])); b = float(rng.choice([0.0, 0.25, 0.5]))
    K = float(np.exp(rng.uniform(np.log(0.3), np.log(50)))); fing = str(rng.choice(["soft", "medium", "stiff"]))
    src = str(rng.choice(["declared", "measured"])); h = rng.uniform(0.2, 1.5); d = rng.uniform(0.3, 3.0)
    tr = press_slide(depth_mm=d, press_s=rng.uniform(0.05, 0.4), hold_s=rng.uniform(0.2, 0.6), slide_s=0.0,
                     release_s=rng.uniform(0.05, 0.4), rest_s=0.1)
    dev = OmniVirtual(trajectory=tr, finger=fing, damping_ns_per_m=b)
    st = ControllerSettings.for_device(dev, damping=measured_damping(b)) if src == "measured" else None
    plate = Box((20.0, h, 20.0), pose=Pose((0.0, -h, 0.0)))
    loop = ServoLoop(dev, (), {"force": dev}, period_s=T, passivity=True, passivity_settings=st,
                     objects=[("plate", [Spring(K)])], hit_tester=HitTester([("plate", plate)]))
    loop.start(tr.duration_s); w = -np.inf
    while True:
        more = loop.tick(); w = max(w, dev.energy_to_user_j())
        if not more: break
    loop.finish()
    return w, dict(T=T, b=b, K=round(K, 3), h=round(h, 2), d=round(d, 2), f=fing, src=src)


def cell(rng, kind, perturb):
    T = float(rng.choice([2.5e-4, 5e-4, 1e-3, 2e-3])); b = float(rng.choice([0.0, 0.25, 0.5]))
    K = float(np.exp(rng.uniform(np.log(0.3), np.log(50)))); fing = str(rng.choice(["soft", "medium", "stiff"]))
    src = str(rng.choice(["declared", "measured"]))
    d = rng.uniform(0.5, 3.0); ps = rng.uniform(0.05, 0.4); hs = rng.uniform(0.2, 0.6); rs = rng.uniform(0.05, 0.4)
    tr = press_slide(depth_mm=d, press_s=ps, hold_s=hs, slide_s=0.0, release_s=rs, rest_s=0.1)
    t_ev = ps + rng.uniform(-0.3, 1.0) * hs          # the event: during the press or the hold
    K2 = K * float(np.exp(rng.uniform(np.log(1.5), np.log(20))))
    dticks = int(rng.integers(1, 4)); nbad = int(rng.integers(1, 20)); amp = rng.uniform(0.2, 3.0); fhz = rng.uniform(1, 20)
    safety = None if START_RAMP_S is None else SafetyLayer(OmniVirtual.limits, ramp_time_s=START_RAMP_S)
    dev = OmniVirtual(trajectory=tr, finger=fing, damping_ns_per_m=b, safety=safety)
    st = ControllerSettings.for_device(dev, damping=measured_damping(b)) if src == "measured" else None
    kw = {}
    if kind == "delay" and perturb: kw["delay_ticks"] = dticks
    if kind == "moving":
        box = Box((20.0, 10.0, 10.0), pose=Pose((0.0, -10.0, 0.0)))
        kw.update(objects=[("A", [Spring(K)])], hit_tester=HitTester([("A", box)]))
        loop = ServoLoop(dev, (), {"force": dev}, period_s=T, passivity=True, passivity_settings=st, **kw)
    else:
        loop = ServoLoop(dev, [Spring(K)], {"force": dev}, period_s=T, passivity=True, passivity_settings=st, **kw)
    if kind == "nan" and perturb:
        real = dev._read_state
        def rs_(t0=[None]):
            s = real()
            if t_ev <= dev.t < t_ev + nbad * T:
                from hapticsdk.devices.actuators import SensedState
                return SensedState.of(s.t, s.px, float("nan"), s.pz, s.vx, s.vy, s.vz, 0.0, 0.0, 0.0)
            return s
        dev._read_state = rs_
    loop.start(tr.duration_s); w = own = -np.inf; switched = paused = False
    sent = asked = 0.0; fmax = dev.limits.max_force_n
    scene = None
    through = False   # the probe went past the box's middle (its bottom face the nearest)
    wall = -10.0; jump = 0.0; f_prev = 0.0
    if kind == "moving":
        # the work the wall's own motion does through the force applied (J): the scene's,
        # not the rendering's (docs/runtime.md, Passivity, "A moving wall")
        scene = 0.0
    while True:
        t = loop.ticks * T
        if perturb and not switched and t >= t_ev:
            switched = True
            if kind == "switch": loop.set_renderers(0, [Spring(K2)])
            if kind == "pause": loop.paused = True; paused = True
        if kind == "pause" and paused and t >= t_ev + nbad * T: loop.paused = False; paused = False
        if kind == "moving" and perturb and t >= t_ev:
            y_new = -10.0 + amp * np.sin(2 * np.pi * fhz * (t - t_ev))
            jump = (y_new - wall) * 1e-3; wall = y_new   # the box's top moves along y, the force's axis
            loop.set_pose(0, Pose((0.0, y_new, 0.0)))
        more = loop.tick(); e = dev.energy_to_user_j(); w = max(w, e)
        if scene is not None:
            # the move's work at the mean of the forces held before and after it (exact for
            # a wall that is a spring of the depth, and for a held force)
            n = loop._held_n   # the direction of the force sent (None: +y)
            f_now = loop.last_force_n * (1.0 if n is None else n[1])   # along y, the wall's motion
            scene += 0.5 * (f_prev + f_now) * jump
            f_prev = f_now; jump = 0.0
            own = max(own, e - scene)
            through = through or (n is not None and n[1] < 0.0)
        if loop.last_penetration_mm > 0.0:
            sent += loop.last_force_n; asked += min(K * loop.last_penetration_mm, fmax)
        if not more: break
    loop.finish()
    return w, dict(T=T, b=b, K=round(K, 2), K2=round(K2, 2), src=src, f=fing,
                   delivered=sent / asked if asked > 0.0 else float("nan"), own=own, through=through)


# ---- three axes (--axes 3): the simulated Omni with x, y and z actuated ----------------
KINDS3 = ("face", "edge", "corner", "ball", "two", "taps", "random")


def _box_spot(rng, where, h=10.0):
    """A point on the surface of the box of half size ``h`` whose top face is y = 0 (centre
    (0, -h, 0)) and the unit vector into the box there: on a face, an edge or a corner."""
    s = rng.choice([-1.0, 1.0], 3)
    if where == "face":
        a = int(rng.integers(3)); p = rng.uniform(-0.6 * h, 0.6 * h, 3); p[a] = s[a] * h
        n = np.zeros(3); n[a] = -s[a]
    elif where == "edge":
        a = int(rng.integers(3)); p = s * h; p[a] = rng.uniform(-0.6 * h, 0.6 * h)
        n = -s.copy(); n[a] = 0.0
    else:
        p = s * h; n = -s.copy()
    p = p + np.array([0.0, -h, 0.0])
    return p, n / np.linalg.norm(n)


def traj3(rng, kind):
    """A 3-D finger path about a spot of the scene: knots drawn at random within a cube of
    0.5-5 mm about the spot, up to 0.3-3 mm inside along the inward normal, at 5-1500 mm/s
    (log-uniform) in random directions with holds of 0-0.1 s; ``taps`` goes in and out
    through the spot. Starts and ends 2 mm outside. Returns the trajectory and the scene
    (objects for the hit tester)."""
    if kind == "ball":
        R = rng.uniform(8, 40); u = rng.normal(size=3); u /= np.linalg.norm(u)
        c = np.array([0.0, -R, 0.0]); p, n = c + R * u, -u
        scene = [("ball", Sphere(R, pose=Pose(tuple(c))))]
    elif kind == "two":
        # on the seam of two abutting boxes: its top edge line, or where it meets a side edge
        z = rng.choice([rng.uniform(-6, 6), 10.0 * rng.choice([-1.0, 1.0])])
        p = np.array([0.0, 0.0, z]); n = np.array([0.0, -1.0, -np.sign(z) if abs(z) == 10.0 else 0.0])
        n /= np.linalg.norm(n)
        scene = [("A", Box((10.0, 10.0, 10.0), pose=Pose((-10.0, -10.0, 0.0)))),
                 ("B", Box((10.0, 10.0, 10.0), pose=Pose((10.0, -10.0, 0.0))))]
    else:
        where = str(rng.choice(["face", "edge", "corner"])) if kind in ("random", "taps") else kind
        p, n = _box_spot(rng, where)
        scene = [("A", Box((10.0, 10.0, 10.0), pose=Pose((0.0, -10.0, 0.0))))]
    spread = rng.uniform(0.5, 5.0); d = rng.uniform(0.3, 3.0); m = int(rng.integers(3, 15))
    out = p - 2.0 * n
    pts = [(0.0, *out)]; t = rng.uniform(0.02, 0.3); q = out
    for i in range(m):
        if kind == "taps":
            nxt = [p + rng.uniform(-spread, spread, 3) * 0.3 + n * d * rng.uniform(0.2, 1.0), out]
        else:
            nxt = [p + rng.uniform(-spread, spread, 3) + n * d * rng.uniform(-0.5, 1.0)]
        for r in nxt:
            v = float(np.exp(rng.uniform(np.log(5.0), np.log(1500.0))))
            t += max(float(np.linalg.norm(r - q)) / v, 1e-4); pts.append((t, *r)); q = r
            if rng.uniform() < 0.3:
                t += rng.uniform(0.0, 0.1); pts.append((t, *r))
    v = float(np.exp(rng.uniform(np.log(5.0), np.log(1500.0))))
    t += max(float(np.linalg.norm(out - q)) / v, 1e-4); pts.append((t, *out))
    t += 0.1; pts.append((t, *out))
    return Trajectory([(k[0], k[1], k[2], k[3]) for k in pts]), scene


def run3(rng, kind, passivity=True, perturb=True):
    """One cell of ``--axes 3``: the energy to the finger (J, largest over the run), the
    cell's draws and the delivered ratio (``moving``: also the energy in the wall's frame,
    ``own``; ``perturb`` False: the same cell with the box still)."""
    T = float(rng.choice([2.5e-4, 5e-4, 1e-3, 2e-3, 4e-3])); b = float(rng.choice([0.0, 0.25, 0.5]))
    K = float(np.exp(rng.uniform(np.log(0.3), np.log(50)))); fing = str(rng.choice(["soft", "medium", "stiff"]))
    src = str(rng.choice(["declared", "measured"]))
    tr, scene = traj3(rng, "random" if kind == "moving" else kind)
    mv = None
    if kind == "moving":
        # the box moves amp mm along a random direction u at fhz from t_ev on
        u = rng.normal(size=3); u /= np.linalg.norm(u)
        mv = (rng.uniform(0.2, 3.0), rng.uniform(1, 20), u, rng.uniform(0.0, 0.7) * tr.duration_s)
    safety = None if START_RAMP_S is None else SafetyLayer(Omni3Virtual.limits, ramp_time_s=START_RAMP_S)
    dev = Omni3Virtual(trajectory=tr, finger=fing, damping_ns_per_m=b, safety=safety)
    st = ControllerSettings.for_device(dev, damping=measured_damping(b)) if src == "measured" and passivity else None
    loop = ServoLoop(dev, (), {"force": dev}, period_s=T, passivity=passivity, passivity_settings=st,
                     objects=[(name, [Spring(K)]) for name, _ in scene], hit_tester=HitTester(scene))
    loop.start(tr.duration_s); w = own = -np.inf
    sent = asked = 0.0; fmax = dev.limits.max_force_n
    c0 = np.array(scene[0][1].pose.position_mm); at = c0; jump = np.zeros(3); f_prev = np.zeros(3); work = 0.0
    while True:
        if mv is not None and perturb and loop.ticks * T >= mv[3]:
            amp, fhz, u, t_ev = mv
            c = c0 + u * amp * np.sin(2 * np.pi * fhz * (loop.ticks * T - t_ev))
            jump = (c - at) * 1e-3; at = c
            loop.set_pose(0, Pose(tuple(c)))
        more = loop.tick(); e = dev.energy_to_user_j(); w = max(w, e)
        if mv is not None:
            # the move's work through the force applied, at the mean of the forces held
            # before and after it (the scene's, as the one-axis ``moving``)
            n = loop._held_n
            f_now = loop.last_force_n * np.array((0.0, 1.0, 0.0) if n is None else n)
            work += 0.5 * float(np.dot(f_prev + f_now, jump))
            f_prev = f_now; jump = np.zeros(3)
            own = max(own, e - work)
        if loop.last_penetration_mm > 0.0:
            sent += loop.last_force_n; asked += min(K * loop.last_penetration_mm, fmax)
        if not more: break
    loop.finish()
    r = dict(T=T, b=b, K=round(K, 3), src=src, f=fing, delivered=sent / asked if asked > 0.0 else float("nan"))
    if mv is not None:
        r["own"] = own
    return w, r


def main3(kind, cells, seed):
    """``--axes 3``: every kind of KINDS3 (or the one asked), with the controller on and,
    as the control, off."""
    if kind == "moving":
        runs = {}
        for perturb in (False, True):
            rng = np.random.default_rng(seed)
            runs[perturb] = [run3(rng, kind, True, perturb) for _ in range(cells)]
        e0 = np.array([r[0] for r in runs[False]]); e1 = np.array([r[0] for r in runs[True]])
        o1 = np.array([r[1]["own"] for r in runs[True]])
        worst = runs[True][int(np.argmax(o1))][1]
        print(f"3 axes, moving: world frame over 0.1 mJ {int(np.sum(e1 > 1e-4))}/{cells} (still box "
              f"{int(np.sum(e0 > 1e-4))}, largest {e0.max() * 1e3:.3f} mJ); in the wall's frame over 0.1 mJ "
              f"{int(np.sum(o1 > 1e-4))}, of those with the still box under it {int(np.sum((o1 > 1e-4) & (e0 <= 1e-4)))} "
              f"(largest {o1.max() * 1e3:.3f} mJ, cell {int(np.argmax(o1))}: {worst}); median delivered with the "
              f"move {np.nanmedian([r[1]['delivered'] for r in runs[True]]):.4f}", flush=True)
        return
    for k in (KINDS3 if kind == "all" else (kind,)):
        for on in (True, False):
            rng = np.random.default_rng(seed)
            rs = [run3(rng, k, on) for _ in range(cells)]
            es = np.array([r[0] for r in rs])
            worst = rs[int(np.argmax(es))][1]
            print(f"3 axes, {k}, controller {'on' if on else 'off'}: over 0.1 mJ {int(np.sum(es > 1e-4))}/{cells}, "
                  f"largest {es.max() * 1e3:.3f} mJ ({worst}), "
                  f"median delivered {np.nanmedian([r[1]['delivered'] for r in rs]):.4f}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("kind", choices=["slide", "taps", "ball", "nan", "switch", "pause", "delay", "moving", "plain", "thin",
                                     *KINDS3[:3], "two", "random", "all"])
    ap.add_argument("--cells", type=int, default=150)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--axes", type=int, choices=[1, 3], default=1,
                    help="1: the simulated Omni's y axis (omni-virtual); 3: x, y and z (omni3-virtual)")
    ap.add_argument("--start-ramp-s", type=float, default=None,
                    help="the safety layer's start ramp (s), all kinds but ball (default: the layer's own)")
    a = ap.parse_args()
    # the controller's spent-bound warning is for a live loop's user (once per controller);
    # here it would print once per cell among the results
    logging.getLogger("hapticsdk.passivity.controller").setLevel(logging.ERROR)
    global START_RAMP_S
    START_RAMP_S = a.start_ramp_s
    if a.axes == 3:
        main3(a.kind, a.cells, a.seed)
        return
    if a.kind in ("slide", "taps"):
        for two in (False, True):
            rng = np.random.default_rng(a.seed)
            es = np.array([run(rng, a.kind, two)[0] for _ in range(a.cells)])
            print(f"{a.kind}, {'two objects' if two else 'one object'}: over 0.1 mJ {int(np.sum(es > 1e-4))}/{a.cells}, "
                  f"largest {es.max() * 1e3:.3f} mJ")
    elif a.kind == "ball":
        rng = np.random.default_rng(a.seed)
        es = np.array([run_ball(rng)[0] for _ in range(a.cells)])
        print(f"ball: over 0.1 mJ {int(np.sum(es > 1e-4))}/{a.cells}, largest {es.max() * 1e3:.3f} mJ")
    elif a.kind == "thin":
        rng = np.random.default_rng(a.seed)
        rs = [run_thin(rng) for _ in range(a.cells)]
        es = np.array([r[0] for r in rs])
        past = np.array([r[1]["d"] > r[1]["h"] for r in rs])
        print(f"thin plates: over 0.1 mJ {int(np.sum(es > 1e-4))}/{a.cells} ({int(np.sum((es > 1e-4) & past))} "
              f"of the {int(past.sum())} pressed past the middle), largest {es.max() * 1e3:.3f} mJ")
    elif a.kind == "plain":
        rng = np.random.default_rng(a.seed)
        rs = [cell(rng, "switch", False) for _ in range(a.cells)]
        es = np.array([r[0] for r in rs])
        print(f"plain presses: over 0.1 mJ {int(np.sum(es > 1e-4))}/{a.cells}, largest {es.max() * 1e3:.3f} mJ, "
              f"median delivered {np.nanmedian([r[1]['delivered'] for r in rs]):.4f}")
    else:
        runs = {}
        for perturb in (False, True):
            rng = np.random.default_rng(a.seed)
            runs[perturb] = [cell(rng, a.kind, perturb) for _ in range(a.cells)]
        e0 = np.array([r[0] for r in runs[False]]); e1 = np.array([r[0] for r in runs[True]])
        only = (e1 > 1e-4) & (e0 <= 1e-4)
        print(f"{a.kind}: over 0.1 mJ with the event only {int(only.sum())}/{a.cells} "
              f"(largest {e1[e0 <= 1e-4].max() * 1e3:.3f} mJ); without the event {int(np.sum(e0 > 1e-4))}, "
              f"with it {int(np.sum(e1 > 1e-4))} (largest {e1.max() * 1e3:.3f} mJ)")
        if a.kind == "moving":
            # the rendering's own energy: the world-frame figure less the ideal moving
            # wall's kinematic work along the same stylus motion (the scene's)
            o1 = np.array([r[1]["own"] for r in runs[True]])
            th = np.array([r[1]["through"] for r in runs[True]])
            only = (o1 > 1e-4) & (e0 <= 1e-4)
            print(f"moving, in the wall's frame (world less the wall's motion's work through the force): over 0.1 mJ "
                  f"{int(np.sum(o1 > 1e-4))}/{a.cells} (of those the probe past the box's middle "
                  f"{int(np.sum((o1 > 1e-4) & th))}; on the top face only, largest "
                  f"{o1[~th].max() * 1e3:.3f} mJ), of those without the event under it {int(only.sum())} "
                  f"(largest {o1.max() * 1e3:.3f} mJ); median delivered with the event "
                  f"{np.nanmedian([r[1]['delivered'] for r in runs[True]]):.4f}")


if __name__ == "__main__":
    main()
