"""A press and hold on a box that moves along y through ``ServoLoop`` on the simulated
Omni, with the energy in the wall's frame as ``bench/bench_servo_paths.py moving`` computes
it; shared by the runtime tests of a moving wall and of a turn on one axis.

Importable as ``moving_slabs`` through ``tests/conftest.py``."""

from __future__ import annotations

import math

from hapticsdk.passivity import ControllerSettings
from hapticsdk.runtime import ServoLoop
from hapticsdk.scene.geometry import Box, HitTester, Pose
from hapticsdk.sim.finger import press_slide
from omni_fits import measured
from renderers import Spring


def moving_slab(k: float, period_s: float, damping: float | None, finger: str, depth: float,
                half_mm: tuple[float, float, float], amp_mm: float, hz: float, t_move: float, press_s: float = 0.1,
                hold_s: float = 0.3, release_s: float = 0.1) -> tuple[float, float, bool]:
    """``(world, wall frame, turned)``: the largest energy the arm gave the finger (J) over
    a press and hold on a box of half sizes ``half_mm`` (its top at y = 0) that, from
    ``t_move`` (s), moves ``amp_mm`` up and down along y at ``hz`` (damping ``damping`` N
    s/m, measured hands off; None: 0, and nothing credited); the largest of it less the
    work of the box's motion through the force applied, each move at the mean of the force
    vectors held before and after it (the scene's); and whether the force turned to -y
    (the probe past the box's middle)."""
    from hapticsdk_hardness.omni import OmniVirtual

    tr = press_slide(depth_mm=depth, press_s=press_s, hold_s=hold_s, slide_s=0.0, release_s=release_s, rest_s=0.1)
    dev = OmniVirtual(trajectory=tr, finger=finger, damping_ns_per_m=damping or 0.0)
    h = half_mm[1]
    box = Box(half_mm, pose=Pose((0.0, -h, 0.0)))
    st = ControllerSettings.for_device(dev, damping=measured(damping)) if damping is not None else None
    loop = ServoLoop(dev, (), {"force": dev}, period_s=period_s, passivity=True, objects=[("A", [Spring(k)])],
                     hit_tester=HitTester([("A", box)]), passivity_settings=st)
    loop.start(tr.duration_s)
    world = frame = -math.inf
    scene = 0.0          # the work of the box's motion through the force (J)
    wall = -h
    f_prev = 0.0
    turned = False
    while True:
        t = loop.ticks * period_s
        jump = 0.0
        if t >= t_move:
            y = -h + amp_mm * math.sin(2.0 * math.pi * hz * (t - t_move))
            jump, wall = (y - wall) * 1e-3, y
            loop.set_pose(0, Pose((0.0, y, 0.0)))
        more = loop.tick()
        n = loop._held_n
        f_now = loop.last_force_n * (1.0 if n is None else n[1])   # along y, the box's motion
        scene += 0.5 * (f_prev + f_now) * jump
        f_prev = f_now
        turned = turned or (n is not None and n[1] < 0.0)
        e = dev.energy_to_user_j()
        world = max(world, e)
        frame = max(frame, e - scene)
        if not more:
            break
    loop.finish()
    return world, frame, turned
