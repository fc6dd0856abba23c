"""Instructions and simulated cache misses per servo tick, counted by valgrind's
cachegrind: figures that do not move with the machine's load, optionally side by side
with a git ref.

    OMP_NUM_THREADS=1 python bench/bench_tick_instructions.py [--ticks 4000] [--baseline REF] [--json]
                                                              [--scene timing|ball3|face3]

What it measures: the scene of ``hapticsdk bench timing`` (hardness + roughness on the
simulated Omni, voice coil and piezo; 1 ms period, simulated clock). A child of this
interpreter runs 500 warm-up ticks (the interpreter specialises its byte code), then
``--ticks`` ticks, under ``valgrind --tool=cachegrind`` (``PYTHONHASHSEED=0``: the count
is the same on every run); a second child runs the warm-up alone; the difference over
``--ticks`` is the count per tick. Four rows per tree:

* ``tick + simulation``: the loop as the timing benchmark runs it, each tick followed by
  the simulated devices' steps (``device.step``, the voice coil's and piezo's synthesis);
* ``tick alone``: the simulation frozen after the warm-up (at 0.5 s the probe slides in
  contact, so every renderer and actuator is active; the state no longer changes);
* both again with the passivity controller off (``passivity=False``): what the rest of
  the tick costs.

Columns: instructions (``I refs``), level-1 instruction-cache misses and level-1 data
misses of cachegrind's simulated caches (its model of this CPU's caches, not the CPU's
counters, which this virtual machine does not expose). Misses matter: the tick's CPU
time in ``bench timing`` is about twice its time when run hot, because the simulation
(numpy code) evicts the interpreter's code and data from the caches between ticks.

``--scene ball3`` and ``--scene face3``: a stylus on ``omni3-virtual`` (x, y and z
actuated, so the loop re-reads the controller's history where the contact normal turns:
``hapticsdk/runtime/turns.py``) pressed 1 mm into a plain spring wall of 0.5 N/mm and
sliding back and forth along x over +-5 mm at 20 mm/s, 1 ms period, the medium finger, 0.5
N s/m of damping declared: over the top of a ball of 20 mm radius (the normal turns on
every tick that the reading moves) or along the top face of a box (the normal never
turns). The frozen rows do not apply there (a frozen stylus reads the same position every
tick, so the normal never turns): two rows, ``tick + simulation`` with the controller on
and off.

What it does not measure: time; the real CPU's caches, branch predictor or frequency;
the import and start-up of a process. With ``--baseline REF`` the files of ``REF`` are
exported (:mod:`hapticsdk.benchmarks.baseline`) and counted the same way; plugins and
numpy are the environment's for both (their entry points name this environment's
plugins; the export's ``plugins/*/src`` come first on the path, as in ``bench timing``).
Needs valgrind (Debian package ``valgrind``).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

CHILD = r'''
import gc, os, sys
from hapticsdk.benchmarks.timing import build_scene
from hapticsdk.runtime import ServoLoop
ticks, frozen, passivity = int(sys.argv[1]), sys.argv[2] == "1", sys.argv[3] == "1"
dev, renderers, acts = build_scene(10.0)
loop = ServoLoop(dev, renderers, acts, period_s=0.001, passivity=passivity)
loop.start(9.0)
gc.disable()
for _ in range(500):
    loop.tick()
if frozen:
    loop._sim_device = False
    loop._stepped = []
for _ in range(ticks):
    loop.tick()
# end here: no exit handlers (a frozen piezo would synthesise its pending commands when
# stopped at exit, which is not the tick), the same for both counts
os._exit(0)
'''

#: the 3-axis scenes (``--scene ball3|face3``); argv: ticks, scene, passivity
CHILD3 = r'''
import gc, math, os, sys
from pathlib import Path
import hapticsdk
sys.path.insert(0, str(Path(hapticsdk.__file__).resolve().parents[1] / "tests"))
from renderers import Spring
from hapticsdk.runtime import ServoLoop
from hapticsdk.scene.geometry import Box, HitTester, Pose, Sphere
from hapticsdk.sim.finger import Trajectory
from hapticsdk_hardness.omni3 import Omni3Virtual
ticks, scene, passivity = int(sys.argv[1]), sys.argv[2], sys.argv[3] == "1"
R, depth, half, speed = 20.0, 1.0, 5.0, 20.0
if scene == "ball3":
    shape = Sphere(R, pose=Pose((0.0, -R, 0.0)))
    top = lambda x: math.sqrt(R * R - x * x) - R
else:
    shape = Box((R, R, R), pose=Pose((0.0, -R, 0.0)))
    top = lambda x: 0.0
xs = [-half + 0.25 * i for i in range(int(4 * half) * 2 + 1)]
knots = [(0.0, -half, 1.0, 0.0), (0.2, -half, top(-half) - depth, 0.0)]
t = 0.2
for leg in range(12):
    for x in (xs[1:] if leg % 2 == 0 else xs[-2::-1]):
        t += 0.25 / speed
        knots.append((t, x, top(x) - depth, 0.0))
dev = Omni3Virtual(trajectory=Trajectory(knots), finger="medium", damping_ns_per_m=0.5)
loop = ServoLoop(dev, (), {"force": dev}, period_s=0.001, passivity=passivity, objects=[("o", [Spring(0.5)])],
                 hit_tester=HitTester([("o", shape)]))
loop.start(t)
gc.disable()
for _ in range(500):
    loop.tick()
for _ in range(ticks):
    loop.tick()
os._exit(0)
'''

ROWS = (("tick + simulation", False, True), ("tick alone", True, True),
        ("tick + simulation, passivity off", False, False), ("tick alone, passivity off", True, False))
_COUNT = re.compile(r"==\d+==\s+(I\s+refs|I1\s+misses|D1\s+misses):\s+([\d,]+)")


ROWS3 = (("tick + simulation", False, True), ("tick + simulation, passivity off", False, False))
SCENES = ("timing", "ball3", "face3")


def count(tree: Path | None, ticks: int, frozen: bool, passivity: bool, scene: str = "timing") -> dict[str, int]:
    """cachegrind's totals of one child (``ticks`` after the warm-up)."""
    from hapticsdk.benchmarks.baseline import PRELUDE, _child_env
    env = _child_env(tree)
    env["PYTHONHASHSEED"] = "0"
    if tree is not None:
        env["HAPTICSDK_BASELINE_TREE"] = str(tree)
    else:
        env.pop("HAPTICSDK_BASELINE_TREE", None)
    cmd = ["valgrind", "--tool=cachegrind", "--cache-sim=yes", "--cachegrind-out-file=/dev/null",
           sys.executable, "-c", PRELUDE + (CHILD if scene == "timing" else CHILD3), str(ticks),
           ("1" if frozen else "0") if scene == "timing" else scene, "1" if passivity else "0"]
    out = subprocess.run(cmd, env=env, cwd=tree, capture_output=True, text=True, timeout=1800)
    if out.returncode != 0:
        raise RuntimeError(f"child failed: {out.stderr.strip().splitlines()[-1:]}")
    got = {re.sub(r"\s+", " ", k): int(v.replace(",", "")) for k, v in _COUNT.findall(out.stderr)}
    return {"instructions": got["I refs"], "i1_misses": got["I1 misses"], "d1_misses": got["D1 misses"]}


def per_tick(tree: Path | None, ticks: int, scene: str = "timing") -> dict[str, dict[str, float]]:
    out = {}
    for name, frozen, passivity in (ROWS if scene == "timing" else ROWS3):
        a = count(tree, 0, frozen, passivity, scene)
        b = count(tree, ticks, frozen, passivity, scene)
        out[name] = {k: (b[k] - a[k]) / ticks for k in a}
    return out


def main(argv: list[str]) -> int:
    ticks = int(argv[argv.index("--ticks") + 1]) if "--ticks" in argv else 4000
    ref = argv[argv.index("--baseline") + 1] if "--baseline" in argv else None
    scene = argv[argv.index("--scene") + 1] if "--scene" in argv else "timing"
    if scene not in SCENES:
        print(f"--scene: one of {', '.join(SCENES)}", file=sys.stderr)
        return 2
    if shutil.which("valgrind") is None:
        print("valgrind not found: install the Debian package valgrind", file=sys.stderr)
        return 2
    results: dict[str, dict] = {}
    import hapticsdk
    if ref is not None:
        from hapticsdk.benchmarks.baseline import exported_tree, repository_of, resolve
        repo = repository_of(Path(hapticsdk.__file__).parent)
        commit = resolve(repo, ref)
        with exported_tree(repo, commit) as tree:
            results[f"baseline {ref} ({commit[:10]})"] = per_tick(tree, ticks, scene)
    results["this code"] = per_tick(None, ticks, scene)
    if "--json" in argv:
        print(json.dumps({"ticks": ticks, "scene": scene, "per_tick": results}, indent=1))
        return 0
    print(f"per servo tick, cachegrind (valgrind {subprocess.run(['valgrind', '--version'], capture_output=True, text=True).stdout.strip()}), "
          f"{ticks} ticks after 500 warm-up ticks, PYTHONHASHSEED=0, Python {sys.version.split()[0]}; "
          f"simulated level-1 caches, not the CPU's counters; scene {scene}")
    print(f"{'':34s} {'':40s} {'instructions':>13s} {'I1 misses':>10s} {'D1 misses':>10s}")
    names = list(results)
    for row, _, _ in (ROWS if scene == "timing" else ROWS3):
        for n in names:
            d = results[n][row]
            print(f"{row:34s} {n:40s} {d['instructions']:13.0f} {d['i1_misses']:10.0f} {d['d1_misses']:10.0f}")
        if len(names) == 2:
            b, t = results[names[0]][row], results[names[1]][row]
            print(f"{'':34s} {'this code / baseline':40s} {t['instructions'] / b['instructions']:13.3f} "
                  f"{t['i1_misses'] / b['i1_misses']:10.3f} {t['d1_misses'] / b['d1_misses']:10.3f}")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    raise SystemExit(main(sys.argv[1:]))
