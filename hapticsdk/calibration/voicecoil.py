"""Voice-coil perceived-stiffness calibration, formula (7) of the reference paper.

``GS_coil(f) = a f^2 + b f + c`` (N/mm) over ``f_min <= f <= f_max`` (Hz): the extra
stiffness a person perceives when the voice coil vibrates at ``f`` while pressing.
The paper's fit (a, b, c) = (0.00012, 0.01, -0.3045) over 30..120 Hz is the default.

:func:`hapticsdk.calibration.voicecoil_fit.fit_voicecoil` rebuilds the calibration
from discrimination answers (:mod:`hapticsdk.calibration.discrimination`).
The calibration holds only for the amplifier gain and mounting it was measured with
(``amplifier_gain``, ``mounting``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping, cast

import numpy as np

from ..errors import CalibrationError, ValidationError

PAPER_COEFFICIENTS = (0.00012, 0.01, -0.3045)
PAPER_RANGE_HZ = (30.0, 120.0)
#: Plausibility limit of a calibration's frequency range (Hz): vibrotactile sensitivity
#: ends near 1 kHz, and voice-coil tactors are driven at tens to hundreds of Hz; a curve
#: fitted over 1e5..1e6 Hz is refused, not clamped at render time.
MAX_FREQUENCY_HZ = 2000.0
#: Plausibility limit of ``amplifier_gain`` (dimensionless voltage gain of an audio/
#: tactor amplifier; 1e4 is 80 dB).
MAX_AMPLIFIER_GAIN = 1.0e4


def check_amplifier_gain(gain: Any) -> float | None:
    """``None`` or a finite number in ``(0, MAX_AMPLIFIER_GAIN]``; bool, NaN, negative
    and zero gains raise :class:`CalibrationError` naming ``amplifier_gain``."""
    from ..checks import is_number

    if gain is None:
        return None
    try:
        g = float(gain) if is_number(gain) else math.nan
    except OverflowError:   # an int beyond the float range
        g = math.inf
    if not np.isfinite(g) or not 0 < g <= MAX_AMPLIFIER_GAIN:
        raise CalibrationError(f"voice-coil calibration: amplifier_gain must be a finite number in "
                               f"(0, {MAX_AMPLIFIER_GAIN:g}] or null, got {gain!r}")
    return float(gain)


def calibration_flag(data: Mapping[str, Any], key: str) -> bool:
    """``data[key]`` (default False) when it is a bool: ``"false"`` or ``0`` in a
    calibration's ``generated`` is not a flag (``bool("false")`` is True)."""
    from ..argcheck import flag
    try:
        return flag(data.get(key, False), key)
    except ValidationError as exc:   # a calibration's own error, with the field in its text
        raise CalibrationError(f"{key} {exc.reason}") from None


@dataclass(frozen=True)
class VoiceCoilCalibration:
    """Quadratic map drive frequency (Hz) -> perceived added stiffness (N/mm).

    Attributes:
        coefficients: (a, b, c) of ``a f^2 + b f + c``.
        frequency_range_hz: (f_min, f_max) where the fit holds.
        source: where the coefficients come from.
        confidence_intervals: optional 95 % intervals per coefficient.
        extra: free JSON-ready details (e.g. the per-level PSEs of a fit).
        serial: serial number of the voice coil / amplifier set it belongs to (``None``:
            any device).
        generated: True when fitted to generated (not measured) answers.
        amplifier_gain: amplifier gain the answers were measured with (``None``: the
            paper's, unknown).
        mounting: free text describing how the tactor was mounted.
    """

    coefficients: tuple[float, float, float] = PAPER_COEFFICIENTS
    frequency_range_hz: tuple[float, float] = PAPER_RANGE_HZ
    source: str = "paper formula (7)"
    confidence_intervals: tuple[tuple[float, float], ...] | None = None
    extra: dict[str, Any] = field(default_factory=dict, compare=False)
    serial: str | None = None
    generated: bool = False
    amplifier_gain: float | None = None
    mounting: str = ""

    def __post_init__(self) -> None:
        from ..checks import is_number

        if len(tuple(self.coefficients)) != 3 or len(tuple(self.frequency_range_hz)) != 2 or not all(
                is_number(v) for v in (*self.coefficients, *self.frequency_range_hz)):
            raise CalibrationError(f"voice-coil calibration: coefficients (a, b, c) and frequency_range_hz "
                                   f"(lo, hi) must be numbers, got {self.coefficients!r}, {self.frequency_range_hz!r}")
        try:
            a, b, c = (float(v) for v in self.coefficients)
            lo, hi = (float(v) for v in self.frequency_range_hz)
        except OverflowError:   # an int beyond the float range
            a = b = c = lo = hi = math.nan
        if not all(np.isfinite([a, b, c, lo, hi])) or not 0 < lo < hi:
            raise CalibrationError(f"invalid voice-coil calibration {self.coefficients} on {self.frequency_range_hz}")
        if hi > MAX_FREQUENCY_HZ:
            raise CalibrationError(f"voice-coil calibration: frequency_range_hz {lo:g}..{hi:g} Hz goes above "
                                   f"{MAX_FREQUENCY_HZ:g} Hz (not a vibrotactile drive frequency)")
        check_amplifier_gain(self.amplifier_gain)
        f = np.linspace(lo, hi, 256)
        with np.errstate(over="ignore", invalid="ignore"):
            gs = self.gs_coil(f)
        if not np.isfinite(gs).all():   # coefficients of 1e308: an infinite stiffness is no curve
            raise CalibrationError(f"voice-coil calibration: the curve is not finite over its frequency range "
                                   f"(coefficients {self.coefficients}, range {self.frequency_range_hz} Hz)")
        if np.any(np.diff(gs) <= 0):
            raise CalibrationError("voice-coil calibration must increase over its frequency range "
                                   f"(coefficients {self.coefficients}, range {self.frequency_range_hz} Hz)")

    def check_limits(self, limits: Any, *, device: str = "voice coil") -> None:
        """Refuse this calibration for a device whose declared ``frequency_range_hz``
        (:class:`~hapticsdk.devices.actuators.ActuatorLimits`) does not hold its frequency range;
        raises :class:`CalibrationError` naming the field."""
        rng = getattr(limits, "frequency_range_hz", None) if limits is not None else None
        if rng is None:
            return
        lo, hi = self.frequency_range_hz
        if lo < rng[0] * (1 - 1e-9) or hi > rng[1] * (1 + 1e-9):
            raise CalibrationError(f"voice-coil calibration: frequency_range_hz {lo:g}..{hi:g} Hz leaves "
                                   f"{device}'s declared range {rng[0]:g}..{rng[1]:g} Hz")

    @classmethod
    def paper(cls) -> "VoiceCoilCalibration":
        """The calibration of the reference paper (formula (7) with its published
        coefficients).
        """
        return cls()

    def gs_coil(self, f_hz: Any) -> np.ndarray:
        """Perceived added stiffness (N/mm) at drive frequency ``f_hz``."""
        a, b, c = self.coefficients
        f = np.asarray(f_hz, float)
        return (a * f + b) * f + c

    @property
    def gs_range(self) -> tuple[float, float]:
        """(smallest, largest) added stiffness reachable (N/mm)."""
        lo, hi = self.frequency_range_hz
        return float(self.gs_coil(lo)), float(self.gs_coil(hi))

    def frequency_for(self, gs_n_per_mm: Any) -> tuple[np.ndarray, np.ndarray]:
        """Invert formula (7): the drive frequency (Hz) giving added stiffness ``gs``.

        Returns ``(f_hz, residual_n_per_mm)``; outside the reachable stiffness range the
        frequency is clamped to the range end and ``residual = gs - GS_coil(f)`` says
        by how much the request is missed (0 inside the range).
        """
        a, b, c = self.coefficients
        lo, hi = self.frequency_range_hz
        g = np.asarray(gs_n_per_mm, float)
        if a != 0:
            disc = np.maximum(b * b - 4 * a * (c - g), 0.0)
            # numerically stable root of a f^2 + b f + (c - g) = 0 on the increasing branch
            q = -0.5 * (b + np.sign(b if b != 0 else 1.0) * np.sqrt(disc))
            with np.errstate(divide="ignore", invalid="ignore"):
                r1 = q / a
                r2 = np.where(q != 0, (c - g) / np.where(q != 0, q, 1.0), np.inf)
            f = np.where((r1 >= lo - 1e-9) & (r1 <= hi + 1e-9), r1, r2)
        else:
            f = (g - c) / b
        f = np.clip(np.nan_to_num(f, nan=lo, posinf=hi, neginf=lo), lo, hi)
        return f, g - self.gs_coil(f)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (the calibration file format, ``schemas/calibration.schema.json``)."""
        return {"kind": "voicecoil", "coefficients": [float(v) for v in self.coefficients],
                "frequency_range_hz": [float(v) for v in self.frequency_range_hz], "source": self.source,
                "confidence_intervals": [[float(v) for v in ci] for ci in self.confidence_intervals]
                if self.confidence_intervals else None,
                "serial": self.serial, "generated": bool(self.generated),
                "amplifier_gain": self.amplifier_gain, "mounting": self.mounting,
                "extra": dict(self.extra)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "VoiceCoilCalibration":
        """Inverse of :meth:`to_dict` (unknown keys such as ``schema_version`` ignored)."""
        if not isinstance(data, dict) or data.get("kind", "voicecoil") != "voicecoil":
            raise CalibrationError("not a voice-coil calibration (kind must be 'voicecoil')")
        from ..argcheck import number
        try:
            ci = data.get("confidence_intervals")
            # the numbers as given ("1" and True are no coefficient): __post_init__ checks them
            return cls(coefficients=cast("tuple[float, float, float]", tuple(data["coefficients"])),
                       frequency_range_hz=cast("tuple[float, float]", tuple(data["frequency_range_hz"])),
                       source=str(data.get("source", "")),
                       confidence_intervals=cast(Any, tuple(tuple(number(v, "confidence_intervals") for v in c)
                                                            for c in ci)) if ci else None,
                       extra=dict(data.get("extra") or {}), serial=data.get("serial"),
                       generated=calibration_flag(data, "generated"),
                       amplifier_gain=data.get("amplifier_gain"), mounting=str(data.get("mounting") or ""))
        except (KeyError, TypeError, ValueError) as exc:
            raise CalibrationError(f"voice-coil calibration: bad or missing field ({exc})") from None


if not TYPE_CHECKING:  # moved names, deprecated since 0.2 (a type checker sees only the new places)
    from .._deprecation import moved_names
    __getattr__ = moved_names(__name__, {"VoiceCoilFit": "hapticsdk.calibration.voicecoil_fit", "fit_voicecoil": "hapticsdk.calibration.voicecoil_fit"})
