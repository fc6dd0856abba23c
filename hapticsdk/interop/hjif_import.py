"""Import MPEG-I haptics ``.hjif`` files: a summary of what a file holds and what the SDK
can play of it, and the SDK's own exports read back to the exact numbers.

:func:`import_summary` lists every perception with its modality (as written and
canonical), channels, band types, effect and keyframe counts, the frequencies its
keyframes name, and whether the SDK plays it (and why not). :func:`sdk_materials` reads
the metadata :mod:`hapticsdk.interop.hjif_export` writes into the description fields and
checks it against the values the perceptions themselves carry.
"""

from __future__ import annotations

import os
from typing import Any

from ..errors import FormatError
from .hjif_export import META_FORMAT, META_MARKER
from ..schemas_io import non_finite_at
from .hjif_model import HapticFile, Perception, load_json, read_hjif
from .hjif_synth import (
    SYNTH_BAND_TYPES,
    effect_length_ticks,
    file_duration_s,
    is_vibrotactile,
    resolve_effect,
    unsupported_parts,
)

__all__ = ["load", "split_description", "sdk_materials", "import_summary"]


def load(path: str | os.PathLike[str]) -> HapticFile:
    """Read and check a ``.hjif`` file (see :func:`hapticsdk.interop.hjif_model.read_hjif`)."""
    return read_hjif(path)


def split_description(text: str, *, field: str = "description") -> tuple[str, dict[str, Any] | None]:
    """``(human text, metadata)`` of a description field; metadata ``None`` when the field
    carries none. Malformed metadata raises :class:`FormatError` naming ``field``."""
    i = text.find(META_MARKER)
    if i < 0:
        return text, None
    try:  # the file reader's JSON rules: bounded depth, no NaN/Infinity, no duplicate key
        meta = load_json(text[i + len(META_MARKER):], source=field)
    except FormatError as exc:
        raise FormatError(f"hapticsdk metadata is not valid JSON: {exc.reason}", field=field) from None
    if not isinstance(meta, dict):
        raise FormatError("hapticsdk metadata must be a JSON object", field=field)
    bad = non_finite_at(meta)
    if bad is not None:
        raise FormatError(f"hapticsdk metadata: {bad[1]} at {bad[0][1:]} is not a finite number", field=field)
    return text[:i], meta


def _meta_entry(m: Any, field: str) -> dict[str, Any]:
    """A material entry of the top-level metadata, checked where the SDK uses it: an
    object with a string ``name``; ``features`` / ``targets`` objects of numbers;
    ``generated`` a bool."""
    if not isinstance(m, dict) or not isinstance(m.get("name"), str):
        raise FormatError("hapticsdk metadata: a material entry is not an object with a string name", field=field)
    for key in ("features", "targets"):
        v = m.get(key)
        if v is not None and not (isinstance(v, dict) and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in v.values())):
            raise FormatError(f"hapticsdk metadata: {m['name']!r}.{key} is not an object of numbers", field=field)
    if not isinstance(m.get("generated", False), bool):
        raise FormatError(f"hapticsdk metadata: {m['name']!r}.generated is not true or false", field=field)
    return m


def _signal_value(p: Perception) -> float | None:
    """Value of a constant single-effect perception as the reference synthesiser computes
    it: first amplitude keyframe x channel gain x 10^perception_unit_exponent."""
    if len(p.channels) != 1 or len(p.channels[0].bands) != 1 or len(p.channels[0].bands[0].effects) != 1:
        return None
    ch = p.channels[0]
    eff = resolve_effect(p, ch.bands[0].effects[0])
    amps = [k.amplitude_modulation for k in eff.keyframes if k.amplitude_modulation is not None]
    if not amps or len(set(amps)) != 1:
        return None
    return amps[0] * ch.gain * 10.0 ** p.perception_unit_exponent_or_default


def _first_frequency(p: Perception) -> float | None:
    for ch in p.channels:
        for b in ch.bands:
            for e in b.effects:
                for k in resolve_effect(p, e).keyframes:
                    if k.frequency_modulation is not None:
                        return k.frequency_modulation
    return None


def sdk_materials(hfile: HapticFile) -> dict[str, dict[str, Any]]:
    """Materials of an SDK export, keyed by name: the top-level metadata (targets,
    features, solver provenance) plus, per exported part, the metadata values and the
    values the perceptions carry (``*_from_content``). Empty for files the SDK did not write."""
    _, top = split_description(hfile.description, field="description")
    if not top or top.get("format") != META_FORMAT:
        return {}
    out: dict[str, dict[str, Any]] = {}
    materials = top.get("materials", [])
    if not isinstance(materials, list):
        raise FormatError("hapticsdk metadata: materials is not a list", field="description")
    for m in materials:
        m = _meta_entry(m, "description")
        out[m["name"]] = {**m, "parts": {}}
    for p in hfile.perceptions:
        field = f"{p.path}.description"
        _, meta = split_description(p.description, field=field)
        if not meta or "material" not in meta:
            continue
        name, role = meta["material"], meta.get("role", p.perception_modality)
        if not isinstance(name, str) or not isinstance(role, str):
            raise FormatError("hapticsdk metadata: material and role must be strings", field=field)
        entry = out.setdefault(name, {"name": name, "parts": {}})
        part = {"perception": p.path, "modality": p.perception_modality, **meta}
        value = _signal_value(p)
        if role == "stiffness":
            part["GS_from_content"] = value
        elif role == "texture":
            part["AFpeak_from_content"] = value
            part["Fpeak_keyframe_hz"] = _first_frequency(p)
        elif role == "coil":
            part["coil_amplitude_from_content"] = value
            part["coil_frequency_keyframe_hz"] = _first_frequency(p)
        entry["parts"][role] = part
    return out


def _perception_summary(hfile: HapticFile, p: Perception) -> dict[str, Any]:
    human, meta = split_description(p.description, field=f"{p.path}.description")
    bands: list[str] = []
    n_eff = n_kf = 0
    freqs: set[float] = set()
    signals: set[str] = set()
    refs = 0
    end = 0.0
    ts = hfile.ticks_per_second
    for ch in p.channels:
        for b in ch.bands:
            bands.append(b.band_type)
            for e in b.effects:
                n_eff += 1
                refs += e.effect_type == "Reference"
                r = resolve_effect(p, e)
                n_kf += len(r.keyframes)
                if r.base_signal:
                    signals.add(r.base_signal)
                for k in r.keyframes:
                    if k.frequency_modulation is not None:
                        freqs.add(float(k.frequency_modulation))
                if b.band_type in SYNTH_BAND_TYPES and r.effect_type != "Composite":
                    end = max(end, (r.position + effect_length_ticks(r, b.band_type, ts)) / ts)
    vib = is_vibrotactile(p)
    reason = ("played as vibration" if vib else
              f"{p.perception_modality} perception: not played (the SDK plays vibrotactile content of .hjif files)")
    if vib and p.perception_modality == "Other":
        reason = ("modality 'Other' (what MPEG's reference encoder writes for AHAP/IVS/WAV input): "
                  "played as vibration")
    fl = sorted(freqs)
    return {"path": p.path, "id": p.id, "modality": p.perception_modality, "modality_as_written": p.modality_as_written,
            "description": human[:200], "sdk_metadata": meta is not None,
            "unit_exponent": p.unit_exponent_or_default,
            "perception_unit_exponent": p.perception_unit_exponent_or_default,
            "channels": len(p.channels), "band_types": sorted(set(bands)), "bands": len(bands),
            "effects": n_eff, "reference_effects": refs, "library_effects": len(p.effect_library),
            "keyframes": n_kf, "base_signals": sorted(signals),
            "keyframe_frequencies_hz": fl[:20] + (["..."] if len(fl) > 20 else []),
            "reference_devices": [d.name for d in p.reference_devices],
            "duration_s": end, "playable": vib, "reason": reason}


def import_summary(hfile: HapticFile, *, source: str | None = None) -> dict[str, Any]:
    """What a file holds, what the SDK plays of it, and SDK metadata if present."""
    out: dict[str, Any] = {
        "file": source, "version": hfile.version,
        "format_version": hfile.format_version.to_dict() if hfile.format_version else None,
        "profile": hfile.profile, "level": hfile.level,
        "date": hfile.date, "timescale": hfile.ticks_per_second, "timescale_in_file": hfile.timescale is not None,
        "description": split_description(hfile.description)[0][:200],
        "avatars": len(hfile.avatars), "syncs": len(hfile.syncs),
        "perceptions": [_perception_summary(hfile, p) for p in hfile.perceptions],
        "duration_s": file_duration_s(hfile),
        "not_played": unsupported_parts(hfile)}
    mats = sdk_materials(hfile)
    if mats:
        out["sdk_materials"] = mats
    return out


def format_summary(s: dict[str, Any]) -> str:
    """Human-readable form of :func:`import_summary`."""
    lines = [f"{s.get('file') or 'hjif'}: MPEG-I haptics {s['version']} profile {s['profile']} level {s['level']}, "
             f"timescale {s['timescale']} ticks/s{'' if s['timescale_in_file'] else ' (default)'}, "
             f"{len(s['perceptions'])} perception(s), {s['duration_s']:.3f} s"]
    fv = s.get("format_version")
    if fv:
        lines.append(f"  read as the reference reader of {fv['recognised']} reads it"
                     + (f"; {fv['changes']} normalisation(s):" if fv["changes"] else ""))
        lines += [f"    {c['path']}: {c['change']}" for c in fv["normalised"][:50]]
        if fv["changes"] > 50:
            lines.append(f"    ... {fv['changes'] - 50} more (--json lists them all)")
    for p in s["perceptions"]:
        fr = ", ".join(f"{f:g}" if not isinstance(f, str) else f for f in p["keyframe_frequencies_hz"])
        lines.append(f"  {p['path']} id {p['id']} {p['modality']}"
                     + (f" (written {p['modality_as_written']!r})" if p["modality_as_written"] != p["modality"] else "")
                     + f": {p['channels']} channel(s), bands {', '.join(p['band_types']) or '-'}, "
                       f"{p['effects']} effect(s) ({p['reference_effects']} reference), {p['keyframes']} keyframe(s)"
                     + (f", frequencies {fr} Hz" if fr else "") + f"; {p['reason']}")
    for u in s["not_played"]:
        lines.append(f"  not played: {u['path']}: {u['what']}: {u['reason']}")
    for name, m in (s.get("sdk_materials") or {}).items():
        gen = " (GENERATED data)" if m.get("generated") else ""
        feats = ", ".join(f"{k}={v:.6g}" for k, v in (m.get("features") or {}).items())
        lines.append(f"  hapticsdk material {name}{gen}: targets {m.get('targets')}; features {feats}; "
                     f"parts {', '.join(m.get('parts', {}))}")
    return "\n".join(lines)
