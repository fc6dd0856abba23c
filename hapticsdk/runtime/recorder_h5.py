"""HDF5 live recordings (``Session(record="run.h5")``), through the optional h5py
(the ``h5`` extra).

The servo appends every chunk of ticks (:data:`~hapticsdk.runtime.recorder.CHUNK_ROWS`)
to chunked, resizable datasets of ``run.h5.part`` and flushes the file: memory stays one
chunk whatever the length of the run. The file holds the same arrays, under the same
names, as the ``.npz`` recording (``t``, ``state_t``, ``position_mm``, ``velocity_mm_s``,
``device_force_n``, ``buttons``, ``force_n``, ``penetration_mm``, ``object_id``,
``cmd/<role>/<field>`` and ``<role>.<field>``; ``state_t`` and ``<role>.<field>`` are
HDF5 hard links to ``t`` and ``cmd/<role>/<field>``, stored once) and the
``hapticsdk-run`` header as the root attribute ``header_json``. At the end the file is
completed and renamed over ``run.h5``: a reader sees the old file or the whole new one.

Written in HDF5's single-writer/multiple-reader mode (SWMR, ``libver="latest"``): the
library orders its writes so that the file on disk is a consistent HDF5 file at every
moment, and after each chunk the dataset ``rows`` (written last, then flushed) says how
many rows are complete. So a servo killed mid-run leaves ``run.h5.part`` holding every
chunk flushed before the kill; the last, partly filled chunk (at most ``CHUNK_ROWS``
ticks) is lost, as with ``.npz``. :func:`recover_h5` copies those rows into ``run.h5``.
What SWMR does not cover: a machine crash (power loss) can lose what the kernel had not
yet written to the disk, and a file truncated by other means can be unreadable; then
:func:`recover_h5` raises :class:`~hapticsdk.errors.RecordingError` naming the file.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..errors import RecordingError, ValidationError
from . import recording_layout as layout

#: the optional extra that installs h5py
EXTRA = "hapticsdk[h5]"
_SUFFIXES = (".h5", ".hdf5")


def is_h5(path: "str | Path") -> bool:
    """Whether ``path`` names an HDF5 recording (``.h5`` / ``.hdf5``, or their ``.part``)."""
    name = Path(path).name.lower()
    if name.endswith(".part"):
        name = name[: -len(".part")]
    return name.endswith(_SUFFIXES)


def h5py_module(field: str = "record") -> Any:
    """The h5py module, or a :class:`ValidationError` saying how to install it."""
    try:
        import h5py  # noqa: PLC0415 - optional
    except ImportError as exc:
        raise ValidationError(f"HDF5 recording needs the optional h5py package (the {EXTRA} extra): {exc}",
                              field=field) from None
    return h5py


def _link_aliases(f: Any, roles: Sequence[str]) -> None:
    """The npz's repeated names as hard links to the stored datasets (stored once)."""
    for name, target in layout.aliases(roles).items():
        f[name] = f[target]


class H5Appender:
    """Appends rows of a recording stream to chunked, resizable datasets (the servo side)."""

    def __init__(self, part: Path, header: Mapping[str, Any], chunk_rows: int) -> None:
        h5py = h5py_module()
        self.part = Path(part)
        self._layout = layout.stored(header["columns"], header["roles"])
        self.rows = 0
        f = self._f = h5py.File(self.part, "w", libver="latest")
        f.attrs["stream_header_json"] = json.dumps(dict(header))
        for name, idx in self._layout.items():
            shape = (0,) if len(idx) == 1 else (0, len(idx))
            f.create_dataset(name, shape=shape, maxshape=(None,) + shape[1:], dtype="<f8",
                             chunks=(chunk_rows,) + shape[1:])
        for name, (rest, dtype) in layout.ZEROS.items():
            f.create_dataset(name, shape=(0, *rest), maxshape=(None, *rest), dtype=dtype, chunks=(chunk_rows, *rest))
        _link_aliases(f, header["roles"])
        f.create_dataset("rows", data=np.zeros(1, dtype="<i8"))
        f.swmr_mode = True  # from here on the file on disk stays consistent
        f.flush()

    def append(self, a: np.ndarray) -> None:
        """Append the rows ``a`` (n x columns), then record how many rows are complete."""
        n = a.shape[0]
        if n == 0:
            return
        f, m = self._f, self.rows + n
        for name, idx in self._layout.items():
            ds = f[name]
            ds.resize(m, axis=0)
            ds[self.rows:m] = layout.take(a, idx)
        for name in layout.ZEROS:
            f[name].resize(m, axis=0)
            f[name][self.rows:m] = 0
        f.flush()  # the data first, then the count that vouches for it
        f["rows"][0] = m
        f.flush()
        self.rows = m

    def close(self) -> None:
        """Close the file (the servo's part of the work)."""
        if self._f is not None:
            self._f.close()
            self._f = None


def _open_part(h5py: Any, part: Path) -> Any:
    try:
        return h5py.File(part, "r")
    except (OSError, RuntimeError, ValueError):  # what h5py raises for a file HDF5 cannot open
        try:  # a writer killed in SWMR mode leaves the file marked as open for writing
            return h5py.File(part, "r", swmr=True)
        except (OSError, RuntimeError, ValueError) as exc:
            raise RecordingError(f"{part}: not a readable HDF5 recording ({exc})", field="record") from None


def finish_h5(part: Path, path: Path, run_header: Mapping[str, Any], *, rows: int | None = None) -> Path:
    """Write ``run_header`` and the complete rows of ``part`` into ``path``, atomically.

    When the writer closed ``part`` normally it is completed in place and renamed;
    otherwise (``rows`` given: a recovery) the complete rows are copied chunk by chunk
    into a fresh file next to ``path``, which is renamed over it."""
    from ..fileio import check_output_path
    h5py = h5py_module()
    path = Path(check_output_path(path, field="record"))
    text = json.dumps(dict(run_header), default=lambda o: o.item() if hasattr(o, "item") else str(o))
    if rows is None:
        with h5py.File(part, "r+") as f:
            f.attrs["header_json"] = text
            f.flush()
        with open(part, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(part, path)
        return path
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with _open_part(h5py, part) as src, h5py.File(tmp, "w") as dst:
            header = json.loads(src.attrs["stream_header_json"])
            step = 1 << 16
            for name in layout.stored(header["columns"], header["roles"]):
                ds = src[name]
                out = dst.create_dataset(name, shape=(rows,) + ds.shape[1:], dtype=ds.dtype,
                                         chunks=True if rows else None)
                for i in range(0, rows, step):
                    out[i:min(i + step, rows)] = ds[i:min(i + step, rows)]
            for name, (rest, dtype) in layout.ZEROS.items():
                dst.create_dataset(name, data=np.zeros((rows, *rest), dtype=dtype))
            _link_aliases(dst, header["roles"])
            dst.create_dataset("rows", data=np.array([rows], dtype="<i8"))
            dst.attrs["header_json"] = text
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    part.unlink()
    return path


def read_part_header(part: Path) -> tuple[dict[str, Any], int]:
    """The stream header and the count of complete rows of an HDF5 ``.part``."""
    h5py = h5py_module()
    with _open_part(h5py, part) as f:
        try:
            header = layout.check_header(layout.parse_header(f.attrs["stream_header_json"], part), part)
            rows = int(f["rows"][0])
            shortest = min(f[name].shape[0] for name in layout.stored(header["columns"], header["roles"]))
        except RecordingError:   # the header's own check names the field
            raise
        except (KeyError, ValueError) as exc:
            raise RecordingError(f"{part}: not a hapticsdk HDF5 recording ({exc})", field="record") from None
    return header, min(rows, shortest)


def read_arrays(path: Path, *, max_bytes: int) -> dict[str, np.ndarray]:
    """Every array of an HDF5 run file by its ``.npz`` name (``header_json`` included);
    a file whose datasets hold more than ``max_bytes`` is refused before reading."""
    h5py = h5py_module(field="runlog")
    try:
        with h5py.File(path, "r") as f:
            if "header_json" not in f.attrs:
                raise RecordingError(f"{path}: no header_json (not a completed hapticsdk run file)",
                                     field="runlog.header_json")
            sizes: list[int] = []
            f.visititems(lambda _n, o: sizes.append(o.size * o.dtype.itemsize)
                         if isinstance(o, h5py.Dataset) else None)
            if sum(sizes) > max_bytes:
                raise RecordingError(f"{path}: holds {sum(sizes)} bytes, more than the {max_bytes} accepted",
                                     field="runlog")
            n = int(f["rows"][0]) if "rows" in f else None
            data: dict[str, np.ndarray] = {}

            def take(name: str, ds: Any) -> None:
                if isinstance(ds, h5py.Dataset) and name != "rows":
                    data[name] = ds[:n] if n is not None and ds.ndim else ds[()]

            for name, obj in f.items():
                if isinstance(obj, h5py.Group):
                    for role, g in obj.items():
                        for fld, ds in g.items():
                            take(f"{name}/{role}/{fld}", ds)
                else:
                    take(name, obj)
            data["header_json"] = np.array(str(f.attrs["header_json"]))
    except RecordingError:
        raise
    except Exception as exc:  # noqa: BLE001 - h5py raises OSError, KeyError, ValueError...
        raise RecordingError(f"{path}: not a readable HDF5 run file ({type(exc).__name__}: {exc})",
                             field="runlog") from None
    return data
