"""Apple Haptic and Audio Pattern (``.ahap``) files: read, check, and convert to the SDK's
MPEG-I haptics model so that ``import`` and ``play`` treat them like ``.hjif`` content.

The structure (Apple, "Representing haptic patterns in AHAP files", Core Haptics docs):

- root: ``Version`` (number), optional ``Metadata`` (object), ``Pattern`` (array);
- each ``Pattern`` entry holds one of ``Event``, ``ParameterCurve`` or ``Parameter`` (a
  dynamic parameter);
- ``Event``: ``Time`` (s), ``EventType`` (``HapticTransient``, ``HapticContinuous``,
  ``AudioContinuous``, ``AudioCustom``), ``EventDuration`` (s, continuous events; Apple caps
  it at 30 s), ``EventParameters`` (``ParameterID`` / ``ParameterValue``: ``HapticIntensity``
  and ``HapticSharpness``, 0..1; other IDs such as ``AttackTime`` are kept out and listed),
  ``EventWaveformPath`` (audio);
- ``ParameterCurve``: ``ParameterID`` (``HapticIntensityControl``,
  ``HapticSharpnessControl``), ``Time``, ``ParameterCurveControlPoints`` (``Time`` relative
  to the curve, ``ParameterValue``), interpolated linearly between points and held after the
  last;
- ``Parameter``: ``ParameterID``, ``Time``, ``ParameterValue``: a step to the value at
  ``Time``.

Apple's loader sets missing entries to defaults, clamps out-of-range values and ignores
unknown keys. Apple's own published sample files (the AHAP samples of its Core Haptics
Unity plug-in) put a comma after the last member of an object or array, which strict JSON
refuses and the plug-in's reader accepts: the SDK reads such a file too, and says so
(:attr:`AhapPattern.relaxed`). Only a comma between a value and the ``}`` or ``]`` that
closes it is dropped; any other JSON error is reported as it is. The SDK does the same for values (every clamp is reported by JSON path) and
keys, and refuses wrong types and missing required fields with a
:class:`~hapticsdk.errors.FormatError` naming the path (``Pattern[3].Event.Time``).

Control parameters: the intensity control multiplies event intensities (0..1); the
sharpness control is added to event sharpness (-1..1). The latest curve or dynamic parameter
that has started sets a control's value.

Mapping (see ``docs/interop.md``):

- intensity -> amplitude as a fraction of the actuator's full scale;
- sharpness -> frequency ``f = 65 Hz + s x (300 - 65) Hz``. Apple publishes no physical
  mapping for sharpness (it is "the feel" of an event); this is the linear map MPEG's
  reference AHAP encoder uses (its band of 65..300 Hz);
- a continuous event is a VectorialWave effect (sine) with keyframes at its start, end and
  every control change; a transient is a VectorialWave effect of two periods of its
  frequency (the shape of MPEG's transient: two sine periods), so its sharpness is kept.
- audio events (``AudioContinuous``, ``AudioCustom``) are reported by name, not played.
"""

from __future__ import annotations

import bisect
import math
import os
import re
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..errors import FormatError
from .budget import ContentBudgetError
from .hjif_model import (
    MAX_FILE_BYTES,
    Band,
    Channel,
    Effect,
    HapticFile,
    Keyframe,
    Perception,
    load_json,
    read_bounded,
    utf8_text,
)
# typed field access with JSON-path errors, shared with the .hjif parser
from .hjif_model import _get, _obj

#: sharpness 0 and 1 map to these frequencies (Hz): MPEG reference AHAP encoder's band
SHARPNESS_HZ = (65.0, 300.0)
#: Apple's cap on a continuous event's duration (s)
MAX_CONTINUOUS_S = 30.0
#: values assumed when an event gives none (Apple's article names no defaults; these are
#: the SDK's: full intensity, mid sharpness)
DEFAULT_INTENSITY = 1.0
DEFAULT_SHARPNESS = 0.5
#: time base of the converted content (ticks per second): 0.1 ms
TIMESCALE = 10000
#: a transient plays this many periods of its frequency
TRANSIENT_PERIODS = 2
#: the longest event converted (s): a continuous event at Apple's cap, or a transient's
#: periods at the lowest frequency, whichever is longer
LONGEST_EVENT_S = max(MAX_CONTINUOUS_S, TRANSIENT_PERIODS / SHARPNESS_HZ[0])
#: latest time a pattern may name (s): an event starting then still ends within the
#: largest effect position of the converted content (2^31 - 1 ticks, as in .hjif)
MAX_TIME_S = (2 ** 31 - 1 - math.ceil(LONGEST_EVENT_S * TIMESCALE)) / TIMESCALE
#: most Pattern entries read (each costs O(log n) to convert; the synthesis budgets of
#: :mod:`hapticsdk.interop.budget` bound what they cost to play)
MAX_PATTERN_ENTRIES = 100_000
#: most control changes converted into the keyframes of one continuous event: the
#: keyframes per effect the .hjif reader rewrites at most (the same budget)
MAX_EVENT_KEYFRAMES = 4096
#: most keyframes one conversion writes (overlapping events each copy the control changes
#: inside them): 2^18 keyframes are some 50 MiB of Python objects
MAX_TOTAL_KEYFRAMES = 2 ** 18

HAPTIC_EVENTS = ("HapticTransient", "HapticContinuous")
AUDIO_EVENTS = ("AudioContinuous", "AudioCustom")
CONTROLS = {"HapticIntensityControl": (0.0, 1.0, 1.0), "HapticSharpnessControl": (-1.0, 1.0, 0.0)}


def sharpness_to_hz(s: float) -> float:
    """Frequency (Hz) for sharpness ``s`` (clamped to 0..1)."""
    s = min(1.0, max(0.0, float(s)))
    lo, hi = SHARPNESS_HZ
    return lo + s * (hi - lo)


@dataclass
class AhapEvent:
    """A haptic event: its JSON path, type, start (s), duration (s, continuous events),
    intensity and sharpness (0..1, clamped)."""

    path: str
    kind: str
    time_s: float
    duration_s: float = 0.0
    intensity: float = DEFAULT_INTENSITY
    sharpness: float = DEFAULT_SHARPNESS


@dataclass
class AhapControl:
    """A control change: a curve (points ``(t, value)``, absolute s) or a step (one point)."""

    path: str
    parameter: str
    start_s: float
    points: list[tuple[float, float]]

    def value(self, t: float) -> float:
        """Value at ``t`` >= start (linear between points, held after the last); O(log n)."""
        pts = self.points
        if t <= pts[0][0]:
            return pts[0][1]
        if t >= pts[-1][0]:
            return pts[-1][1]
        j = bisect.bisect_left(self._times(), t)
        (t0, v0), (t1, v1) = pts[j - 1], pts[j]
        return v1 if t1 == t0 else v0 + (v1 - v0) * (t - t0) / (t1 - t0)

    def _times(self) -> list[float]:
        cached = self.__dict__.get("_t")
        if cached is None or len(cached) != len(self.points):
            cached = [p[0] for p in self.points]
            self.__dict__["_t"] = cached
        return cached


@dataclass
class AhapPattern:
    """A checked AHAP pattern: haptic events, control changes, and what is not played."""

    version: float
    events: list[AhapEvent]
    controls: list[AhapControl]
    not_played: list[dict[str, str]] = field(default_factory=list)
    clamped: list[dict[str, str]] = field(default_factory=list)
    #: what was read beyond strict JSON (trailing commas), with where
    relaxed: list[dict[str, str]] = field(default_factory=list)

    def control(self, parameter: str, t: float, *, before: bool = False) -> float:
        """Value of control ``parameter`` at ``t`` (``before``: just before ``t``): the
        latest control of that parameter started by then (the later one in the file when
        two start together); O(log n)."""
        starts, ctrls = self._index(parameter)
        j = (bisect.bisect_left if before else bisect.bisect_right)(starts, t)
        if j == 0:
            return CONTROLS[parameter][2]
        return min(CONTROLS[parameter][1], max(CONTROLS[parameter][0], ctrls[j - 1].value(t)))

    def _index(self, parameter: str) -> tuple[list[float], list[AhapControl]]:
        key = ("_idx", parameter)
        memo: dict[Any, Any] = self.__dict__   # keyed by tuples, never an attribute name
        cached = memo.get(key)
        if cached is None:
            ctrls = sorted((c for c in self.controls if c.parameter == parameter), key=lambda c: c.start_s)
            cached = ([c.start_s for c in ctrls], ctrls)
            memo[key] = cached
        return cached

    def change_times(self) -> tuple[list[float], set[float]]:
        """Sorted times at which any control changes slope or steps, and the step times."""
        cached = self.__dict__.get("_changes")
        if cached is None:
            times: set[float] = set()
            steps: set[float] = set()
            for c in self.controls:
                times.add(c.start_s)
                steps.add(c.start_s)
                times.update(p[0] for p in c.points)
            cached = (sorted(times), steps)
            self.__dict__["_changes"] = cached
        return cached


# ------------------------------------------------------------------------ reading
def read_ahap(path: str | os.PathLike[str], *, max_bytes: int = MAX_FILE_BYTES) -> AhapPattern:
    """Read and check an ``.ahap`` file (the same size and depth caps and the same bounded
    reader as ``.hjif``: :func:`~hapticsdk.interop.hjif_model.read_bounded`)."""
    name, data = read_bounded(path, max_bytes=max_bytes, kind=".ahap")
    return parse_ahap_text(utf8_text(data, source=name), source=name)


def parse_ahap_text(text: str, *, source: str = "ahap") -> AhapPattern:
    """Parse AHAP JSON text (duplicate keys are read as Apple's JSON reader reads them:
    the last one counts). Text that is JSON once the commas before a closing ``}`` or ``]``
    are dropped is read, and the pattern's ``relaxed`` says where the first one was and how
    many there were; otherwise the strict parser's error stands."""
    try:
        return parse_ahap(load_json(text, source=source, unique_keys=False))
    except FormatError as exc:
        if exc.field != source:     # a field's error: the JSON itself was read
            raise
        strict = exc
    stripped, dropped = _without_trailing_commas(text)
    if not dropped:
        raise strict
    try:
        doc = load_json(stripped, source=source, unique_keys=False)
    except FormatError:
        raise strict from None
    pat = parse_ahap(doc)
    line = text.count("\n", 0, dropped[0]) + 1
    col = dropped[0] - (text.rfind("\n", 0, dropped[0]) + 1) + 1
    pat.relaxed.append({"path": f"line {line} column {col}",
                        "change": f"{len(dropped)} trailing comma{'s' if len(dropped) > 1 else ''} before a "
                                  "closing } or ] ignored (not JSON; Apple's Core Haptics Unity plug-in reads it)"})
    return pat


#: a JSON string (skipped whole), or a comma followed by whitespace and a closing bracket
_TRAILING = re.compile(r'"(?:[^"\\]|\\.)*"|,(?=[ \t\r\n]*[}\]])')
#: what a JSON value ends with: a string's quote, a number's digit, true/false/null, } or ]
_VALUE_END = frozenset('"0123456789eEl}]')


def _without_trailing_commas(text: str) -> tuple[str, list[int]]:
    """``text`` without the commas that follow a value and precede a ``}`` or ``]`` (strings
    left as they are), and the offsets of the commas dropped. A comma after ``[``, ``{``
    or another comma is not a trailing comma and stays (the strict error then stands)."""
    dropped: list[int] = []
    parts: list[str] = []
    last = 0
    for m in _TRAILING.finditer(text):
        if m.group(0) != ",":
            continue
        i = m.start() - 1
        while i >= 0 and text[i] in " \t\r\n":
            i -= 1
        if i < 0 or text[i] not in _VALUE_END:
            continue
        parts.append(text[last:m.start()])
        last = m.end()
        dropped.append(m.start())
    parts.append(text[last:])
    return "".join(parts), dropped


def _num(obj: Mapping[str, Any], key: str, path: str, *, required: bool = True, default: float = 0.0) -> float:
    return float(_get(obj, key, path, "number", required=required, default=default))


def _str(obj: Mapping[str, Any], key: str, path: str) -> str:
    v: str = _get(obj, key, path, "str")
    return v


def _list(obj: Mapping[str, Any], key: str, path: str, *, required: bool = True) -> list[Any]:
    v: list[Any] = _get(obj, key, path, "list", required=required, default=[])
    return v


def parse_ahap(doc: Any) -> AhapPattern:
    """Check a decoded AHAP document and return its :class:`AhapPattern`."""
    root = _obj(doc, "$")
    version = _num(root, "Version", "", required=False, default=1.0)
    if "Metadata" in root:
        _obj(root["Metadata"], "Metadata")
    entries = _list(root, "Pattern", "")
    if len(entries) > MAX_PATTERN_ENTRIES:
        raise FormatError(f"{len(entries)} entries, above the {MAX_PATTERN_ENTRIES} read", field="Pattern")
    pat = AhapPattern(version=version, events=[], controls=[])

    def clamp(v: float, lo: float, hi: float, where: str) -> float:
        if v < lo or v > hi:
            c = min(hi, max(lo, v))
            pat.clamped.append({"path": where, "change": f"{v!r} clamped to {c!r} (range {lo:g}..{hi:g})"})
            return c
        return v

    for i, e in enumerate(entries):
        path = f"Pattern[{i}]"
        e = _obj(e, path)
        kinds = [k for k in ("Event", "ParameterCurve", "Parameter") if k in e]
        if len(kinds) != 1:
            raise FormatError("an entry holds exactly one of Event, ParameterCurve, Parameter"
                              + (f" (has {', '.join(kinds)})" if kinds else ""), field=path)
        kind = kinds[0]
        path = f"{path}.{kind}"
        body = _obj(e[kind], path)
        t = clamp(_num(body, "Time", path), 0.0, math.inf, f"{path}.Time")
        if t > MAX_TIME_S:
            raise FormatError(f"{t:g} s is beyond the latest time read ({MAX_TIME_S:.0f} s)", field=f"{path}.Time")
        if kind == "Event":
            etype = _str(body, "EventType", path)
            if etype in AUDIO_EVENTS:
                wave = body.get("EventWaveformPath")
                pat.not_played.append({"path": path, "what": f"{etype} event"
                                       + (f" ({wave})" if isinstance(wave, str) else ""),
                                       "reason": "audio events are not played (the SDK drives haptic actuators)"})
                continue
            if etype not in HAPTIC_EVENTS:
                raise FormatError(f"unknown EventType {etype!r}; expected one of "
                                  f"{', '.join(HAPTIC_EVENTS + AUDIO_EVENTS)}", field=f"{path}.EventType")
            ev = AhapEvent(path=path, kind=etype, time_s=t)
            if etype == "HapticContinuous":
                ev.duration_s = clamp(_num(body, "EventDuration", path), 0.0, MAX_CONTINUOUS_S, f"{path}.EventDuration")
            for j, prm in enumerate(_list(body, "EventParameters", path, required=False)):
                ppath = f"{path}.EventParameters[{j}]"
                prm = _obj(prm, ppath)
                pid = _str(prm, "ParameterID", ppath)
                val = _num(prm, "ParameterValue", ppath)
                if pid == "HapticIntensity":
                    ev.intensity = clamp(val, 0.0, 1.0, f"{ppath}.ParameterValue")
                elif pid == "HapticSharpness":
                    ev.sharpness = clamp(val, 0.0, 1.0, f"{ppath}.ParameterValue")
                else:
                    pat.not_played.append({"path": ppath, "what": f"event parameter {pid}",
                                           "reason": "not rendered (the SDK renders intensity and sharpness)"})
            pat.events.append(ev)
            continue
        pid = _str(body, "ParameterID", path)
        if pid not in CONTROLS:
            pat.not_played.append({"path": path, "what": f"{kind} {pid}",
                                   "reason": "not rendered (the SDK renders the intensity and sharpness controls)"})
            continue
        lo, hi, _ = CONTROLS[pid]
        if kind == "Parameter":
            v = clamp(_num(body, "ParameterValue", path), lo, hi, f"{path}.ParameterValue")
            pat.controls.append(AhapControl(path, pid, t, [(t, v)]))
            continue
        pts: list[tuple[float, float]] = []
        for j, cp in enumerate(_list(body, "ParameterCurveControlPoints", path)):
            cpath = f"{path}.ParameterCurveControlPoints[{j}]"
            cp = _obj(cp, cpath)
            ct = t + clamp(_num(cp, "Time", cpath), 0.0, math.inf, f"{cpath}.Time")
            if ct > MAX_TIME_S:
                raise FormatError(f"{ct:g} s is beyond the latest time read ({MAX_TIME_S:.0f} s)",
                                  field=f"{cpath}.Time")
            if pts and ct < pts[-1][0]:
                raise FormatError(f"control points out of time order ({ct - t:g} s after {pts[-1][0] - t:g} s)",
                                  field=f"{cpath}.Time")
            pts.append((ct, clamp(_num(cp, "ParameterValue", cpath), lo, hi, f"{cpath}.ParameterValue")))
        if not pts:
            raise FormatError("a parameter curve needs at least one control point",
                              field=f"{path}.ParameterCurveControlPoints")
        pat.controls.append(AhapControl(path, pid, t, pts))
    return pat


# ------------------------------------------------------------------------ conversion
def _ticks(t_s: float) -> int:
    return int(round(t_s * TIMESCALE))


def _continuous(pat: AhapPattern, ev: AhapEvent) -> Effect:
    t0, t1 = ev.time_s, ev.time_s + ev.duration_s
    times, steps = pat.change_times()
    inner = times[bisect.bisect_right(times, t0):bisect.bisect_left(times, t1)]
    if len(inner) > MAX_EVENT_KEYFRAMES:
        raise ContentBudgetError(f"{len(inner)} control changes inside one continuous event, above the "
                                 f"{MAX_EVENT_KEYFRAMES} converted (docs/safety.md)", field=ev.path)
    cuts = {t0, t1, *inner}

    def kf(t: float, before: bool) -> Keyframe:
        a = ev.intensity * pat.control("HapticIntensityControl", t, before=before)
        s = ev.sharpness + pat.control("HapticSharpnessControl", t, before=before)
        return Keyframe(_ticks(t - t0), min(1.0, max(0.0, a)), sharpness_to_hz(s))

    kfs: list[Keyframe] = []
    for t in sorted(cuts):
        if t == t1 and t1 > t0:  # a change exactly at the end does not play
            kfs.append(kf(t, True))
            continue
        if t in steps and t != t0:  # a step inside: the value before it, then after
            kfs.append(kf(t, True))
        kfs.append(kf(t, False))
    return Effect("Basis", _ticks(t0), phase=0.0, base_signal="Sine", keyframes=kfs, path=ev.path)


def _transient_hz(pat: AhapPattern, ev: AhapEvent) -> float:
    """Frequency of a transient: its sharpness plus the sharpness control at its time."""
    return sharpness_to_hz(ev.sharpness + pat.control("HapticSharpnessControl", ev.time_s))


def _transient(pat: AhapPattern, ev: AhapEvent) -> Effect:
    t = ev.time_s
    f = _transient_hz(pat, ev)
    a = min(1.0, max(0.0, ev.intensity * pat.control("HapticIntensityControl", t)))
    length = max(1, _ticks(TRANSIENT_PERIODS / f))
    return Effect("Basis", _ticks(t), phase=0.0, base_signal="Sine",
                  keyframes=[Keyframe(0, a, f), Keyframe(length, a, f)], path=ev.path)


def to_haptic_file(pat: AhapPattern, *, source: str = "ahap") -> HapticFile:
    """The pattern as one Vibrotactile perception: a channel with a band of continuous
    events and a band of transients (bands add up, as MPEG's synthesiser adds them).
    Amplitudes are fractions of the actuator's full scale."""
    lo, hi = int(math.floor(SHARPNESS_HZ[0])), int(math.ceil(SHARPNESS_HZ[1]))
    cont = []
    total = 0
    for e in pat.events:
        if e.kind != "HapticContinuous":
            continue
        cont.append(_continuous(pat, e))
        total += len(cont[-1].keyframes)
        if total > MAX_TOTAL_KEYFRAMES:
            raise ContentBudgetError(f"continuous events would need more than {MAX_TOTAL_KEYFRAMES} keyframes "
                                     "(overlapping events under many control changes; docs/safety.md)", field=e.path)
    cont.sort(key=lambda x: x.position)
    tran = sorted((_transient(pat, e) for e in pat.events if e.kind == "HapticTransient"), key=lambda x: x.position)
    bands = []
    if cont:
        bands.append(Band("VectorialWave", lo, hi, effects=cont, path="perceptions[0].channels[0].bands[0]"))
    if tran:
        bands.append(Band("VectorialWave", lo, hi, effects=tran, path=f"perceptions[0].channels[0].bands[{len(bands)}]"))
    ch = Channel(0, "AHAP haptic events (amplitude: fraction of full scale)", 1.0, 1.0, 0, bands=bands,
                 path="perceptions[0].channels[0]")
    per = Perception(0, 0, f"converted from Apple AHAP {source}", "Vibrotactile", channels=[ch],
                     unit_exponent=0, perception_unit_exponent=0, modality_as_written="AHAP", path="perceptions[0]")
    return HapticFile(version="AHAP", profile="Main", level=1, date="", description=f"AHAP {pat.version:g}",
                      perceptions=[per], timescale=TIMESCALE)


def summary(pat: AhapPattern, *, source: str | None = None) -> dict[str, Any]:
    """What an AHAP file holds and what the SDK plays of it (``import --json``)."""
    end = 0.0
    for e in pat.events:
        last = e.duration_s if e.kind == "HapticContinuous" else TRANSIENT_PERIODS / _transient_hz(pat, e)
        end = max(end, e.time_s + last)
    return {"file": source, "format": "AHAP", "version": pat.version,
            "events": {k: sum(e.kind == k for e in pat.events) for k in HAPTIC_EVENTS},
            "controls": {k: sum(c.parameter == k for c in pat.controls) for k in CONTROLS},
            "duration_s": end, "sharpness_to_frequency_hz": list(SHARPNESS_HZ),
            "clamped": list(pat.clamped), "not_played": list(pat.not_played), "relaxed": list(pat.relaxed)}


def format_summary(s: dict[str, Any]) -> str:
    """Human-readable form of :func:`summary`."""
    ev = ", ".join(f"{v} {k}" for k, v in s["events"].items())
    lines = [f"{s.get('file') or 'ahap'}: Apple AHAP version {s['version']:g}, {ev}, {s['duration_s']:.3f} s; "
             f"sharpness 0..1 -> {s['sharpness_to_frequency_hz'][0]:g}..{s['sharpness_to_frequency_hz'][1]:g} Hz"]
    lines += [f"  read beyond strict JSON: {r['path']}: {r['change']}" for r in s.get("relaxed", [])]
    lines += [f"  clamped: {c['path']}: {c['change']}" for c in s["clamped"]]
    lines += [f"  not played: {u['path']}: {u['what']}: {u['reason']}" for u in s["not_played"]]
    return "\n".join(lines)
