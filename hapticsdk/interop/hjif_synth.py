"""Sample-accurate synthesis of MPEG-I haptics vibrotactile content.

What is synthesised, per channel of every vibrotactile perception (``Vibrotactile``,
``Vibrotactile Texture``, and ``Other``, the modality MPEG's reference encoder writes for
every AHAP/IVS/WAV input):

- **VectorialWave** bands: each Basis effect (or Reference effect, resolved through the
  perception's ``effect_library`` and played at the reference's position) spans
  ``position .. position + last relative_position`` (ticks). Its amplitude is the linear
  interpolation of the ``amplitude_modulation`` keyframes (held before the first and after
  the last; 1 when there is none). Its frequency is the linear interpolation of the
  ``frequency_modulation`` keyframes, clamped to the band's frequency limits, and the
  signal's phase is the exact integral of that piecewise-linear frequency (a chirp between
  keyframes, no phase jump at a keyframe). The base signal (``Sine``, ``Square``,
  ``Triangle``, ``SawToothUp``, ``SawToothDown``) is evaluated at that phase plus the
  effect's ``phase``; shapes as in the reference synthesiser (every one starts at its
  value for phase 0: Sine, Triangle and the saw teeth at 0, Square at +1).
- **Transient** bands: each keyframe is a 22 ms pulse of two sine periods scaled by its
  amplitude (the reference synthesiser's transient).
- **Curve** bands: the keyframes' amplitudes interpolated (``Linear``; ``Cubic`` and the
  other curve types by a cubic spline, ``Akima`` by an Akima spline).

Bands of a channel add up; the sum is clipped to [-1, 1] and multiplied by the channel's
``gain`` (as the reference synthesiser does); ``10 ** perception_unit_exponent`` converts
that value to the perception's unit (m/s^2 for vibrotactile content, as the SDK reads it).

Not synthesised, and always reported by JSON path and name (never dropped silently):
perceptions of other modalities (force, stiffness, temperature, ...), ``WaveletWave``
bands (their SPIHT streams are not decoded) and ``Composite`` effects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Iterator

import numpy as np

from ..errors import FormatError, ValidationError
from .budget import check_output, check_rate, check_work
from .hjif_model import Band, Effect, HapticFile, Keyframe, Perception

#: modalities synthesised as vibration
VIBROTACTILE_MODALITIES = ("Vibrotactile", "Vibrotactile Texture", "Other")
#: band types synthesised
SYNTH_BAND_TYPES = ("VectorialWave", "Transient", "Curve")
#: length of a transient (ms), as in the reference synthesiser
TRANSIENT_DURATION_MS = 22.0
#: longest stretch synthesised in one call (s); pass ``seconds`` to synthesise less
MAX_SYNTH_SECONDS = 600.0


# ------------------------------------------------------------------------ base signals
def base_signal(name: str, cycles: np.ndarray) -> np.ndarray:
    """Base signal ``name`` at phase ``cycles`` (in periods, 1 = 2 pi rad); values in [-1, 1]."""
    c = np.asarray(cycles, float)
    if name == "Sine":
        return np.sin(2.0 * np.pi * c)
    if name == "Square":
        return np.where(c - np.floor(c) < 0.5, 1.0, -1.0)
    if name == "Triangle":
        u = c - 0.25
        return 1.0 - 4.0 * np.abs(np.round(u) - u)
    if name == "SawToothUp":
        return 2.0 * (c - np.floor(c + 0.5))
    if name == "SawToothDown":
        return 2.0 * (np.floor(c + 0.5) - c)
    raise ValidationError(f"unknown base signal {name!r}", field="base_signal")


# ------------------------------------------------------------------------ effect tracks
def resolve_effect(perception: Perception, effect: Effect) -> Effect:
    """The effect to play: a Reference effect replaced by its library effect (following
    library references), placed at the reference's position."""
    seen: set[int] = set()
    cur = effect
    while cur.effect_type == "Reference":
        if cur.id in seen or cur.id is None:
            raise FormatError(f"effect library references loop through id {cur.id}", field=effect.path)
        seen.add(cur.id)
        lib = perception.library_effect(cur.id)
        if lib is None:
            raise FormatError(f"effect id {cur.id} is not in the effect library", field=f"{cur.path}.id")
        cur = lib
    if cur is effect:
        return effect
    return Effect(effect_type=cur.effect_type, position=effect.position, id=cur.id, phase=cur.phase,
                  base_signal=cur.base_signal, keyframes=cur.keyframes, semantic_keywords=cur.semantic_keywords,
                  wavelet_stream=cur.wavelet_stream, path=f"{effect.path} -> {cur.path}")


def _positions(kfs: list[Keyframe], attr: str) -> tuple[np.ndarray, np.ndarray]:
    pts = [(0 if k.relative_position is None else k.relative_position, getattr(k, attr))
           for k in kfs if getattr(k, attr) is not None]
    if not pts:
        return np.zeros(0), np.zeros(0)
    a = np.asarray(pts, float)
    return a[:, 0], a[:, 1]


def effect_length_ticks(effect: Effect, band_type: str, timescale: int) -> float:
    """Length of a resolved effect (ticks): the last keyframe's relative position, plus a
    transient's duration on Transient bands; 0 without keyframes."""
    pos = [k.relative_position for k in effect.keyframes if k.relative_position is not None]
    if not effect.keyframes:
        return 0.0
    last = float(max(pos)) if pos else 0.0
    if band_type == "Transient":
        last += TRANSIENT_DURATION_MS * timescale / 1000.0
    return last


def amplitude_track(effect: Effect, rel_ticks: np.ndarray) -> np.ndarray:
    """Amplitude of a VectorialWave effect at ``rel_ticks`` (ticks from its position):
    linear between amplitude keyframes, held outside them, 1 without any."""
    xp, fp = _positions(effect.keyframes, "amplitude_modulation")
    if xp.size == 0:
        return np.ones_like(rel_ticks, dtype=float)
    return np.interp(rel_ticks, xp, fp)


def frequency_breakpoints(effect: Effect, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Breakpoints (ticks, Hz) of the effect's piecewise-linear frequency, clamped to
    ``[lo, hi]`` with the crossing points inserted (so the clamped curve is still exactly
    piecewise linear). Empty arrays when the effect has no frequency keyframe."""
    xp, fp = _positions(effect.keyframes, "frequency_modulation")
    if xp.size == 0:
        return xp, fp
    if hi < lo:
        lo, hi = hi, lo
    xs: list[float] = [float(xp[0])]
    fs: list[float] = [float(fp[0])]
    for i in range(1, xp.size):
        x0, f0, x1, f1 = float(xp[i - 1]), float(fp[i - 1]), float(xp[i]), float(fp[i])
        if x1 > x0 and f1 != f0:
            cuts = []
            for level in (lo, hi):
                s = (level - f0) / (f1 - f0)
                if 0.0 < s < 1.0:
                    cuts.append(s)
            for s in sorted(cuts):
                xs.append(x0 + s * (x1 - x0))
                fs.append(f0 + s * (f1 - f0))
        xs.append(x1)
        fs.append(f1)
    return np.asarray(xs), np.clip(np.asarray(fs), lo, hi)


def frequency_track(xs: np.ndarray, fs: np.ndarray, rel_ticks: np.ndarray) -> np.ndarray:
    """Instantaneous frequency (Hz) at ``rel_ticks``; 0 when there are no breakpoints."""
    if xs.size == 0:
        return np.zeros_like(rel_ticks, dtype=float)
    return np.interp(rel_ticks, xs, fs)


def cycles_track(xs: np.ndarray, fs: np.ndarray, rel_ticks: np.ndarray, timescale: int) -> np.ndarray:
    """Exact integral of the piecewise-linear frequency from 0 to ``rel_ticks``, in
    periods (frequency held constant before the first and after the last breakpoint)."""
    x = np.asarray(rel_ticks, float)
    if xs.size == 0:
        return np.zeros_like(x)
    dxs = np.diff(xs)
    cum = np.concatenate([[fs[0] * xs[0]], fs[0] * xs[0] + np.cumsum(0.5 * (fs[1:] + fs[:-1]) * dxs)])
    idx = np.searchsorted(xs, x, side="right") - 1
    out = np.empty_like(x)
    before = idx < 0
    out[before] = fs[0] * x[before]
    after = idx >= xs.size - 1
    out[after] = cum[-1] + fs[-1] * (x[after] - xs[-1])
    mid = ~(before | after)
    if mid.any():
        i = idx[mid]
        dx = x[mid] - xs[i]
        width = xs[i + 1] - xs[i]
        slope = np.divide(fs[i + 1] - fs[i], width, out=np.zeros_like(width), where=width > 0)
        out[mid] = cum[i] + fs[i] * dx + 0.5 * slope * dx * dx
    return out / float(timescale)


def _vectorial(effect: Effect, band: Band, rel: np.ndarray, timescale: int) -> np.ndarray:
    amp = amplitude_track(effect, rel)
    xs, fs = frequency_breakpoints(effect, band.lower_frequency_limit, band.upper_frequency_limit)
    cyc = cycles_track(xs, fs, rel, timescale) + (effect.phase or 0.0) / (2.0 * math.pi)
    return amp * base_signal(effect.base_signal or "Sine", cyc)


def _transient(effect: Effect, rel: np.ndarray, timescale: int) -> np.ndarray:
    d = TRANSIENT_DURATION_MS * timescale / 1000.0
    out = np.zeros_like(rel)
    for k in effect.keyframes:  # rel is ascending: each pulse touches only its own window
        if k.amplitude_modulation is None:
            continue
        p = 0 if k.relative_position is None else k.relative_position
        i0, i1 = np.searchsorted(rel, p, side="left"), np.searchsorted(rel, p + d, side="right")
        out[i0:i1] += k.amplitude_modulation * np.sin(4.0 * np.pi * (rel[i0:i1] - p) / d)
    return out


def _curve(effect: Effect, band: Band, rel: np.ndarray) -> np.ndarray:
    xp, fp = _positions(effect.keyframes, "amplitude_modulation")
    if xp.size == 0:
        return np.zeros_like(rel)
    kind = band.curve_type or "Cubic"
    # equal positions: keep the last value (a step), as interpolators need increasing x
    keep = np.concatenate([np.diff(xp) > 0, [True]])
    xp, fp = xp[keep], fp[keep]
    if xp.size < 3 or kind == "Linear":
        return np.interp(rel, xp, fp)
    from scipy.interpolate import Akima1DInterpolator, CubicSpline

    f = Akima1DInterpolator(xp, fp) if kind == "Akima" else CubicSpline(xp, fp, bc_type="natural")
    return np.asarray(f(np.clip(rel, xp[0], xp[-1])), float)


def effect_samples(effect: Effect, band: Band, rel_ticks: np.ndarray, timescale: int) -> np.ndarray:
    """Samples of a resolved effect at ``rel_ticks`` (ticks from its position); zero
    outside the effect's span."""
    length = effect_length_ticks(effect, band.band_type, timescale)
    rel = np.asarray(rel_ticks, float)
    inside = (rel >= 0) & (rel <= length) if effect.keyframes else np.zeros(rel.shape, bool)
    out = np.zeros_like(rel)
    if not inside.any():
        return out
    r = rel[inside]
    if band.band_type == "VectorialWave":
        out[inside] = _vectorial(effect, band, r, timescale)
    elif band.band_type == "Transient":
        out[inside] = _transient(effect, r, timescale)
    elif band.band_type == "Curve":
        out[inside] = _curve(effect, band, r)
    return out


# ------------------------------------------------------------------------ whole file
@dataclass
class ChannelSignal:
    """Synthesised signal of one channel.

    Attributes:
        path: JSON path of the channel.
        perception_index, channel_index: positions in the file.
        modality: the perception's modality.
        samples: normalised signal (clipped band sum times the channel gain).
        unit_factor: ``10 ** perception_unit_exponent``: ``samples * unit_factor`` is in
            the perception's unit.
        reference_device: name of the channel's reference device, if any.
        bands: band types synthesised.
    """

    path: str
    perception_index: int
    channel_index: int
    modality: str
    samples: np.ndarray
    unit_factor: float
    gain: float
    reference_device: str | None = None
    bands: list[str] = field(default_factory=list)


@dataclass
class Synthesis:
    """Result of :func:`synthesize`: one :class:`ChannelSignal` per synthesised channel,
    and every part not synthesised (``unsupported``: path, what, reason)."""

    fs: float
    duration_s: float
    channels: list[ChannelSignal]
    unsupported: list[dict[str, str]]

    def channel(self, path: str) -> ChannelSignal:
        """The synthesised signal of channel ``path``; raises
        :class:`~hapticsdk.errors.ValidationError` when there is none.
        """
        for c in self.channels:
            if c.path == path:
                return c
        raise ValidationError(f"no synthesised channel {path!r}", field="channel")


def is_vibrotactile(p: Perception) -> bool:
    """Whether the perception's modality is one the vibration actuators play."""
    return p.perception_modality in VIBROTACTILE_MODALITIES


def unsupported_parts(hfile: HapticFile) -> list[dict[str, str]]:
    """Every part of the file that is not synthesised as vibration, with the reason."""
    out: list[dict[str, str]] = []
    for p in hfile.perceptions:
        if not is_vibrotactile(p):
            kind = ("kinesthetic" if p.perception_modality in ("Force", "Stiffness", "Position", "Velocity",
                                                                "Acceleration", "Friction") else "non-vibrotactile")
            label = p.description.split(" hapticsdk-meta:")[0].strip()
            label = f" {label[:60]!r}" if label else ""
            out.append({"path": p.path, "what": f"perception {p.id} ({p.perception_modality}){label}",
                        "reason": f"{kind} perception: the SDK plays only vibrotactile content from .hjif files"})
            continue
        for ch in p.channels:
            for b in ch.bands:
                if b.band_type not in SYNTH_BAND_TYPES:
                    out.append({"path": b.path, "what": f"{b.band_type} band",
                                "reason": "wavelet streams are not decoded by the SDK"})
                    continue
                for e in b.effects:
                    r = resolve_effect(p, e)
                    if r.effect_type == "Composite":
                        out.append({"path": e.path, "what": "Composite effect",
                                    "reason": "composite effects are not synthesised"})
    return out


def played_effects(p: Perception, ch: Any) -> Iterator[tuple[Band, Effect]]:
    """``(band, resolved effect)`` of every effect of channel ``ch`` that is synthesised."""
    for b in ch.bands:
        if b.band_type not in SYNTH_BAND_TYPES:
            continue
        for e in b.effects:
            r = resolve_effect(p, e)
            if r.effect_type != "Composite":
                yield b, r


def file_duration_s(hfile: HapticFile) -> float:
    """End of the last synthesised effect of any vibrotactile channel (s)."""
    ts = hfile.ticks_per_second
    end = 0.0
    for p in hfile.perceptions:
        if not is_vibrotactile(p):
            continue
        for ch in p.channels:
            for b, r in played_effects(p, ch):
                end = max(end, r.position + effect_length_ticks(r, b.band_type, ts))
    return end / ts


def effect_work(hfile: HapticFile, channels: list[tuple[int, int]], end_s: float, rate_hz: float
                ) -> tuple[float, str]:
    """Effect samples that synthesising ``channels`` ((perception, channel) indices) up to
    ``end_s`` at ``rate_hz`` evaluates, and the path of the channel that costs most: each
    effect costs the samples of its own window (linear in the number of effects; nothing
    is evaluated)."""
    ts = hfile.ticks_per_second
    end = end_s * ts
    work = 0.0
    heaviest, most = "perceptions", -1.0
    for pi, ci in channels:
        p = hfile.perceptions[pi]
        before = work
        for b, r in played_effects(p, p.channels[ci]):
            lo = max(0.0, float(r.position))
            hi = min(end, r.position + effect_length_ticks(r, b.band_type, ts))
            if hi >= lo:
                work += (hi - lo) / ts * rate_hz + 1.0
        if work - before > most:
            heaviest, most = p.channels[ci].path, work - before
    return work, heaviest


def synthesize(hfile: HapticFile, *, fs: float = 8000.0, seconds: float | None = None) -> Synthesis:
    """Synthesise every vibrotactile channel of ``hfile`` at ``fs`` (Hz) for ``seconds``
    (default: to the end of the last effect, at most :data:`MAX_SYNTH_SECONDS`).

    Raises:
        ContentBudgetError: the output or the work of overlapping effects is above the
            budgets of :mod:`hapticsdk.interop.budget` (checked before anything is allocated).
    """
    if not (math.isfinite(fs) and fs > 0):
        raise ValidationError(f"sample rate must be > 0 Hz, got {fs!r}", field="fs")
    check_rate(fs, field="fs")
    ts = hfile.ticks_per_second
    unsupported = unsupported_parts(hfile)
    dur = file_duration_s(hfile) if seconds is None else float(seconds)
    if not (math.isfinite(dur) and dur >= 0):
        raise ValidationError(f"seconds must be >= 0, got {seconds!r}", field="seconds")
    if dur > MAX_SYNTH_SECONDS:
        raise ValidationError(f"content lasts {dur:.1f} s, above the {MAX_SYNTH_SECONDS:g} s synthesised at once; "
                              "pass a shorter duration (--seconds)", field="seconds")
    n = int(round(dur * fs)) + 1
    chans = [(pi, ci) for pi, p in enumerate(hfile.perceptions) if is_vibrotactile(p) for ci in range(len(p.channels))]
    check_output(len(chans), n, field="perceptions")
    check_work(*effect_work(hfile, chans, dur, fs), len(chans), n)
    t_ticks = np.arange(n) / fs * ts
    channels: list[ChannelSignal] = []
    for pi, p in enumerate(hfile.perceptions):
        if not is_vibrotactile(p):
            continue
        for ci, ch in enumerate(p.channels):
            acc = np.zeros(n)
            kinds = []
            for b in ch.bands:
                if b.band_type not in SYNTH_BAND_TYPES:
                    continue
                kinds.append(b.band_type)
                for e in b.effects:
                    r = resolve_effect(p, e)
                    if r.effect_type == "Composite":
                        continue
                    length = effect_length_ticks(r, b.band_type, ts)
                    i0 = int(np.searchsorted(t_ticks, r.position, side="left"))
                    i1 = int(np.searchsorted(t_ticks, r.position + length, side="right"))
                    if i1 > i0:
                        acc[i0:i1] += effect_samples(r, b, t_ticks[i0:i1] - r.position, ts)
            dev = p.reference_device(ch.reference_device_id)
            channels.append(ChannelSignal(path=ch.path, perception_index=pi, channel_index=ci,
                                          modality=p.perception_modality,
                                          samples=np.clip(acc, -1.0, 1.0) * ch.gain,
                                          unit_factor=10.0 ** p.perception_unit_exponent_or_default,
                                          gain=ch.gain, reference_device=dev.name if dev else None, bands=kinds))
    return Synthesis(fs=float(fs), duration_s=dur, channels=channels, unsupported=unsupported)


# ------------------------------------------------------------------------ control tracks
@dataclass
class ControlTrack:
    """What an oscillator actuator plays for one channel: per tick the frequency (Hz) and
    the normalised amplitude (>= 0, channel gain included) of the loudest active component
    (actuators play one sine at a time). ``overlaps`` counts ticks where several
    components were active (the quieter ones are not played); ``curve_ticks`` counts ticks
    with Curve-band content (a low-frequency waveform, not played by oscillators)."""

    path: str
    frequency_hz: np.ndarray
    amplitude: np.ndarray
    overlaps: int
    curve_ticks: int
    unit_factor: float
    reference_device: str | None
    base_signals: list[str]


def control_track(hfile: HapticFile, perception_index: int, channel_index: int,
                  times_s: np.ndarray) -> ControlTrack:
    """Per-tick frequency and amplitude of one vibrotactile channel at ``times_s``."""
    p = hfile.perceptions[perception_index]
    ch = p.channels[channel_index]
    ts = hfile.ticks_per_second
    t = np.asarray(times_s, float) * ts
    best_a = np.zeros_like(t)
    best_f = np.zeros_like(t)
    active = np.zeros(t.shape, int)
    curve = np.zeros(t.shape, bool)
    signals: set[str] = set()
    for b in ch.bands:
        if b.band_type not in SYNTH_BAND_TYPES:
            continue
        for e in b.effects:
            r = resolve_effect(p, e)
            if r.effect_type == "Composite" or not r.keyframes:
                continue
            length = effect_length_ticks(r, b.band_type, ts)
            # t is ascending: work on the effect's own window only
            i0 = int(np.searchsorted(t, r.position, side="left"))
            i1 = int(np.searchsorted(t, r.position + length, side="right"))
            if i1 <= i0:
                continue
            rel = t[i0:i1] - r.position
            if b.band_type == "Curve":
                curve[i0:i1] = True
                continue
            if b.band_type == "VectorialWave":
                signals.add(r.base_signal or "Sine")
                a = np.abs(amplitude_track(r, rel))
                xs, fs_ = frequency_breakpoints(r, b.lower_frequency_limit, b.upper_frequency_limit)
                f = frequency_track(xs, fs_, rel)
            else:  # Transient: 22 ms pulses of two sine periods
                a = np.zeros_like(rel)
                f = np.zeros_like(rel)
                d = TRANSIENT_DURATION_MS * ts / 1000.0
                for k in r.keyframes:
                    if k.amplitude_modulation is None:
                        continue
                    pk = 0 if k.relative_position is None else k.relative_position
                    j0, j1 = np.searchsorted(rel, pk, side="left"), np.searchsorted(rel, pk + d, side="right")
                    a[j0:j1] = np.maximum(a[j0:j1], abs(k.amplitude_modulation))
                    f[j0:j1] = 2.0 * 1000.0 / TRANSIENT_DURATION_MS
                signals.add("Transient")
            active[i0:i1] += a > 0
            take = a > best_a[i0:i1]
            best_a[i0:i1] = np.where(take, a, best_a[i0:i1])
            best_f[i0:i1] = np.where(take, f, best_f[i0:i1])
    amp = np.minimum(best_a, 1.0) * abs(ch.gain)
    dev = p.reference_device(ch.reference_device_id)
    return ControlTrack(path=ch.path, frequency_hz=best_f, amplitude=amp, overlaps=int((active > 1).sum()),
                        curve_ticks=int(curve.sum()), unit_factor=10.0 ** p.perception_unit_exponent_or_default,
                        reference_device=dev.name if dev else None, base_signals=sorted(signals))


def spectrum_peak_hz(x: np.ndarray, fs: float) -> float:
    """Frequency (Hz) of the largest FFT magnitude of ``x`` (DC excluded), refined by a
    parabola through the peak bin and its neighbours (Hann window)."""
    x = np.asarray(x, float)
    if x.size < 8 or not np.any(x):
        return 0.0
    w = np.hanning(x.size)
    mag = np.abs(np.fft.rfft((x - x.mean()) * w))
    mag[0] = 0.0
    k = int(np.argmax(mag))
    pos = float(k)
    if 0 < k < mag.size - 1:
        a, b, c = np.log(mag[k - 1:k + 2] + 1e-300)
        den = a - 2 * b + c
        pos += 0.5 * (a - c) / den if den != 0 else 0.0
    return pos * fs / x.size


def describe_channel(sig: ChannelSignal, fs: float) -> dict[str, Any]:
    """Peak frequency and envelope figures of a synthesised channel (for reports)."""
    x = sig.samples
    nz = np.flatnonzero(np.abs(x) > 1e-12)
    return {"path": sig.path, "modality": sig.modality, "bands": sig.bands, "gain": sig.gain,
            "reference_device": sig.reference_device,
            "peak_frequency_hz": round(spectrum_peak_hz(x, fs), 3),
            "max_abs": float(np.max(np.abs(x))) if x.size else 0.0,
            "rms": float(np.sqrt(np.mean(x * x))) if x.size else 0.0,
            "active_s": [float(nz[0] / fs), float(nz[-1] / fs)] if nz.size else None,
            "unit_factor": sig.unit_factor}
