"""The arrays of a live recording's run file, as slices of its stream's columns.

One description for both writers (:mod:`hapticsdk.runtime.recorder`: ``.npz``;
:mod:`hapticsdk.runtime.recorder_h5`: ``.h5``): the stream's columns, the arrays stored
from them, the names that repeat a stored array (the servo log's names, which the
plotting helpers read; HDF5 stores them as hard links) and the arrays a live recording
has no data for (zeros, for the ``hapticsdk-run`` format).
"""

from __future__ import annotations

from typing import Any, Sequence

#: command fields recorded per role
CMD_FIELDS = ("force_n", "frequency_hz", "amplitude")
#: the stream's state columns, before the commands
STATE_COLUMNS = ("t", "px", "py", "pz", "vx", "vy", "vz", "force_n", "penetration_mm", "object_id")
#: arrays written as zeros: name -> (shape after the tick axis, dtype)
ZEROS: dict[str, tuple[tuple[int, ...], str]] = {"device_force_n": ((3,), "<f8"), "buttons": ((), "<i8")}


def columns(roles: Sequence[str]) -> list[str]:
    """The stream's columns for ``roles`` (the state, then each role's commands)."""
    return list(STATE_COLUMNS) + [f"cmd/{r}/{f}" for r in roles for f in CMD_FIELDS]


def stored(cols: Sequence[str], roles: Sequence[str]) -> dict[str, tuple[int, ...]]:
    """Array name -> the stream columns it holds, consecutive (one column: a 1-D array)."""
    at = {c: k for k, c in enumerate(cols)}
    out: dict[str, tuple[int, ...]] = {"t": (at["t"],), "position_mm": (at["px"], at["py"], at["pz"]),
                                       "velocity_mm_s": (at["vx"], at["vy"], at["vz"])}
    for c in ("force_n", "penetration_mm", "object_id"):
        out[c] = (at[c],)
    for r in roles:
        for f in CMD_FIELDS:
            out[f"cmd/{r}/{f}"] = (at[f"cmd/{r}/{f}"],)
    return out


def aliases(roles: Sequence[str]) -> dict[str, str]:
    """Name -> the stored array it repeats: ``state_t`` and the servo log's
    ``<role>.<field>`` (vibration fields)."""
    out = {"state_t": "t"}
    for r in roles:
        for f in CMD_FIELDS[1:]:
            out[f"{r}.{f}"] = f"cmd/{r}/{f}"
    return out


def take(a: Any, idx: tuple[int, ...]) -> Any:
    """The array ``idx`` (from :func:`stored`) of the rows ``a``: a view (a slice of the
    columns, never a copy, so a memory-mapped stream stays on disk)."""
    return a[:, idx[0]] if len(idx) == 1 else a[:, idx[0]:idx[-1] + 1]


#: the largest object id a stream maps to a name: ids travel in the float64
#: ``object_id`` column of every row, and a float64 holds each integer up to 2**53
#: exactly (53-bit significand), none above it
MAX_OBJECT_ID = 2 ** 53


def parse_header(raw: Any, part: Any) -> Any:
    """The JSON text of a stream header (``bytes`` of an ``.npz`` stream, the ``str``
    attribute of an HDF5 one) parsed with the rules of every SDK JSON reader
    (:func:`hapticsdk.schemas_io.parse_json`: bounded nesting, no ``NaN`` / ``Infinity``);
    anything else raises :class:`~hapticsdk.errors.RecordingError` naming the file and
    ``record`` plus the JSON path."""
    from ..errors import RecordingError
    from ..schemas_io import parse_json

    if isinstance(raw, (bytes, bytearray, memoryview)):
        try:
            raw = bytes(raw).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise RecordingError(f"{part}: damaged recording stream header: not UTF-8 text (byte {exc.start})",
                                 field="record.header") from None
    if not isinstance(raw, str):
        raise RecordingError(f"{part}: damaged recording stream header: {type(raw).__name__}, not JSON text",
                             field="record.header")
    return parse_json(raw, part, field="record", error=RecordingError)


def _is_object_id(key: Any) -> bool:
    """``key`` spells an object id: ASCII digits with an optional minus, within
    :data:`MAX_OBJECT_ID` (``str.isdigit`` also takes ``"\u00b2"``, which ``int`` does not)."""
    import re

    return (isinstance(key, str) and re.fullmatch(r"-?[0-9]{1,16}", key) is not None
            and abs(int(key)) <= MAX_OBJECT_ID)


def check_header(header: Any, part: Any) -> dict[str, Any]:
    """The header of a recording stream (``.part``, both writers), checked before its
    fields are used: an object whose ``roles`` are distinct names, whose ``columns`` are
    :func:`columns` of them, whose ``period_s`` is a number of seconds > 0 and whose
    ``objects`` map object ids (whole numbers) to names. A stream left by a crash may be
    damaged anywhere: each defect raises :class:`~hapticsdk.errors.RecordingError` naming
    the file and the field (``record.columns``), not a ``KeyError`` or ``ZeroDivisionError``."""
    from collections.abc import Mapping

    from ..argcheck import number
    from ..errors import RecordingError, ValidationError

    def bad(what: str, key: str) -> RecordingError:
        return RecordingError(f"{part}: damaged recording stream header: {what}", field=f"record.{key}")

    if not isinstance(header, Mapping):
        raise bad(f"must be an object, got {type(header).__name__}", "header")
    for key in ("columns", "roles", "period_s"):
        if key not in header:
            raise bad(f"no {key!r}", key)
    roles = header["roles"]
    if not isinstance(roles, list) or not all(isinstance(r, str) and r for r in roles) or len(set(roles)) != len(roles):
        raise bad(f"roles must be a list of distinct names, got {roles!r:.80}", "roles")
    if header["columns"] != columns(roles):
        raise bad(f"columns {header['columns']!r:.80} are not those of roles {roles}", "columns")
    try:
        number(header["period_s"], "period_s", lo=0.0, lo_open=True)
    except ValidationError as exc:
        raise bad(f"period_s {exc.reason}", "period_s") from None
    objects = header.get("objects", {})
    if not isinstance(objects, Mapping) or not all(
            _is_object_id(k) and isinstance(v, str) for k, v in objects.items()):
        raise bad(f"objects must map object ids to names, got {objects!r:.80}", "objects")
    return dict(header)

