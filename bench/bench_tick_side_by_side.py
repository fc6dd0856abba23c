"""Servo tick of two source trees, interleaved: same machine, same minutes.

usage: python bench/bench_tick_side_by_side.py OLD_TREE NEW_TREE ROUNDS SECONDS

e.g. the last round's code next to this one:
    git archive 73fd5b9 | tar -x -C /tmp/old     # the tree to compare with
    OMP_NUM_THREADS=1 python bench/bench_tick_side_by_side.py /tmp/old . 6 10

Each round runs, in a fresh subprocess per tree (alternating order), the timing scene of
hapticsdk.benchmarks.timing for SECONDS of simulated time and prints the tick's CPU
median and p99 (thread_time_ns, per tick), plus the CPU time of an empty call measured
in the same process with the same clock (the bare reference). The trees are imported
from PYTHONPATH (the editable install's finder is taken out of the child's import
system), every plugin from the tree's own ``plugins/*/src``; each child checks it ran the
tree it was given. On a shared machine the robust figure is the ratio new/old per round
(both runs of a round see about the same load).
"""
import json
import os
import statistics
import subprocess
import sys

CHILD = r'''
import sys
# the editable install's finder would import the worktree of the venv: the tree on
# PYTHONPATH wins
sys.meta_path[:] = [f for f in sys.meta_path if not getattr(f, "__module__", "").startswith("__editable__")
                    and not getattr(type(f), "__module__", "").startswith("__editable__")]
import json, time, hapticsdk, hapticsdk_hardness
from hapticsdk.benchmarks.timing import build_scene
from hapticsdk.runtime import ServoLoop
sec = float(__import__("sys").argv[1])
dev, rs, acts = build_scene(sec)
rep = ServoLoop(dev, rs, acts, period_s=0.001).run(sec)
def f(): pass
tt = time.thread_time_ns
ref = []
for _ in range(2000):
    q0 = tt(); f(); ref.append(tt() - q0)
ref.sort()
print(json.dumps({"file": hapticsdk.__file__, "pfile": hapticsdk_hardness.__file__, "med": rep.tick_cpu_median_us, "p99": rep.tick_cpu_p99_us,
                  "ref_med_us": ref[len(ref)//2] / 1e3}))
'''
def run(tree, sec):
    env = dict(os.environ)
    plug = [os.path.join(tree, "plugins", p, "src") for p in sorted(os.listdir(os.path.join(tree, "plugins")))]
    env["PYTHONPATH"] = os.pathsep.join([tree, *plug])
    out = subprocess.run([sys.executable, "-c", CHILD, str(sec)], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])
old, new = (os.path.abspath(p) for p in sys.argv[1:3])
rounds, sec = int(sys.argv[3]), float(sys.argv[4])
res = {"old": [], "new": []}
for r in range(rounds):
    order = [("old", old), ("new", new)] if r % 2 == 0 else [("new", new), ("old", old)]
    for name, tree in order:
        d = run(tree, sec)
        assert d["file"].startswith(tree) and d["pfile"].startswith(tree), d
        res[name].append(d)
        print(r, name, json.dumps(d), flush=True)
ratios_med = [n["med"] / o["med"] for o, n in zip(res["old"], res["new"])]
ratios_p99 = [n["p99"] / o["p99"] for o, n in zip(res["old"], res["new"])]
for name in ("old", "new"):
    m = statistics.median(d["med"] for d in res[name]); p = statistics.median(d["p99"] for d in res[name])
    ref = statistics.median(d["ref_med_us"] for d in res[name])
    print(f"{name}: tick CPU median {m:.2f} us, p99 {p:.2f} us (median over {rounds} runs); empty call {ref:.3f} us; "
          f"median/empty call {m / ref:.0f}")
print(f"new/old median ratio: {statistics.median(ratios_med):.3f} (per round {[round(x, 3) for x in ratios_med]})")
print(f"new/old p99 ratio: {statistics.median(ratios_p99):.3f} (per round {[round(x, 3) for x in ratios_p99]})")
