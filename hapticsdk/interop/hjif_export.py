"""Export solved materials (a :class:`~hapticsdk.plan.RenderPlan`) as MPEG-I haptics
``.hjif`` perceptions.

Per material:

- **hardness** -> a ``Stiffness`` perception: one channel, one ``Curve`` band (Linear),
  one Basis effect of constant amplitude 1.0 written as three keyframes (the reference
  synthesiser outputs nothing for a Curve effect of exactly two); the channel ``gain`` is the solved ``GS``, so
  the value the reference synthesiser computes (amplitude x gain x 10^perception_unit_exponent,
  exponent 0) is GS, in N/mm (``unit_exponent`` -3: lengths in mm). When GS exceeds the
  force arm's limit (2.3 N/mm, formula (8)), a ``Vibrotactile`` perception follows: the
  voice-coil vibration at the frequency the calibration (formula (7)) gives for the excess
  stiffness, as a library effect (Sine, constant amplitude) placed by a Reference effect,
  on a channel whose reference device is ``voicecoil-virtual``.
- **roughness** -> a ``Vibrotactile Texture`` perception: the vibration at the reference
  sliding speed (Sine at Fpeak, channel gain AFpeak so the value is AFpeak in m/s^2), on a
  channel whose reference device is ``piezo-virtual``. The format has no velocity-indexed
  field, so the speed law of formula (9) (f = Fpeak |v_x| / 80 mm/s, silent below
  20 mm/s) is carried as metadata.

Exact numbers (features, targets, solver provenance, the law's constants) travel in the
description fields: a human sentence, then :data:`META_MARKER` and compact JSON, which
:mod:`hapticsdk.interop.hjif_import` reads back to the same floats. Keyframe frequencies
are written as integers because MPEG's reference reader ignores non-integer
``frequency_modulation`` values; the exact frequency is in the metadata.

Effects have a nominal length (``effect_seconds``, default 1 s): a material is a property,
not a timeline; a player repeats or holds it while the contact lasts.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
from pathlib import Path
from typing import Any, Mapping

from ..errors import ValidationError
from .hjif_model import (
    Band,
    Channel,
    Effect,
    HapticFile,
    Keyframe,
    Perception,
    ReferenceDevice,
)

#: separates the human text of a description from the SDK's JSON metadata
META_MARKER = " hapticsdk-meta:"
#: format tag of the metadata
META_FORMAT = "hapticsdk-hjif"
META_VERSION = 1
#: timescale the SDK writes (ticks per second), as MPEG's reference encoder does
TIMESCALE = 1000
#: the format version the SDK writes: the ``version`` string and the shape (the FDIS
#: shape of ISO/IEC 23090-31, read by MPEG's reference software from release CRM4 on)
FORMAT_VERSION = "2023"
FORMAT_SHAPE = "CRM4 / FDIS 2023 (2024-03)"
#: Curve bands of the SDK's stiffness perceptions: frequency limits (Hz), like the
#: reference encoder's curve bands (72.5 Hz cut-off, written as an integer)
CURVE_BAND_HZ = (0, 72)
#: VectorialWave band of the texture perception (Hz): wide enough for the speed law
TEXTURE_BAND_HZ = (1, 1000)


def describe(text: str, meta: Mapping[str, Any]) -> str:
    """A description field: ``text`` then the marker and compact JSON (exact floats)."""
    return text + META_MARKER + json.dumps(meta, separators=(",", ":"), allow_nan=False, sort_keys=True)


def _renderer_describe(dimension: str, features: Mapping[str, float], options: Mapping[str, Any]) -> dict[str, Any]:
    from ..plugins import registry

    cls = registry("dimension").load(dimension)
    dim = cls() if isinstance(cls, type) else cls
    r = dim.renderer(dict(features), **dict(options))
    return dict(r.describe())


def _constant_effect(length_ticks: int, amplitude: float, frequency_hz: int | None, *, effect_id: int | None = None
                     ) -> Effect:
    # three keyframes: MPEG's reference synthesiser adds nothing for a Curve effect of
    # exactly two keyframes (it interpolates them, then skips the copy into the band)
    mid = length_ticks // 2
    kfs = [Keyframe(0, amplitude, frequency_hz), Keyframe(mid, amplitude, frequency_hz),
           Keyframe(length_ticks, amplitude, frequency_hz)]
    if frequency_hz is None:
        return Effect("Basis", 0, id=effect_id, keyframes=kfs)
    return Effect("Basis", 0, id=effect_id, phase=0.0, base_signal="Sine", keyframes=kfs)


def _solve_meta(solve: Mapping[str, Any]) -> dict[str, Any]:
    keep = ("method", "seed", "success", "error", "intensities", "message", "models", "nfev", "constraint_violation")
    return {k: solve[k] for k in keep if k in solve}


def _is_generated(name: str, source: str) -> bool:
    if source != "library":
        return False
    try:
        from ..perception.materials import load_library
        return bool(load_library().get(name).generated)
    except ValidationError:
        return False


def export_plan(plan: Any, *, effect_seconds: float = 1.0, date: str | None = None) -> HapticFile:
    """The ``.hjif`` document of a compiled plan (every material, kept dimensions).

    Args:
        plan: a :class:`~hapticsdk.plan.RenderPlan` (or its dict form).
        effect_seconds: nominal length of each effect (s): at least one tick (0.5 ms rounds to 1 ms), at most 3600.
        date: ISO 8601 date written in the file (default: now, UTC).
    """
    from ..plan import RenderPlan

    if not isinstance(plan, RenderPlan):
        plan = RenderPlan.from_dict(plan)
    if not (math.isfinite(effect_seconds) and 0 < effect_seconds <= 3600):
        raise ValidationError(f"must be in (0, 3600] s, got {effect_seconds!r}", field="effect_seconds")
    length = int(round(effect_seconds * TIMESCALE))
    if length < 1:  # would be an effect of no length: every keyframe at 0
        raise ValidationError(f"{effect_seconds!r} s is shorter than one tick ({1 / TIMESCALE:g} s) of the "
                              "written timescale", field="effect_seconds")
    ropts = dict(plan.settings.get("renderer_options") or {})
    perceptions: list[Perception] = []
    materials_meta = []
    any_generated = False
    for name, mp in plan.materials.items():
        generated = _is_generated(name, mp.source)
        any_generated |= generated
        exported: list[str] = []
        not_exported: list[dict[str, str]] = []
        for dim in mp.dimensions:
            pid = len(perceptions)
            base = {"material": name, "dimension": dim, "targets": dict(mp.targets), "generated": generated}
            if dim == "hardness" and "GS" in mp.features:
                gs = float(mp.features["GS"])
                d = _renderer_describe("hardness", {"GS": gs}, ropts.get("hardness", {}))
                meta = {**base, "role": "stiffness", "GS_n_per_mm": gs, "W_mj": mp.features.get("W"),
                        "arm_stiffness_n_per_mm": d.get("omni_stiffness_n_per_mm"),
                        "coil_stiffness_n_per_mm": d.get("coil_stiffness_n_per_mm")}
                band = Band("Curve", *CURVE_BAND_HZ, curve_type="Linear", effects=[_constant_effect(length, 1.0, None)])
                perceptions.append(Perception(
                    id=pid, avatar_id=0, perception_modality="Stiffness", unit_exponent=-3, perception_unit_exponent=0,
                    description=describe(f"{name} hardness: global stiffness GS = {gs:.6g} N/mm while pressing "
                                         "(value = amplitude x channel gain, N/mm)", meta),
                    channels=[Channel(0, "stiffness GS (N/mm)", gs, 1.0, 0, bands=[band])]))
                exported.append("hardness.stiffness")
                f_coil = d.get("coil_frequency_hz")
                if f_coil is not None:
                    cal = d.get("calibration") or {}
                    lo, hi = (cal.get("frequency_range_hz") or [30.0, 120.0])
                    amp = float(d.get("coil_amplitude", 0.5))
                    cmeta = {**base, "role": "coil", "GS_n_per_mm": gs, "coil_frequency_hz": float(f_coil),
                             "coil_amplitude": amp, "coil_stiffness_n_per_mm": d.get("coil_stiffness_n_per_mm"),
                             "coil_residual_n_per_mm": d.get("coil_residual_n_per_mm"),
                             "arm_stiffness_n_per_mm": d.get("omni_stiffness_n_per_mm"),
                             "calibration_source": cal.get("source"), "calibration_generated": cal.get("generated")}
                    lib = _constant_effect(length, amp, int(round(float(f_coil))), effect_id=0)
                    band = Band("VectorialWave", int(math.floor(lo)), int(math.ceil(hi)),
                                effects=[Effect("Reference", 0, id=0)])
                    perceptions.append(Perception(
                        id=len(perceptions), avatar_id=0, perception_modality="Vibrotactile",
                        unit_exponent=0, perception_unit_exponent=0,
                        description=describe(
                            f"{name} hardness, voice coil: {float(f_coil):.4g} Hz at drive amplitude {amp:g} while in "
                            f"contact adds {d.get('coil_stiffness_n_per_mm', 0.0):.4g} N/mm above the arm's "
                            f"{d.get('omni_stiffness_n_per_mm', 0.0):.4g} N/mm (formula (7))", cmeta),
                        reference_devices=[ReferenceDevice(1, "voicecoil-virtual",
                                                           {"type": "VCA", "minimum_frequency": float(lo),
                                                            "maximum_frequency": float(hi)})],
                        effect_library=[lib],
                        channels=[Channel(0, "voice-coil vibration (normalised drive)", 1.0, 1.0, 0,
                                          reference_device_id=1, bands=[band])]))
                    exported.append("hardness.coil")
            elif dim == "roughness" and "Fpeak" in mp.features and "AFpeak" in mp.features:
                fpk = float(mp.features["Fpeak"])
                afpk = float(mp.features["AFpeak"])
                d = _renderer_describe("roughness", dict(mp.features), ropts.get("roughness", {}))
                meta = {**base, "role": "texture", "Fpeak_hz": fpk, "AFpeak_m_s2": afpk, "P_m2_s4": mp.features.get("P"),
                        "v_ref_mm_s": d.get("v_ref_mm_s"), "v_gate_mm_s": d.get("v_gate_mm_s"),
                        "speed_law": "f = Fpeak * |v_x| / v_ref; vibration only while |v_x| >= v_gate",
                        "piezo_v_out_v": d.get("v_out_v"), "table_generated": d.get("table_generated")}
                lo, hi = TEXTURE_BAND_HZ
                lib = _constant_effect(length, 1.0, int(round(fpk)), effect_id=0)
                perceptions.append(Perception(
                    id=pid, avatar_id=0, perception_modality="Vibrotactile Texture", unit_exponent=0,
                    perception_unit_exponent=0,
                    description=describe(
                        f"{name} roughness: lateral vibration Fpeak {fpk:.4g} Hz, AFpeak {afpk:.4g} m/s^2 at the "
                        f"reference sliding speed {d.get('v_ref_mm_s', 80.0):g} mm/s; while sliding the frequency "
                        f"scales with |v_x| / {d.get('v_ref_mm_s', 80.0):g} mm/s and stops below "
                        f"{d.get('v_gate_mm_s', 20.0):g} mm/s (formula (9))", meta),
                    reference_devices=[ReferenceDevice(1, "piezo-virtual", {"type": "Piezo"})],
                    effect_library=[lib],
                    channels=[Channel(0, "lateral acceleration (m/s^2) at the reference speed", afpk, 1.0, 0,
                                      reference_device_id=1,
                                      bands=[Band("VectorialWave", lo, hi, effects=[Effect("Reference", 0, id=0)])])]))
                exported.append("roughness.texture")
            else:
                not_exported.append({"dimension": dim, "reason": "no MPEG-I mapping for this dimension in the SDK"})
        materials_meta.append({
            "name": name, "source": mp.source, "generated": generated, "targets": dict(mp.targets),
            "dimensions": list(mp.dimensions), "features": dict(mp.features),
            "pinned_features": dict(mp.pinned_features),
            "dropped": [{"dimension": x.dimension, "reason": x.reason,
                         "predicted_loss_percent": x.predicted_loss_percent, "replacement": x.replacement}
                        for x in mp.dropped],
            "exported": exported, "not_exported": not_exported, "solve": _solve_meta(mp.solve)})
    if not perceptions:
        raise ValidationError("the plan renders no dimension that maps to MPEG-I haptics (hardness, roughness)",
                              field="plan.materials")
    settings = {k: plan.settings.get(k) for k in ("solver", "importance", "model") if k in plan.settings}
    top = {"format": META_FORMAT, "format_version": META_VERSION, "scene": plan.scene,
           "plugin_api_version": plan.plugin_api_version, "settings": settings, "materials": materials_meta,
           "generated_data": any_generated}
    note = " Values come from GENERATED data (the reference paper published none)." if any_generated else ""
    text = (f"hapticsdk export of scene {plan.scene!r}: {len(plan.materials)} material(s), "
            f"{len(perceptions)} perception(s).{note}")
    return HapticFile(version=FORMAT_VERSION, profile="Main", level=1,
                      date=date or _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat(),
                      description=describe(text, top), perceptions=perceptions, avatars=[], syncs=[],
                      timescale=TIMESCALE)


def write_hjif(hfile: HapticFile, path: str | os.PathLike[str], *, field: str = "output") -> Path:
    """Write ``hfile`` to ``path`` atomically (temporary file + rename), read back first
    with the SDK's own reader (:func:`~hapticsdk.interop.hjif_model.read_hjif`): content
    it would refuse is not written and the old file stays."""
    from ..fileio import atomic_write_text, check_output_path
    from .hjif_model import read_hjif

    p = check_output_path(path, field=field)
    return atomic_write_text(p, hfile.to_json(), field=field, verify=read_hjif)
