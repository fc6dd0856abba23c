"""Recording format for exploration trials, and the ratings file.

A *recording set* is a directory::

    recordings.json          manifest (schema ``schemas/recording.schema.json``)
    ratings.json             ratings (schema ``schemas/ratings.schema.json``)
    trials/S1_t01.npz ...    one file per trial, ``.npz`` or ``.csv``

Each trial file holds the columns of :data:`COLUMNS` (CSV: a header row with these
names; ``.npz``: one array per name, ``phase`` as a unicode string array):

========================  ======  =====================================================
column                    unit    meaning
========================  ======  =====================================================
``time_s``                s       sample time, uniform steps of ``1/fs_hz``
``force_n``               N       normal force on the fingertip
``displacement_mm``       mm      indentation along the normal (0 at first contact)
``acc_x``/``acc_y``/``acc_z``     acceleration in the manifest's ``accel_unit``
                                  (``"m/s^2"`` or ``"g"``); ``lateral_axis`` names the
                                  sliding direction
``velocity_mm_s``         mm/s    lateral sliding velocity
``phase``                 --      ``press`` or ``slide``
========================  ======  =====================================================

The sample id and trial number of a file are given by its manifest entry. All checks
raise :class:`hapticsdk.errors.RecordingError` whose message names the file, sample
and trial and whose ``field`` names the offending column or manifest key.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from ..errors import RecordingError, ValidationError
from ..schemas_io import load_schema, non_finite_at, read_json

#: Columns of one trial file, in file order.
COLUMNS: tuple[str, ...] = ("time_s", "force_n", "displacement_mm", "acc_x", "acc_y",
                            "acc_z", "velocity_mm_s", "phase")
NUMERIC_COLUMNS: tuple[str, ...] = COLUMNS[:-1]
PHASES: tuple[str, ...] = ("press", "slide")
#: Standard gravity (m/s^2) for ``accel_unit == "g"``.
G0 = 9.80665
MANIFEST_NAME = "recordings.json"
RATINGS_NAME = "ratings.json"
#: Largest unpacked size of one trial file (bytes); a 4 s trial at 500 Hz is about 130 kB.
MAX_TRIAL_BYTES = 64 * 1024 * 1024
#: Minimum press and slide durations (s) a trial must have.
MIN_PRESS_S = 0.3
MIN_SLIDE_S = 2.2


def validate_json(doc: Any, schema_name: str, *, source: str) -> None:
    """Validate ``doc`` against ``schemas/<schema_name>``; raise RecordingError naming the path."""
    import jsonschema

    bad = non_finite_at(doc)   # NaN passes "minimum"/"maximum", inf passes "number"
    if bad is not None:
        raise RecordingError(f"{source}: {bad[1]} is not a finite number",
                             field=".".join(re.findall(r"[^.\[\]]+", bad[0])) or "(root)")
    schema = load_schema(schema_name.removesuffix(".schema.json"))
    validator = jsonschema.Draft202012Validator(schema)
    errors = sorted(validator.iter_errors(doc), key=lambda e: list(e.absolute_path))
    if errors:
        err = errors[0]
        path = ".".join(str(p) for p in err.absolute_path) or "(root)"
        raise RecordingError(f"{source}: {err.message}", field=path)


@dataclass
class Trial:
    """One exploration trial (press then slide), all arrays of length ``n``.

    ``acc`` is ``(n, 3)`` in m/s^2 (converted from the file's unit); ``lateral`` is the
    column index of the sliding direction.
    """

    sample: str
    trial: int
    fs_hz: float
    time_s: np.ndarray
    force_n: np.ndarray
    displacement_mm: np.ndarray
    acc: np.ndarray
    velocity_mm_s: np.ndarray
    phase: np.ndarray
    lateral: int = 0
    source: str = "<memory>"
    full_scale: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def where(self) -> str:
        """``file (sample S1, trial 3)`` for error messages."""
        return f"{self.source} (sample {self.sample}, trial {self.trial})"

    def columns(self, accel_unit: str = "m/s^2") -> dict[str, np.ndarray]:
        """The file columns; accelerations in ``accel_unit``."""
        scale = 1.0 / G0 if accel_unit == "g" else 1.0
        return {"time_s": self.time_s, "force_n": self.force_n,
                "displacement_mm": self.displacement_mm, "acc_x": self.acc[:, 0] * scale,
                "acc_y": self.acc[:, 1] * scale, "acc_z": self.acc[:, 2] * scale,
                "velocity_mm_s": self.velocity_mm_s, "phase": self.phase}


# --------------------------------------------------------------------------- files
def write_trial_file(path: Path, cols: Mapping[str, np.ndarray]) -> None:
    """Write one trial's columns to ``.npz`` or ``.csv`` (chosen by suffix), exactly round-trippable."""
    from ..fileio import atomic_savez, atomic_writer
    path = Path(path)
    _mkdir(path.parent)
    def check(tmp: Path) -> None:  # read back by the reader, as a file of this suffix
        read_trial_file(tmp, suffix=path.suffix)

    if path.suffix == ".npz":
        arrays: dict[str, Any] = {c: np.asarray(cols[c]) for c in COLUMNS}
        atomic_savez(path, verify=check, **arrays)
    elif path.suffix == ".csv":
        n = len(cols["time_s"])
        num = np.column_stack([np.asarray(cols[c], float) for c in NUMERIC_COLUMNS])
        with atomic_writer(path, "w", newline="", verify=check) as fh:
            fh.write(",".join(COLUMNS) + "\n")
            for i in range(n):
                fh.write(",".join(repr(float(v)) for v in num[i]) + "," + str(cols["phase"][i]) + "\n")
    else:
        raise RecordingError(f"{path}: unsupported trial file type (use .npz or .csv)", field="file")


def read_trial_file(path: Path, *, suffix: str | None = None) -> dict[str, np.ndarray]:
    """Read the columns of one trial file; missing file/columns or bad values raise RecordingError.
    ``suffix`` (``".npz"`` / ``".csv"``) overrides the path's own (a writer reading back
    its temporary file)."""
    from ..argcheck import file_path
    try:
        path = file_path(path, "file")
    except ValidationError as exc:
        raise RecordingError(exc.reason, field="file") from None
    kind = path.suffix if suffix is None else suffix
    if not path.is_file():
        raise RecordingError(f"{path}: trial file not found", field="file")
    if kind == ".npz":
        import zipfile
        import zlib
        try:
            with np.load(path, allow_pickle=False) as z:
                unpacked = sum(i.file_size for i in z.zip.infolist()) if hasattr(z, "zip") else 0
                if unpacked > MAX_TRIAL_BYTES:  # a zip bomb is refused before it is decompressed
                    raise RecordingError(f"{path}: unpacks to {unpacked} bytes, more than the "
                                         f"{MAX_TRIAL_BYTES} accepted for one trial", field="file")
                cols = {k: z[k] for k in z.files}
        except RecordingError:
            raise
        except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as exc:
            # truncated or corrupted archive, a pickled member, not a zip at all
            why = ("pickled data or not an .npz archive; pickles are never loaded" if "pickle" in str(exc)
                   else f"{type(exc).__name__}: {exc}")
            raise RecordingError(f"{path}: unreadable npz ({why})", field="file") from None
    elif kind == ".csv":
        from ..schemas_io import csv_header, read_csv_rows
        _, rows = read_csv_rows(path, field="file", error=RecordingError)  # UTF-8, bounded, well-formed
        if not rows:
            raise RecordingError(f"{path}: empty file (no header)", field="rows")
        header = csv_header(rows[0], path, field="file", error=RecordingError)
        body = [r for r in rows[1:] if r]
        cols = {}
        for j, name in enumerate(header):
            vals = [r[j].strip() if j < len(r) else "" for r in body]
            if name == "phase":
                cols[name] = np.array(vals, dtype=str)
            else:
                try:
                    cols[name] = np.array([float(v) if v != "" else np.nan for v in vals], float)
                except ValueError as exc:
                    raise RecordingError(f"{path}: non-numeric value ({exc})", field=name) from None
    else:
        raise RecordingError(f"{path}: unsupported trial file type (use .npz or .csv)", field="file")
    missing = [c for c in COLUMNS if c not in cols]
    if missing:
        raise RecordingError(f"{path}: missing columns {missing}; required {list(COLUMNS)}",
                             field=missing[0])
    return cols


def trial_from_columns(cols: Mapping[str, np.ndarray], *, sample: str, trial: int, fs_hz: float,
                       accel_unit: str = "m/s^2", lateral_axis: str = "x", source: str = "<memory>",
                       full_scale: Mapping[str, Sequence[float]] | None = None) -> Trial:
    """Build a :class:`Trial` from file columns (accelerations converted to m/s^2)."""
    where = f"{source} (sample {sample}, trial {trial})"
    if accel_unit not in ("m/s^2", "g"):
        raise RecordingError(f"{where}: accel_unit must be 'm/s^2' or 'g', got {accel_unit!r}",
                             field="accel_unit")
    if lateral_axis not in ("x", "y", "z"):
        raise RecordingError(f"{where}: lateral_axis must be x, y or z", field="lateral_axis")
    n = len(cols["time_s"])
    for c in COLUMNS:
        if np.ndim(cols[c]) != 1 or len(cols[c]) != n:
            raise RecordingError(f"{where}: column {c} has shape {np.shape(cols[c])}, expected ({n},)",
                                 field=c)
    num = {}
    for c in NUMERIC_COLUMNS:
        try:
            num[c] = np.asarray(cols[c], dtype=float)
        except (TypeError, ValueError):
            raise RecordingError(f"{where}: column {c} is not numeric", field=c) from None
    scale = G0 if accel_unit == "g" else 1.0
    acc = np.column_stack([num["acc_x"], num["acc_y"], num["acc_z"]]) * scale
    fsc = {k: (float(v[0]), float(v[1])) for k, v in (full_scale or {}).items()}
    if "acc" in fsc:
        fsc["acc"] = (fsc["acc"][0] * scale, fsc["acc"][1] * scale)
    return Trial(sample=str(sample), trial=int(trial), fs_hz=float(fs_hz), time_s=num["time_s"],
                 force_n=num["force_n"], displacement_mm=num["displacement_mm"], acc=acc,
                 velocity_mm_s=num["velocity_mm_s"], phase=np.asarray(cols["phase"]).astype(str),
                 lateral="xyz".index(lateral_axis), source=source, full_scale=fsc)


# --------------------------------------------------------------------------- checks
def validate_trial(tr: Trial, *, expected_fs_hz: float | None = 500.0,
                   min_press_s: float = MIN_PRESS_S, min_slide_s: float = MIN_SLIDE_S) -> None:
    """Raise RecordingError if the trial is empty, short, NaN, clipped, constant or at a wrong rate.

    Checks, in order: rows present; no NaN/Inf in any numeric column; declared rate
    equals ``expected_fs_hz`` (if given) and the time column steps by ``1/fs_hz``
    (1 % tolerance); phase values are press/slide with at least ``min_press_s`` of
    press and ``min_slide_s`` of slide; force, displacement and lateral acceleration
    are not constant; no sample sits at a declared sensor full-scale limit (clipping).
    """
    w = tr.where
    n = len(tr.time_s)
    if n == 0:
        raise RecordingError(f"{w}: empty recording (0 rows)", field="rows")
    arrays = {"time_s": tr.time_s, "force_n": tr.force_n, "displacement_mm": tr.displacement_mm,
              "acc_x": tr.acc[:, 0], "acc_y": tr.acc[:, 1], "acc_z": tr.acc[:, 2],
              "velocity_mm_s": tr.velocity_mm_s}
    for name, a in arrays.items():
        bad = ~np.isfinite(a)
        if bad.any():
            raise RecordingError(f"{w}: {int(bad.sum())} NaN/Inf values in {name} (first at row "
                                 f"{int(np.argmax(bad))})", field=name)
    if not (np.isfinite(tr.fs_hz) and tr.fs_hz > 0):
        raise RecordingError(f"{w}: sampling rate must be positive, got {tr.fs_hz}", field="fs_hz")
    if expected_fs_hz is not None and abs(tr.fs_hz - expected_fs_hz) > 1e-6 * expected_fs_hz:
        raise RecordingError(f"{w}: sampling rate {tr.fs_hz:g} Hz, expected {expected_fs_hz:g} Hz",
                             field="fs_hz")
    if n >= 2:
        dt = np.diff(tr.time_s)
        step = 1.0 / tr.fs_hz
        off = np.abs(dt - step) > 0.01 * step
        if off.any():
            i = int(np.argmax(off))
            raise RecordingError(
                f"{w}: time step {dt[i]:.6g} s at row {i + 1} does not match the declared rate "
                f"{tr.fs_hz:g} Hz (step {step:.6g} s); median step implies "
                f"{1.0 / float(np.median(dt)) if np.median(dt) > 0 else float('nan'):.6g} Hz",
                field="time_s")
    bad_phase = ~np.isin(tr.phase, PHASES)
    if bad_phase.any():
        raise RecordingError(f"{w}: phase value {tr.phase[np.argmax(bad_phase)]!r} at row "
                             f"{int(np.argmax(bad_phase))}; valid {list(PHASES)}", field="phase")
    for ph, need in (("press", min_press_s), ("slide", min_slide_s)):
        have = int(np.count_nonzero(tr.phase == ph)) / tr.fs_hz
        if have < need:
            raise RecordingError(f"{w}: recording too short: {have:.3g} s of {ph} phase, "
                                 f"need >= {need:g} s", field="phase")
    for name in ("force_n", "displacement_mm", "acc_" + "xyz"[tr.lateral]):
        a = arrays[name]
        if np.ptp(a) == 0.0:
            raise RecordingError(f"{w}: {name} is constant ({a[0]:g}); sensor disconnected?",
                                 field=name)
    fs = tr.full_scale
    if "force_n" in fs:
        hit = tr.force_n >= fs["force_n"][1]
        if hit.any():
            raise RecordingError(f"{w}: force clipped at full scale {fs['force_n'][1]:g} N in "
                                 f"{int(hit.sum())} samples", field="force_n")
    if "acc" in fs:
        lo, hi = fs["acc"]
        for j, name in enumerate(("acc_x", "acc_y", "acc_z")):
            hit = (tr.acc[:, j] <= lo) | (tr.acc[:, j] >= hi)
            if hit.any():
                raise RecordingError(f"{w}: acceleration clipped at full scale in "
                                     f"{int(hit.sum())} samples", field=name)


# --------------------------------------------------------------------------- sets
@dataclass
class RecordingSet:
    """A loaded recording set: manifest facts and the trial entries (files loaded lazily)."""

    root: Path
    manifest: dict

    @property
    def fs_hz(self) -> float:
        """Sampling rate of the recordings (Hz)."""
        return float(self.manifest["fs_hz"])

    @property
    def samples(self) -> list[dict]:
        """The manifest's sample descriptions."""
        return list(self.manifest.get("samples", []))

    @property
    def entries(self) -> list[dict]:
        """The manifest's trial entries (sample, trial, file)."""
        return list(self.manifest["trials"])

    def load_trial(self, entry: Mapping[str, Any]) -> Trial:
        """Load (not yet validate) the trial of one manifest entry."""
        m = self.manifest
        path = path_inside(self.root, entry["file"], field="file", where=str(self.root / MANIFEST_NAME))
        cols = read_trial_file(path)
        return trial_from_columns(cols, sample=entry["sample"], trial=entry["trial"],
                                  fs_hz=entry.get("fs_hz", m["fs_hz"]),
                                  accel_unit=m.get("accel_unit", "m/s^2"),
                                  lateral_axis=m.get("lateral_axis", "x"),
                                  source=str(path), full_scale=m.get("full_scale"))

    def iter_trials(self):
        """Load and yield every trial of the manifest, in order (each validated as it is
        read).
        """
        for e in self.entries:
            yield self.load_trial(e)


def path_inside(root: Path | str, name: Any, *, field: str, where: str = "") -> Path:
    """``root / name`` for a file named by a manifest, refused with RecordingError when
    ``name`` is absolute, empty or climbs out of ``root`` with ``..`` (a manifest is data:
    it may only name files inside its own folder)."""
    import posixpath

    text = str(name)
    w = f"{where}: " if where else ""
    if not text or "\x00" in text:
        raise RecordingError(f"{w}empty or invalid file name {text!r}", field=field)
    norm = posixpath.normpath(text.replace("\\", "/"))
    if (text.startswith(("/", "\\")) or Path(text).is_absolute() or (len(text) > 1 and text[1] == ":")
            or norm == ".." or norm.startswith("../")):
        raise RecordingError(f"{w}file {text!r} is outside the recording folder (absolute or '..'); "
                             "name files relative to the manifest's folder", field=field)
    return Path(root) / norm


def _read_checked(path: Path | str, default_name: str, schema: str) -> tuple[Path, Any]:
    """Read a JSON file (or ``default_name`` inside a directory) and validate it."""
    from ..argcheck import file_path
    try:
        p = file_path(path, "file")
    except ValidationError as exc:
        raise RecordingError(exc.reason, field="file") from None
    if p.is_dir():
        p = p / default_name
    doc = read_json(p, field="file", error=RecordingError)
    validate_json(doc, schema, source=str(p))
    return p, doc


def load_manifest(path: Path | str) -> RecordingSet:
    """Load and schema-validate ``recordings.json`` (``path`` is the file or its directory)."""
    p, doc = _read_checked(path, MANIFEST_NAME, "recording.schema.json")
    seen = set()
    for i, e in enumerate(doc["trials"]):
        key = (e["sample"], e["trial"])
        if key in seen:
            raise RecordingError(f"{p}: duplicate trial {key}", field=f"trials.{i}")
        seen.add(key)
        path_inside(p.parent, e["file"], field=f"trials.{i}.file", where=str(p))
    if "ratings" in doc:
        path_inside(p.parent, doc["ratings"], field="ratings", where=str(p))
    return RecordingSet(root=p.parent, manifest=doc)


def write_manifest(root: Path, manifest: Mapping[str, Any]) -> Path:
    """Schema-validate and write ``recordings.json`` into ``root``."""
    from ..fileio import atomic_write_text
    root = Path(root)
    _mkdir(root)
    validate_json(dict(manifest), "recording.schema.json", source=str(root / MANIFEST_NAME))
    return atomic_write_text(root / MANIFEST_NAME, json.dumps(manifest, indent=1) + "\n", verify=load_manifest)


def _mkdir(d: Path) -> None:
    from ..errors import FileWriteError
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise FileWriteError(f"cannot create the directory: {exc.strerror or exc}", field=str(d)) from None


# --------------------------------------------------------------------------- ratings
@dataclass
class Ratings:
    """Ratings 0..100 per sample, dimension and rater (``values[sample][dim]`` has one entry per rater)."""

    dimensions: tuple[str, ...]
    raters: tuple[str, ...]
    values: dict[str, dict[str, list[float]]]
    scale_max: float = 100.0
    generated: bool = False
    source: str = ""

    def mean_normalised(self, samples: Sequence[str], *, where: str = "ratings") -> np.ndarray:
        """``(len(samples), k)`` mean rating over raters divided by the scale maximum (0..1)."""
        out = np.empty((len(samples), len(self.dimensions)))
        for i, s in enumerate(samples):
            if s not in self.values:
                raise RecordingError(f"{where}: no ratings for sample {s}", field=f"ratings.{s}")
            for j, d in enumerate(self.dimensions):
                out[i, j] = float(np.mean(self.values[s][d])) / self.scale_max
        return out

    def to_json(self) -> dict:
        """The ratings as ``schemas/ratings.schema.json`` JSON."""
        return {"schema_version": 1, "generated": self.generated, "source": self.source,
                "scale": {"min": 0, "max": self.scale_max}, "dimensions": list(self.dimensions),
                "raters": list(self.raters), "ratings": self.values}


def load_ratings(path: Path | str) -> Ratings:
    """Load and validate a ratings file (``path`` is the file or its directory)."""
    p, doc = _read_checked(path, RATINGS_NAME, "ratings.schema.json")
    dims = tuple(doc["dimensions"])
    raters = tuple(doc["raters"])
    for s, per in doc["ratings"].items():
        for d in dims:
            if d not in per:
                raise RecordingError(f"{p}: sample {s} lacks dimension {d}", field=f"ratings.{s}.{d}")
            if len(per[d]) != len(raters):
                raise RecordingError(f"{p}: sample {s} has {len(per[d])} {d} ratings for "
                                     f"{len(raters)} raters", field=f"ratings.{s}.{d}")
    return Ratings(dimensions=dims, raters=raters,
                   values={s: {d: [float(v) for v in per[d]] for d in dims}
                           for s, per in doc["ratings"].items()},
                   scale_max=float(doc["scale"]["max"]), generated=bool(doc.get("generated", False)),
                   source=str(doc.get("source", "")))


def write_ratings(path: Path, ratings: Ratings) -> Path:
    """Schema-validate and write a ratings file."""
    doc = ratings.to_json()
    validate_json(doc, "ratings.schema.json", source=str(path))
    from ..fileio import atomic_write_text
    return atomic_write_text(path, json.dumps(doc, indent=1) + "\n", verify=load_ratings)


if not TYPE_CHECKING:  # moved names, deprecated since 0.2 (a type checker sees only the new places)
    from .._deprecation import moved_names
    __getattr__ = moved_names(__name__, {"schema_dir": "hapticsdk.schemas_io"})
