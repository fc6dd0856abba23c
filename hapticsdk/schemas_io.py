"""JSON Schema loading and validation for the SDK's files (``schemas/``).

Every file format of the SDK (material library, scene, render plan, recording,
ratings, calibration) has a JSON Schema in ``schemas/``; :func:`validate` checks an
instance with ``jsonschema`` and turns the first error into a
:class:`~hapticsdk.errors.ValidationError` whose ``field`` is the JSON path.
"""

from __future__ import annotations

import json
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
    cls = jsonschema.validators.validator_for(schema)
    # the deepest error is the most specific one: report it first
    errors = sorted(cls(schema).iter_errors(instance), key=lambda e: -len(e.absolute_path))
    if errors:
        err = errors[0]
        path = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in err.absolute_path)
        field = f"{name}{path}" if path else name
        where = f"{source}: " if source else ""
        raise ValidationError(f"{where}{err.message}", field=field)


def read_json(path: str | Path, *, field: str, error: type[ValidationError] = ValidationError) -> Any:
    """Parse a JSON file; a missing file or bad JSON raises ``error`` naming the file and ``field``."""
    p = Path(path)
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except (FileNotFoundError, IsADirectoryError):
        raise error(f"file not found: {p}", field=field) from None
    except json.JSONDecodeError as exc:
        raise error(f"{p}: not valid JSON: {exc}", field=field) from None


def load_json(path: str | Path, schema: str) -> Any:
    """Read a JSON file and validate it; errors name the file and the field."""
    data = read_json(path, field=schema)
    validate(data, schema, source=str(path))
    return data
