"""Play the vibrotactile content of a ``.hjif`` file on the SDK's vibration actuators.

The actuators (``piezo-virtual``, ``voicecoil-virtual``, and their hardware siblings) are
oscillators: each servo tick they take one frequency and one amplitude through their
public :meth:`~hapticsdk.devices.actuators.Actuator.command`, which passes the safety layer. So
each tick the player sends, per actuator, the loudest component active among the
channels routed to it (:func:`hapticsdk.interop.hjif_synth.control_track`), and reports
what that leaves out (other base signals than Sine play as their fundamental; overlapping
components; Curve-band content).

Routing: a channel whose reference device names one of the selected actuators plays on
that actuator only; a channel naming another SDK actuator is reported and not played;
a channel without a reference device plays on every selected actuator.

Amplitude mapping, by each actuator's calibration:

- piezo: the channel value times ``10 ** perception_unit_exponent`` is an acceleration
  (m/s^2); the roughness table ``Tab`` gives the voltage for it at the tick's frequency;
- voice coil: its amplitude unit is a normalised drive (0..1): the normalised value is the
  drive. Its calibration (formula (7)) maps drive frequency to perceived added stiffness,
  reported for the played frequencies inside its range.

Time is simulated (as fast as the machine goes) unless ``realtime`` or an actuator is
real (not ``simulated``: then always paced on the clock); every exit path
(end, exception of any type, ``KeyboardInterrupt``) stops and closes every actuator
opened. Nothing is opened before the whole file has been checked and tracked.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ..errors import ValidationError
from .hjif_model import HapticFile
from .budget import check_output, check_work
from .hjif_synth import (
    MAX_SYNTH_SECONDS,
    effect_work,
    control_track,
    file_duration_s,
    is_vibrotactile,
    spectrum_peak_hz,
    unsupported_parts,
)

DEFAULT_ACTUATORS = ("piezo-virtual", "voicecoil-virtual")
#: SDK actuator names a reference device may name to route a channel
SDK_VIBRATION_ACTUATORS = ("piezo-virtual", "piezo-serial", "piezo-usb", "voicecoil-virtual")


@dataclass
class PlayReport:
    """Outcome of :func:`play`: per actuator what was commanded and output, the routing,
    and every part of the file not played (with reasons)."""

    seconds: float
    tick_s: float
    realtime: bool
    actuators: dict[str, dict[str, Any]] = field(default_factory=dict)
    routing: list[dict[str, Any]] = field(default_factory=list)
    not_played: list[dict[str, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """The report as a JSON-ready dict: duration (s), tick (s), real time or not, per-
        actuator summary, routing, what was not played and notes.
        """
        return {"seconds": self.seconds, "tick_s": self.tick_s, "realtime": self.realtime,
                "actuators": self.actuators, "routing": self.routing, "not_played": self.not_played,
                "notes": self.notes}


def _route(hfile: HapticFile, actuators: Sequence[str]) -> tuple[list[tuple[int, int, list[str]]], list[dict[str, Any]],
                                                                  list[dict[str, str]]]:
    plan: list[tuple[int, int, list[str]]] = []
    routing: list[dict[str, Any]] = []
    skipped: list[dict[str, str]] = []
    for pi, p in enumerate(hfile.perceptions):
        if not is_vibrotactile(p):
            continue
        for ci, ch in enumerate(p.channels):
            dev = p.reference_device(ch.reference_device_id)
            name = dev.name if dev else None
            if name is not None and name in actuators:
                targets = [name]
            elif name in SDK_VIBRATION_ACTUATORS:
                skipped.append({"path": ch.path, "what": f"channel {ch.id}",
                                "reason": f"its reference device {name!r} is not among the selected actuators "
                                          f"{list(actuators)}"})
                continue
            else:
                targets = list(actuators)
            plan.append((pi, ci, targets))
            routing.append({"channel": ch.path, "reference_device": name, "actuators": targets})
    return plan, routing, skipped


def _piezo_table(table: Any) -> Any:
    from hapticsdk_roughness.table import (
        resolve_table,  # the piezo's calibration (roughness Tab)
    )
    return resolve_table(table)


def _band_limits(hfile: HapticFile) -> tuple[float, float]:
    """Lowest lower and highest upper frequency limit of the vibrotactile bands (Hz)."""
    lims = [(b.lower_frequency_limit, b.upper_frequency_limit) for p in hfile.perceptions if is_vibrotactile(p)
            for c in p.channels for b in c.bands]
    if not lims:
        return (0.0, 0.0)
    return float(min(x for x, _ in lims)), float(max(y for _, y in lims))


def piezo_full_scale_m_s2(table: Any, band_hz: tuple[float, float], max_volts: float | None = None) -> float:
    """Largest acceleration (m/s^2) the piezo ``table`` reaches at its highest voltage (or at
    ``max_volts``, the actuator's declared maximum, when lower) at every frequency of
    ``band_hz`` (clamped to the table): a normalised amplitude of 1.0 then means the same
    acceleration at any frequency of the band, and never a voltage the actuator clips."""
    lo_t, hi_t = table.frequency_range_hz
    lo, hi = max(band_hz[0], lo_t), min(band_hz[1], hi_t)
    if hi < lo:
        lo = hi = min(max(band_hz[0], lo_t), hi_t)
    grid = np.linspace(lo, hi, 64)
    top = float(table.voltages_v[-1])
    volts = top if max_volts is None else min(top, float(max_volts))
    return float(np.min(table.accelerations_at(grid, volts)))


def _declared_max_volts(act: Any) -> float | None:
    """The actuator's declared maximum drive (V), or ``None`` when it declares none in V."""
    lim = getattr(act, "limits", None)
    vmax = getattr(lim, "max_amplitude", None)
    return float(vmax) if vmax is not None and getattr(lim, "amplitude_unit", "") == "V" else None


def play(hfile: HapticFile, *, seconds: float | None = None, actuators: Sequence[str] = DEFAULT_ACTUATORS,
         tick_s: float = 0.001, realtime: bool = False, piezo_table: Any = None,
         actuator_options: dict[str, dict[str, Any]] | None = None, piezo_full_scale: bool = False) -> PlayReport:
    """Play ``hfile``'s vibrotactile channels for ``seconds`` (default: its length).

    Args:
        hfile: a checked file (:func:`hapticsdk.interop.hjif_model.read_hjif`).
        seconds: duration (s), at most :data:`~hapticsdk.interop.hjif_synth.MAX_SYNTH_SECONDS`.
        actuators: actuator plugin names to play on.
        tick_s: servo period (s).
        realtime: pace ticks to the wall clock (default: simulated time; always paced
            when one of the actuators is real, i.e. not ``simulated``).
        piezo_table: the piezo's ``Tab`` (path, dict or table; default the generated one).
        actuator_options: name -> keyword options for :func:`~hapticsdk.devices.actuators.create_actuator`,
            merged over the user device configuration file and ``$HAPTICSDK_DEVICE_OPTIONS``
            (:func:`hapticsdk.devices.device_options.trusted_options`), as for ``render_plan``.
        piezo_full_scale: amplitudes are fractions of the piezo's full scale (AHAP content):
            1.0 is the largest acceleration its table reaches at every frequency of the
            content's bands (see :func:`piezo_full_scale_m_s2`), instead of m/s^2.
    """
    from ..devices.actuators import create_actuator

    if not (math.isfinite(tick_s) and 1e-5 <= tick_s <= 0.1):
        raise ValidationError(f"must be in [1e-5, 0.1] s, got {tick_s!r}", field="tick_s")
    if not actuators:
        raise ValidationError("no actuator selected", field="actuators")
    dur = file_duration_s(hfile) if seconds is None else float(seconds)
    if not (math.isfinite(dur) and 0 <= dur <= MAX_SYNTH_SECONDS):
        raise ValidationError(f"must be in [0, {MAX_SYNTH_SECONDS:g}] s, got {dur!r}", field="seconds")
    n = int(math.ceil(dur / tick_s - 1e-9))
    times = np.arange(n) * tick_s
    plan, routing, skipped = _route(hfile, list(actuators))
    # budgets (docs/safety.md) before any track is computed
    check_output(len(plan), n, field="perceptions")
    check_work(*effect_work(hfile, [(pi, ci) for pi, ci, _ in plan], dur, 1.0 / tick_s), len(plan), n)
    report = PlayReport(seconds=n * tick_s, tick_s=tick_s, realtime=realtime, routing=routing,
                        not_played=unsupported_parts(hfile) + skipped)

    # every track and mapped command computed before any actuator is opened
    per_act: dict[str, list[Any]] = {a: [] for a in actuators}
    for pi, ci, targets in plan:
        tr = control_track(hfile, pi, ci, times)
        for a in targets:
            per_act[a].append(tr)
        if tr.overlaps:
            report.notes.append(f"{tr.path}: {tr.overlaps} tick(s) with overlapping components; "
                                "the loudest one is played")
        if tr.curve_ticks:
            report.notes.append(f"{tr.path}: Curve-band content on {tr.curve_ticks} tick(s) is not played "
                                "by oscillator actuators")
        other = [s for s in tr.base_signals if s not in ("Sine", "Transient")]
        if other:
            report.notes.append(f"{tr.path}: base signal(s) {', '.join(other)} played as their fundamental sine")
    commands: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    table = None
    made: dict[str, Any] = {}  # actuators created (never opened) to read their declared limits

    def options(a: str) -> dict[str, Any]:
        from ..devices.device_options import trusted_options  # as render_plan: config < environment < code
        return {**trusted_options(a), **dict((actuator_options or {}).get(a, {}))}

    for a, tracks in per_act.items():
        if not tracks:
            continue
        amp_n = np.zeros(n)
        amp_u = np.zeros(n)
        freq = np.zeros(n)
        if len(tracks) > 1:
            both = int((np.sum([tr.amplitude > 0 for tr in tracks], axis=0) > 1).sum())
            if both:
                report.notes.append(f"{a}: {both} tick(s) where {len(tracks)} channels overlap; "
                                    "the loudest one is played")
        for tr in tracks:
            take = tr.amplitude > amp_n
            amp_n = np.where(take, tr.amplitude, amp_n)
            amp_u = np.where(take, tr.amplitude * tr.unit_factor, amp_u)
            freq = np.where(take, tr.frequency_hz, freq)
        if a.startswith("piezo"):
            table = table or _piezo_table(piezo_table)
            if piezo_full_scale:
                made[a] = create_actuator(a, **options(a))  # not opened: its declared limits
                fs_acc = piezo_full_scale_m_s2(table, _band_limits(hfile), _declared_max_volts(made[a]))
                amp_u = amp_n * fs_acc
                report.notes.append(f"{a}: amplitude 1.0 = {fs_acc:.4g} m/s^2 (the largest acceleration its table "
                                    "reaches within its declared maximum at every frequency of the content)")
            out = np.zeros(n)
            cache: dict[tuple[float, float], float] = {}
            for j in np.flatnonzero(amp_u > 0):
                key = (float(freq[j]), float(amp_u[j]))
                if key not in cache:
                    cache[key] = table.voltage_for(*key)[0]
                out[j] = cache[key]
            commands[a] = (freq, out, amp_u)
        else:
            commands[a] = (freq, amp_n, amp_u)
    if not commands:
        report.notes.append("nothing to play on the selected actuators")
        return report

    opened: dict[str, Any] = {}
    outputs: dict[str, list[np.ndarray]] = {a: [] for a in commands}
    try:
        for a in commands:
            act = made.get(a) or create_actuator(a, **options(a))
            opened[a] = act
            act.open()
            if hasattr(act.safety, "set_period"):
                # like the servo loop: stale-command age and the backend's command
                # deadline (DRV2667 host watchdog: 3 periods at least) follow the tick
                act.safety.set_period(tick_s)
        from ..perception.dimensions import ChannelCommand

        # a real actuator is always paced: content played back to back on hardware would
        # be all of the file's seconds in a fraction of the time
        realtime = bool(realtime) or any(not getattr(act, "simulated", False) for act in opened.values())
        report.realtime = realtime
        t0 = time.monotonic()
        last_f = {a: 0.0 for a in commands}
        for k in range(n):
            now = t0 + k * tick_s
            if realtime:
                delay = now - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            for a, (freq, amp, _) in commands.items():
                f = float(freq[k]) if amp[k] > 0 else last_f[a]
                if f > 0:
                    last_f[a] = f
                cmd = ChannelCommand(role="vibration", frequency_hz=f if f > 0 else None, amplitude=float(amp[k]))
                opened[a].command(cmd, now=now)
            for a in commands:
                step = getattr(opened[a], "step", None)
                if step is not None:
                    y = step(tick_s)
                    if isinstance(y, np.ndarray) and y.size:
                        outputs[a].append(y)
    finally:
        for act in opened.values():
            act.stop()
            act.close()

    for a, (freq, amp, amp_u) in commands.items():
        act = opened[a]
        on = amp > 0
        info: dict[str, Any] = {"ticks": n, "active_ticks": int(on.sum()),
                                "frequency_hz": [float(freq[on].min()), float(freq[on].max())] if on.any() else None,
                                "max_amplitude": float(amp.max()) if n else 0.0,
                                "amplitude_unit": act.limits.amplitude_unit,
                                "safety": act.safety.report()}
        if a.startswith("piezo"):
            info["max_acceleration_m_s2_requested"] = float(amp_u.max()) if n else 0.0
            info["table_generated"] = bool(getattr(table, "generated", False))
            if hasattr(act, "waveform"):
                _, v = act.waveform()
                info["output_peak_frequency_hz"] = round(spectrum_peak_hz(v, act.fs), 3)
                info["output_max_v"] = float(np.max(np.abs(v))) if v.size else 0.0
        else:
            y = np.concatenate(outputs[a]) if outputs[a] else np.zeros(0)
            fs = float(getattr(act, "fs", 0.0) or 0.0)
            if y.size and fs:
                info["output_peak_frequency_hz"] = round(spectrum_peak_hz(y, fs), 3)
                info["output_max"] = float(np.max(np.abs(y)))
            if a.startswith("voicecoil") and on.any():
                from ..calibration import VoiceCoilCalibration
                cal = VoiceCoilCalibration.paper()
                lo, hi = cal.frequency_range_hz
                fr = freq[on]
                inr = fr[(fr >= lo) & (fr <= hi)]
                if inr.size:
                    gs = cal.gs_coil(inr)
                    info["perceived_added_stiffness_n_per_mm"] = [float(np.min(gs)), float(np.max(gs))]
        report.actuators[a] = info
    return report


def format_report(r: PlayReport) -> str:
    """Text of a play report: what was played on which actuator (frequency and amplitude
    ranges), and what was not played and why.
    """
    lines = [f"played {r.seconds:.3f} s ({'real time' if r.realtime else 'simulated time'}, tick {r.tick_s * 1e3:g} ms)"]
    for a, info in r.actuators.items():
        fr = info["frequency_hz"]
        frs = f"{fr[0]:.4g}..{fr[1]:.4g} Hz" if fr else "silent"
        out = f", output peak {info['output_peak_frequency_hz']:g} Hz" if "output_peak_frequency_hz" in info else ""
        hits = info["safety"].get("limit_hits") if isinstance(info["safety"], dict) else None
        lines.append(f"  {a}: {info['active_ticks']}/{info['ticks']} ticks active, {frs}, max amplitude "
                     f"{info['max_amplitude']:.4g} {'(normalised)' if info['amplitude_unit'] in ('1', '') else info['amplitude_unit']}{out}"
                     + (f", safety limits hit {hits}" if hits else "")
                     + (" (voltages from the GENERATED piezo table)" if info.get("table_generated") else ""))
    for x in r.routing:
        lines.append(f"  {x['channel']} -> {', '.join(x['actuators'])}")
    for u in r.not_played:
        lines.append(f"  not played: {u['path']}: {u['what']}: {u['reason']}")
    for note in r.notes:
        lines.append(f"  note: {note}")
    return "\n".join(lines)
