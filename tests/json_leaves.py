"""Helpers for tests that change one number of a JSON document at a time."""

from __future__ import annotations

import copy
from typing import Any, Iterator

Path = tuple[Any, ...]


def nodes(data: Any, path: Path = ()) -> Iterator[tuple[Path, Any]]:
    """Every ``(path, value)`` in nested dicts and lists, the whole document (``()``)
    first, in document order; ``path`` holds keys and indices."""
    yield path, data
    if isinstance(data, dict):
        for k, v in data.items():
            yield from nodes(v, (*path, k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            yield from nodes(v, (*path, i))


def number_leaves(data: Any) -> Iterator[tuple[Path, Any]]:
    """Every ``(path, value)`` of a number (not a bool) in ``data``, in document order."""
    return ((p, v) for p, v in nodes(data) if isinstance(v, (int, float)) and not isinstance(v, bool))


def dotted(path: Path) -> str:
    """``path`` as the SDK names fields: ``.objects[0].pose``."""
    return "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path)


def replaced(data: Any, path: Path, value: Any) -> Any:
    """A deep copy of ``data`` with the item at ``path`` set to ``value``."""
    d = copy.deepcopy(data)
    cur = d
    for k in path[:-1]:
        cur = cur[k]
    cur[path[-1]] = value
    return d
