"""Recording a live session tick by tick from the servo side, with bounded memory.

``Session(record="run.npz")`` makes the servo append every tick to ``run.npz.part``
(a small binary stream, layout below) in chunks of :data:`CHUNK_ROWS` ticks written
straight to the kernel (no user-space buffer), so memory stays one chunk whatever the
length of the run. When the session ends, the servo (after every actuator is stopped)
turns the stream into ``run.npz``, a ``hapticsdk-run`` v1 file
(:mod:`hapticsdk.runlog`: ``hapticsdk replay run.npz`` plays it back) that also holds
the servo log's own arrays (``force_n``, ``penetration_mm``, ``object_id``,
``<role>.frequency_hz`` / ``<role>.amplitude``, as ``Session(log_path=...)`` writes
them, so the plotting helpers read either). The ``.npz`` is written column by column
from a memory map of the stream (bounded memory again) to a temporary file that is
renamed over the target: a reader sees the old file or the whole new one.

A session cut short (the servo process killed) leaves ``run.npz.part``: every chunk the
servo had written is in it (the kernel keeps what was written when a process dies; a
machine crash can lose what was not yet on disk), and the last, partly filled chunk is
lost (at most :data:`CHUNK_ROWS` ticks). :func:`recover` (and :func:`load_recording`,
``hapticsdk replay``) turns the complete rows of a ``.part`` into the ``.npz``.

Stream layout (little-endian): 8 bytes ``HSDKREC1``; 8 bytes header length ``h``;
``h`` bytes of JSON (``columns``, ``roles``, ``period_s``, ``objects``), padded with
spaces to a multiple of 8; then rows of ``len(columns)`` float64.

``Session(record="run.h5")`` (or ``.hdf5``) writes the same arrays to an HDF5 file
instead, through the optional h5py (the ``h5`` extra): the chunks are
appended to resizable datasets of ``run.h5.part`` as they fill, and a servo killed
mid-run leaves every flushed chunk readable (:mod:`hapticsdk.runtime.recorder_h5`).
Without h5py, asking for ``.h5`` is a :class:`~hapticsdk.errors.ValidationError` that
names the extra.
"""

from __future__ import annotations

import json
import os
import struct
import zipfile
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..errors import RecordingError, ValidationError
from . import recording_layout as layout

MAGIC = b"HSDKREC1"
#: ticks per chunk written (1.0 s at 1 kHz: about 150 kB with three roles)
CHUNK_ROWS = 1024


def check_record_path(path: Any) -> Path:
    """The ``record=`` path of a session: ``.npz``, or ``.h5`` / ``.hdf5`` when h5py is
    installed (otherwise a :class:`ValidationError` naming the extra)."""
    from ..fileio import check_output_path
    from .recorder_h5 import h5py_module, is_h5
    p = Path(check_output_path(path, field="record"))
    if is_h5(p):
        h5py_module()
        return p
    if p.suffix.lower() != ".npz":
        raise ValidationError(f"record must name a .npz, .h5 or .hdf5 file, got {str(p)!r}", field="record")
    return p


def part_path(path: "str | Path") -> Path:
    """Where the stream of ``path`` is written while the session runs."""
    p = Path(path)
    return p.with_name(p.name + ".part")


class LiveRecorder:
    """The servo's recorder: :meth:`add` after every tick, :meth:`close` at the end."""

    def __init__(self, path: "str | Path", roles: Sequence[str], period_s: float,
                 objects: Mapping[int, str] | None = None, chunk_rows: int = CHUNK_ROWS) -> None:
        self.path = Path(path)
        self.roles = list(roles)
        self.columns = layout.columns(self.roles)
        self.width = len(self.columns)
        self.objects = dict(objects or {})
        self.period_s = float(period_s)
        self.chunk_rows = int(chunk_rows)
        self._chunk = bytearray(self.chunk_rows * self.width * 8)
        self._mv = memoryview(self._chunk).cast("d")
        self._n = 0  # rows in the chunk
        self.rows = 0  # rows written to the stream
        self.part = part_path(self.path)
        self.part.parent.mkdir(parents=True, exist_ok=True)
        header = {"columns": self.columns, "roles": self.roles, "period_s": self.period_s,
                  "objects": {str(k): v for k, v in self.objects.items()}}
        self._h5: Any = None
        self._fh: Any = None
        from .recorder_h5 import H5Appender, is_h5
        if is_h5(self.path):
            self._h5 = H5Appender(self.part, header, self.chunk_rows)
        else:
            self._fh = open(self.part, "wb", buffering=0)  # noqa: SIM115 - closed by close()
            head = json.dumps(header).encode()
            head += b" " * (-len(head) % 8)
            self._fh.write(MAGIC + struct.pack("<Q", len(head)) + head)

    def add(self, loop: Any, object_id: float) -> None:
        """Append the tick ``loop`` has just run (its last state, penetration, force and
        each role's command from its log)."""
        mv = self._mv
        j = self._n * self.width
        st = loop.last_state
        mv[j] = loop.last_t or 0.0
        if st is not None:
            # the loop keeps a SensedState: its floats (its array fields would be built)
            mv[j + 1] = st.px
            mv[j + 2] = st.py
            mv[j + 3] = st.pz
            mv[j + 4] = st.vx
            mv[j + 5] = st.vy
            mv[j + 6] = st.vz
        else:
            for k in range(1, 7):
                mv[j + k] = np.nan
        mv[j + 7] = loop.last_force_n
        mv[j + 8] = loop.last_penetration_mm
        mv[j + 9] = object_id
        i = (loop.ticks - 1) % loop._cap  # noqa: SLF001 - the loop's log ring
        k = j + 10
        for s in loop._slots:  # noqa: SLF001 - in the order of self.roles
            mv[k] = s.log_n[i]
            mv[k + 1] = s.log_f[i]
            mv[k + 2] = s.log_a[i]
            k += 3
        self._n += 1
        if self._n == self.chunk_rows:
            self._flush()

    def _flush(self) -> None:
        if self._n:
            if self._h5 is not None:
                self._h5.append(np.frombuffer(self._chunk, dtype="<f8", count=self._n * self.width)
                                .reshape(self._n, self.width))
            else:
                self._fh.write(memoryview(self._chunk)[: self._n * self.width * 8])
            self.rows += self._n
            self._n = 0

    def close(self, objects: Mapping[int, str] | None = None) -> Path:
        """Write the last rows and turn the stream into the run file (``.npz``: the stream
        is removed; ``.h5``: the file is completed and renamed)."""
        if objects:
            self.objects.update(objects)
        if self._h5 is not None:
            self._flush()
            self._h5.close()
            self._h5 = None
            from .recorder_h5 import finish_h5
            return finish_h5(self.part, self.path, _run_header(self.period_s, self.roles, self.rows,
                                                               self.objects, recovered=False))
        if self._fh is not None:
            self._flush()
            self._fh.close()
            self._fh = None
        out = recover(self.part, self.path, objects=self.objects)
        return out


def _run_header(period_s: float, roles: Sequence[str], n: int, names: Mapping[int, str], *,
                recovered: bool) -> dict[str, Any]:
    """The ``hapticsdk-run`` header of a live recording of ``n`` ticks."""
    from ..runlog import FORMAT, VERSION
    return {"format": FORMAT, "version": VERSION, "n_ticks": n, "period_s": period_s,
            "roles": sorted(roles), "device": None,
            "meta": {"source": "hapticsdk live session recording", "objects": {str(k): v for k, v in names.items()},
                     "recovered_from_part": recovered}}


def _read_part(part: Path) -> tuple[dict[str, Any], np.ndarray]:
    """Header and a read-only memory map of the complete rows of a stream."""
    try:
        with open(part, "rb") as fh:
            head = fh.read(16)
            if len(head) < 16 or head[:8] != MAGIC:
                raise RecordingError(f"{part}: not a hapticsdk recording stream", field="record")
            (h,) = struct.unpack("<Q", head[8:])
            if h > 1 << 20:
                raise RecordingError(f"{part}: header of {h} bytes", field="record")
            raw = fh.read(h)
    except OSError as exc:
        raise RecordingError(f"{part}: unreadable recording stream ({exc})", field="record") from None
    header = layout.check_header(layout.parse_header(raw, part), part)
    width = len(header["columns"])
    off = 16 + h
    n = max(os.path.getsize(part) - off, 0) // (8 * width)
    if n == 0:
        return header, np.zeros((0, width))
    return header, np.memmap(part, dtype="<f8", mode="r", offset=off, shape=(n, width))


def recover(part: "str | Path", path: "str | Path | None" = None, *,
            objects: Mapping[int, str] | None = None) -> Path:
    """Turn the complete rows of a recording stream ``part`` into a run file ``path``
    (default: ``part`` without ``.part``), written atomically; removes ``part``."""
    from ..fileio import atomic_writer
    from ..runlog import _json_default
    from .recorder_h5 import finish_h5, is_h5, read_part_header
    part = Path(part)
    path = Path(path) if path is not None else part.with_name(part.name[: -len(".part")])
    if is_h5(part):
        h5_header, rows = read_part_header(part)
        names = {**{int(k): v for k, v in h5_header.get("objects", {}).items()}, **dict(objects or {})}
        return finish_h5(part, path, _run_header(h5_header["period_s"], h5_header["roles"], rows, names,
                                                 recovered=True), rows=rows)
    header, a = _read_part(part)
    n = a.shape[0]
    names = {**{int(k): v for k, v in header.get("objects", {}).items()}, **dict(objects or {})}
    run_header = _run_header(header["period_s"], header["roles"], n, names, recovered=True)

    def put(zf: zipfile.ZipFile, name: str, arr: np.ndarray) -> None:
        with zf.open(name + ".npy", "w", force_zip64=True) as fh:
            np.lib.format.write_array(fh, np.asarray(arr), allow_pickle=False)

    with atomic_writer(path, "wb") as fh:
        with zipfile.ZipFile(fh, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
            arrays = {name: layout.take(a, idx) for name, idx in layout.stored(header["columns"], header["roles"]).items()}
            for name, arr in arrays.items():
                put(zf, name, arr)
            for name, target in layout.aliases(header["roles"]).items():
                put(zf, name, arrays[target])  # the servo log's names (plotting helpers)
            for name, (shape, dtype) in layout.ZEROS.items():
                put(zf, name, np.zeros((n, *shape), dtype=dtype))
            put(zf, "header_json", np.array(json.dumps(run_header, default=_json_default)))
    del a
    try:
        part.unlink()
    except OSError:
        pass
    return path


def load_recording(path: "str | Path") -> Any:
    """The :class:`~hapticsdk.runlog.RunLog` of a recording: ``path`` itself, or, when
    only its stream is left (a session cut short), the stream's complete rows (the
    ``.npz`` is written from them first)."""
    from ..argcheck import file_path
    from ..runlog import load_run
    try:
        p = file_path(path, "runlog")
    except ValidationError as exc:
        raise RecordingError(exc.reason, field="runlog") from None
    if p.name.endswith(".part"):
        p = recover(p)
    elif not p.exists() and part_path(p).exists():
        recover(part_path(p), p)
    return load_run(p)
