"""The installed entry points of the SDK's plugin groups, remembered between processes.

Finding the plugins reads every installed distribution's ``entry_points.txt`` through
:mod:`importlib.metadata`, and naming a plugin's distribution parses its ``METADATA``.
Importing :mod:`importlib.metadata` alone (it imports :mod:`email`, :mod:`zipfile`,
:mod:`csv`) costs 12-15 ms, the scan 3 ms, the names 2 ms: a sixth of a ``hapticsdk
render S7`` that takes no other metadata (pluggy, from 1.4 on, imports it only to load entry
points, hence the core's floor ``pluggy>=1.4``). So the result of a scan is kept in
``<cache>/plugin-index/<sha256>.json`` (:func:`hapticsdk.fileio.cache_dir`), the hash
taken over everything the scan reads (:func:`fingerprint`):

* ``sys.path`` in order (the current folder for ``""``) and ``sys.implementation``;
* for each folder on it, its modification time (adding or removing a distribution adds or
  removes a ``*.dist-info`` / ``*.egg-info`` entry, which changes it -- the same signal
  :mod:`importlib.metadata` itself caches on), the names of the metadata folders in it,
  and for each the modification time and size of its ``entry_points.txt`` and of its
  ``METADATA`` (``PKG-INFO`` in an ``*.egg-info``) (a distribution rewritten in place);
* for a zip archive on ``sys.path``, its modification time and size.

Any difference gives another hash, so the next process scans with
:mod:`importlib.metadata` as before and stores the new result. A process whose
``sys.meta_path`` holds a distribution finder other than the standard path finder (the
scan would ask it too), or in which :mod:`importlib.metadata`'s ``entry_points`` or
``distributions`` was replaced (a test hiding a distribution), always scans and stores
nothing. Nothing in the index is
trusted beyond what a scan returned: names, values and versions are copied from
:mod:`importlib.metadata`'s own objects, and a stored entry point is loaded the way
:meth:`importlib.metadata.EntryPoint.load` loads one (import the module, then follow the
attribute path).
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
from dataclasses import dataclass
from importlib import import_module
from typing import Any, Callable, Iterable

#: bump when the stored layout changes (an old index is then ignored)
FORMAT = 1

#: distributions whose version every run reads (the validation markers of
#: :mod:`hapticsdk.schemas_io`); stored with each scan
VERSIONS = ("jsonschema", "hapticsdk")


@dataclass(frozen=True)
class IndexedEntryPoint:
    """An installed entry point as a scan found it: its group, name and value, the
    ``module`` and ``attr`` parts :mod:`importlib.metadata` read from the value, and the
    name and version of the distribution that declares it (``None`` when the entry point
    has no distribution)."""

    group: str
    name: str
    value: str
    module: str
    attr: str | None
    distribution: str | None
    version: str | None

    def load(self) -> Any:
        """Import the module and return the object the value names (as
        :meth:`importlib.metadata.EntryPoint.load`)."""
        obj = import_module(self.module)
        for part in filter(None, (self.attr or "").split(".")):
            obj = getattr(obj, part)
        return obj


def _stat(path: str) -> list[int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return [st.st_mtime_ns, st.st_size]


def _metadata_children(folder: str) -> list[str]:
    base_is_egg = os.path.basename(folder).lower().endswith(".egg")
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    return sorted(n for n in names if n.lower().endswith((".dist-info", ".egg-info"))
                  or (base_is_egg and n.lower() == "egg-info"))


def _metadata_replaced() -> bool:
    """Whether :mod:`importlib.metadata` is imported and its ``entry_points`` or
    ``distributions`` is no longer its own function (a wrapper installed by a test or an
    application, e.g. to hide a distribution): then what a scan returns is not a function
    of the files alone."""
    md = sys.modules.get("importlib.metadata")
    if md is None:
        return False
    own = getattr(md, "__file__", None)
    return any(getattr(getattr(getattr(md, name, None), "__code__", None), "co_filename", None) != own
               for name in ("entry_points", "distributions"))


def fingerprint() -> str | None:
    """sha256 over what a scan of the installed entry points reads (module docstring), or
    ``None`` when the scan is not a function of those files alone: a distribution finder
    other than the standard path finder is installed, or :mod:`importlib.metadata`'s
    functions were replaced (:func:`_metadata_replaced`)."""
    from importlib.machinery import PathFinder
    for finder in sys.meta_path:
        if finder is not PathFinder and getattr(finder, "find_distributions", None) is not None:
            return None
    if _metadata_replaced():
        return None
    parts: list[Any] = [FORMAT, sys.implementation.cache_tag, sys.version]
    for entry in sys.path:
        if not isinstance(entry, str):
            parts.append(repr(entry))
            continue
        folder = os.path.abspath(entry or os.curdir)
        parts.append([entry, folder, _stat(folder)])
        for child in _metadata_children(folder):
            where = os.path.join(folder, child)
            meta = "METADATA" if child.lower().endswith(".dist-info") else "PKG-INFO"
            # an old single-file *.egg-info is the metadata itself
            parts.append([child, _stat(os.path.join(where, "entry_points.txt")),
                          _stat(os.path.join(where, meta)) or _stat(where)])
    blob = json.dumps(parts, separators=(",", ":")).encode()
    return hashlib.sha256(blob).hexdigest()


def _index_path(key: str) -> Any:
    from .fileio import cache_dir
    return cache_dir() / "plugin-index" / f"{key}.json"


def _read(path: Any) -> dict[str, Any] | None:
    try:
        doc = json.loads(path.read_bytes())
        if doc.get("format") != FORMAT:
            return None
        rows = doc["entry_points"]
        versions = dict(doc["versions"])
        if not all(len(row) == 7 and all(v is None or isinstance(v, str) for v in row) and row[0]
                   and row[1] and row[3] for row in rows) or \
                not all(isinstance(v, (str, type(None))) for v in versions.values()):
            return None
        eps = [IndexedEntryPoint(*row) for row in rows]
    except Exception:   # absent, unreadable or of another layout: scan again
        return None
    return {"entry_points": eps, "versions": versions}


def _scan(scan: Callable[[], Iterable[Any]]) -> tuple[dict[str, Any], bool]:
    """Entry points of ``scan()`` (importlib.metadata objects) and the versions of
    :data:`VERSIONS`; the flag says whether the result may be stored."""
    from importlib import metadata

    storable = True
    named: dict[int, tuple[str, str]] = {}   # one METADATA parse per distribution
    eps = []
    for ep in scan():
        dist = getattr(ep, "dist", None)
        if dist is None:
            name = version = None
        else:
            got = named.get(id(dist))
            if got is None:
                got = named[id(dist)] = (dist.metadata["Name"], dist.version)
            name, version = got
        try:
            module, attr = ep.module, ep.attr
        except Exception:        # a value importlib.metadata cannot read: load() reports it
            module, attr, storable = ep.value, None, False
        eps.append(IndexedEntryPoint(ep.group, ep.name, ep.value, module, attr, name, version))
    versions: dict[str, str | None] = {}
    for dist_name in VERSIONS:
        try:
            versions[dist_name] = metadata.version(dist_name)
        except Exception:
            versions[dist_name] = None
    return {"entry_points": eps, "versions": versions}, storable


def _store(path: Any, index: dict[str, Any]) -> None:
    from dataclasses import astuple

    from .fileio import atomic_write_json
    doc = {"format": FORMAT, "entry_points": [list(astuple(ep)) for ep in index["entry_points"]],
           "versions": index["versions"]}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_json(path, doc, indent=None)
    except Exception:   # a read-only cache folder: the next process scans again
        pass


def load(scan: Callable[[], Iterable[Any]], *, use_stored: bool = True) -> dict[str, Any]:
    """``{"entry_points": [IndexedEntryPoint ...], "versions": {name: version}}``: the
    stored index of this environment when there is one (and ``use_stored``), else the
    result of ``scan()`` (an iterable of :class:`importlib.metadata.EntryPoint`), which
    is then stored."""
    key = fingerprint()
    try:
        path = _index_path(key) if key is not None else None
    except Exception:   # no cache folder can be named here: scan every time
        path = None
    if path is not None and use_stored:
        got = _read(path)
        if got is not None:
            return got
    index, storable = _scan(scan)
    if path is not None and storable:
        _store(path, index)
    return index


class _SdkGroup(str):
    """An entry-point ``group=`` selector equal to every group named ``hapticsdk.*``, so
    one ``metadata.entry_points(group=...)`` call (one scan of the installed distributions'
    metadata) returns the entry points of all the SDK's groups; works with the
    ``EntryPoint.matches`` of Python 3.9-3.13 and with wrappers of
    ``metadata.entry_points`` that pass ``**kw``."""

    def __eq__(self, other: object) -> bool:
        return isinstance(other, str) and other.startswith(GROUP_PREFIX)

    def __ne__(self, other: object) -> bool:
        return not self.__eq__(other)

    __hash__ = str.__hash__


#: the entry-point groups the index holds: every group whose name starts with this
GROUP_PREFIX = "hapticsdk."

#: this process's index (``None`` until first asked, reset by :func:`forget`)
_current: dict[str, Any] | None = None
_rescan = False


def _scan_sdk_groups() -> list[Any]:
    from importlib import metadata
    return list(metadata.entry_points(group=_SdkGroup(GROUP_PREFIX + "*")))


def current() -> dict[str, Any]:
    """This process's index of the ``hapticsdk.*`` entry-point groups (:func:`load`, once
    per process; after :func:`forget` the next call scans again)."""
    global _current, _rescan
    if _current is None:
        _current = load(_scan_sdk_groups, use_stored=not _rescan)
        _rescan = False
    return _current


def forget() -> None:
    """Drop this process's index; the next :func:`current` scans the installed
    distributions again (and stores the result), whatever is stored."""
    global _current, _rescan
    _current = None
    _rescan = True


def entry_points(group: str) -> list[IndexedEntryPoint]:
    """The installed entry points of one ``hapticsdk.*`` group, in scan order."""
    return [ep for ep in current()["entry_points"] if ep.group == group]


def version(name: str) -> str:
    """The installed version of distribution ``name``: from the index when it recorded
    ``name`` (see :data:`VERSIONS`), else :func:`importlib.metadata.version` (which raises
    :class:`importlib.metadata.PackageNotFoundError` when it is not installed)."""
    got = current()["versions"].get(name) if name in VERSIONS else None
    if got is not None:
        return got
    from importlib import metadata
    return metadata.version(name)
