"""Builders of .hjif documents from the format's structure (MPEG-I haptics JSON), for the
interop tests. Every test writes its own files; no external content is used."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any


def kf(pos: int | None = None, amp: float | None = None, freq: float | None = None) -> dict[str, Any]:
    d: dict[str, Any] = {}
    if pos is not None:
        d["relative_position"] = pos
    if amp is not None:
        d["amplitude_modulation"] = amp
    if freq is not None:
        d["frequency_modulation"] = freq
    return d


def basis(position: int, keyframes: list[dict[str, Any]], base_signal: str = "Sine", phase: float = 0.0,
          **extra: Any) -> dict[str, Any]:
    return {"effect_type": "Basis", "position": position, "phase": phase, "base_signal": base_signal,
            "keyframes": keyframes, **extra}


def reference(position: int, effect_id: int) -> dict[str, Any]:
    return {"effect_type": "Reference", "id": effect_id, "position": position}


def band(effects: list[dict[str, Any]], band_type: str = "VectorialWave", lo: int = 0, hi: int = 1000,
         **extra: Any) -> dict[str, Any]:
    return {"band_type": band_type, **extra, "lower_frequency_limit": lo, "upper_frequency_limit": hi,
            "effects": effects}


def channel(bands: list[dict[str, Any]], cid: int = 0, gain: float = 1.0, **extra: Any) -> dict[str, Any]:
    return {"id": cid, "description": f"channel {cid}", "gain": gain, "mixing_coefficient": 1.0,
            "body_part_mask": 0, **extra, "bands": bands}


def perception(channels: list[dict[str, Any]], modality: str = "Vibrotactile", pid: int = 0,
               library: list[dict[str, Any]] | None = None, devices: list[dict[str, Any]] | None = None,
               **extra: Any) -> dict[str, Any]:
    return {"id": pid, "avatar_id": 0, "description": f"perception {pid}", "perception_modality": modality,
            **extra, "reference_devices": devices or [], "effect_library": library or [], "channels": channels}


def doc(perceptions: list[dict[str, Any]], timescale: int | None = 1000, **extra: Any) -> dict[str, Any]:
    d: dict[str, Any] = {"version": "2023", "profile": "Main", "level": 1, "date": "2024-01-02",
                         "description": "test content", **extra}
    if timescale is not None:
        d["timescale"] = timescale
    d.update({"avatars": [], "perceptions": perceptions, "syncs": []})
    return d


def tone(freq: float, ms: int = 1000, amp: float = 1.0, base_signal: str = "Sine", position: int = 0,
         phase: float = 0.0) -> dict[str, Any]:
    """A Basis effect of constant amplitude and frequency lasting ``ms`` ticks."""
    return basis(position, [kf(0, amp, freq), kf(ms, amp, freq)], base_signal=base_signal, phase=phase)


def single(effect: dict[str, Any], **band_kw: Any) -> dict[str, Any]:
    """A one-perception, one-channel, one-band document holding ``effect``."""
    return doc([perception([channel([band([effect], **band_kw)])])])


def valid_doc() -> dict[str, Any]:
    """A document exercising library references, several bands and keyframes (for mutation)."""
    lib = [{**basis(0, [kf(0, 1.0, 200), kf(300, 1.0, 200)]), "id": 5}]
    return doc([perception(
        [channel([band([tone(120, 200), reference(300, 5)]),
                  band([basis(0, [kf(0, 0.2, 80), kf(100, 0.5), kf(200, 0.1, 90)])], lo=0, hi=300)]),
         channel([band([tone(250, 100)])], cid=1)],
        library=lib)])


def write(path: Path, d: Any) -> Path:
    path.write_text(json.dumps(d), encoding="utf-8")
    return path


def mutated(fn: Any) -> dict[str, Any]:
    d = copy.deepcopy(valid_doc())
    fn(d)
    return d


def plan_for(material: str) -> Any:
    """The compiled plan of a library material with every dimension kept."""
    from hapticsdk.compiler import compile_scene
    from hapticsdk.scene import Scene
    from hapticsdk.scene.model import _merge

    s = Scene.for_material(material)
    s = Scene(objects=s.objects, devices=s.devices, settings=_merge(s.settings, {"importance": {"enabled": False}}),
              name=s.name)
    return compile_scene(s)


def refused_unread(read: Any, path: Path, monkeypatch: Any, size: int) -> Any:
    """Make ``path`` a sparse file of ``size`` bytes (none written), call ``read(path)``
    with ``Path.open`` forbidden, and return the error it raises (``pytest.raises``
    info): a file over the size cap is refused from its size, never opened."""
    import pathlib

    import pytest

    from hapticsdk.errors import FormatError

    with path.open("wb") as fh:
        fh.truncate(size)
    real_open = pathlib.Path.open
    monkeypatch.setattr(pathlib.Path, "open", lambda self, *a, **k: pytest.fail("opened for reading"))
    try:
        with pytest.raises(FormatError, match="cap") as ei:
            read(path)
    finally:
        monkeypatch.setattr(pathlib.Path, "open", real_open)
    return ei
