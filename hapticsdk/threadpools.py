"""The native thread pools of BLAS and OpenMP libraries, held to one thread.

The SDK's arrays are small (a 5-20-2 network, populations of hundreds, 2 x 2 to 5 x 5
systems), so a second BLAS thread never shortens a call: it only busy-waits for work. An
OpenBLAS pool starts its worker threads when the library loads, and they spin for a
while even if no call ever uses them. Measured on a 2-CPU VM (Python 3.11, numpy's
scipy-openblas 0.3.31): ``import numpy`` alone cost 70-100 ms of CPU on the worker
thread; ``hapticsdk render S7`` took 0.45-0.50 s of CPU with the default pool and
0.26-0.29 s with one thread, at the same wall time on an idle machine and 0.39-0.44 s
against 0.45-0.68 s of wall beside two CPU-bound processes; ``hapticsdk train`` (2
restarts) 1.3-1.7 s of CPU against 1.0 s at the same wall time; a batch of 10^5 amortised
solves 0.33 s either way (docs/runtime.md, "Start-up").

Two users of this module:

- the ``hapticsdk`` command (:func:`hapticsdk.cli.run`) calls :func:`default_one_thread`
  before any command imports numpy: one thread unless the user has set one of
  :data:`POOL_ENV` (then every pool is left as the user set it);
- the servo process of a live session calls :func:`one_thread_environment` before it
  builds and :func:`one_thread` after, whatever the environment says (its reason: the
  busy worker kept a CPU from the servo thread).

An application that imports hapticsdk as a library keeps its own pools: a library does
not set its host's environment. docs/runtime.md says how to hold them to one thread.
"""

from __future__ import annotations

import os
import sys
from typing import MutableMapping

#: BLAS / OpenMP thread-pool setters tried on every already-loaded library (first found wins)
POOL_SETTERS = ("openblas_set_num_threads", "openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
                "scipy_openblas_set_num_threads64_", "MKL_Set_Num_Threads", "bli_thread_set_num_threads",
                "omp_set_num_threads")
#: the environment variables the pools read when their library loads
POOL_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")


def one_thread_environment(environ: MutableMapping[str, str] | None = None) -> None:
    """BLAS / OpenMP libraries loaded from now on start one thread (environment)."""
    env = os.environ if environ is None else environ
    for k in POOL_ENV:
        env[k] = "1"


def default_one_thread(environ: MutableMapping[str, str] | None = None) -> bool:
    """One thread for the pools loaded from now on, unless the environment already sets
    any of :data:`POOL_ENV` (a user's choice, kept whole). Returns whether it set them.

    Call it before numpy is imported: a pool already loaded keeps the size it started with."""
    env = os.environ if environ is None else environ
    if any(k in env for k in POOL_ENV):
        return False
    one_thread_environment(env)
    return True


def one_thread() -> str:
    """Limit the BLAS / OpenMP thread pools of this process (the servo process) to one
    thread; returns what was done (for the servo's summary).

    Why: a BLAS call the servo makes every tick (the simulated arm's exact step calls
    ``scipy.linalg.expm`` for each measured period) hands work to the pool's worker
    thread, which then busy-waits for the next job, and with one job per millisecond it
    never goes to sleep: it kept a whole CPU busy (measured with ``perf``:
    ``blas_thread_server``), so on a 2-CPU machine with a busy application thread the
    servo thread itself waited for a CPU for milliseconds. The environment variables
    cover libraries loaded from now on; libraries already loaded (the spawn start method
    imports the application's main module, and with it numpy, before the servo runs)
    get their ``*_set_num_threads(1)``. Only libraries already in the process are
    touched (``RTLD_NOLOAD``): no native code is loaded by this."""
    one_thread_environment()
    if not sys.platform.startswith("linux"):
        return f"environment only ({', '.join(POOL_ENV)} = 1; loaded libraries not inspected on {sys.platform})"
    import ctypes
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as fh:
            paths = sorted({ln.split(None, 5)[5].strip() for ln in fh if len(ln.split(None, 5)) == 6})
    except OSError as exc:
        return f"environment only (/proc/self/maps: {exc})"
    done = []
    for p in paths:
        base = os.path.basename(p)
        low = base.lower()
        if ".so" not in low or not any(k in low for k in ("blas", "mkl", "blis", "omp", "lapack")):
            continue
        try:
            lib = ctypes.CDLL(p, mode=os.RTLD_NOLOAD | os.RTLD_LOCAL)
        except OSError:
            continue
        for sym in POOL_SETTERS:
            fn = getattr(lib, sym, None)
            if fn is None:
                continue
            try:
                fn.argtypes = [ctypes.c_int]
                fn.restype = None
                fn(1)
                done.append(f"{base}: {sym}(1)")
            except Exception as exc:  # noqa: BLE001 - reported, never fatal
                done.append(f"{base}: {sym} failed: {exc}")
            break
    return "; ".join(done) if done else "no thread pool loaded (environment set for later ones)"
