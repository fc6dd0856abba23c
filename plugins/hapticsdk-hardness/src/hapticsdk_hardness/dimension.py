"""The hardness dimension: features GS (N/mm) and W (mJ), constraint (4), renderer (8).

Formula (8) of the reference paper splits a material's global stiffness ``GS`` between
two actuators: the Omni renders the spring ``min(GS, GS_max) * Y`` (Y: penetration in mm,
force in N, ``GS_max = 2.3`` N/mm) and, when ``GS > GS_max``, a voice coil vibrates at
the frequency ``f_coil`` whose perceived added stiffness (formula (7)) is
``GS - GS_max``, with constant amplitude while the probe is in contact. Stiffness above
the Omni's limit never goes to the arm.
"""

from __future__ import annotations

import math

from typing import Any, ClassVar, Mapping

import numpy as np

from hapticsdk.calibration import VoiceCoilCalibration
from hapticsdk.perception.dimensions import (ChannelCommand, Constraint, DimensionRenderer, PerceptionDimension, RoleSpec,
                                  TickInput)
from hapticsdk.errors import ValidationError
from hapticsdk.perception.features import Feature

#: Omni force at the nominal position (N): MF of formula (4).
MF_N = 3.3
#: Stiffest spring the paper renders on the Omni (N/mm): GS_max of formula (8).
GS_MAX_N_PER_MM = 2.3


class WorkConstraint(Constraint):
    """W >= Wv = MF^2 / (2 GS): the work of pressing to the Omni's maximum force (formula (4)).

    GS in N/mm and MF in N give Wv in mJ. A non-positive GS gives an unbounded Wv.
    """

    name: ClassVar[str] = "hardness.work"
    features: ClassVar[tuple[str, ...]] = ("GS", "W")

    def __init__(self, mf_n: float = MF_N) -> None:
        if not np.isfinite(mf_n) or mf_n <= 0:
            raise ValidationError(f"MF must be > 0 N, got {mf_n!r}", field="mf_n")
        self.mf_n = float(mf_n)

    def _bound_and_value(self, cols: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        gs = np.asarray(cols["GS"], float)
        w = np.asarray(cols["W"], float)
        q = np.multiply(gs, 2.0)
        if q.ndim and q.size and (q.item() > 0 if q.size == 1 else np.minimum.reduce(q, axis=None) > 0):
            # every GS > 0 (a NaN fails the test): MF^2 / (2 GS) in one plain division
            return np.divide(self.mf_n ** 2, q, out=q), w
        # MF^2 / (2 GS) where GS > 0, +inf elsewhere (NaN included)
        wv = np.divide(self.mf_n ** 2, q, out=np.full(gs.shape, np.inf), where=gs > 0)
        return wv, w

    def _bound_and_value_one(self, row: Mapping[str, float]) -> tuple[float, float]:
        gs = row["GS"]
        # the same operations as above: MF^2 / (2 GS) where GS > 0, +inf elsewhere (NaN too)
        return (self.mf_n ** 2 / (gs * 2.0) if gs > 0 else math.inf), row["W"]


class PressForceConstraint(Constraint):
    """W <= F_max^2 / (2 GS): the pressing force implied by stiffness and work,
    ``sqrt(2 GS W)``, stays within what the recordings reached (``press_force_max_n`` of the
    model's data). Not in the paper: without it the inverse solve may pair a stiffness with
    a work that no recording had (e.g. GS 2.5 N/mm with W 120 mJ, a 24 N press), where the
    perception model extrapolates. Written as ``F_max^2/(2 GS) >= W``.
    """

    name: ClassVar[str] = "hardness.press_force"
    features: ClassVar[tuple[str, ...]] = ("GS", "W")

    def __init__(self, f_max_n: float) -> None:
        if not np.isfinite(f_max_n) or f_max_n <= 0:
            raise ValidationError(f"press_force_max_n must be > 0 N, got {f_max_n!r}",
                                  field="press_force_max_n")
        self.f_max_n = float(f_max_n)

    def _bound_and_value(self, cols: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        gs = np.asarray(cols["GS"], float)
        w = np.asarray(cols["W"], float)
        w_max = self.f_max_n ** 2 / (2.0 * np.maximum(gs, 1e-12))
        return w, w_max

    def _bound_and_value_one(self, row: Mapping[str, float]) -> tuple[float, float]:
        gs = row["GS"]
        # np.maximum(gs, 1e-12): a NaN stays NaN
        return row["W"], self.f_max_n ** 2 / (2.0 * (1e-12 if gs < 1e-12 else gs))


class HardnessRenderer(DimensionRenderer):
    """Per-tick commands of formula (8) for one material.

    Args:
        gs_n_per_mm: the material's global stiffness GS (N/mm), >= 0.
        calibration: :class:`~hapticsdk.calibration.VoiceCoilCalibration` (formula (7));
            default the paper's.
        gs_max_n_per_mm: stiffest spring the force arm renders (N/mm).
        coil_amplitude: voice-coil drive amplitude while in contact (0..1).

    Attributes:
        omni_stiffness_n_per_mm: the spring the arm renders.
        coil_stiffness_n_per_mm: the added stiffness asked of the voice coil (0 if none).
        coil_frequency_hz: its drive frequency (None if the coil is not used).
        coil_residual_n_per_mm: the part of the request the calibration range cannot meet.
    """

    roles = ("force", "coil")

    def __init__(self, gs_n_per_mm: float, *, calibration: VoiceCoilCalibration | None = None,
                 gs_max_n_per_mm: float = GS_MAX_N_PER_MM, coil_amplitude: float = 0.5) -> None:
        from hapticsdk.argcheck import number
        gs = number(gs_n_per_mm, "GS", lo=0.0)
        gs_max_n_per_mm = number(gs_max_n_per_mm, "gs_max_n_per_mm", lo=0.0, lo_open=True)
        coil_amplitude = number(coil_amplitude, "coil_amplitude", lo=0.0, hi=1.0)
        if calibration is not None and not isinstance(calibration, VoiceCoilCalibration):
            if not isinstance(calibration, dict):
                raise ValidationError(f"must be a voice-coil calibration (an object in the calibration file "
                                      f"format), got {type(calibration).__name__} {calibration!r:.60}",
                                      field="calibration")
            from hapticsdk.calibration.store import calibration_from_dict
            calibration = calibration_from_dict({"schema_version": 1, "kind": "voicecoil", **calibration})
            if not isinstance(calibration, VoiceCoilCalibration):   # e.g. a piezo table's "kind"
                raise ValidationError(f"must be a voice-coil calibration (kind 'voicecoil'), got a "
                                      f"{type(calibration).__name__}", field="calibration")
        self.calibration = calibration or VoiceCoilCalibration.paper()
        self.gs = gs
        self.omni_stiffness_n_per_mm = min(gs, float(gs_max_n_per_mm))
        self.coil_stiffness_n_per_mm = max(gs - float(gs_max_n_per_mm), 0.0)
        if self.coil_stiffness_n_per_mm > 0:
            f, resid = self.calibration.frequency_for(self.coil_stiffness_n_per_mm)
            self.coil_frequency_hz: float | None = float(f)
            self.coil_residual_n_per_mm = float(resid)
            self._amp = float(coil_amplitude)
        else:
            self.coil_frequency_hz = None
            self.coil_residual_n_per_mm = 0.0
            self._amp = 0.0
        self._k = self.omni_stiffness_n_per_mm
        self._f = self.coil_frequency_hz

    def tick(self, inp: TickInput) -> list[ChannelCommand]:
        # positional fields (role, force_n, frequency_hz, amplitude): keyword binding
        # costs measurably at 1 kHz
        if inp.in_contact:
            return [ChannelCommand("force", self._k * inp.penetration_mm),
                    ChannelCommand("coil", None, self._f, self._amp)]
        return [ChannelCommand("force", 0.0), ChannelCommand("coil", None, self._f, 0.0)]

    def _fast_law(self) -> Any:
        """:meth:`tick` on plain floats (the servo loop's steady-state tick; see
        ``DimensionRenderer._fast_law``): ``(force_n, None, None, None, frequency_hz,
        amplitude)`` for the roles ``force``, ``coil``. Stateless; the spring and the
        coil's drive are fixed when the renderer is built."""
        k, fc, amp = self._k, self._f, self._amp

        def law(t: float, dt: float, pen: float, in_contact: bool, v0: float, v1: float, v2: float,
                vf0: float, vf1: float, vf2: float, step: float) -> tuple:
            if in_contact:
                return (k * pen, None, None, None, fc, amp)
            return (0.0, None, None, None, fc, 0.0)
        return law

    def rendered_stiffness_n_per_mm(self) -> float:
        """Total stiffness of formula (8): arm spring + calibrated coil stiffness (N/mm)."""
        if self._f is None:
            return self.omni_stiffness_n_per_mm
        return self.omni_stiffness_n_per_mm + float(self.calibration.gs_coil(self._f))

    def describe(self) -> dict[str, Any]:
        return {"GS": self.gs, "omni_stiffness_n_per_mm": self.omni_stiffness_n_per_mm,
                "coil_stiffness_n_per_mm": self.coil_stiffness_n_per_mm,
                "coil_frequency_hz": self.coil_frequency_hz,
                "coil_residual_n_per_mm": self.coil_residual_n_per_mm,
                "coil_amplitude": self._amp, "calibration": self.calibration.to_dict()}


class HardnessDimension(PerceptionDimension):
    """Perceived hardness when pressing (0 soft .. 1 hard)."""

    name: ClassVar[str] = "hardness"
    description: ClassVar[str] = ("perceived hardness while pressing: global stiffness GS and work W; "
                                  "rendered by a force arm up to 2.3 N/mm plus a voice coil (formula (8))")
    features: ClassVar[tuple[Feature, ...]] = (
        Feature("GS", "N/mm", 0.0, 10.0, "global stiffness while pressing"),
        Feature("W", "mJ", 0.0, 100.0, "work of pressing"),
    )
    default_actuators: ClassVar[dict[str, str]] = {"force": "omni-virtual", "coil": "voicecoil-virtual"}
    roles: ClassVar[dict[str, RoleSpec]] = {
        "force": RoleSpec("force", {"force_n": "N"}, "spring force GS * penetration (formula (8), arm part)"),
        "coil": RoleSpec("vibration", {"frequency_hz": "Hz", "amplitude": "1"},
                         "voice-coil vibration whose frequency adds perceived stiffness (formula (7))")}
    #: formula (7) comes from the voice coil's saved calibration when there is one
    calibrations: ClassVar[dict[str, tuple[str, str]]] = {"calibration": ("voicecoil", "coil")}
    render_features: ClassVar[tuple[str, ...]] = ("GS",)

    def constraints(self, **context: float) -> list[Constraint]:
        """Formula (4) always; the recorded press-force range when the model's data give it
        (``press_force_max_n``, see :class:`PressForceConstraint`)."""
        out: list[Constraint] = [WorkConstraint(float(context.get("mf_n", MF_N)))]
        if context.get("press_force_max_n") is not None:
            out.append(PressForceConstraint(float(context["press_force_max_n"])))
        return out

    def renderer(self, features: Mapping[str, float], **options: Any) -> HardnessRenderer:
        if "GS" not in features:
            raise ValidationError(f"hardness needs feature GS; got {sorted(features)}", field="features.GS")
        return HardnessRenderer(float(features["GS"]), **options)
