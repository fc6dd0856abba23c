"""Calibration and run-file commands: ``calibrate voicecoil|piezo|damping|answers|list``,
``replay``."""

from __future__ import annotations

import argparse
from typing import Any

from . import emit
from .argtypes import bounded_int, nonneg_float, nonneg_int, open_unit_interval, positive_float, serial


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``calibrate`` (``voicecoil``, ``piezo``, ``answers``, ``list``) and ``replay`` to
    the ``hapticsdk`` command.
    """
    cal = sub.add_parser("calibrate", help="fit actuator calibrations (voice coil formula (7), piezo Tab)")
    csub = cal.add_subparsers(dest="calibrate_command", metavar="KIND")
    from . import missing_subcommand
    cal.set_defaults(func=missing_subcommand(cal, "KIND"))

    p = csub.add_parser("voicecoil", help="fit formula (7) to stiffness-discrimination answers (CSV)")
    p.add_argument("answers", help="CSV with columns person, frequency_hz, spring_n_per_mm, spring_stiffer")
    p.add_argument("--confidence", type=open_unit_interval, default=0.95,
                   help="level of the coefficient intervals, strictly between 0 and 1")
    p.add_argument("--serial", type=serial, help="device serial number the calibration belongs to "
                                                "(at most 126 characters)")
    p.add_argument("--amplifier-gain", type=positive_float,
                   help="amplifier gain used in the experiment (a finite number > 0)")
    p.add_argument("--mounting", default="", help="how the tactor was mounted")
    _save_args(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_voicecoil)

    p = csub.add_parser("piezo", help="build the piezo table Tab from acceleration measurements")
    p.add_argument("measurements", help="CSV with columns frequency_hz, voltage_v, acceleration_m_s2, "
                                        "or a piezo table JSON")
    p.add_argument("--serial", type=serial, help="device serial number the calibration belongs to "
                                                "(at most 126 characters)")
    _save_args(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_piezo)

    p = csub.add_parser("damping", help="the force arm's damping, measured hands off: fit a run of the "
                                        "excitation, or write the excitation to play (docs/calibration.md)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--run", metavar="CSV", help="a hands-off run: columns position_mm, force_n, one row per "
                                                  "period (the reading, then the force applied after it)")
    src.add_argument("--simulate", action="store_true", help="a GENERATED run on the simulated arm (--mass, "
                                                             "--damping, --period, --resolution)")
    src.add_argument("--write-excitation", metavar="CSV", help="write the excitation's forces (column force_n, "
                                                               "one per period) for --period, --mass, --max-force")
    src.add_argument("--device", metavar="NAME", help="play the run on this force device (an actuator plugin, "
                                                      "e.g. omni-virtual) in real time, nobody holding it, and "
                                                      "fit it; its serial is the device's own, else --serial")
    p.add_argument("--device-option", action="append", default=[], metavar="KEY=VALUE",
                   help="--device: an option of the device (repeatable; VALUE read as JSON when it parses), e.g. "
                        "finger=none for the simulated Omni nobody holds; merged over the user's device "
                        "configuration and $HAPTICSDK_DEVICE_OPTIONS")
    p.add_argument("--latency", type=nonneg_float,
                   help="--device: the most time (s) between a position's sample and the read returning it, and "
                        "between a command returning and its force at the motor, where the device declares no "
                        "transport_latency_s (a real device with neither is refused)")
    p.add_argument("--axis", type=bounded_int(0, 2), default=1, help="--device: the axis driven and read, 0-2 "
                                                                     "(x, y, z; default 1)")
    p.add_argument("--period", type=positive_float, default=0.001, help="servo period of the run (s, default 0.001)")
    p.add_argument("--resolution", type=nonneg_float,
                   help="encoder resolution (mm, default 0.055, the Omni's; --device: the device's own)")
    p.add_argument("--mass", type=positive_float,
                   help="the arm's declared apparent mass (kg, default 0.045; --device: the device's own): sizes "
                        "the excitation")
    p.add_argument("--max-force", type=positive_float,
                   help="the arm's force limit (N, default 3.3; --device: the device's own)")
    p.add_argument("--damping", type=nonneg_float, default=0.5,
                   help="--simulate: the simulated arm's true damping (N*s/m, default 0.5)")
    p.add_argument("--serial", type=serial, help="device serial number the calibration belongs to (the "
                                                "controller uses a damping file only for its own serial)")
    _save_args(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_damping)

    p = csub.add_parser("answers", help="write GENERATED discrimination answers from formula (7) (for trying "
                                        "the voice-coil fit; not measured data)")
    p.add_argument("out", help="CSV to write")
    p.add_argument("--people", type=bounded_int(1, 1000), default=10, help="simulated people, 1..1000")
    p.add_argument("--seed", type=nonneg_int, default=0, help="random seed of the simulated answers, >= 0")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_answers)

    p = csub.add_parser("list", help="calibration files and the calibration each kind uses")
    p.add_argument("--dir", help="calibration directory (default $HAPTICSDK_CALIBRATION_DIR or "
                                 "~/.config/hapticsdk/calibration)")
    p.add_argument("--serial", action="append", default=[], metavar="KIND=SERIAL",
                   help="serial number per kind (repeatable)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_list)

    p = sub.add_parser("replay", help="summarise a recorded run file (.npz) and check it plays back")
    p.add_argument("runfile", help="run file written by a recorder (.npz, or .h5 from a live session)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_replay)


def _save_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--save", nargs="?", const="", metavar="DIR",
                   help="write the calibration file (to DIR, default the calibration directory)")
    p.add_argument("--out", metavar="FILE", help="write the calibration file to FILE")


def _check_save(args: argparse.Namespace) -> None:
    """Check ``--out FILE`` / ``--save DIR`` before the fit runs."""
    from ..errors import FileWriteError
    from ..fileio import check_output_path

    if args.out:
        check_output_path(args.out, field="--out")
    if args.save:
        from ..argcheck import file_path
        from ..errors import ValidationError
        try:
            d = file_path(args.save, "--save")
        except ValidationError as exc:
            raise FileWriteError(exc.reason, field="--save") from None
        if d.exists() and not d.is_dir():
            raise FileWriteError(f"{str(d)!r} is not a directory", field="--save")


def _save(args: argparse.Namespace, cal: Any) -> str | None:
    from ..calibration import save_calibration

    if args.out:
        return str(save_calibration(cal, path=args.out))
    if args.save is not None:
        return str(save_calibration(cal, args.save or None))
    return None


def cmd_voicecoil(args: argparse.Namespace) -> int:
    """``calibrate voicecoil``: fit formula (7) to discrimination answers, print the fit and
    optionally save the calibration. Returns the exit status.
    """
    from ..calibration import fit_voicecoil
    from ..calibration.voicecoil import PAPER_COEFFICIENTS

    _check_save(args)
    res = fit_voicecoil(args.answers, confidence=args.confidence, serial=args.serial,
                        amplifier_gain=args.amplifier_gain, mounting=args.mounting)
    saved = _save(args, res.calibration) if res.success else None
    out = res.to_dict()
    out["paper_coefficients"] = list(PAPER_COEFFICIENTS)
    out["paper_inside_intervals"] = [lo <= c <= hi for c, (lo, hi) in zip(PAPER_COEFFICIENTS, res.confidence_intervals)]
    out["saved"] = saved
    if args.json:
        emit(out, True)
    else:
        lines = [f"voice-coil calibration from {sum(lv.n_answers for lv in res.levels)} answers"
                 f"{' (GENERATED)' if res.generated else ''}: {res.message}",
                 f"  {'f (Hz)':>7} {'PSE (N/mm)':>11} {'95% interval':>18} {'sigma':>7}"]
        for lv in res.levels:
            flag = " censored" if lv.censored else ""
            lines.append(f"  {lv.frequency_hz:7.1f} {lv.pse_n_per_mm:11.4f} "
                         f"[{lv.pse_ci[0]:7.4f}, {lv.pse_ci[1]:7.4f}] {lv.sigma_n_per_mm:7.4f}{flag}")
        names = ("a (N/mm/Hz^2)", "b (N/mm/Hz)", "c (N/mm)")
        lines.append(f"  GS_coil(f) = a f^2 + b f + c, {100 * res.confidence:g} % intervals "
                     f"(reduced chi2 {res.chi2_reduced:.2f}):")
        for n, c, (lo, hi), pc in zip(names, res.coefficients, res.confidence_intervals, PAPER_COEFFICIENTS):
            lines.append(f"    {n:14} {c: .6g}  [{lo: .6g}, {hi: .6g}]   paper {pc:g}")
        if saved:
            lines.append(f"  saved to {saved}")
        print("\n".join(lines))
    return 0 if res.success else 1


def cmd_piezo(args: argparse.Namespace) -> int:
    """``calibrate piezo``: build the piezo table from acceleration measurements, print it
    and optionally save it. Returns the exit status.
    """
    from pathlib import Path

    import numpy as np

    from ..calibration import PiezoTable, read_measurements_csv

    _check_save(args)
    path = Path(args.measurements)
    if path.suffix.lower() == ".json":
        from ..errors import CalibrationError, ValidationError
        from ..schemas_io import read_json
        try:
            data = read_json(path, field="measurements")
        except ValidationError as exc:
            raise CalibrationError(str(exc)) from None
        table = PiezoTable.from_dict(data)
    else:
        table = read_measurements_csv(path)
    if args.serial:
        table.serial = args.serial
    # round trip at the midpoints between measured frequencies and voltages
    fm = 0.5 * (table.frequencies_hz[1:] + table.frequencies_hz[:-1])
    errs = []
    for f in fm:
        row = table._row(f)
        for a in 0.5 * (row[1:] + row[:-1]):
            v, ok = table.voltage_for(f, a)
            if ok and a > 0:
                errs.append(abs(table.acceleration_at(f, v) - a) / a)
    saved = _save(args, table)
    out: dict[str, Any] = {"kind": "piezo", "serial": table.serial, "generated": table.generated, "source": table.source,
           "frequency_range_hz": list(table.frequency_range_hz),
           "voltage_range_v": [float(table.voltages_v[0]), float(table.voltages_v[-1])],
           "acceleration_range_m_s2": [float(table.acceleration.min()), float(table.acceleration.max())],
           "grid": [int(table.frequencies_hz.size), int(table.voltages_v.size)],
           "round_trip_max_rel_error": float(np.max(errs)) if errs else None, "saved": saved}
    if args.json:
        emit(out, True)
    else:
        print(f"piezo table{' (GENERATED)' if table.generated else ''}: {out['grid'][0]} frequencies "
              f"{out['frequency_range_hz'][0]:g}..{out['frequency_range_hz'][1]:g} Hz x {out['grid'][1]} voltages "
              f"{out['voltage_range_v'][0]:g}..{out['voltage_range_v'][1]:g} V; acceleration "
              f"{out['acceleration_range_m_s2'][0]:.4g}..{out['acceleration_range_m_s2'][1]:.4g} m/s^2; "
              f"Tab round trip max error {out['round_trip_max_rel_error']:.2e}"
              + (f"; saved to {saved}" if saved else ""))
    return 0


def cmd_damping(args: argparse.Namespace) -> int:
    """``calibrate damping``: fit a hands-off run (or a GENERATED one), print the damping and
    its lower bound, optionally save the calibration; or write the excitation to play.
    Returns the exit status."""
    from ..calibration.damping import excitation, fit_damping, read_run_csv, simulated_run, write_excitation_csv

    if args.device:
        return _damping_on_device(args)
    for name, default in (("resolution", 0.055), ("mass", 0.045), ("max_force", 3.3)):
        if getattr(args, name) is None:
            setattr(args, name, default)
    if args.write_excitation:
        from ..fileio import check_output_path
        check_output_path(args.write_excitation, field="--write-excitation")
        f = excitation(args.period, args.max_force, args.mass)
        write_excitation_csv(args.write_excitation, f)
        out = {"path": args.write_excitation, "forces": int(f.size), "period_s": args.period,
               "duration_s": f.size * args.period, "peak_force_n": float(abs(f).max())}
        emit(out, args.json, f"wrote {f.size} forces ({f.size * args.period:.2f} s at {args.period:g} s, peak "
                             f"{out['peak_force_n']:.3g} N) to {args.write_excitation}; play them hands off, record "
                             "position_mm and force_n per period, then: hapticsdk calibrate damping --run CSV")
        return 0
    _check_save(args)
    if args.simulate:
        f, y = simulated_run(args.period, args.mass, args.damping, args.resolution, args.max_force)
        generated, source = True, (f"GENERATED: simulated arm, mass {args.mass:g} kg, damping {args.damping:g} "
                                   f"N*s/m, encoder {args.resolution:g} mm, period {args.period:g} s")
    else:
        f, y = read_run_csv(args.run)
        generated, source = False, f"hands-off run {args.run}"
    fit = fit_damping(f, y, args.period, args.resolution)
    return _report_damping(args, fit, args.serial, generated, source, args.resolution)


def _report_damping(args: argparse.Namespace, fit: Any, serial: str | None, generated: bool, source: str,
                    resolution_mm: float, extra: dict[str, Any] | None = None) -> int:
    """Save (``--save``/``--out``) a successful fit as the serial's damping calibration and
    print it; the exit status (1 when the fit failed)."""
    from ..calibration.damping import DampingCalibration

    saved = None
    if fit.success:
        cal = DampingCalibration.from_fit(fit, period_s=args.period, resolution_mm=resolution_mm,
                                          serial=serial, generated=generated, source=source)
        saved = _save(args, cal)
    out = {"kind": "damping", "serial": serial, "generated": generated, "source": source, **fit.to_dict(),
           "mass_kg": fit.mass_kg, "damping_ns_per_m": fit.damping_ns_per_m, **(extra or {}), "saved": saved}
    if args.json:
        emit(out, True)
    else:
        head = f"damping{' (GENERATED)' if generated else ''} from {fit.readings} readings: {fit.message}"
        if fit.success:
            head += (f"\n  fitted {fit.damping_ns_per_m:.4g} N*s/m (mass {fit.mass_kg:.4g} kg, offset "
                     f"{fit.offset_n:.3g} N); lower bound {fit.trusted_damping_ns_per_m:.4g} N*s/m (worst-case "
                     f"reading error {fit.worst_error_ns_per_m:.3g}, of it timing "
                     f"{fit.timing_error_ns_per_m:.3g}; standard error {fit.damping_se_ns_per_m:.2g}); "
                     f"rms residual {fit.fun * 1e3:.3g} mm; {fit.runtime_s * 1e3:.1f} ms")
        if extra:
            head += (f"\n  played in real time: {extra['late_ticks']} late ticks (over 1.5 periods) of "
                     f"{fit.readings - 1}, longest step {extra['longest_step_s'] * 1e3:.3g} ms, latency "
                     f"{extra['latency_s'] * 1e3:g} ms (all in the bound)")
        print(head + (f"\n  saved to {saved}" if saved else ""))
    return 0 if fit.success else 1


def _damping_on_device(args: argparse.Namespace) -> int:
    """``calibrate damping --device NAME``: open the device, play the hands-off run on it in
    real time (:func:`~hapticsdk.calibration.damping.play_damping_run`: 0 N through
    the start ramp, 0 N and closed on every exit), fit, report, save."""
    from ..calibration.damping import play_damping_run
    from ..devices.actuators import create_actuator
    from ..devices.device_options import parse_option, trusted_options
    from ..errors import ValidationError

    _check_save(args)
    opts = trusted_options(args.device)
    opts.update(parse_option(item) for item in args.device_option)
    dev = create_actuator(args.device, **opts)
    if getattr(dev, "channel", None) != "force" or not callable(getattr(dev, "read_state", None)):
        raise ValidationError(f"{args.device!r} is not a force device that reads its position", field="--device")
    own = getattr(dev, "serial_number", None)
    if own and args.serial and args.serial != own:
        # the loop looks a calibration up by the serial the device reports: one saved
        # under another would never be credited
        raise ValidationError(f"{args.device!r} reports serial {own!r}; a calibration saved for {args.serial!r} "
                              "would not be used for it (leave --serial out)", field="--serial")
    serial = own or args.serial
    run = play_damping_run(dev, period_s=args.period, axis=args.axis, mass_kg=args.mass, max_force_n=args.max_force,
                           latency_s=args.latency)
    res = float(getattr(dev, "encoder_resolution_mm", 0.0) or 0.0) if args.resolution is None else args.resolution
    source = (f"{'GENERATED: simulated device' if run.simulated else 'device'} {args.device}, hands off, played "
              f"in real time at {args.period:g} s ({run.late_ticks} late ticks), latency {run.latency_s:g} s")
    extra = {"late_ticks": run.late_ticks, "latency_s": run.latency_s,
             "longest_step_s": float(max(run.times_s[1:] - run.times_s[:-1]))}
    return _report_damping(args, run.fit, serial, run.simulated, source, res, extra)


def cmd_answers(args: argparse.Namespace) -> int:
    """``calibrate answers``: write GENERATED discrimination answers simulated from formula
    (7). Returns the exit status.
    """
    from ..calibration import generate_answers

    from ..fileio import check_output_path
    check_output_path(args.out, field="out")
    ans = generate_answers(people=args.people, seed=args.seed)
    p = ans.to_csv(args.out)
    out = {"path": str(p), "answers": len(ans), "generated": True, "source": ans.source}
    emit(out, args.json, f"wrote {len(ans)} GENERATED answers to {p}")
    return 0


def cmd_list(args: argparse.Namespace) -> int:
    """``calibrate list``: calibration files in the calibration directory and the
    calibration each kind uses. Returns the exit status.
    """
    from ..calibration import calibration_dir, calibrations_in_use, list_calibrations
    from ..errors import ValidationError

    from ..argcheck import serial_number

    serials: dict[str, str | None] = {}
    for item in args.serial:
        kind, sep, value = item.partition("=")
        if not sep or not value:
            raise ValidationError(f"expected KIND=SERIAL, got {item!r}", field="--serial")
        serials[kind] = serial_number(value, "--serial")
    directory = args.dir or calibration_dir()
    out: dict[str, Any] = {"directory": str(directory),
           "files": [e.to_dict() for e in list_calibrations(directory)],
           "in_use": calibrations_in_use(serials, directory=directory)}
    if args.json:
        emit(out, True)
    else:
        lines = [f"calibration directory: {directory}"]
        lines += [f"  {e['path']}: " + (f"skipped: {e['error']}" if e["error"] else f"{e['kind']} serial={e['serial']}")
                  for e in out["files"]] or ["  (no files)"]
        lines.append("in use:")
        lines += [f"  {u['kind']:9} serial={u['serial']} {u['origin']}: {u['source']}" for u in out["in_use"]]
        print("\n".join(lines))
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    """``replay``: summarise a recorded run file and check that it plays back unchanged.
    Returns the exit status.
    """
    import numpy as np

    from ..runlog import PlaybackDevice
    from ..runtime.recorder import load_recording

    run = load_recording(args.runfile)  # a run file, or the stream a cut-short live recording left
    dev = PlaybackDevice(run=run)
    # play every recorded state back through the device and check it returns them
    mismatches = 0
    with dev:
        for i in range(len(run)):
            st = dev.read_state()
            if not np.array_equal(st.position_mm, run.position_mm[i]):
                mismatches += 1
            dev.step(run.period_s or 1e-3)
    out = run.summary()
    out["playback_ticks"] = len(run)
    out["playback_mismatches"] = mismatches
    if args.json:
        emit(out, True)
    else:
        roles = ", ".join(f"{r} ({', '.join(sorted(v))})" for r, v in out["roles"].items()) or "none"
        dur = "(not finite)" if out["duration_s"] is None else f"{out['duration_s']:.3f}"
        print(f"{args.runfile}: {out['n_ticks']} ticks over {dur} s "
              f"(period {out['period_s'] or float('nan'):.6f} s); roles: {roles}; "
              f"playback {'ok' if mismatches == 0 else f'{mismatches} mismatching ticks'}")
        for role, fields in out["roles"].items():
            for f, r in fields.items():
                print(f"  {role}.{f}: {r['min']:.4g} .. {r['max']:.4g} over {r['ticks']} ticks")
        for name, why in out.get("not_finite", {}).items():
            print(f"  {name}: not finite, {why}")
    return 0 if mismatches == 0 else 1
