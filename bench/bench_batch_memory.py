"""usage: python bench/bench_batch_memory.py [N]

RSS per chunk of a default-method batch solve of 10^6 targets (hardness, roughness):
prints, after each chunk of DEFAULT_CHUNK_SIZE targets, the targets done, VmRSS and
VmHWM (MB) and the elapsed time. Stopped from outside after a few minutes; the slope
per chunk extrapolates to the whole batch."""
import sys, time
import numpy as np
import hapticsdk as hs
from hapticsdk.solvers import base as solvers_base

def rss():
    d = {}
    for line in open("/proc/self/status"):
        if line.startswith(("VmRSS", "VmHWM")):
            k, v = line.split(":")
            d[k] = int(v.split()[0]) / 1024
    return d

n = int(sys.argv[1]) if len(sys.argv) > 1 else 10**6
rng = np.random.default_rng(0)
T = rng.uniform(0.05, 0.95, size=(n, 2))
orig = solvers_base._BatchData.add
done = [0]
t0 = time.perf_counter()
def add(self, sub, x, *a, **k):
    orig(self, sub, x, *a, **k)
    done[0] += len(x)
    r = rss()
    print(f"{done[0]:8d} targets  RSS {r['VmRSS']:7.1f} MB  HWM {r['VmHWM']:7.1f} MB  {time.perf_counter() - t0:7.1f} s",
          flush=True)
solvers_base._BatchData.add = add
print("before solve", rss(), "targets array MB", T.nbytes / 2**20, flush=True)
res = hs.solve(T, dimensions=["hardness", "roughness"], seed=1)
print("done", rss(), flush=True)
