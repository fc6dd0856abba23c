"""Renderer shipping: renderers built in the application cross the command pipe
pickled, and the large calibration tables they hold (the piezo's ~300 kB drive table,
the same for every material) cross once per session and are referred to afterwards
(persistent ids ``(_TABLE_PID, key)``).

:func:`dump_renderers` is the application's end, :func:`_load_renderers` the servo's.
Part of :mod:`hapticsdk.runtime.session`.
"""

from __future__ import annotations

import io
import pickle
from typing import Any


#: persistent-id tag of a calibration table the servo keeps (see Session._prebuilt)
_TABLE_PID = "hapticsdk-table"


class _RendererUnpickler(pickle.Unpickler):
    """Unpickles renderers whose calibration tables were sent before (references
    ``(_TABLE_PID, key)`` into ``tables``)."""

    def __init__(self, data: bytes, tables: dict[int, Any]) -> None:
        super().__init__(io.BytesIO(data))
        self.tables = tables

    def persistent_load(self, pid: Any) -> Any:
        if isinstance(pid, tuple) and len(pid) == 2 and pid[0] == _TABLE_PID and pid[1] in self.tables:
            return self.tables[pid[1]]
        raise pickle.UnpicklingError(f"unknown table reference {pid!r} (its table was never received)")


def dump_renderers(renderers: Any, known: dict[int, tuple[Any, int]], first_key: int
                   ) -> tuple[bytes, dict[int, bytes], dict[int, Any]]:
    """The application's end: ``renderers`` pickled, with every object of
    :func:`_shared_table_types` they hold pickled as a reference ``(_TABLE_PID, key)``.
    ``known`` maps ``id(table)`` to ``(table, key)`` for the tables the servo already
    holds; a table not in it gets a new key from ``first_key`` on. Returns the payload,
    the new tables pickled ``{key: bytes}`` (to be sent first) and the new tables
    themselves ``{key: table}`` (to be added to ``known`` once sent)."""
    kinds = _shared_table_types()
    new: dict[int, bytes] = {}
    pending: dict[int, Any] = {}

    class _Pickler(pickle.Pickler):
        def persistent_id(self, obj: Any) -> Any:
            if type(obj) not in kinds:
                return None
            hit = known.get(id(obj))
            if hit is not None and hit[0] is obj:
                return (_TABLE_PID, hit[1])
            for k, o in pending.items():
                if o is obj:
                    return (_TABLE_PID, k)
            key = first_key + len(new)
            new[key] = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
            pending[key] = obj
            return (_TABLE_PID, key)

    out = io.BytesIO()
    _Pickler(out, protocol=pickle.HIGHEST_PROTOCOL).dump(renderers)
    return out.getvalue(), new, pending


def _load_renderers(payload: bytes, tables: dict[int, Any]) -> Any:
    """The servo's end: renderers pickled by :func:`dump_renderers`, their tables taken
    from ``tables``."""
    return _RendererUnpickler(payload, tables).load()


def _shared_table_types() -> tuple:
    """Types pickled once per session and then referred to (material independent,
    large): the piezo drive table."""
    from ...calibration.piezo import PiezoTable
    return (PiezoTable,)
