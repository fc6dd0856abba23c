"""Side by side with older code: the servo tick of a git ref and of this code, interleaved.

``hapticsdk bench timing --baseline REF`` exports the tree of ``REF`` (``git archive`` of
the repository this package is imported from, into a temporary folder; the repository
itself is not touched) and runs the same measurement on both trees, each in a fresh
child process of this interpreter, alternating the order every round so that both see
the same minutes of the machine's load:

* the servo tick of the timing material (:data:`SCENE`: hardness and, where installed,
  roughness on the simulated Omni, voice coil and piezo; simulated clock, so no tick
  waits) for ``seconds`` of simulated time: the tick's on-CPU time of the servo thread
  (``time.thread_time_ns`` around each tick, as ``LoopReport.tick_cpu_*``), median and
  p99 over the ticks of the run;
* in the same child, with the same clock, the bare reference: one empty Python call with
  the clock read around it (median over 2001 calls).

Both trees' children import from their own tree: the baseline's from the export (on
``PYTHONPATH``, its ``plugins/*/src`` too, with the editable-install finders of this
environment taken out of the child's import system), this tree's as this process does;
each child reports the files it imported, and a child that imported the wrong tree is an
error. The plugins' entry points (names) are this environment's.

What it measures: the code's cost per tick on this machine, in the same run, as a median
over rounds, and the ratio of each tree's tick to its own empty call and of this tree to
the baseline (per round and their median). What it does not measure: period jitter, the
real-time behaviour or a live session (``bench live``), other scenes, or the code of
anything outside the two trees (numpy, the interpreter: the same for both).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..errors import ValidationError
from ..quantiles import median

#: first lines of a child's code: with ``HAPTICSDK_BASELINE_TREE`` set, import from
#: PYTHONPATH, not from the environment's editable installs
PRELUDE = r'''
import os, sys
if os.environ.get("HAPTICSDK_BASELINE_TREE"):
    sys.meta_path[:] = [f for f in sys.meta_path
                        if not str(getattr(f, "__module__", "")).startswith("__editable__")
                        and not str(getattr(type(f), "__module__", "")).startswith("__editable__")]
'''

#: the measurement each child runs (the same source for both trees); argv: seconds, period
SCENE = PRELUDE + r'''
import json, time
import hapticsdk
from hapticsdk.plugins import registry
from hapticsdk.runtime import ServoLoop
from hapticsdk.sim.finger import press_slide
seconds, period = float(sys.argv[1]), float(sys.argv[2])
dims, acts = registry("dimension"), registry("actuator")
cycle = press_slide(depth_mm=3.0, press_s=0.3, hold_s=0.1, slide_s=1.0, release_s=0.3, rest_s=0.2)
tr = cycle
while tr.duration_s < seconds:
    tr = tr.then(cycle, gap_s=0.01)
dev = acts.load("omni-virtual")(trajectory=tr, finger="stiff")
renderers = [dims.load("hardness")().renderer({"GS": 3.0})]
actuators = {"force": dev, "coil": acts.load("voicecoil-virtual")()}
if "roughness" in dims and "piezo-virtual" in acts:
    renderers.append(dims.load("roughness")().renderer({"Fpeak": 150.0, "AFpeak": 5.0}))
    actuators["vibration"] = acts.load("piezo-virtual")(period_s=period)
rep = ServoLoop(dev, renderers, actuators, period_s=period).run(seconds)
for a in {id(a): a for a in [dev, *actuators.values()]}.values():
    a.close()
def nothing():
    return None
read = time.thread_time_ns
ref = []
for _ in range(2001):
    q0 = read()
    nothing()
    ref.append(read() - q0)
ref.sort()
files = [hapticsdk.__file__] + [sys.modules[type(r).__module__].__file__ for r in renderers]
print(json.dumps({"tick_cpu_median_us": rep.tick_cpu_median_us, "tick_cpu_p99_us": rep.tick_cpu_p99_us,
                  "ticks": rep.ticks, "empty_call_us": ref[len(ref) // 2] / 1e3, "files": files}))
'''


def repository_of(path: Path) -> Path:
    """The top folder of the git checkout holding ``path``; a ValidationError naming
    ``--baseline`` when there is none (an installed package has no history to compare)."""
    try:
        out = subprocess.run(["git", "-C", str(path), "rev-parse", "--show-toplevel"],
                             capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise ValidationError(f"--baseline needs git: {exc}", field="--baseline") from None
    if out.returncode != 0:
        raise ValidationError(f"--baseline needs a git checkout of hapticsdk; {path} is not in one",
                              field="--baseline")
    return Path(out.stdout.strip())


def resolve(repo: Path, ref: str) -> str:
    """The commit ``ref`` names in ``repo`` (40 hex digits); a ValidationError otherwise."""
    if not isinstance(ref, str) or not ref or ref.startswith("-"):
        raise ValidationError(f"not a git ref: {ref!r}", field="--baseline")
    out = subprocess.run(["git", "-C", str(repo), "rev-parse", "--verify", "--quiet", f"{ref}^{{commit}}"],
                         capture_output=True, text=True, timeout=30)
    if out.returncode != 0:
        raise ValidationError(f"no commit {ref!r} in {repo}", field="--baseline")
    return out.stdout.strip()


@contextlib.contextmanager
def exported_tree(repo: Path, commit: str) -> Iterator[Path]:
    """The files of ``commit`` in a temporary folder (``git archive``; removed after)."""
    data = subprocess.run(["git", "-C", str(repo), "archive", "--format=tar", commit],
                          capture_output=True, timeout=300, check=True).stdout
    with tempfile.TemporaryDirectory(prefix="hapticsdk-baseline-") as tmp:
        with tarfile.open(fileobj=io.BytesIO(data)) as tar:
            if hasattr(tarfile, "data_filter"):
                tar.extractall(tmp, filter="data")
            else:   # pragma: no cover - Pythons without extraction filters (our own repository's archive)
                tar.extractall(tmp)
        yield Path(tmp)


def _child_env(tree: Path | None) -> dict[str, str]:
    env = dict(os.environ)
    env.setdefault("OMP_NUM_THREADS", "1")
    if tree is not None:
        plugins = tree / "plugins"
        srcs = [str(p / "src") for p in sorted(plugins.iterdir()) if (p / "src").is_dir()] if plugins.is_dir() else []
        env["PYTHONPATH"] = os.pathsep.join([str(tree), *srcs])
    return env


def run_code(tree: Path | None, code: str, args: list[str], timeout_s: float = 600.0) -> dict[str, Any]:
    """Run ``code`` (starting with :data:`PRELUDE`) in a child of this interpreter that
    imports from ``tree`` (``None``: this environment's code) and prints one JSON object
    as its last line, which is returned. Raises RuntimeError with the child's last error
    line when it fails."""
    env = _child_env(tree)
    if tree is not None:
        env["HAPTICSDK_BASELINE_TREE"] = str(tree)
    else:
        env.pop("HAPTICSDK_BASELINE_TREE", None)
    out = subprocess.run([sys.executable, "-c", code, *args], env=env, capture_output=True, text=True,
                         timeout=timeout_s, cwd=tree)   # `python -c` imports from its working folder first
    if out.returncode != 0:
        last = (out.stderr.strip().splitlines() or ["(no output)"])[-1]
        raise RuntimeError(f"the measurement failed in {'the baseline tree' if tree else 'this tree'}: {last}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def run_child(tree: Path | None, seconds: float, period_s: float) -> dict[str, Any]:
    """One measurement (:data:`SCENE`) in a child of this interpreter, importing from
    ``tree`` (``None``: this environment's code). Raises RuntimeError with the child's
    last error line when it fails, or when it imported code from elsewhere."""
    d = run_code(tree, SCENE, [repr(float(seconds)), repr(float(period_s))], timeout_s=max(600.0, 60 * seconds))
    if tree is not None:
        root = str(tree.resolve())
        wrong = [f for f in d["files"] if not str(Path(f).resolve()).startswith(root)]
        if wrong:
            raise RuntimeError(f"the baseline child imported {wrong} instead of the baseline tree {root}")
    else:
        import hapticsdk
        if Path(d["files"][0]).resolve() != Path(hapticsdk.__file__).resolve():
            raise RuntimeError(f"the child imported {d['files'][0]}, not this code ({hapticsdk.__file__})")
    return d


def summarise(old: list[dict[str, Any]], new: list[dict[str, Any]]) -> dict[str, Any]:
    """Medians over rounds of each tree's tick figures and empty call, each tree's tick
    over its own empty call, and this tree over the baseline (per round, paired, and the
    median of those ratios)."""
    def side(runs: list[dict[str, Any]]) -> dict[str, Any]:
        med = median([r["tick_cpu_median_us"] for r in runs])
        p99 = median([r["tick_cpu_p99_us"] for r in runs])
        ref = median([r["empty_call_us"] for r in runs])
        return {"tick_cpu_median_us": med, "tick_cpu_p99_us": p99, "empty_call_us": ref,
                "median_over_empty_call": med / ref, "p99_over_empty_call": p99 / ref,
                "runs": runs}
    per_med = [n["tick_cpu_median_us"] / o["tick_cpu_median_us"] for o, n in zip(old, new)]
    per_p99 = [n["tick_cpu_p99_us"] / o["tick_cpu_p99_us"] for o, n in zip(old, new)]
    return {"baseline": side(old), "this": side(new),
            "ratio_median": median(per_med), "ratio_p99": median(per_p99),
            "ratio_median_per_round": per_med, "ratio_p99_per_round": per_p99}


def run_baseline(ref: str, seconds: float = 10.0, rounds: int = 3, period_s: float = 0.001,
                 progress: Any = None) -> dict[str, Any]:
    """The tick of ``ref`` and of this code, ``rounds`` interleaved pairs (see the module
    doc); returns :func:`summarise` plus the commit, the settings and the machine."""
    from .reference import machine
    if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 1:
        raise ValidationError(f"rounds must be an integer >= 1, got {rounds!r}", field="--rounds")
    here = Path(__file__).resolve().parents[2]
    repo = repository_of(here)
    commit = resolve(repo, ref)
    before = machine()
    old: list[dict[str, Any]] = []
    new: list[dict[str, Any]] = []
    with exported_tree(repo, commit) as tree:
        for r in range(rounds):
            order = [(old, tree), (new, None)] if r % 2 == 0 else [(new, None), (old, tree)]
            for runs, t in order:
                runs.append(run_child(t, seconds, period_s))
                if progress is not None:
                    progress(f"round {r + 1}/{rounds}: {'baseline' if t else 'this tree'} done")
    out = summarise(old, new)
    out.update({"ref": ref, "commit": commit, "seconds": seconds, "rounds": rounds, "period_s": period_s,
                "clock": "time.thread_time_ns (on-CPU time of the servo thread)",
                "statistic": "per run: median and p99 over the ticks; reported: median over rounds",
                "machine_before": before, "machine_after": machine()})
    return out


def format_baseline(d: dict[str, Any]) -> str:
    """Text report of :func:`run_baseline`."""
    b, t = d["baseline"], d["this"]
    mb, ma = d["machine_before"], d["machine_after"]
    rows = [(f"baseline {d['ref']} ({d['commit'][:10]})", b), ("this code", t)]
    w = max(len(n) for n, _ in rows)
    lines = [f"servo tick, {d['rounds']} interleaved rounds x {d['seconds']:g} s simulated at period "
             f"{d['period_s'] * 1e3:g} ms, one child process per tree and round, same interpreter",
             f"clock: {d['clock']}; statistic: {d['statistic']}",
             f"{'':{w}}  tick CPU median / p99 (us)   empty call (us)   tick / empty call: median / p99"]
    for name, s in rows:
        lines.append(f"{name:{w}}  {s['tick_cpu_median_us']:8.2f} / {s['tick_cpu_p99_us']:8.2f}   "
                     f"{s['empty_call_us']:13.3f}     {s['median_over_empty_call']:10.1f} / "
                     f"{s['p99_over_empty_call']:.1f}")
    lines.append(f"this code / baseline, paired by round: median {d['ratio_median']:.3f} (rounds "
                 f"{', '.join(f'{x:.3f}' for x in d['ratio_median_per_round'])}), p99 {d['ratio_p99']:.3f} "
                 f"(rounds {', '.join(f'{x:.3f}' for x in d['ratio_p99_per_round'])})")
    lines.append(f"machine: {mb['cpu_model']}, {mb['cpus']} CPUs, load {mb['load_1min']:.2f} -> "
                 f"{ma['load_1min']:.2f}, Python {mb['python']}")
    lines.append("measures the tick's compute cost of both trees in the same minutes; not period jitter, "
                 "real-time behaviour or live sessions (bench live)")
    return "\n".join(lines)
