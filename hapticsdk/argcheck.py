"""One validation layer for API arguments and command-line values.

Every public function that takes a number, an array of numbers, a device serial, an
output path or a pose from its caller checks it here, and the ``hapticsdk`` command's
argparse types (:mod:`hapticsdk.cli.argtypes`) call the same functions. A bad value
raises :class:`~hapticsdk.errors.ValidationError` whose ``field`` names the argument
(``tolerance``, ``targets[0][1]``, ``--serial``), never a ``TypeError`` or
``ValueError`` from deep inside numpy, matplotlib or the operating system.

Rules (docs/safety.md, "Named errors"):

* a number is an ``int`` / ``float`` / numpy real, never a ``bool`` or a string
  (``"0.5"`` is refused: a string that happens to parse is a bug in the caller);
* a switch (``flag``) is ``True`` or ``False`` (or a numpy bool), never a ``1``, a string
  or ``None`` read by its truth value (``"no"`` is true);
* an array of numbers is checked element by element, and the first bad element is named
  by its index;
* a device serial number is at most :data:`MAX_SERIAL_CHARS` characters with no control
  characters (a USB string descriptor holds at most 126 UTF-16 code units; a serial goes
  into a file name, which the file system caps at 255 bytes);
* a figure path ends in a format the plotting backend writes.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from .checks import is_number
from .errors import ValidationError

if TYPE_CHECKING:
    from pathlib import Path

__all__ = ["number", "flag", "number_array", "serial_number", "file_path", "figure_path", "call_with_options", "MAX_SERIAL_CHARS", "FIGURE_FORMATS"]

#: longest device serial number accepted: a USB string descriptor is at most 255 bytes,
#: 2 of them header, the rest UTF-16 code units: (255 - 2) // 2 = 126
MAX_SERIAL_CHARS = 126

#: formats matplotlib's bundled Agg, PDF, PS, SVG and PGF backends write (``savefig``
#: suffixes), checked without importing matplotlib; :func:`hapticsdk.plotting.save_figure`
#: checks again against the installed matplotlib's own list
FIGURE_FORMATS = ("eps", "jpeg", "jpg", "pdf", "pgf", "png", "ps", "raw", "rgba", "svg", "svgz", "tif",
                  "tiff", "webp")


def number(value: Any, field: str, *, lo: float | None = None, hi: float | None = None,
           lo_open: bool = False, hi_open: bool = False, integer: bool = False) -> float:
    """``value`` as a float, when it is a finite real number (not a bool, not a string)
    within ``lo``..``hi`` (open ends with ``lo_open`` / ``hi_open``); with ``integer``
    a whole number (returned as a float still: callers ``int()`` it)."""
    if not is_number(value):
        raise ValidationError(f"must be a number, got {type(value).__name__} {value!r:.80}", field=field)
    try:
        v = float(value)
    except (OverflowError, ValueError, TypeError):
        raise ValidationError(f"must be a finite number, got {value!r:.80}", field=field) from None
    if not math.isfinite(v):
        raise ValidationError(f"must be a finite number, got {value!r}", field=field)
    if integer and v != int(v):
        raise ValidationError(f"must be a whole number, got {value!r}", field=field)
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise ValidationError(f"must be {'>' if lo_open else '>='} {lo:g}, got {value!r}", field=field)
    if hi is not None and (v > hi or (hi_open and v == hi)):
        raise ValidationError(f"must be {'<' if hi_open else '<='} {hi:g}, got {value!r}", field=field)
    return v


def flag(value: Any, field: str) -> bool:
    """``value`` as a bool, when it is ``True`` or ``False`` (or a numpy bool)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValidationError(f"must be True or False, got {type(value).__name__} {value!r:.80}", field=field)
    return bool(value)


_NUMBER_TYPES = frozenset((int, float, np.float64, np.float32, np.int64, np.int32))


def _walk_bad(value: Any, field: str, finite: bool = True) -> None:
    """Name the first element of a nested sequence that is not a (finite) real number."""
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "fiu":
            if not finite:
                return
            bad: Any = np.argwhere(~np.isfinite(value.astype(float))) if value.size else []
            if len(bad):
                idx = "".join(f"[{int(i)}]" for i in bad[0])
                raise ValidationError(f"must be finite numbers, got {value[tuple(bad[0])]!r}", field=field + idx)
            return
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        for i, x in enumerate(value):
            _walk_bad(x, f"{field}[{i}]", finite)
        return
    if finite:
        number(value, field)
    elif not is_number(value):
        raise ValidationError(f"must be a number, got {type(value).__name__} {value!r:.80}", field=field)


def number_array(value: Any, field: str, *, ndim: tuple[int, ...] | None = None,
                 finite: bool = True) -> np.ndarray:
    """``value`` (a nested list / tuple or a numeric array) as a float array of finite
    numbers; a string, a bool, ``None`` or a non-finite element is named by its index
    (``targets[0][1]``); ragged rows and the wrong number of dimensions are refused.
    ``finite=False`` lets NaN and infinities through (for a caller whose own check names
    them better, e.g. by column name)."""
    if isinstance(value, (str, bytes)) or value is None or isinstance(value, bool):
        raise ValidationError(f"must be an array of numbers, got {type(value).__name__}", field=field)
    try:  # fast path: already numeric and finite (a type scan in C, no per-element checks)
        raw = np.asarray(value)
        if not isinstance(value, np.ndarray) and raw.dtype.kind in "fiu":
            # numpy turns [0.5, True] into floats: the element types decide
            kinds = set(map(type, np.asarray(value, dtype=object).ravel().tolist()))
            if not kinds <= _NUMBER_TYPES:
                raw = None  # type: ignore[assignment]  # the element types decide: re-read below
    except (ValueError, TypeError):
        raw = None
    if raw is None or raw.dtype.kind not in "fiu" or (finite and not np.isfinite(raw).all()):
        _walk_bad(value, field, finite)  # names the first bad element (a string, a bool, NaN)
    try:
        arr = np.asarray(value, dtype=float)
    except (ValueError, TypeError) as exc:
        raise ValidationError(f"must be a rectangular array of numbers ({exc})", field=field) from None
    if ndim is not None and arr.ndim not in ndim:
        raise ValidationError(f"must have {' or '.join(map(str, ndim))} dimension(s), got shape {arr.shape}",
                              field=field)
    return arr


def serial_number(value: Any, field: str = "serial") -> str | None:
    """A device serial number: ``None`` or a non-empty string of at most
    :data:`MAX_SERIAL_CHARS` characters without control characters."""
    if value is None:
        return None
    if not isinstance(value, str):
        raise ValidationError(f"must be a string, got {type(value).__name__}", field=field)
    if not value.strip():
        raise ValidationError("must not be empty", field=field)
    if len(value) > MAX_SERIAL_CHARS:
        raise ValidationError(f"{len(value)} characters, more than the {MAX_SERIAL_CHARS} a USB serial "
                              f"number can have", field=field)
    if any(ord(c) < 32 or ord(c) == 127 for c in value):
        raise ValidationError("must not contain control characters", field=field)
    return value


def file_path(value: Any, field: str = "path") -> "Path":
    """A path argument of a reader or writer: a non-empty ``str`` or ``os.PathLike``
    (``None``, a number, a list or ``bytes`` raise :class:`ValidationError` naming
    ``field`` instead of ``TypeError`` from the operating system layer)."""
    import os
    from pathlib import Path

    try:
        text = os.fspath(value)
    except TypeError:
        raise ValidationError(f"must be a file path, got {type(value).__name__} {value!r:.60}", field=field) from None
    if not isinstance(text, str) or not text:
        raise ValidationError(f"must be a file path, got {value!r:.60}", field=field)
    if "\x00" in text:   # the operating system's calls raise ValueError on it
        raise ValidationError(f"must not contain a NUL character, got {text!r:.60}", field=field)
    try:  # the file system's own limits (NAME_MAX per name, PATH_MAX), asked once here:
        os.lstat(text)  # pathlib's exists() / is_file() raise OSError on them instead of answering
    except OSError as exc:
        import errno
        if exc.errno == errno.ENAMETOOLONG:
            raise ValidationError(f"file name too long for the file system ({len(os.fsencode(text))} bytes, "
                                  f"a name longer than its limit): {text[:60]!r}...", field=field) from None
    except (ValueError, UnicodeError):  # a lone surrogate the file system encoding cannot hold
        raise ValidationError(f"not a file name this system can encode: {text[:60]!r}", field=field) from None
    return Path(text)


def figure_path(value: Any, field: str = "path") -> str:
    """A figure output path whose suffix is one of :data:`FIGURE_FORMATS` (no suffix:
    PNG)."""
    import os
    from pathlib import Path

    try:
        text = os.fspath(value)
    except TypeError:
        raise ValidationError(f"must be a path, got {type(value).__name__}", field=field) from None
    suffix = Path(str(text)).suffix[1:].lower()
    if suffix and suffix not in FIGURE_FORMATS:
        raise ValidationError(f"cannot write a figure as {suffix!r}; use one of {', '.join(FIGURE_FORMATS)}",
                              field=field)
    return str(text)



def call_with_options(fn: Any, *args: Any, options: Any, field: str) -> Any:
    """``fn(*args, **options)``, where ``options`` came from a file or a caller: not an
    object, or a keyword ``fn`` (or the class it forwards to) does not take, raises a
    :class:`ValidationError` naming the option (``plan.settings.renderer_options.hardness.sink``)
    instead of a raw ``TypeError``; so does a ``TypeError``, ``ValueError``, ``LookupError``
    (an index or key of an option value) or ``ArithmeticError`` (``OverflowError`` of a
    float that became an infinite int, ``decimal.InvalidOperation``) that ``fn`` raises on
    a value of the options (a plugin that did not check one), naming ``field``."""
    import re
    from collections.abc import Mapping

    if not isinstance(options, Mapping):
        raise ValidationError(f"must be an object of options, got {type(options).__name__}", field=field)
    try:
        return fn(*args, **dict(options))
    except ValidationError as exc:  # an option's own check: its field is put under ``field``
        head = re.split(r"[.\[]", exc.field or "", maxsplit=1)[0]
        if head and head in options:
            raise type(exc)(exc.reason, field=f"{field}.{exc.field}") if type(exc) is ValidationError else exc
        raise
    except (TypeError, ValueError, LookupError, ArithmeticError) as exc:
        m = re.search(r"unexpected keyword argument '([^']*)'", str(exc)) if isinstance(exc, TypeError) else None
        if m is not None:
            key = m.group(1)
            raise ValidationError(f"unknown option {key!r} ({exc})", field=f"{field}.{key}") from None
        if not options and not isinstance(exc, (TypeError, ValueError)):
            raise  # no option to blame: a bug of the callee
        # the callee (often a plugin) choked on a value of these options instead of
        # naming it: the options are the input at fault, so the error names them
        name = getattr(fn, "__qualname__", None) or type(fn).__name__
        raise ValidationError(f"{name} rejected these options: {type(exc).__name__}: {exc}", field=field) from exc


def refuse_file_options(dim: Any, options: Any, field: str) -> None:
    """A scene or plan names no file to read: the calibration options a dimension declares
    (``PerceptionDimension.calibrations``, e.g. the roughness renderer's piezo ``table``)
    must be given inline, as an object in the calibration file format. A string there
    would be read as a path (a file chosen by data), so it raises a
    :class:`ValidationError` naming the option; code passes a path or a loaded table
    directly, and saved calibrations come from the per-user calibration store."""
    from collections.abc import Mapping

    if not isinstance(options, Mapping):
        return
    for key in getattr(dim, "calibrations", None) or {}:
        value = options.get(key)
        if value is not None and not isinstance(value, Mapping):
            raise ValidationError(
                f"a scene or plan cannot name a file or a stored object to read ({type(value).__name__} "
                f"{value!r:.60}); give the calibration inline as an object, save it in the calibration "
                f"store ('hapticsdk calibrate ...'), or pass it from code", field=f"{field}.{key}")
