"""``hapticsdk bench stability | fidelity | timing | live``: servo-runtime benchmarks.

Heavy imports (the simulators, the plugins) happen inside the handlers.
"""

from __future__ import annotations

import argparse
from typing import Any


def register_bench(bench_sub: Any) -> None:
    """Add ``bench stability``, ``bench fidelity``, ``bench timing`` (and the other runtime
    benchmarks) under ``hapticsdk bench``.
    """
    from .argtypes import bounded_int, figure_file, nonneg_int, positive_float, positive_int

    p = bench_sub.add_parser("stability", help="stiff virtual walls on a simulated arm: the SDK's passivity "
                                               "controller beside the plain wall, PO/PC, energy bounding and a "
                                               "virtual coupling, on the fixed grid or --random cells")
    p.add_argument("--quick", action="store_true", help="small grid, 3 s runs (for tests)")
    p.add_argument("--random", type=positive_int, default=None, metavar="N",
                   help="N cells drawn from the whole space (trajectory, finger, period, encoder, arm, "
                        "damping) instead of the fixed grid")
    p.add_argument("--seed", type=nonneg_int, default=1, help="seed of --random (default 1)")
    p.add_argument("--duration", type=positive_float, default=None, help="seconds per cell (default 10)")
    p.add_argument("--plot", metavar="PNG", type=figure_file, help="write a figure: energy to the user (log scale) and "
                                                 "delivered force ratio per controller, and the SDK's ratio "
                                                 "against the best passive peer (needs matplotlib)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_stability)

    p = bench_sub.add_parser("live", help="live session: servo jitter under application load, material "
                                          "switch latency / force step / energy, application call times")
    p.add_argument("--isolation", choices=("process", "thread"), default="process",
                   help="servo in its own process (default) or in a thread of the application")
    p.add_argument("--app-load", choices=("none", "python-thread", "numpy-thread", "all"), default="python-thread",
                   help="what the application does meanwhile (default python-thread)")
    p.add_argument("--seconds", type=positive_float, default=10.0, help="run length per load (default 10 s)")
    p.add_argument("--period", type=positive_float, default=None, metavar="S",
                   help="servo period in s (default the scene's, 0.001; 0.00025 = 4 kHz, the rate of DHD arms)")
    p.add_argument("--pin-cpu", type=nonneg_int, default=None, metavar="N",
                   help="pin the servo thread to CPU N (reported if refused)")
    p.add_argument("--fifo-priority", type=_fifo_priority, default=argparse.SUPPRESS, metavar="P",
                   help="the servo's SCHED_FIFO priority: 1..99, 'auto' (where the OS allows it; the default of "
                        "a servo process) or 'off' (the default of a servo thread); the outcome is printed")
    p.add_argument("--record", choices=("npz", "h5", "none"), default="npz",
                   help="record every tick to a temporary file of this format meanwhile (default npz; h5 needs "
                        "hapticsdk[h5]); the servo's RSS slope is reported")
    p.add_argument("--baseline", metavar="REF", default=None,
                   help="instead: the live session of git ref REF and of this code side by side, interleaved in "
                        "one run (needs a git checkout; one application load; --seconds per run)")
    p.add_argument("--rounds", type=bounded_int(1, 100), default=2,
                   help="with --baseline: interleaved rounds (default 2)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_live)

    p = bench_sub.add_parser("fidelity", help="force and frequency error against servo period (0.25..4 ms)")
    p.add_argument("--periods", type=positive_float, nargs="+", default=None, metavar="S",
                   help="servo periods in s (default 0.00025 0.0005 0.001 0.002 0.004)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_fidelity)

    p = bench_sub.add_parser("timing", help="per-tick compute time and period jitter of the servo loop")
    p.add_argument("--seconds", type=positive_float, default=60.0, help="run length (default 60 s)")
    p.add_argument("--realtime", action="store_true", help="pace on the machine clock (jitter figures)")
    p.add_argument("--load", action="store_true", help="run a second CPU-bound process meanwhile")
    p.add_argument("--period", type=positive_float, default=0.001, help="servo period in s (default 0.001)")
    p.add_argument("--pin-cpu", type=nonneg_int, default=None, metavar="N",
                   help="pin the servo thread to CPU N (reported if refused)")
    p.add_argument("--fifo-priority", type=bounded_int(1, 99), default=None, metavar="P",
                   help="request SCHED_FIFO priority P, 1..99 (reported if refused; prefer with --realtime)")
    p.add_argument("--mlockall", action="store_true", help="lock the process's memory (Linux; reported if refused)")
    p.add_argument("--declared-rt-machine", action="store_true", help="judge the jitter limits (pass/fail)")
    p.add_argument("--baseline", metavar="REF", default=None,
                   help="instead: the tick of git ref REF and of this code side by side, interleaved in one run "
                        "(needs a git checkout; simulated clock; --seconds per run)")
    p.add_argument("--rounds", type=bounded_int(1, 100), default=3,
                   help="with --baseline: interleaved rounds (default 3)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_timing)


def _fifo_priority(text: str) -> int | str | None:
    """``--fifo-priority``: 'auto', 'off' (None) or an integer 1..99."""
    from .argtypes import bounded_int
    if text in ("auto", "off"):
        return None if text == "off" else text
    return bounded_int(1, 99)(text)


def _live(args: argparse.Namespace) -> int:
    from ..benchmarks.live import APP_LOADS, format_rows, run_live
    from . import emit
    if args.baseline is not None:
        return _live_baseline(args)
    loads = APP_LOADS if args.app_load == "all" else (args.app_load,)
    rt: dict[str, Any] = {}   # options not given: the session's defaults
    if hasattr(args, "fifo_priority"):
        rt["fifo_priority"] = args.fifo_priority
    if args.pin_cpu is not None:
        rt["cpu"] = args.pin_cpu
    if args.record == "h5":
        from ..runtime.recorder_h5 import h5py_module
        h5py_module(field="--record")
    res = run_live(args.isolation, loads, args.seconds, rt=rt or None, period_s=args.period, record=args.record)
    rows = res if isinstance(res, list) else [res]
    emit(res, args.json, format_rows(rows) + "\n(shared machines: other processes' load is in these figures)")
    return 0


def _stability(args: argparse.Namespace) -> int:
    from ..benchmarks.stability import DEFAULT_GRID, QUICK_GRID
    from ..benchmarks.stability_random import run_grid, run_random
    from ..progress import Progress
    from . import emit
    if args.plot:  # before the work: a figure that cannot be written fails now
        from ..fileio import check_output_path
        check_output_path(args.plot, field="--plot")
    with Progress("bench stability", quiet=args.json) as progress:
        if args.random is not None:
            res = run_random(args.random, args.seed, progress=progress)
            head = f"{args.random} random cells (seed {args.seed})"
        else:
            grid = dict(QUICK_GRID if args.quick else DEFAULT_GRID)
            if args.duration:
                grid["duration_s"] = args.duration
            res = run_grid(grid, progress=progress)
            head = f"fixed grid, {len(res['cells'])} cells, {grid['duration_s']:g} s each"
    if args.plot:
        from ..plotting import plot_stability
        plot_stability(res, args.plot)
        res["plot"] = args.plot
    s = res["summary"]
    n = s["cells"]
    rows = []
    for name, c in s["controllers"].items():
        rows.append(f"  {name:<12} {c['cells_energy_within_bound']:>6}/{n:<6} {c['max_energy_to_user_j'] * 1e3:>12.4g} "
                    f"{c['median_delivered_ratio']:>10.3f} {c['max_force_step_n']:>10.3f} "
                    f"{c['most_negative_contact_force_n']:>10.3f}")
    text = (f"{head}, {res['runtime_s']:.1f} s (simulated arm, exact zero-order hold; energy from the raw state)\n"
            f"  {'ctrl':<12} {'E<=' + format(s['energy_bound_j'] * 1e3, 'g') + 'mJ':>13} {'max E (mJ)':>12} "
            f"{'median F/Kx':>10} {'max dF (N)':>10} {'min F (N)':>10}\n" + "\n".join(rows) + "\n"
            f"sdk controller: energy within {s['energy_bound_j'] * 1e3:g} mJ in {s['sdk_energy_within_bound']}/{n} cells; "
            f"never pulls in {s['sdk_no_pull']}/{n}; force steps within its ramp in {s['sdk_step_within_ramp']}/{n} "
            f"(rises within it in {s['sdk_rise_within_ramp']}/{n}; "
            f"within the ramp plus the Colgate spring, K_c x reading change, in "
            f"{s['sdk_step_within_ramp_plus_spring']}/{n}; on the ticks the book was not overdrawn in "
            f"{s['sdk_step_within_ramp_plus_spring_where_ramp_kept']}/{n}: it fell below the ramp, "
            f"the book overdrawn, in {s['sdk_cells_below_ramp']}/{n}); "
            f"delivered >= {100 - s['delivered_shortfall_allowed'] * 100:g} % of the best passive peer's in "
            f"{s['sdk_delivered_vs_best_passive_peer']}/{s['cells_with_a_passive_peer']} cells that have a peer "
            f"within the energy bound, and of the best such peer that never pulls and steps within the sdk's "
            f"ramp in {s['sdk_delivered_vs_best_shaped_peer']}/{s['cells_with_a_shaped_peer']}; "
            f"the spring alone (the energy bound spent) on more than half the contact ticks in "
            f"{s['sdk_spring_only_over_half']}/{n}" + _like_for_like_text(s) + _lanes_text(s, n)
            + (f"\nfigure saved to {args.plot}" if args.plot else ""))
    emit(res, args.json, text)
    declared_met = s.get("declared_damping", {}).get("sdk_energy_within_bound", n) == n
    return 0 if s["sdk_energy_within_bound"] == n and declared_met else 1


def _like_for_like_text(s: dict[str, Any]) -> str:
    """The ``sdk`` lane's delivered counts against the peers on the damping it trusts: context
    next to the goal's comparison (the peers on the declared damping)."""
    d = s.get("peers_on_trusted_damping")
    if d is None:
        return ""
    med = s["controllers"]
    peers = ", ".join(f"{p} {med[p]['median_delivered_ratio']:.3f}" for p in d["peers"] if p in med)
    return (f"\n  (the goal's comparison is the one above, the peers on the declared damping; as context, like for "
            f"like, the peers on the damping the sdk lane trusts, the measured lower bound: at the best passive "
            f"peer in {d['sdk_delivered_vs_best_passive_peer']}/{d['cells_with_a_passive_peer']}, at the best "
            f"shaped peer in {d['sdk_delivered_vs_best_shaped_peer']}/{d['cells_with_a_shaped_peer']}; median "
            f"delivered {peers}, sdk {med['sdk']['median_delivered_ratio']:.3f})")


def _lanes_text(s: dict[str, Any], n: int) -> str:
    """The two sdk lanes' note: which damping each credits, the declared lane's goal counts
    and the calibration's bound against the true damping."""
    d = s.get("declared_damping")
    if d is None:
        return ""
    cal = s.get("damping_calibration", {})
    return (f"\n  (sdk: the damping measured hands off on each cell's arm, its bound above the true damping in "
            f"{cal.get('cells_trusted_above_true', 'n/a')}/{cal.get('cells_calibrated', n)} cells, median "
            f"{cal.get('median_trusted_over_true', float('nan')):.3f} of it; sdk_declared: the default share of the declared damping, "
            f"median {cal.get('median_declared_share_over_true', float('nan')):.3f} of it)\n"
            f"sdk_declared: energy within {s['energy_bound_j'] * 1e3:g} mJ in {d['sdk_energy_within_bound']}/{n}; never pulls in {d['sdk_no_pull']}/{n}; "
            f"steps within the ramp in {d['sdk_step_within_ramp']}/{n} (rises in {d['sdk_rise_within_ramp']}/{n}; "
            f"{d['sdk_step_within_ramp_plus_spring']}/{n} with the spring, "
            f"{d['sdk_step_within_ramp_plus_spring_where_ramp_kept']}/{n} on the ticks the book was not overdrawn, "
            f"below the ramp in {d['sdk_cells_below_ramp']}/{n}); at the best passive peer in {d['sdk_delivered_vs_best_passive_peer']}/"
            f"{d['cells_with_a_passive_peer']}, at the best shaped peer in {d['sdk_delivered_vs_best_shaped_peer']}/"
            f"{d['cells_with_a_shaped_peer']}; the spring alone on more than half the contact ticks in "
            f"{d['sdk_spring_only_over_half']}/{n}")


def _fidelity(args: argparse.Namespace) -> int:
    from ..benchmarks.fidelity import PERIODS_S, run_fidelity
    from ..progress import Progress
    from . import emit
    with Progress("bench fidelity", quiet=args.json) as progress:
        rows = run_fidelity(tuple(args.periods) if args.periods else PERIODS_S, progress=progress)
    text = "\n".join(["period_ms  force_err_rms_N  freq_err_Hz rms/max  unquantised rms/max  tick_median_us"] +
                     [f"{r['period_s'] * 1e3:9.2f}  {r['force_error_rms_n']:15.4f}  "
                      f"{r['frequency_error_hz']:8.3f} / {r['frequency_error_max_hz']:6.2f}  "
                      f"{r['frequency_error_unquantised_hz']:10.3f} / {r['frequency_error_unquantised_max_hz']:6.2f}  "
                      f"{r['tick_median_us']:14.1f}" for r in rows]
                     + ["(freq_err: the frequency the DRV2667 holds, in its 7.8125 Hz steps; unquantised: the "
                        "frequency commanded)"])
    emit(rows, args.json, text)
    return 0


def _timing(args: argparse.Namespace) -> int:
    from ..benchmarks.timing import format_table, run_timing
    from . import emit
    if args.baseline is not None:
        return _timing_baseline(args)
    rt = {"cpu": args.pin_cpu, "fifo_priority": args.fifo_priority, "mlockall": args.mlockall}
    d = run_timing(args.seconds, realtime=args.realtime, load=args.load, period_s=args.period, rt=rt,
                   declared_rt_machine=args.declared_rt_machine)
    text = (f"{d['ticks']} ticks ({', '.join(d['dimensions'])}), overruns {d['overruns']}\n" + format_table([d]))
    emit(d, args.json, text)
    return 0


def _timing_baseline(args: argparse.Namespace) -> int:
    """``bench timing --baseline REF``: :func:`hapticsdk.benchmarks.baseline.run_baseline`."""
    from ..benchmarks.baseline import format_baseline, run_baseline
    from ..errors import ValidationError
    from . import emit
    other = [f for f, on in (("--realtime", args.realtime), ("--load", args.load),
                             ("--pin-cpu", args.pin_cpu is not None), ("--fifo-priority", args.fifo_priority is not None),
                             ("--mlockall", args.mlockall), ("--declared-rt-machine", args.declared_rt_machine)) if on]
    if other:
        raise ValidationError(f"--baseline compares the tick's compute cost on the simulated clock; it does not "
                              f"take {', '.join(other)}", field="--baseline")
    d = run_baseline(args.baseline, seconds=args.seconds, rounds=args.rounds, period_s=args.period)
    emit(d, args.json, format_baseline(d))
    return 0


def _live_baseline(args: argparse.Namespace) -> int:
    """``bench live --baseline REF``: :func:`hapticsdk.benchmarks.baseline.run_live_baseline`."""
    from ..benchmarks.baseline import format_live_baseline, run_live_baseline
    from ..errors import ValidationError
    from . import emit
    other = [f for f, on in (("--app-load all", args.app_load == "all"), ("--pin-cpu", args.pin_cpu is not None),
                             ("--fifo-priority", hasattr(args, "fifo_priority"))) if on]
    if other:
        raise ValidationError(f"--baseline runs one application load with the session's default real-time "
                              f"settings in both trees; it does not take {', '.join(other)}", field="--baseline")
    d = run_live_baseline(args.baseline, isolation=args.isolation, load=args.app_load, seconds=args.seconds,
                          rounds=args.rounds, period_s=args.period or 1e-3, record=args.record)
    emit(d, args.json, format_live_baseline(d))
    return 0
