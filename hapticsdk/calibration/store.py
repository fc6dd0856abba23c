"""Calibration files: one JSON file per calibration, found by kind and device serial.

Files (format ``schemas/calibration.schema.json``) live in the calibration directory:
``$HAPTICSDK_CALIBRATION_DIR`` if set, else ``$XDG_CONFIG_HOME/hapticsdk/calibration``
(``~/.config/hapticsdk/calibration``). :func:`save_calibration` names them
``<kind>-<serial>.json`` (``<kind>-any.json`` without a serial), but any ``*.json``
file in the directory is considered; its ``kind`` and ``serial`` fields decide.

:func:`load_calibration` returns the calibration for a device, in this order: a file
with that kind and serial; a file with that kind and no serial (``"serial": null``,
any device); the default (voice coil: the paper's formula (7); piezo: the ``default``
the caller passes, e.g. a plugin's generated table). The answer says which was used,
for ``hapticsdk doctor``'s "calibrations in use".
"""

from __future__ import annotations

import datetime as _dt
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import CalibrationError, ValidationError
from .piezo import PiezoTable
from .voicecoil import VoiceCoilCalibration

KINDS = ("voicecoil", "piezo")
ENV_DIR = "HAPTICSDK_CALIBRATION_DIR"


def calibration_dir() -> Path:
    """The calibration directory (it need not exist)."""
    env = os.environ.get(ENV_DIR)
    if env:
        return Path(env).expanduser()
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "hapticsdk" / "calibration"


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise ValidationError(f"unknown calibration kind {kind!r}; valid: {list(KINDS)}", field="kind")


def calibration_to_dict(cal: VoiceCoilCalibration | PiezoTable) -> dict[str, Any]:
    """The file content for ``cal`` (schema-valid)."""
    if not isinstance(cal, (VoiceCoilCalibration, PiezoTable)):
        raise ValidationError(f"not a calibration: {type(cal).__name__}", field="calibration")
    d = {"schema_version": 1, **cal.to_dict(),
         "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    if d.get("serial") is None:
        d["serial"] = None
    return d


def calibration_from_dict(data: dict[str, Any], *, source: str = "") -> VoiceCoilCalibration | PiezoTable:
    """Validate ``data`` against the schema and build the calibration object."""
    from ..schemas_io import validate

    validate(data, "calibration", source=source)
    if data["kind"] == "voicecoil":
        return VoiceCoilCalibration.from_dict(data)
    return PiezoTable.from_dict(data)


def read_calibration(path: str | Path) -> VoiceCoilCalibration | PiezoTable:
    """Read one calibration file (errors name the file and the field)."""
    from ..schemas_io import load_json

    p = Path(path)
    data = load_json(p, "calibration")
    try:
        return calibration_from_dict(data, source=str(p))
    except CalibrationError as exc:
        raise CalibrationError(f"{p}: {exc}") from None


def save_calibration(cal: VoiceCoilCalibration | PiezoTable, directory: str | Path | None = None, *,
                     path: str | Path | None = None) -> Path:
    """Write ``cal`` to ``path``, or to ``<directory>/<kind>-<serial|any>.json`` (default
    directory: :func:`calibration_dir`). Returns the path written."""
    data = calibration_to_dict(cal)
    calibration_from_dict(data)  # never write a file we could not read back
    if path is None:
        d = Path(directory) if directory is not None else calibration_dir()
        serial = data.get("serial") or "any"
        safe = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in str(serial))
        path = d / f"{data['kind']}-{safe}.json"
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(data, indent=1))
    return p


@dataclass
class CalibrationEntry:
    """One file of the calibration directory (``error`` set when it does not load)."""

    path: Path
    kind: str | None
    serial: str | None
    generated: bool | None
    source: str
    error: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"path": str(self.path), "kind": self.kind, "serial": self.serial,
                "generated": self.generated, "source": self.source, "error": self.error}


def _scan(directory: str | Path | None) -> list[tuple[CalibrationEntry, VoiceCoilCalibration | PiezoTable | None]]:
    """Every ``*.json`` file of the calibration directory: its entry and the loaded
    calibration (``None`` when it does not load)."""
    d = Path(directory) if directory is not None else calibration_dir()
    out: list[tuple[CalibrationEntry, VoiceCoilCalibration | PiezoTable | None]] = []
    if not d.is_dir():
        return out
    for p in sorted(d.glob("*.json")):
        try:
            cal = read_calibration(p)
        except (ValidationError, CalibrationError) as exc:
            out.append((CalibrationEntry(p, None, None, None, "", error=str(exc)), None))
            continue
        kind = "voicecoil" if isinstance(cal, VoiceCoilCalibration) else "piezo"
        out.append((CalibrationEntry(p, kind, cal.serial, bool(cal.generated), cal.source), cal))
    return out


def list_calibrations(directory: str | Path | None = None) -> list[CalibrationEntry]:
    """Every ``*.json`` file of the calibration directory, loaded or with its error."""
    return [e for e, _ in _scan(directory)]


@dataclass
class LoadedCalibration:
    """Answer of :func:`load_calibration`.

    Attributes:
        kind: ``"voicecoil"`` or ``"piezo"``.
        serial: the serial asked for.
        calibration: the calibration object (``None``: no file and no default).
        origin: ``"file"`` (serial match), ``"file-any"`` (file without serial),
            ``"default"`` or ``"none"``.
        path: the file used, if any.
        skipped: files of this kind that failed to load (path: error).
    """

    kind: str
    serial: str | None
    calibration: VoiceCoilCalibration | PiezoTable | None
    origin: str
    path: Path | None
    skipped: dict[str, str]

    @property
    def generated(self) -> bool | None:
        return None if self.calibration is None else bool(self.calibration.generated)

    @property
    def source(self) -> str:
        """Human-readable provenance (file path or default, and the calibration's source)."""
        if self.calibration is None:
            return "none (no calibration file and no default)"
        where = str(self.path) if self.path is not None else "built-in default"
        return f"{where}: {self.calibration.source}"

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "serial": self.serial, "origin": self.origin,
                "path": str(self.path) if self.path else None, "generated": self.generated,
                "source": self.source, "skipped": dict(self.skipped)}


def load_calibration(kind: str, serial: str | None = None, *, directory: str | Path | None = None,
                     default: Any = None) -> LoadedCalibration:
    """The calibration of kind ``kind`` for the device with ``serial``.

    Args:
        kind: ``"voicecoil"`` or ``"piezo"``.
        serial: device serial number (``None``: only files without a serial match).
        directory: calibration directory (default :func:`calibration_dir`).
        default: used when no file matches; a calibration object or a zero-argument
            callable returning one. Voice coil without ``default``: the paper's
            formula (7). Piezo without ``default``: ``calibration`` is ``None``.

    Files that fail validation are skipped (listed in ``skipped``), never used.
    """
    _check_kind(kind)
    exact = anyone = None
    skipped: dict[str, str] = {}
    for e, cal in _scan(directory):
        if e.error is not None:
            if f'"{kind}"' in _peek_kind(e.path):
                skipped[str(e.path)] = e.error
            continue
        if e.kind != kind:
            continue
        if serial is not None and e.serial == serial and exact is None:
            exact = (e, cal)
        elif e.serial is None and anyone is None:
            anyone = (e, cal)
    for found, origin in ((exact, "file"), (anyone, "file-any")):
        if found is not None:
            entry, cal = found
            return LoadedCalibration(kind, serial, cal, origin, entry.path, skipped)
    if default is not None:
        cal = default() if callable(default) else default
        return LoadedCalibration(kind, serial, cal, "default", None, skipped)
    if kind == "voicecoil":
        return LoadedCalibration(kind, serial, VoiceCoilCalibration.paper(), "default", None, skipped)
    return LoadedCalibration(kind, serial, None, "none", None, skipped)


def _peek_kind(path: Path) -> str:
    from ..schemas_io import read_json

    try:
        return json.dumps(read_json(path, field="calibration").get("kind"))
    except Exception:
        return ""


def calibrations_in_use(serials: dict[str, str | None] | None = None, *, directory: str | Path | None = None,
                        defaults: dict[str, Any] | None = None) -> list[dict[str, Any]]:
    """For ``hapticsdk doctor``: which calibration each kind would use (one dict per
    kind: kind, serial, origin, path, generated, source, skipped)."""
    serials = serials or {}
    defaults = defaults or {}
    return [load_calibration(k, serials.get(k), directory=directory, default=defaults.get(k)).to_dict()
            for k in KINDS]


__all__ = ["KINDS", "ENV_DIR", "calibration_dir", "save_calibration", "read_calibration", "load_calibration",
           "list_calibrations", "calibrations_in_use", "calibration_to_dict", "calibration_from_dict",
           "LoadedCalibration", "CalibrationEntry"]
