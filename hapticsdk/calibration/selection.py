"""Which saved calibration each renderer uses.

A perception dimension whose renderer needs an actuator calibration declares it::

    class HardnessDimension(PerceptionDimension):
        #: renderer option -> (calibration kind, channel role of the calibrated actuator)
        calibrations = {"calibration": ("voicecoil", "coil")}

The compiler (:func:`hapticsdk.compiler.compile_scene`) and the runtime
(:func:`hapticsdk.runtime.render.render_plan`) then load that calibration through the
calibration store (:func:`hapticsdk.calibration.load_calibration`), for the serial
number of the actuator on that role (its ``serial_number`` option, else any device),
pass it to the renderer, and record where it came from: the file and the SHA-256 of the
bytes read, or that no file was saved and the renderer's built-in default (the paper's
formula (7), a plugin's generated piezo table) was used. A calibration given explicitly
in the scene's ``renderer_options`` wins over the store and is recorded as such.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

from .store import calibration_dir, load_calibration

__all__ = ["declared_calibrations", "select_calibrations"]


def declared_calibrations(dim: Any) -> dict[str, tuple[str, str]]:
    """``renderer option -> (kind, role)`` a dimension declares (``{}`` if none)."""
    decl = getattr(dim, "calibrations", None) or {}
    out: dict[str, tuple[str, str]] = {}
    for opt, spec in dict(decl).items():
        kind, role = spec
        out[str(opt)] = (str(kind), str(role))
    return out


def _serial(options: Mapping[str, Any] | None) -> str | None:
    for key in ("serial_number", "serial"):
        v = (options or {}).get(key)
        if isinstance(v, str) and v:
            return v
    return None


def select_calibrations(dimension: str, dim: Any, *, renderer_options: Mapping[str, Any] | None = None,
                        role_options: Mapping[str, Mapping[str, Any]] | None = None,
                        directory: str | Path | None = None) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """The calibrations of one dimension's renderer.

    Args:
        dimension: the dimension's name (for the record's keys).
        dim: the dimension object (its ``calibrations`` declaration is read).
        renderer_options: the scene's ``renderer_options`` for this dimension; an option
            given there is used as is.
        role_options: role -> actuator options (``serial_number`` picks the file).
        directory: calibration directory (default :func:`calibration_dir`).

    Returns:
        ``(options, records)``: renderer option -> calibration object to pass (only for
        files found; the renderer's own default otherwise), and record key
        (``dimension``, or ``dimension.option`` when it declares several) -> record with
        ``kind``, ``role``, ``serial``, ``origin`` (``"file"``, ``"file-any"``,
        ``"default"``, ``"renderer_options"``), ``file``, ``sha256``, ``source`` (words),
        ``generated`` and ``skipped`` (files of that kind that did not load).
    """
    decl = declared_calibrations(dim)
    given = dict(renderer_options or {})
    opts: dict[str, Any] = {}
    records: dict[str, dict[str, Any]] = {}
    for opt, (kind, role) in decl.items():
        key = dimension if len(decl) == 1 else f"{dimension}.{opt}"
        serial = _serial((role_options or {}).get(role))
        rec: dict[str, Any] = {"kind": kind, "role": role, "serial": serial, "file": None, "sha256": None,
                               "generated": None, "skipped": {}}
        if opt in given:
            v = given[opt]
            rec.update(origin="renderer_options",
                       source=f"given in settings.renderer_options.{dimension}.{opt}"
                              + (f" ({v})" if isinstance(v, (str, Path)) else ""))
            records[key] = rec
            continue
        d = Path(directory) if directory is not None else calibration_dir()
        loaded = load_calibration(kind, serial, directory=d)
        rec["skipped"] = dict(loaded.skipped)
        if loaded.path is not None and loaded.calibration is not None:
            opts[opt] = loaded.calibration
            rec.update(origin=loaded.origin, file=str(loaded.path), sha256=loaded.sha256,
                       generated=bool(loaded.calibration.generated),
                       source=f"calibration file {loaded.path} ({loaded.calibration.source})")
        else:
            who = f"serial {serial!r}" if serial else "any device"
            rec.update(origin="default",
                       source=f"default: no {kind} calibration file saved for {who} in {d}; the "
                              f"renderer's built-in calibration is used")
        records[key] = rec
    return opts, records

