"""End to end ``hapticsdk render S7`` (3 s simulated, defaults): CPU and wall time of the
whole process, optionally side by side with a git ref.

    python bench/bench_render_s7.py [--runs 8] [--baseline REF]

Each run is a fresh ``python -m hapticsdk render S7`` of this interpreter; its CPU time is
the child's user + sys (``os.wait4`` rusage), its wall time ``time.perf_counter`` around
it. Byte-code caches are written and used (one warm-up run per tree first, not counted;
``PYTHONDONTWRITEBYTECODE`` is removed from the children's environment), as for an
installed package; the warm-up also fills the SDK's cache folder where the tree has one
(validation markers, the model's description and chain, the entry-point index), as any
run after the first does. With ``--baseline REF`` the files of ``REF`` are exported
(:mod:`hapticsdk.benchmarks.baseline`) and the runs alternate baseline / this code, so
both see the same load; the report gives min and median of each and the ratio of the
medians (and of the minima). Also printed: an empty ``python -c pass`` of the same
interpreter (the bare reference: interpreter start-up alone), measured the same way in the
same run. The children get this process's environment as it is: each tree sizes its
BLAS / OpenMP thread pools as it would on a user's machine (run it with
``OMP_NUM_THREADS=1`` to compare one-thread pools only; before 2026-11-28 the children got
that by default, which hid the old code's spinning OpenBLAS worker). Not measured: realtime rendering, other materials, a cold disk cache, the first run
after an install (an empty SDK cache folder).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
from pathlib import Path


def one(args: list[str], env: dict[str, str], cwd: str | None) -> tuple[float, float]:
    w0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, *args], env=env, cwd=cwd, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE)
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - w0
    err = p.stderr.read().decode() if p.stderr else ""
    if p.stderr:
        p.stderr.close()
    if os.waitstatus_to_exitcode(status) not in (0, 1):
        raise RuntimeError(f"{args} failed: {err[-500:]}")
    return ru.ru_utime + ru.ru_stime, wall


def main() -> None:
    argv = sys.argv[1:]
    runs = int(argv[argv.index("--runs") + 1]) if "--runs" in argv else 8
    ref = argv[argv.index("--baseline") + 1] if "--baseline" in argv else None
    from hapticsdk.benchmarks.baseline import _child_env, exported_tree, repository_of, resolve
    from hapticsdk.benchmarks.reference import machine
    render = ["-m", "hapticsdk", "render", "S7"]
    trees: list[tuple[str, Path | None]] = [("this code", None)]
    stack = []
    if ref is not None:
        repo = repository_of(Path(__file__).resolve().parent)
        commit = resolve(repo, ref)
        cm = exported_tree(repo, commit)
        trees.insert(0, (f"baseline {ref} ({commit[:10]})", cm.__enter__()))
        stack.append(cm)
    try:
        envs = {}
        for name, tree in trees:
            env = _child_env(tree, one_pool_thread=False)   # as users run it: the tree sizes its pools
            env.pop("PYTHONDONTWRITEBYTECODE", None)
            if tree is not None:
                env["HAPTICSDK_BASELINE_TREE"] = str(tree)
            envs[name] = env
            one(render, env, str(tree) if tree else None)      # warm-up: byte-code written
        before = machine()
        res: dict[str, list[tuple[float, float]]] = {n: [] for n, _ in trees}
        bare: list[tuple[float, float]] = []
        for r in range(runs):
            order = trees if r % 2 == 0 else trees[::-1]
            for name, tree in order:
                if tree is not None:
                    args = ["-c", "import os, sys, runpy\n"
                            "sys.meta_path[:] = [f for f in sys.meta_path if not str(getattr(f, '__module__', ''))"
                            ".startswith('__editable__') and not str(getattr(type(f), '__module__', ''))"
                            ".startswith('__editable__')]\n"
                            "import hapticsdk\n"
                            "assert hapticsdk.__file__.startswith(os.environ['HAPTICSDK_BASELINE_TREE']), hapticsdk.__file__\n"
                            "sys.argv = ['hapticsdk', 'render', 'S7']\n"
                            "runpy.run_module('hapticsdk', run_name='__main__')\n"]
                else:
                    args = render
                res[name].append(one(args, envs[name], str(tree) if tree else None))
            bare.append(one(["-c", "pass"], envs[trees[-1][0]], None))
        after = machine()
    finally:
        for cm in stack:
            cm.__exit__(None, None, None)
    print(f"hapticsdk render S7 (3 s simulated), whole process, {runs} runs per tree"
          f"{', alternating' if ref else ''}; CPU = user + sys of the child (rusage), wall = perf_counter")
    print(f"machine {before['cpu_model']}, {before['cpus']} CPUs, load {before['load_1min']:.2f} -> "
          f"{after['load_1min']:.2f}, Python {before['python']}")
    med = statistics.median
    rows = [*((n, res[n]) for n, _ in trees), ("bare reference: python -c pass", bare)]
    for name, xs in rows:
        cpu = [c for c, _ in xs]
        wall = [w for _, w in xs]
        print(f"  {name:34} CPU min / median {min(cpu) * 1e3:6.0f} / {med(cpu) * 1e3:6.0f} ms   "
              f"wall min / median {min(wall) * 1e3:6.0f} / {med(wall) * 1e3:6.0f} ms")
    if ref is not None:
        b, t = res[trees[0][0]], res[trees[1][0]]
        print(f"  this code / baseline: CPU median {med([c for c, _ in t]) / med([c for c, _ in b]):.3f}, "
              f"CPU min {min(c for c, _ in t) / min(c for c, _ in b):.3f}; wall median "
              f"{med([w for _, w in t]) / med([w for _, w in b]):.3f}")


if __name__ == "__main__":
    main()
