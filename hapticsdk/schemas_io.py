"""JSON Schema loading and validation for the SDK's files (``schemas/``).

Every file format of the SDK (material library, scene, render plan, recording,
ratings, calibration) has a JSON Schema in ``schemas/``; :func:`validate` checks an
instance with ``jsonschema`` and turns the first error into a
:class:`~hapticsdk.errors.ValidationError` whose ``field`` is the JSON path.
"""

from __future__ import annotations

import json
import math
import sys
from functools import lru_cache
from pathlib import Path
from typing import Any

from .errors import ValidationError

_HERE = Path(__file__).resolve().parent


def schema_dir() -> Path:
    """Folder holding the schemas (inside the package, or the source tree's ``schemas/``)."""
    for cand in (_HERE / "schemas", _HERE.parent / "schemas"):
        if cand.is_dir():
            return cand
    raise FileNotFoundError("hapticsdk schemas folder not found next to the package")


@lru_cache(maxsize=None)
def load_schema(name: str) -> dict[str, Any]:
    """The schema ``schemas/<name>.schema.json``."""
    path = schema_dir() / f"{name}.schema.json"
    if not path.is_file():
        known = sorted(p.name.split(".")[0] for p in schema_dir().glob("*.schema.json"))
        raise ValidationError(f"no schema named {name!r}; known: {known}", field="schema")
    return json.loads(path.read_text())


def validate(instance: Any, name: str, *, source: str = "") -> None:
    """Validate ``instance`` against schema ``name``; raise :class:`ValidationError` naming
    the offending field (and ``source``, e.g. the file path) on the first error."""
    import jsonschema

    schema = load_schema(name)
    # before the schema: every comparison with NaN is False, so a NaN passes "minimum" and
    # "maximum", and inf passes "number" (none of the SDK's formats has a non-finite field)
    bad = non_finite_at(instance)
    if bad is not None:
        where = f"{source}: " if source else ""
        raise ValidationError(f"{where}{bad[1]} is not a finite number", field=f"{name}{bad[0]}")
    key = _non_string_key_at(instance)
    if key is not None:   # JSON keys are strings; a dict built in code may hold None or 1
        where = f"{source}: " if source else ""
        raise ValidationError(f"{where}key {key[1]!r:.60} is not a string", field=f"{name}{key[0]}")
    cls = jsonschema.validators.validator_for(schema)
    # the deepest error is the most specific one: report it first
    errors = sorted(cls(schema).iter_errors(instance), key=lambda e: -len(e.absolute_path))
    if errors:
        err = errors[0]
        path = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in err.absolute_path)
        field = f"{name}{path}" if path else name
        where = f"{source}: " if source else ""
        raise ValidationError(f"{where}{err.message}", field=field)


def non_finite_at(data: Any) -> tuple[str, str] | None:
    """``(path, value)`` of the first number in ``data`` (nested dicts and lists, as parsed
    JSON or built in memory) that is not finite: a NaN or infinite float (``json`` reads
    ``1e400`` as ``inf`` and ``NaN`` as NaN), or an integer too large for a float (any
    float() of it overflows). ``None`` when every number is finite. The path is as
    :func:`validate` names fields (``.objects[0].intensities.hardness``); the walk is
    iterative, as :func:`check_depth`'s, so depth and width cost no stack."""
    from collections.abc import Mapping

    import numpy as np

    stack: list[tuple[Any, str]] = [(data, "")]
    while stack:
        node, where = stack.pop()
        if isinstance(node, (float, np.floating)):
            if not math.isfinite(node):
                return where, repr(float(node))
        elif isinstance(node, (int, np.integer)) and not isinstance(node, bool):
            if abs(int(node)) > _FLOAT_MAX_INT:
                return where, f"an integer of {len(str(abs(int(node))))} digits"
        elif isinstance(node, Mapping):
            stack.extend((v, f"{where}.{k}") for k, v in reversed(list(node.items())))
        elif isinstance(node, (list, tuple)):
            stack.extend((v, f"{where}[{i}]") for i, v in reversed(list(enumerate(node))))
    return None


def _non_string_key_at(data: Any) -> tuple[str, Any] | None:
    """``(path of the object, key)`` of the first key in ``data`` that is not a string
    (iterative, as :func:`non_finite_at`)."""
    from collections.abc import Mapping

    stack: list[tuple[Any, str]] = [(data, "")]
    while stack:
        node, where = stack.pop()
        if isinstance(node, Mapping):
            for k in node:
                if not isinstance(k, str):
                    return where, k
            stack.extend((v, f"{where}.{k}") for k, v in reversed(list(node.items())))
        elif isinstance(node, (list, tuple)):
            stack.extend((v, f"{where}[{i}]") for i, v in reversed(list(enumerate(node))))
    return None


#: the largest integer a float holds without overflow (``int(sys.float_info.max)``)
_FLOAT_MAX_INT = int(sys.float_info.max)


#: largest JSON file the SDK reads (bytes); scenes, plans and calibrations are far smaller
MAX_JSON_BYTES = 64 * 1024 * 1024
#: deepest nesting of arrays/objects accepted in a JSON file (the SDK's formats need < 15)
MAX_JSON_DEPTH = 100
#: largest CSV / text table the SDK reads (bytes)
MAX_TEXT_BYTES = 256 * 1024 * 1024


def read_bytes(path: str | Path, *, field: str, error: type[ValidationError] = ValidationError,
               max_bytes: int = MAX_JSON_BYTES) -> bytes:
    """The bytes of a regular file of at most ``max_bytes``.

    A missing path, a directory, a FIFO or device (which could block for ever), an
    unreadable or too large file raise ``error`` naming the file, with ``field``.
    """
    import os
    import stat

    from .argcheck import file_path
    try:
        p = file_path(path, field)
    except ValidationError as exc:
        raise error(exc.reason, field=field) from None
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise error(f"file not found: {p}", field=field) from None
    except OSError as exc:
        raise error(f"{p}: cannot read: {exc.strerror or exc}", field=field) from None
    if stat.S_ISDIR(st.st_mode):
        raise error(f"{p} is a directory, expected a file", field=field)
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{p} is not a regular file (FIFO, socket or device)", field=field)
    if st.st_size > max_bytes:
        raise error(f"{p}: {st.st_size} bytes, more than the {max_bytes} bytes accepted", field=field)
    # non-blocking open and a second check on the descriptor: a FIFO swapped in after
    # the stat above can neither block the open nor be read
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(p, flags)
    except OSError as exc:
        raise error(f"{p}: cannot open: {exc.strerror or exc}", field=field) from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise error(f"{p} is not a regular file (FIFO, socket or device)", field=field)
        with os.fdopen(fd, "rb", closefd=False) as fh:
            # the file's size (+1 to see growth), not the cap: a 10-byte file must not
            # reserve a buffer of max_bytes
            data = fh.read(min(st.st_size, max_bytes) + 1)
            if len(data) > st.st_size:  # grew since the stat: read on, up to the cap
                data += fh.read(max_bytes + 1 - len(data))
    except OSError as exc:
        raise error(f"{p}: cannot read: {exc.strerror or exc}", field=field) from None
    finally:
        os.close(fd)
    if len(data) > max_bytes:  # grew while being read
        raise error(f"{p}: more than the {max_bytes} bytes accepted", field=field)
    return data


def read_text(path: str | Path, *, field: str, error: type[ValidationError] = ValidationError,
              max_bytes: int = MAX_TEXT_BYTES) -> str:
    """A UTF-8 text file (see :func:`read_bytes`); other encodings raise ``error`` saying
    where the first bad byte is. A UTF-8 byte-order mark is dropped."""
    data = read_bytes(path, field=field, error=error, max_bytes=max_bytes)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise error(f"{Path(path)}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start})",
                    field=field) from None


def read_csv_rows(path: str | Path, *, field: str, error: type[ValidationError] = ValidationError,
                  max_bytes: int = MAX_TEXT_BYTES, comments: bool = False) -> tuple[list[str], list[list[str]]]:
    """``(comment_lines, rows)`` of a UTF-8 CSV file read with :func:`read_text`.

    Blank lines are skipped; with ``comments`` lines starting with ``#`` are returned
    (without the ``#``) instead of parsed. A malformed CSV (e.g. an unclosed quote, a
    NUL byte) raises ``error``."""
    import csv

    text = read_text(path, field=field, error=error, max_bytes=max_bytes)
    lines = text.splitlines()
    notes = [ln[1:].strip() for ln in lines if comments and ln.startswith("#")]
    body = [ln for ln in lines if ln.strip() and not (comments and ln.startswith("#"))]
    try:
        rows = list(csv.reader(body, strict=True))
    except csv.Error as exc:
        raise error(f"{Path(path)}: malformed CSV ({exc})", field=field) from None
    return notes, rows


def csv_header(row: list[str], path: Any, *, field: str, error: type[ValidationError] = ValidationError
               ) -> list[str]:
    """The column names of a CSV header row, stripped; a name given twice raises ``error``
    naming it (each reader looked one up by the first or the last of the two, so which
    column's numbers were used depended on the reader)."""
    header = [h.strip() for h in row]
    seen: set[str] = set()
    for h in header:
        if h and h in seen:
            raise error(f"{path}: column {h!r} appears twice in the header", field=f"{field}.{h}")
        seen.add(h)
    return header


def check_depth(data: Any, field: str, *, max_depth: int = MAX_JSON_DEPTH) -> None:
    """Refuse data built in memory (a dict given to ``Scene.from_dict``, a plan's dict)
    nested deeper than ``max_depth`` -- the bound :func:`read_json` puts on a file -- with
    a :class:`ValidationError` naming the path where it goes too deep; a walk without
    recursion, so neither 5000 levels nor a dict that holds itself exhaust the stack."""
    from collections.abc import Mapping

    stack: list[tuple[Any, int, str]] = [(data, 0, "")]
    while stack:
        node, depth, path = stack.pop()
        if isinstance(node, Mapping):
            items: Any = ((f"{path}.{k}", v) for k, v in node.items())
        elif isinstance(node, (list, tuple)):
            items = ((f"{path}[{i}]", v) for i, v in enumerate(node))
        else:
            continue
        if depth >= max_depth:
            raise ValidationError(f"nested more than {max_depth} levels deep", field=f"{field}{path[:200]}")
        stack.extend((v, depth + 1, p) for p, v in items)


def json_depth(text: str) -> int:
    """Deepest nesting of ``[`` / ``{`` in JSON ``text`` (brackets inside strings ignored);
    linear time, no recursion."""
    import re

    import numpy as np

    if '"' in text:
        text = re.sub(r'"(?:[^"\\]|\\.)*"', '""', text)
    b = np.frombuffer(text.encode("utf-8", "surrogatepass"), dtype=np.uint8)
    if not b.size:
        return 0
    step = _depth_table()[b]
    return int(np.cumsum(step, dtype=np.int64).max())


@lru_cache(maxsize=1)
def _depth_table() -> Any:
    import numpy as np

    t = np.zeros(256, np.int8)
    t[[ord("["), ord("{")]] = 1
    t[[ord("]"), ord("}")]] = -1
    return t



class _Constant:
    """Stands for a ``NaN`` / ``Infinity`` literal while parsing, so its path can be named."""

    __slots__ = ("name",)

    def __init__(self, name: str) -> None:
        self.name = name


def _find_constant(data: Any, path: str = "") -> tuple[str, str] | None:
    """``(path, literal)`` of the first :class:`_Constant` in parsed JSON (iterative:
    the depth was bounded before parsing, the width is not)."""
    stack: list[tuple[Any, str]] = [(data, path)]
    while stack:
        node, where = stack.pop()
        if isinstance(node, _Constant):
            return where, node.name
        if isinstance(node, dict):
            stack.extend((v, f"{where}.{k}") for k, v in reversed(list(node.items())))
        elif isinstance(node, list):
            stack.extend((v, f"{where}[{i}]") for i, v in reversed(list(enumerate(node))))
    return None


def json_path_at(text: str, pos: int) -> str:
    """The JSON path (``.objects[0].pose``) of the innermost value open at character
    ``pos`` of JSON ``text``, from a linear scan of its brackets, commas, colons and
    strings (no parse: used where parsing is refused, e.g. nesting too deep)."""
    import re

    stack: list[list[Any]] = []
    last = ""
    for m in re.finditer(r'"(?:[^"\\]|\\.)*"|[\[\]{},:]', text[:pos]):
        t = m.group()
        if t[0] == '"':
            last = t
        elif t in "[{":
            stack.append([t, 0 if t == "[" else None])
        elif t in "]}":
            if stack:
                stack.pop()
        elif t == "," and stack and stack[-1][0] == "[":
            stack[-1][1] += 1
        elif t == ":" and stack and stack[-1][0] == "{":
            try:
                stack[-1][1] = json.loads(last)
            except ValueError:
                stack[-1][1] = last
    parts = [f"[{v}]" if k == "[" else f".{v}" for k, v in stack[:-1] if v is not None]
    return "".join(parts[:12]) + ("..." if len(parts) > 12 else "")


def read_json(path: str | Path, *, field: str, error: type[ValidationError] = ValidationError,
              max_bytes: int = MAX_JSON_BYTES, max_depth: int = MAX_JSON_DEPTH) -> Any:
    """Parse a JSON file, the one reader of every JSON file the SDK opens.

    Refused with ``error`` naming the file and ``field``: a missing or non-regular file,
    more than ``max_bytes``, text that is not UTF-8, nesting deeper than ``max_depth``
    (checked before parsing, so 5000 nested brackets cannot exhaust the stack), invalid
    JSON, and ``NaN`` / ``Infinity`` (not JSON numbers)."""
    text = read_text(path, field=field, error=error, max_bytes=max_bytes)
    p = Path(path)
    return parse_json(text, p, field=field, error=error, max_depth=max_depth)


def parse_json(text: str, p: str | Path, *, field: str, error: type[ValidationError] = ValidationError,
               max_depth: int = MAX_JSON_DEPTH) -> Any:
    """Parse JSON ``text`` read from file ``p`` (the checks of :func:`read_json` after the
    read): nesting, syntax and ``NaN`` / ``Infinity`` refused with ``error`` whose field is
    ``field`` plus the JSON path where it happens (``scene.objects[0].pose``)."""
    depth = json_depth(text)
    if depth > max_depth:
        where = json_path_at(text, _deep_position(text, max_depth))
        raise error(f"{p}: JSON nested {depth} levels deep, more than the {max_depth} accepted (from "
                    f"{field}{where})", field=f"{field}{where}")
    twice: list[tuple[dict[str, Any], str]] = []

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        obj = dict(items)
        if len(obj) != len(items) and not twice:  # the first object found, named after the parse
            seen: set[str] = set()
            for k, _ in items:
                if k in seen:
                    twice.append((obj, k))
                    break
                seen.add(k)
        return obj

    try:
        data = json.loads(text, parse_constant=_Constant, object_pairs_hook=pairs)
    except json.JSONDecodeError as exc:
        where = json_path_at(text, exc.pos)
        raise error(f"{p}: not valid JSON: {exc}", field=f"{field}{where}") from None
    except (ValueError, RecursionError) as exc:
        raise error(f"{p}: not valid JSON: {exc}", field=field) from None
    # the walk only when a literal may be there ("NaN" inside a string also triggers it)
    bad = _find_constant(data) if ("NaN" in text or "Infinity" in text) else None
    if bad is not None:
        raise error(f"{p}: {bad[1]} is not a JSON number (at {field}{bad[0]})", field=f"{field}{bad[0]}")
    if twice:
        where = f"{field}{_path_of(data, twice[0][0])}.{twice[0][1]}"
        raise error(f"{p}: key {twice[0][1]!r} appears twice in one object (at {where}); JSON readers differ "
                    "on which value they keep", field=where)
    return data


def _path_of(data: Any, target: Any) -> str:
    """The JSON path of the object ``target`` (by identity) in parsed ``data``; iterative."""
    stack: list[tuple[Any, str]] = [(data, "")]
    while stack:
        node, where = stack.pop()
        if node is target:
            return where
        if isinstance(node, dict):
            stack.extend((v, f"{where}.{k}") for k, v in node.items())
        elif isinstance(node, list):
            stack.extend((v, f"{where}[{i}]") for i, v in enumerate(node))
    return ""


def _deep_position(text: str, max_depth: int) -> int:
    """Index in ``text`` of the bracket that opens level ``max_depth + 1`` (strings skipped)."""
    import re
    depth = 0
    for m in re.finditer(r'"(?:[^"\\]|\\.)*"|[\[\]{}]', text):
        t = m.group()
        if t in "[{":
            depth += 1
            if depth > max_depth:
                return m.start()
        elif t in "]}":
            depth -= 1
    return len(text)


def load_json(path: str | Path, schema: str) -> Any:
    """Read a JSON file and validate it; errors name the file and the field.

    Validation is memoised (:func:`_validated_marker`): a file whose content, schema and
    ``jsonschema`` version are exactly those of a file that passed before is not
    validated again (``jsonschema`` costs 40-90 ms to import and warm up, e.g. on every
    ``hapticsdk render`` of a library material). Failures are never memoised.
    """
    data = read_json(path, field=schema)
    marker = _validated_marker(data, schema)
    if marker is not None and marker.is_file():
        return data
    validate(data, schema, source=str(path))
    if marker is not None:
        try:
            from .fileio import atomic_write_bytes
            marker.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(marker, b"")
        except Exception:  # a read-only cache folder: validation still happened
            pass
    return data


def _cache_dir() -> Path:
    from .fileio import cache_dir
    return cache_dir()


@lru_cache(maxsize=None)
def _marker_salt(schema: str) -> tuple[bytes, bytes, bytes] | None:
    """The parts of a validation marker that depend on the schema and the installed
    versions, read once per process (the two version lookups scan the installed
    distributions, ~0.5 ms per file loaded; :mod:`hapticsdk.plugin_index` keeps them with
    the plugins' entry points, so a process that finds them there imports no
    :mod:`importlib.metadata`)."""
    from .plugin_index import version as installed_version
    try:
        schema_bytes = (schema_dir() / f"{schema}.schema.json").read_bytes()
        version = installed_version("jsonschema") + "/" + installed_version("hapticsdk")
    except Exception:
        return None
    return schema.encode(), schema_bytes, version.encode()


def _validated_marker(data: Any, schema: str) -> Path | None:
    """Where the "passed" marker of ``data`` (as parsed by :func:`read_json`) against schema
    ``schema`` lives: ``<cache>/validated/<sha256>``, the hash taken over the instance's
    canonical JSON (sorted keys; ints and floats stay distinct), the schema file's bytes,
    the schema name and the installed ``jsonschema`` and ``hapticsdk`` versions (the
    SDK's own checks in :func:`validate` may change with it). ``None`` (always validate)
    when any of them cannot be read."""
    import hashlib

    salt = _marker_salt(schema)
    try:
        blob = json.dumps(data, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()
    except Exception:
        return None
    if salt is None:
        return None
    h = hashlib.sha256()
    for part in (*salt, blob):
        h.update(len(part).to_bytes(8, "little"))
        h.update(part)
    return _cache_dir() / "validated" / h.hexdigest()
