"""Data-set files, the train-and-export pipeline, the material library and data growth.

A *feature data set* directory (what ``hapticsdk/data/dataset/`` ships) holds::

    dataset.json            facts: generated?, source, fs_hz, df_hz, samples, features
    trial_features.csv      one row per trial: sample, trial, GS, W, Fpeak, AFpeak, P, df_hz
    sample_features.csv     per sample: mean and std of each feature, mean ratings (0..1)
    ratings.json            ratings (schemas/ratings.schema.json)
    truth.json              generating parameters (generated sets only)

Floats are written with ``repr`` so a table reads back bit-for-bit. Training accepts
either such a directory or a recording set (``recordings.json``), whose trials are
then extracted first.
"""

from __future__ import annotations

import csv
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..errors import RecordingError, ValidationError
from ..perception.features import Feature, FeatureSpace
from ..schemas_io import read_json
from .extraction import FEATURE_DESCRIPTIONS, FEATURE_NAMES, FEATURE_UNITS, FeatureTable, extract_set, extract_trials
from .recordings import (MANIFEST_NAME, Ratings, load_manifest, load_ratings, path_inside, validate_json,
                         write_ratings)

DATASET_NAME = "dataset.json"
TRIAL_FEATURES = "trial_features.csv"
SAMPLE_FEATURES = "sample_features.csv"
DIMENSIONS = ("hardness", "roughness")


def shipped_dataset_dir() -> Path:
    """``hapticsdk/data/dataset`` (the shipped generated feature data set)."""
    return Path(__file__).resolve().parent.parent / "data" / "dataset"


@dataclass
class TrainingTable:
    """Trial rows with targets: ``X (n, 5)`` features, ``Y (n, k)`` sample mean ratings (0..1)."""

    features: FeatureTable
    ratings: Ratings
    samples_info: list[dict]
    generated: bool
    source: str
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def X(self) -> np.ndarray:
        """Trial feature rows ``(n, 5)``, physical units."""
        return self.features.X

    @property
    def Y(self) -> np.ndarray:
        """Mean rating of each row's sample, normalised to 0..1, ``(n, k)``."""
        return self.ratings.mean_normalised(self.features.samples)

    @property
    def dimensions(self) -> tuple[str, ...]:
        """The rated dimensions, in column order of :attr:`Y`."""
        return self.ratings.dimensions

    @property
    def df_hz(self) -> float:
        """Frequency resolution of the data set's spectra (Hz)."""
        return self.features.dataset_df_hz

    def feature_space(self) -> FeatureSpace:
        """Features with bounds = range over all trial rows."""
        lo, hi = self.X.min(axis=0), self.X.max(axis=0)
        return FeatureSpace(tuple(Feature(n, FEATURE_UNITS[n], float(a), float(b), FEATURE_DESCRIPTIONS[n])
                                  for n, a, b in zip(FEATURE_NAMES, lo, hi)))

    def info(self, name: str) -> dict:
        """The sample description (name, label, substrate, texture) of sample ``name``."""
        for s in self.samples_info:
            if s["name"] == name:
                return s
        return {"name": name}


# --------------------------------------------------------------------------- files
def write_feature_dataset(out: Path | str, ft: FeatureTable, ratings: Ratings, *, samples_info: Sequence[dict],
                          generated: bool, source: str, fs_hz: float, settings: dict | None = None,
                          truth: dict | None = None) -> Path:
    """Write a feature data set directory (see module doc)."""
    from ..fileio import atomic_write_text, atomic_writer
    out = Path(out)
    _mkdir(out)
    with atomic_writer(out / TRIAL_FEATURES, "w", newline="") as fh:
        fh.write("sample,trial," + ",".join(FEATURE_NAMES) + ",df_hz\n")
        for s, t, x, d in zip(ft.samples, ft.trials, ft.X, ft.df_hz):
            fh.write(f"{s},{int(t)}," + ",".join(repr(float(v)) for v in x) + f",{float(d)!r}\n")
    names = ft.sample_names
    summ = ft.summary()
    means = ratings.mean_normalised(names, where=str(out))
    info = {s["name"]: s for s in samples_info}
    with atomic_writer(out / SAMPLE_FEATURES, "w", newline="") as fh:
        wr = csv.writer(fh, lineterminator="\n")
        wr.writerow(["sample", "label", "substrate", "texture"]
                    + [f"{f}_{m}" for f in FEATURE_NAMES for m in ("mean", "std")] + list(ratings.dimensions))
        for i, n in enumerate(names):
            row = [n, info.get(n, {}).get("label", ""), info.get(n, {}).get("substrate", ""),
                   info.get(n, {}).get("texture", "")]
            row += [repr(summ[n][f][j]) for f in FEATURE_NAMES for j in (0, 1)]
            row += [repr(float(v)) for v in means[i]]
            wr.writerow(row)
    write_ratings(out / "ratings.json", ratings)
    doc = {"schema_version": 1, "format": "hapticsdk-features", "generated": bool(generated),
           "source": source, "fs_hz": float(fs_hz), "df_hz": ft.dataset_df_hz,
           "features": [{"name": n, "unit": FEATURE_UNITS[n]} for n in FEATURE_NAMES],
           "dimensions": list(ratings.dimensions), "samples": list(samples_info),
           "files": {"trial_features": TRIAL_FEATURES, "sample_features": SAMPLE_FEATURES,
                     "ratings": "ratings.json"}}
    if settings is not None:
        doc["generator"] = settings
    if truth is not None:
        atomic_write_text(out / "truth.json", json.dumps(truth, indent=1) + "\n")
    # the index last: a data set interrupted before it has no dataset.json
    atomic_write_text(out / DATASET_NAME, json.dumps(doc, indent=1) + "\n", verify=_read_dataset_index)
    return out


def _read_dataset_index(path: Path) -> Any:
    """The data set index as :func:`load_table` reads it (bounded JSON), for the writer's read-back."""
    from ..schemas_io import read_json
    return read_json(path, field="dataset")


def _mkdir(d: Path) -> None:
    from ..errors import FileWriteError
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise FileWriteError(f"cannot create the directory: {exc.strerror or exc}", field=str(d)) from None


def _read_trial_features(path: Path) -> FeatureTable:
    from ..argcheck import file_path
    try:
        path = file_path(path, "file")
    except ValidationError as exc:
        raise RecordingError(exc.reason, field="file") from None
    if not path.is_file():
        raise RecordingError(f"{path}: trial feature table not found", field="file")
    from ..schemas_io import csv_header, read_csv_rows
    _, rows = read_csv_rows(path, field="file", error=RecordingError)  # UTF-8, bounded, well-formed
    if not rows:
        raise RecordingError(f"{path}: empty file", field="rows")
    head = csv_header(rows[0], path, field="file", error=RecordingError)
    need = ["sample", "trial", *FEATURE_NAMES, "df_hz"]
    missing = [c for c in need if c not in head]
    if missing:
        raise RecordingError(f"{path}: missing columns {missing}", field=missing[0])
    body = [r for r in rows[1:] if r]
    if not body:
        raise RecordingError(f"{path}: no rows", field="rows")
    ix = {c: head.index(c) for c in need}
    try:
        X = np.array([[float(r[ix[f]]) for f in FEATURE_NAMES] for r in body])
        df = np.array([float(r[ix["df_hz"]]) for r in body])
        trials = [int(r[ix["trial"]]) for r in body]
    except (ValueError, IndexError) as exc:
        raise RecordingError(f"{path}: bad value ({exc})", field="rows") from None
    bad = ~np.isfinite(X)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise RecordingError(f"{path}: NaN/Inf at row {r + 1}", field=FEATURE_NAMES[c])
    # the spectrum's resolution bounds the roughness constraint (P >= AFpeak^2 df) and goes
    # into the model file: a NaN made that bound NaN, read as met everywhere
    bad_df = ~(np.isfinite(df) & (df > 0))
    if bad_df.any():
        r = int(np.argmax(bad_df))
        raise RecordingError(f"{path}: df_hz must be a finite number of Hz > 0, got {df[r]!r} at row {r + 1}",
                             field="df_hz")
    return FeatureTable(samples=[r[ix["sample"]] for r in body], trials=trials, X=X, df_hz=df)


def load_table(path: Path | str) -> TrainingTable:
    """Load a training table from a feature data set or a recording set (directory or its JSON)."""
    from ..argcheck import file_path
    try:
        p = file_path(path, "dataset")
    except ValidationError as exc:
        raise RecordingError(exc.reason, field="dataset") from None
    if p.is_file():
        p = p.parent
    if (p / MANIFEST_NAME).is_file():
        rs = load_manifest(p)
        ft = extract_set(rs)
        ratings = load_ratings(path_inside(rs.root, rs.manifest.get("ratings", "ratings.json"), field="ratings",
                                           where=str(rs.root / MANIFEST_NAME)))
        return TrainingTable(ft, ratings, rs.samples or [{"name": n} for n in ft.sample_names],
                             bool(rs.manifest.get("generated", False)), str(rs.manifest.get("source", "")),
                             {"fs_hz": rs.fs_hz, "kind": "recordings", "settings": rs.manifest.get("generator")})
    if (p / DATASET_NAME).is_file():
        doc = read_json(p / DATASET_NAME, field="file", error=RecordingError)
        if not isinstance(doc, dict):
            raise RecordingError(f"{p / DATASET_NAME}: expected a JSON object", field="file")
        from ..schemas_io import non_finite_at
        bad = non_finite_at(doc)   # no schema checks this file: 1e400 (read as inf) is refused here
        if bad is not None:
            raise RecordingError(f"{p / DATASET_NAME}: {bad[1]} is not a finite number", field=bad[0].lstrip("."))
        files = doc.get("files") or {}
        if not isinstance(files, dict):
            raise RecordingError(f"{p / DATASET_NAME}: 'files' must be an object", field="files")
        where = str(p / DATASET_NAME)
        ft = _read_trial_features(path_inside(p, files.get("trial_features", TRIAL_FEATURES),
                                              field="files.trial_features", where=where))
        ratings = load_ratings(path_inside(p, files.get("ratings", "ratings.json"), field="files.ratings",
                                           where=where))
        return TrainingTable(ft, ratings, doc.get("samples", []), bool(doc.get("generated", False)),
                             str(doc.get("source", "")),
                             {"fs_hz": doc.get("fs_hz"), "kind": "features", "settings": doc.get("generator")})
    raise RecordingError(f"{p}: neither {MANIFEST_NAME} (recordings) nor {DATASET_NAME} (features) found",
                         field="file")


# --------------------------------------------------------------------------- generate
def generate_feature_dataset(out: Path | str, n_samples: int = 23, *, seed: int | None = None,
                             n_trials: int | None = None, n_raters: int | None = None,
                             raw_format: str | None = None, progress: Any = None) -> TrainingTable:
    """Generate a set, extract features and write the feature data set (and raw trials if
    ``raw_format``); ``progress(stage, done, total)`` follows each stage (:mod:`hapticsdk.progress`)."""
    from . import generator as gen

    gs = gen.generate(n_samples, seed=gen.DEFAULT_SEED if seed is None else seed,
                      n_trials=n_trials or gen.N_TRIALS, n_raters=n_raters or gen.N_RATERS,
                      progress=progress)
    out = Path(out)
    if raw_format:
        gen.write_recordings(gs, out, fmt=raw_format, progress=progress)
    ft = extract_trials(gs.trials, expected_fs_hz=gen.FS_HZ, progress=progress)
    info = [{"name": s.name, "label": s.label, "substrate": s.substrate, "texture": s.texture} for s in gs.specs]
    source = (f"GENERATED (simulated, not measured) by hapticsdk.training.generator v{gen.GENERATOR_VERSION}, "
              f"seed {gs.seed}")
    write_feature_dataset(out, ft, gs.ratings, samples_info=info, generated=True, source=source,
                          fs_hz=gen.FS_HZ, settings=gs.settings,
                          truth={"generated": True, "samples": [asdict(s) for s in gs.specs], "trials": gs.truth})
    return TrainingTable(ft, gs.ratings, info, True, source, {"truth": gs.truth, "specs": gs.specs})


# --------------------------------------------------------------------------- train
def constraint_context(X: np.ndarray) -> dict[str, float]:
    """Facts of the training rows that the dimensions' constraints use.

    ``press_force_min_n`` / ``press_force_max_n``: the range of the pressing force implied
    by each row's stiffness and work, ``sqrt(2 GS W)`` (N; exact for a linear spring). The
    hardness dimension keeps solutions inside the recorded maximum, where the model was
    trained, instead of letting GS and W drift to combinations no recording had.
    """
    gs = X[:, FEATURE_NAMES.index("GS")]
    w = X[:, FEATURE_NAMES.index("W")]
    f = np.sqrt(2.0 * np.clip(gs, 0.0, None) * np.clip(w, 0.0, None))
    return {"press_force_min_n": float(f.min()), "press_force_max_n": float(f.max())}


def train_dataset(path: Path | str, out: Path | str | None, cfg: Any = None, *,
                  progress: Any = None) -> tuple[dict, Any]:
    """Train on a data set, export ONNX to ``out`` and return (report, TrainResult).

    ``progress(stage, done, total)`` (:mod:`hapticsdk.progress`) follows the network fits.

    Report: ``metrics`` (split -> dimension -> {mse, r, n}), ``onnx_parity_max_abs``,
    ``time_s``, ``data_generated``, ``split``, ``df_hz``, ``training_data_sha256``.
    """
    from . import lm, onnx_export

    t0 = time.perf_counter()
    cfg = cfg or lm.TrainConfig()
    table = load_table(path)
    X, Y = table.X, table.Y
    res = lm.train(X, Y, table.features.samples, FEATURE_NAMES, table.dimensions, cfg, progress=progress)
    space = table.feature_space()
    sha = onnx_export.table_sha256(table.features.samples, table.features.trials, X, Y)
    defaults = dict(zip(FEATURE_NAMES, (float(v) for v in np.median(X, axis=0))))
    meta = onnx_export.build_metadata(space, table.dimensions, feature_defaults=defaults, df_hz=table.df_hz,
                                      metrics=res.metrics, training_data_sha256=sha,
                                      data_generated=table.generated,
                                      constraint_context=constraint_context(X))
    data = onnx_export.model_bytes(res.model, meta)
    rng = np.random.default_rng(0)
    probe = np.concatenate([X, space.random(256, rng)])
    parity = onnx_export.onnx_parity(data, res.model, probe)
    if out is not None:
        from ..fileio import atomic_write_bytes
        p = Path(out)
        _mkdir(p.parent)
        # temp file + fsync + read back by the model reader + rename: never a truncated model
        atomic_write_bytes(p, data, verify=onnx_export.read_back)
    report = {"metrics": res.metrics, "onnx_parity_max_abs": parity, "time_s": time.perf_counter() - t0,
              "data_generated": table.generated, "split": res.split, "df_hz": table.df_hz,
              "training_data_sha256": sha, "epochs": res.fit.epochs, "best_epoch": res.fit.best_epoch,
              "stop": res.fit.stop, "restart": res.restart, "n_samples": len(table.features.sample_names),
              "n_rows": int(len(X)), "config": cfg.to_dict(), "out": str(out) if out else None}
    return report, res


# --------------------------------------------------------------------------- materials
def build_materials(table: TrainingTable) -> dict:
    """Material library document (docs/architecture.md "Material library") from a data set."""
    names = table.features.sample_names
    summ = table.features.summary()
    means = table.ratings.mean_normalised(names)
    mats = []
    for i, n in enumerate(names):
        inf = table.info(n)
        mats.append({"name": n, "label": inf.get("label", n), "substrate": inf.get("substrate", ""),
                     "texture": inf.get("texture", ""),
                     "intensities": {d: float(np.clip(means[i, j], 0.0, 1.0)) for j, d in enumerate(table.dimensions)},
                     "features": {f: summ[n][f][0] for f in FEATURE_NAMES}, "generated": table.generated})
    doc = {"schema_version": 1, "generated": table.generated,
           "source": table.source + "; intensities = mean rating / 100, features = mean over trials",
           "materials": mats}
    validate_json(doc, "materials.schema.json", source="materials.json")
    return doc


def write_materials(table: TrainingTable, path: Path | str) -> Path:
    """Write the material library built from ``table`` (:func:`build_materials`) to
    ``path``, atomically; returns the path.
    """
    from ..fileio import atomic_write_text
    p = Path(path)
    _mkdir(p.parent)
    from ..perception.materials import load_library
    # read back by the library reader (its size, depth and schema checks) before the rename
    return atomic_write_text(p, json.dumps(build_materials(table), indent=1) + "\n", verify=load_library)


# --------------------------------------------------------------------------- growth
def data_growth(sizes: Sequence[int] = (23, 46, 92), *, seed: int | None = None, cfg: Any = None) -> list[dict]:
    """Train on generated sets of ``sizes`` samples; test and CV metrics per size."""
    from . import generator as gen, lm

    cfg = cfg or lm.TrainConfig()
    rows = []
    for n in sizes:
        if n < 3:
            raise ValidationError("each size must be >= 3 samples", field="sizes")
        t0 = time.perf_counter()
        gs = gen.generate(int(n), seed=gen.DEFAULT_SEED if seed is None else seed)
        ft = extract_trials(gs.trials, expected_fs_hz=gen.FS_HZ)
        res = lm.train(ft.X, gs.ratings.mean_normalised(ft.samples), ft.samples, FEATURE_NAMES,
                       gs.ratings.dimensions, cfg)
        rows.append({"n_samples": int(n), "metrics": res.metrics, "time_s": time.perf_counter() - t0})
    return rows
