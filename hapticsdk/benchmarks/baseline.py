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

from ..errors import HapticSDKError, ValidationError
from ..quantiles import median


class BaselineRunError(HapticSDKError, RuntimeError):
    """A child of a side-by-side run failed (its last error line is in the message: e.g.
    a live session's servo stopped by its safety watchdog on a loaded machine) or imported
    code from outside the tree it was given. Not a figure: rerun, or read the message."""

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


def _child_env(tree: Path | None, one_pool_thread: bool = True) -> dict[str, str]:
    """The environment of a measured child: this one's, importing from ``tree``; with
    ``one_pool_thread``, ``OMP_NUM_THREADS=1`` unless set (a measurement of one call in
    one thread). A measurement of a command as users run it passes ``False``, so each
    tree sizes its BLAS pools as it would on their machines."""
    env = dict(os.environ)
    if one_pool_thread:
        env.setdefault("OMP_NUM_THREADS", "1")
    if tree is not None:
        plugins = tree / "plugins"
        srcs = [str(p / "src") for p in sorted(plugins.iterdir()) if (p / "src").is_dir()] if plugins.is_dir() else []
        env["PYTHONPATH"] = os.pathsep.join([str(tree), *srcs])
    return env


def run_code(tree: Path | None, code: str, args: list[str], timeout_s: float = 600.0) -> dict[str, Any]:
    """Run ``code`` (starting with :data:`PRELUDE`) in a child of this interpreter that
    imports from ``tree`` (``None``: this environment's code) and prints one JSON object
    as its last line, which is returned. Raises BaselineRunError with the child's last error
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
        raise BaselineRunError(f"the measurement failed in {'the baseline tree' if tree else 'this tree'}: {last}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def run_child(tree: Path | None, seconds: float, period_s: float) -> dict[str, Any]:
    """One measurement (:data:`SCENE`) in a child of this interpreter, importing from
    ``tree`` (``None``: this environment's code). Raises BaselineRunError with the child's
    last error line when it fails, or when it imported code from elsewhere."""
    d = run_code(tree, SCENE, [repr(float(seconds)), repr(float(period_s))], timeout_s=max(600.0, 60 * seconds))
    _check_files(tree, d)
    return d


def _check_files(tree: Path | None, d: dict[str, Any]) -> None:
    """BaselineRunError unless the child's imported ``files`` lie in ``tree`` (or, for
    ``None``, are this process's own package)."""
    if tree is not None:
        root = str(tree.resolve())
        wrong = [f for f in d["files"] if not str(Path(f).resolve()).startswith(root)]
        if wrong:
            raise BaselineRunError(f"the baseline child imported {wrong} instead of the baseline tree {root}")
    else:
        import hapticsdk
        if Path(d["files"][0]).resolve() != Path(hapticsdk.__file__).resolve():
            raise BaselineRunError(f"the child imported {d['files'][0]}, not this code ({hapticsdk.__file__})")


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


def _interleaved(ref: str, rounds: int, run: Any, progress: Any = None
                 ) -> tuple[str, dict[str, Any], dict[str, Any], list[dict[str, Any]], list[dict[str, Any]]]:
    """``run(tree)`` for the export of ``ref`` and for this code (``tree=None``),
    ``rounds`` pairs, the order alternating; returns the commit, the machine before and
    after, and the baseline's and this code's results."""
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
                runs.append(run(t))
                if progress is not None:
                    progress(f"round {r + 1}/{rounds}: {'baseline' if t else 'this tree'} done")
    return commit, before, machine(), old, new


def run_baseline(ref: str, seconds: float = 10.0, rounds: int = 3, period_s: float = 0.001,
                 progress: Any = None) -> dict[str, Any]:
    """The tick of ``ref`` and of this code, ``rounds`` interleaved pairs (see the module
    doc); returns :func:`summarise` plus the commit, the settings and the machine."""
    from ..scene.limits import check_seconds
    check_seconds(seconds, "seconds")   # before any child (whose timeout follows from it)
    commit, before, after, old, new = _interleaved(ref, rounds, lambda t: run_child(t, seconds, period_s),
                                                   progress)
    out = summarise(old, new)
    out.update({"ref": ref, "commit": commit, "seconds": seconds, "rounds": rounds, "period_s": period_s,
                "clock": "time.thread_time_ns (on-CPU time of the servo thread)",
                "statistic": "per run: median and p99 over the ticks; reported: median over rounds",
                "machine_before": before, "machine_after": after})
    return out


#: a live session (``hapticsdk.benchmarks.live.run_live`` of the child's own tree, with
#: its reference loop); argv: isolation, application load, seconds, period, record
LIVE = PRELUDE + r'''
import json
import hapticsdk
from hapticsdk.benchmarks.live import run_live
isolation, load, seconds, period, record = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), sys.argv[5]
res = run_live(isolation, (load,), seconds, period_s=period, record=record)
row = res[0] if isinstance(res, list) else res
print(json.dumps({"jitter": row["jitter"], "reference": row.get("reference"),
                  "state_us": row["app_call_us"]["state"], "state_p99_us": row["app_call_us"]["state_p99"],
                  "files": [hapticsdk.__file__, sys.modules["hapticsdk.benchmarks.live"].__file__]}))
'''


def run_live_child(tree: Path | None, isolation: str, load: str, seconds: float, period_s: float,
                   record: str) -> dict[str, Any]:
    """One live session (:data:`LIVE`) in a child importing from ``tree`` (``None``: this
    code); its servo process inherits the child's environment and working folder, so it
    imports from the same tree."""
    d = run_code(tree, LIVE, [isolation, load, repr(float(seconds)), repr(float(period_s)), record],
                 timeout_s=max(600.0, 20 * seconds))
    _check_files(tree, d)
    return d


def summarise_live(old: list[dict[str, Any]], new: list[dict[str, Any]]) -> dict[str, Any]:
    """Medians over rounds of each tree's period jitter (p50 / p99 / max, us), missed-tick
    rate and ``state()`` call (p50 / p99, us), the reference loop's jitter of the same
    minutes (the bare reference), each tree's jitter p99 over its reference's, and this
    code over the baseline paired by round (jitter p99, ``state()`` p50)."""
    def side(runs: list[dict[str, Any]]) -> dict[str, Any]:
        j = {k: median([r["jitter"][k] for r in runs]) for k in ("p50_us", "p99_us", "max_us", "missed_tick_rate")}
        refs = [r["reference"] for r in runs if r.get("reference")]
        ref = {k: median([x[k] for x in refs]) for k in ("p50_us", "p99_us", "missed_tick_rate")} if refs else None
        out = {"jitter": j, "reference": ref, "state_us": median([r["state_us"] for r in runs]),
               "state_p99_us": median([r["state_p99_us"] for r in runs]), "runs": runs}
        out["jitter_p99_over_reference"] = j["p99_us"] / ref["p99_us"] if ref and ref["p99_us"] else float("nan")
        return out

    def ratio(a: float, b: float) -> float:
        return a / b if b else float("nan")
    per_p99 = [ratio(n["jitter"]["p99_us"], o["jitter"]["p99_us"]) for o, n in zip(old, new)]
    per_state = [ratio(n["state_us"], o["state_us"]) for o, n in zip(old, new)]
    return {"baseline": side(old), "this": side(new), "ratio_jitter_p99": median(per_p99),
            "ratio_state": median(per_state), "ratio_jitter_p99_per_round": per_p99,
            "ratio_state_per_round": per_state}


def run_live_baseline(ref: str, isolation: str = "process", load: str = "python-thread", seconds: float = 10.0,
                      rounds: int = 2, period_s: float = 0.001, record: str = "none",
                      progress: Any = None) -> dict[str, Any]:
    """``bench live`` of ``ref`` and of this code, interleaved (:func:`_interleaved`)."""
    from ..scene.limits import check_seconds
    check_seconds(seconds, "seconds")   # before any child (whose timeout follows from it)
    commit, before, after, old, new = _interleaved(
        ref, rounds, lambda t: run_live_child(t, isolation, load, seconds, period_s, record), progress)
    out = summarise_live(old, new)
    out.update({"ref": ref, "commit": commit, "seconds": seconds, "rounds": rounds, "period_s": period_s,
                "isolation": isolation, "app_load": load, "record": record,
                "clock": "time.perf_counter: the servo's periods (|period - T|) and the application's wall time of "
                         "each state() call",
                "statistic": "per run: p50 / p99 / max over the periods, state() p50 / p99 over the calls; "
                             "reported: median over rounds",
                "machine_before": before, "machine_after": after})
    return out


def _named_rows(d: dict[str, Any]) -> tuple[list[tuple[str, dict[str, Any]]], int]:
    """The two sides of a side-by-side report with their row names, and the names' width."""
    rows = [(f"baseline {d['ref']} ({d['commit'][:10]})", d["baseline"]), ("this code", d["this"])]
    return rows, max(len(n) for n, _ in rows)


def _machine_line(d: dict[str, Any]) -> str:
    mb, ma = d["machine_before"], d["machine_after"]
    return (f"machine: {mb['cpu_model']}, {mb['cpus']} CPUs, load {mb['load_1min']:.2f} -> "
            f"{ma['load_1min']:.2f}, Python {mb['python']}")


def format_live_baseline(d: dict[str, Any]) -> str:
    """Text report of :func:`run_live_baseline`."""
    rows, w = _named_rows(d)
    lines = [f"live session, {d['isolation']} isolation, application load {d['app_load']}, period "
             f"{d['period_s'] * 1e3:g} ms, {d['rounds']} interleaved rounds x {d['seconds']:g} s, one child "
             f"process per tree and round, same interpreter",
             f"clock: {d['clock']}; statistic: {d['statistic']}",
             f"{'':{w}}  jitter p50 / p99 / max (us)   missed    reference loop p99 (us), missed   "
             f"jitter p99 / reference p99   state() p50 / p99 (us)"]
    for name, s in rows:
        j, r = s["jitter"], s["reference"] or {"p99_us": float("nan"), "missed_tick_rate": float("nan")}
        lines.append(f"{name:{w}}  {j['p50_us']:6.1f} / {j['p99_us']:6.1f} / {j['max_us']:8.1f}   "
                     f"{j['missed_tick_rate'] * 100:6.3f} %   {r['p99_us']:8.1f}, {r['missed_tick_rate'] * 100:6.3f} %"
                     f"        {s['jitter_p99_over_reference']:8.2f}            {s['state_us']:5.1f} / "
                     f"{s['state_p99_us']:.1f}")
    lines.append(f"this code / baseline, paired by round: jitter p99 {d['ratio_jitter_p99']:.3f} (rounds "
                 f"{', '.join(f'{x:.3f}' for x in d['ratio_jitter_p99_per_round'])}), state() p50 "
                 f"{d['ratio_state']:.3f} (rounds {', '.join(f'{x:.3f}' for x in d['ratio_state_per_round'])})")
    lines.append(_machine_line(d))
    lines.append("measures period jitter, missed ticks and state() calls of both trees' live sessions in the same "
                 "minutes, each next to a loop doing nothing else; not the tick's compute cost (bench timing "
                 "--baseline)")
    return "\n".join(lines)


def format_baseline(d: dict[str, Any]) -> str:
    """Text report of :func:`run_baseline`."""
    rows, w = _named_rows(d)
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
    lines.append(_machine_line(d))
    lines.append("measures the tick's compute cost of both trees in the same minutes; not period jitter, "
                 "real-time behaviour or live sessions (bench live)")
    return "\n".join(lines)
