"""Calibration files: one JSON file per calibration, found by kind and device serial.

Files (format ``schemas/calibration.schema.json``) live in the calibration directory:
``$HAPTICSDK_CALIBRATION_DIR`` if set, else the per-user configuration directory of
``platformdirs`` plus ``calibration``: ``$XDG_CONFIG_HOME/hapticsdk/calibration``
(``~/.config/hapticsdk/calibration``) on Linux, ``~/Library/Application
Support/hapticsdk/calibration`` on macOS, ``%LOCALAPPDATA%\\hapticsdk\\calibration`` on
Windows. :func:`save_calibration` names them
``<kind>-<serial>.json`` (``<kind>-any.json`` without a serial), but any ``*.json``
file in the directory is considered; its ``kind`` and ``serial`` fields decide.

:func:`load_calibration` returns the calibration for a device, in this order: a file
with that kind and serial; a file with that kind and no serial (``"serial": null``,
any device); the default (voice coil: the paper's formula (7); piezo: the ``default``
the caller passes, e.g. a plugin's generated table; damping: none, the controller then
credits none of the declared damping by default). The answer says which was used,
for ``hapticsdk doctor``'s "calibrations in use".
"""

from __future__ import annotations

import datetime as _dt
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import CalibrationError, ValidationError
from .damping import DampingCalibration
from .piezo import PiezoTable
from .voicecoil import VoiceCoilCalibration

#: Every calibration object the store reads and writes.
Calibration = VoiceCoilCalibration | PiezoTable | DampingCalibration
#: The class of each calibration kind (a file's ``kind`` field).
_CLASSES: dict[str, type[VoiceCoilCalibration] | type[PiezoTable] | type[DampingCalibration]] = {"voicecoil": VoiceCoilCalibration, "piezo": PiezoTable, "damping": DampingCalibration}

log = logging.getLogger(__name__)
_WARNED: set[tuple[str, str]] = set()

KINDS = tuple(_CLASSES)
ENV_DIR = "HAPTICSDK_CALIBRATION_DIR"


def calibration_dir() -> Path:
    """The calibration directory (it need not exist)."""
    env = os.environ.get(ENV_DIR)
    if env:
        return Path(env).expanduser()
    from platformdirs import user_config_path

    # Linux: $XDG_CONFIG_HOME/hapticsdk (~/.config/hapticsdk); macOS: ~/Library/Application
    # Support/hapticsdk; Windows: %LOCALAPPDATA%\hapticsdk (no author folder)
    return user_config_path("hapticsdk", appauthor=False) / "calibration"


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise ValidationError(f"unknown calibration kind {kind!r}; valid: {list(KINDS)}", field="kind")


def calibration_to_dict(cal: Calibration) -> dict[str, Any]:
    """The file content for ``cal`` (schema-valid)."""
    if not isinstance(cal, tuple(_CLASSES.values())):
        raise ValidationError(f"not a calibration: {type(cal).__name__}", field="calibration")
    d = {"schema_version": 1, **cal.to_dict(),
         "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    if d.get("serial") is None:
        d["serial"] = None
    return d


def calibration_from_dict(data: dict[str, Any], *, source: str = "") -> Calibration:
    """Validate ``data`` against the schema and build the calibration object."""
    from ..schemas_io import validate

    validate(data, "calibration", source=source)
    return _CLASSES[data["kind"]].from_dict(data)


#: largest calibration file read (bytes); a measured piezo table is a few kB
MAX_CALIBRATION_BYTES = 4 * 1024 * 1024


def _read_file(p: Path) -> tuple[Any, str]:
    """``(parsed JSON, sha256 of the bytes parsed)`` of one calibration file.

    Only a regular file is opened (a FIFO, a device -- also through a symbolic link --
    or a directory named ``*.json`` is refused before it could block), the read is
    capped at :data:`MAX_CALIBRATION_BYTES`, the text must be UTF-8 and the nesting
    shallow. Raises :class:`ValidationError` naming the file."""
    import hashlib

    from ..schemas_io import parse_json, read_bytes

    data = read_bytes(p, field="calibration", max_bytes=MAX_CALIBRATION_BYTES)
    digest = hashlib.sha256(data).hexdigest()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValidationError(f"{p}: not UTF-8 text (offset {exc.start})", field="calibration") from None
    # depth, syntax, NaN / Infinity: named by their path in the file (calibration.coefficients[1])
    return parse_json(text, p, field="calibration"), digest


def _from_file(p: Path) -> tuple[Calibration, str]:
    data, digest = _read_file(p)
    try:
        return calibration_from_dict(data, source=str(p)), digest
    except CalibrationError as exc:
        raise CalibrationError(f"{p}: {exc}") from None
    except ValidationError:
        raise
    except (TypeError, ValueError, KeyError, IndexError, OverflowError) as exc:  # e.g. ragged table rows
        raise CalibrationError(f"{p}: not a usable calibration: {type(exc).__name__}: {exc}") from None


def read_calibration(path: str | Path) -> Calibration:
    """Read one calibration file (errors name the file and the field)."""
    from ..argcheck import file_path
    return _from_file(file_path(path, "calibration"))[0]


def save_calibration(cal: Calibration, directory: str | Path | None = None, *,
                     path: str | Path | None = None) -> Path:
    """Write ``cal`` to ``path``, or to ``<directory>/<kind>-<serial|any>.json`` (default
    directory: :func:`calibration_dir`). Returns the path written."""
    from ..argcheck import serial_number
    data = calibration_to_dict(cal)
    serial_number(data.get("serial"), "calibration.serial")  # it becomes part of a file name
    calibration_from_dict(data)  # never write a file we could not read back
    if path is None:
        from ..argcheck import file_path
        d = file_path(directory, "directory") if directory is not None else calibration_dir()
        serial = data.get("serial") or "any"
        # ASCII letters, digits and -_. only: at most 126 bytes, within every file system's name limit
        safe = "".join(ch if (ch.isascii() and ch.isalnum()) or ch in "-_." else "_" for ch in str(serial))
        path = d / f"{data['kind']}-{safe}.json"
    p = Path(path)
    from ..fileio import atomic_write_json
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        from ..errors import FileWriteError
        raise FileWriteError(f"cannot create the directory {str(p.parent)!r}: {exc.strerror or exc}",
                             field=str(p)) from None
    # temporary file + fsync + read back with the reader's limits (size cap included) +
    # rename: a reader sees the old calibration or the new one, content the reader would
    # skip is refused (UnreadableWriteError) and the old file kept; a symbolic link at
    # ``p`` is replaced, not followed
    atomic_write_json(p, data, indent=1, verify=_from_file)
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
    sha256: str | None = None
    #: the ``kind`` field of a file that failed to load, when it could be read
    claimed_kind: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The entry as a JSON-ready dict (path, kind, serial, generated, source, error,
        sha256).
        """
        return {"path": str(self.path), "kind": self.kind, "serial": self.serial,
                "generated": self.generated, "source": self.source, "error": self.error,
                "sha256": self.sha256}


def _scan(directory: str | Path | None) -> list[tuple[CalibrationEntry, Calibration | None]]:
    """Every ``*.json`` file of the calibration directory: its entry and the loaded
    calibration (``None`` when it does not load)."""
    from ..argcheck import file_path
    d = file_path(directory, "directory") if directory is not None else calibration_dir()
    out: list[tuple[CalibrationEntry, Calibration | None]] = []
    if not d.is_dir():
        return out
    try:
        paths = sorted(d.glob("*.json"))
    except OSError as exc:
        log.warning("calibration directory %s not readable: %s", d, exc)
        return out
    for p in paths:
        try:
            cal, digest = _from_file(p)
        except Exception as exc:  # one bad file never stops the others: skipped, named
            msg = str(exc) if isinstance(exc, (ValidationError, CalibrationError)) else \
                f"{type(exc).__name__}: {exc}"
            for prefix in ("calibration: ", f"{p}: "):  # the entry names the file already
                msg = msg[len(prefix):] if msg.startswith(prefix) else msg
            if (str(p), msg) not in _WARNED:  # once per file and reason in a process
                _WARNED.add((str(p), msg))
                log.warning("skipped calibration file %s: %s", p, msg)
            out.append((CalibrationEntry(p, None, None, None, "", error=msg, claimed_kind=_peek_kind(p)), None))
            continue
        kind = _kind_of(cal)
        out.append((CalibrationEntry(p, kind, cal.serial, bool(cal.generated), cal.source, sha256=digest), cal))
    return out


def _kind_of(cal: Calibration) -> str:
    return next(k for k, c in _CLASSES.items() if isinstance(cal, c))


def list_calibrations(directory: str | Path | None = None) -> list[CalibrationEntry]:
    """Every ``*.json`` file of the calibration directory, loaded or with its error."""
    return [e for e, _ in _scan(directory)]


@dataclass
class LoadedCalibration:
    """Answer of :func:`load_calibration`.

    Attributes:
        kind: ``"voicecoil"``, ``"piezo"`` or ``"damping"``.
        serial: the serial asked for.
        calibration: the calibration object (``None``: no file and no default).
        origin: ``"file"`` (serial match), ``"file-any"`` (file without serial),
            ``"default"`` or ``"none"``.
        path: the file used, if any.
        skipped: files of this kind that failed to load (path: error).
        sha256: SHA-256 of the bytes of ``path`` that were parsed (``None`` for a default).
    """

    kind: str
    serial: str | None
    calibration: Calibration | None
    origin: str
    path: Path | None
    skipped: dict[str, str]
    sha256: str | None = None

    @property
    def generated(self) -> bool | None:
        """Whether the calibration in use was generated rather than measured (``None`` when
        none was loaded).
        """
        return None if self.calibration is None else bool(self.calibration.generated)

    @property
    def source(self) -> str:
        """Human-readable provenance (file path or default, and the calibration's source)."""
        if self.calibration is None:
            if self.kind == "damping":
                return ("none (no damping measured for this serial: the stiff-wall controller credits none of "
                        "the declared damping; measure it hands off with hapticsdk calibrate damping --device NAME --save)")
            return "none (no calibration file and no default)"
        if self.path is None:
            return f"default, no calibration file saved: {self.calibration.source}"
        return f"{self.path}: {self.calibration.source}"

    def to_dict(self) -> dict[str, Any]:
        """What was loaded, as a JSON-ready dict: kind, serial, origin, file and its sha256,
        generated, source, and the files skipped with why.
        """
        return {"kind": self.kind, "serial": self.serial, "origin": self.origin,
                "path": str(self.path) if self.path else None, "file": str(self.path) if self.path else None,
                "sha256": self.sha256, "generated": self.generated,
                "source": self.source, "skipped": dict(self.skipped)}


def load_calibration(kind: str, serial: str | None = None, *, directory: str | Path | None = None,
                     default: Any = None) -> LoadedCalibration:
    """The calibration of kind ``kind`` for the device with ``serial``.

    Args:
        kind: ``"voicecoil"``, ``"piezo"`` or ``"damping"``.
        serial: device serial number (``None``: only files without a serial match).
        directory: calibration directory (default :func:`calibration_dir`).
        default: used when no file matches; a calibration object or a zero-argument
            callable returning one. Voice coil without ``default``: the paper's
            formula (7). Piezo or damping without ``default``: ``calibration`` is ``None``.

    Files that fail validation are skipped (listed in ``skipped``), never used.
    """
    _check_kind(kind)
    exact = anyone = None
    skipped: dict[str, str] = {}
    for e, cal in _scan(directory):
        if e.error is not None:
            if e.claimed_kind == kind:
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
            return LoadedCalibration(kind, serial, cal, origin, entry.path, skipped, entry.sha256)
    if default is not None:
        cal = default() if callable(default) else default
        return LoadedCalibration(kind, serial, cal, "default", None, skipped)
    if kind == "voicecoil":
        return LoadedCalibration(kind, serial, VoiceCoilCalibration.paper(), "default", None, skipped)
    return LoadedCalibration(kind, serial, None, "none", None, skipped)


def _peek_kind(path: Path) -> str | None:
    """The ``kind`` field of a file that failed validation (``None`` if unreadable)."""
    try:
        data, _ = _read_file(path)
    except Exception:
        return None
    kind = data.get("kind") if isinstance(data, dict) else None
    return kind if isinstance(kind, str) else None


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
           "LoadedCalibration", "CalibrationEntry", "Calibration"]
