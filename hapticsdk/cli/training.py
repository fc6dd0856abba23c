"""CLI commands ``features``, ``train`` and ``dataset`` (``generate``, ``growth``).

Registered by ``hapticsdk.cli`` through :func:`register`; every handler returns an
exit code (0 ok, 2 for a data/validation error, printed to stderr).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import HapticSDKError
from . import emit
from .argtypes import bounded_int, int_list, nonneg_int

#: largest generated set the command makes (samples, trials per sample, raters)
MAX_SAMPLES, MAX_TRIALS, MAX_RATERS = 10_000, 1_000, 1_000


def _fail(exc: Exception, args: argparse.Namespace | None = None) -> int:
    from . import report_error
    return report_error(exc, args)


def _check_out(path: Path | None, field: str, **kw: bool) -> None:
    """An output path is checked before the work starts (missing directory, a directory)."""
    if path is not None:
        from ..fileio import check_output_path
        check_output_path(path, field=field, **kw)


def cmd_features(args: argparse.Namespace) -> int:
    """Extract features of a recording set; print per-sample mean +- std (or JSON)."""
    from ..training.extraction import FEATURE_NAMES, FEATURE_UNITS, extract_set
    from ..training.recordings import load_manifest

    try:
        rs = load_manifest(args.recordings)
        ft = extract_set(rs)
    except HapticSDKError as exc:
        return _fail(exc, args)
    summ = ft.summary()
    if args.json:
        emit({"df_hz": ft.dataset_df_hz, "generated": bool(rs.manifest.get("generated", False)),
              "units": FEATURE_UNITS,
              "samples": {s: {f: {"mean": m, "std": d} for f, (m, d) in v.items()}
                          for s, v in summ.items()}}, True)
        return 0
    if rs.manifest.get("generated"):
        print("# GENERATED data (simulated, not measured)")
    print(f"# df = {ft.dataset_df_hz:g} Hz; mean +- std over trials")
    print("sample  " + "  ".join(f"{f + ' [' + FEATURE_UNITS[f] + ']':>24}" for f in FEATURE_NAMES))
    for s, v in summ.items():
        print(f"{s:<7} " + "  ".join(f"{v[f][0]:>13.4g} +- {v[f][1]:<7.3g}" for f in FEATURE_NAMES))
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    """Train the perception model on DATASET and export it to ONNX."""
    from ..training import lm
    from ..training.pipeline import train_dataset

    cfg = lm.with_overrides(lm.TrainConfig(), seed=args.seed, folds=args.folds, restarts=args.restarts,
                          target_scale=args.target_scale)
    from ..progress import Progress

    try:
        _check_out(args.out, "--out")
        with Progress("train", quiet=args.json) as progress:
            report, _ = train_dataset(args.dataset, args.out, cfg, progress=progress)
    except HapticSDKError as exc:
        return _fail(exc, args)
    if args.json:
        emit(report, True)
        return 0
    if report["data_generated"]:
        print("# trained on GENERATED data (simulated, not measured)")
    print(f"samples {report['n_samples']}, rows {report['n_rows']}, split {report['split']}")
    print(f"{'split':<11}{'dimension':<11}{'MSE':>10}{'R':>9}")
    for split, per in report["metrics"].items():
        for dim, m in per.items():
            print(f"{split:<11}{dim:<11}{m['mse']:>10.4f}{m['r']:>9.4f}")
    print("paper Table 2: MSE 0.0042 (hardness) 0.0073 (roughness); R 0.9715, 0.9343")
    print(f"ONNX parity max abs {report['onnx_parity_max_abs']:.2e}; time {report['time_s']:.2f} s; "
          f"wrote {report['out']}")
    return 0


def cmd_generate(args: argparse.Namespace) -> int:
    """Generate a data set (raw recordings unless --summary-only, plus feature tables)."""
    from ..training.pipeline import generate_feature_dataset, write_materials

    try:
        _check_generate_out(args.out)
        _check_out(args.materials, "--materials")
        from ..progress import Progress
        with Progress("dataset generate") as progress:
            table = generate_feature_dataset(args.out, args.samples, seed=args.seed, n_trials=args.trials,
                                             n_raters=args.raters,
                                             raw_format=None if args.summary_only else args.format,
                                             progress=progress)
        if args.materials:
            write_materials(table, args.materials)
    except HapticSDKError as exc:
        return _fail(exc, args)
    print(f"wrote GENERATED data set ({len(table.features.sample_names)} samples, "
          f"{len(table.X)} trials) to {args.out}" + (f"; materials to {args.materials}" if args.materials else ""))
    return 0


def _check_generate_out(out: Path) -> None:
    """The output of ``dataset generate`` is a directory: refuse an existing file (it
    would be replaced by a directory's worth of files) and a missing parent directory."""
    from ..errors import FileWriteError, ValidationError
    from ..fileio import check_output_path

    from ..argcheck import file_path
    try:
        file_path(out, "out")
    except ValidationError as exc:
        raise FileWriteError(exc.reason, field="out") from None
    if out.exists() and not out.is_dir():
        raise FileWriteError(f"{str(out)!r} exists and is not a directory (refusing to overwrite it)",
                             field="out")
    if not out.exists():
        check_output_path(out, field="out")


def cmd_growth(args: argparse.Namespace) -> int:
    """Train on generated sets of growing size; print test and CV metrics."""
    from ..training.pipeline import data_growth

    sizes = list(args.sizes)
    try:
        if max(sizes) > MAX_SAMPLES:
            from ..errors import ValidationError
            raise ValidationError(f"sample counts must be <= {MAX_SAMPLES}, got {max(sizes)}", field="--sizes")
        rows = data_growth(sizes, seed=args.seed)
    except HapticSDKError as exc:
        return _fail(exc, args)
    if args.json:
        emit(rows, True)
        return 0
    print(f"{'samples':>8} {'split':<6}{'MSE hard':>10}{'R hard':>9}{'MSE rough':>11}{'R rough':>9}{'time s':>8}")
    for r in rows:
        for sp in ("test", "cv"):
            h, g = r["metrics"][sp]["hardness"], r["metrics"][sp]["roughness"]
            print(f"{r['n_samples']:>8} {sp:<6}{h['mse']:>10.4f}{h['r']:>9.4f}{g['mse']:>11.4f}{g['r']:>9.4f}"
                  f"{r['time_s']:>8.1f}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``features``, ``train`` and ``dataset`` to the ``hapticsdk`` command."""
    p = sub.add_parser("features", help="extract the paper's features from a recording set",
                       description="Extract GS, W, Fpeak, AFpeak, P per trial of RECORDINGS "
                                   "(directory with recordings.json) and print per-sample mean +- std.")
    p.add_argument("recordings", type=Path, help="recording set directory or its recordings.json")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_features)

    p = sub.add_parser("train", help="train the perception model and export it to ONNX",
                       description="Train the 5-20-2 network by Levenberg-Marquardt on DATASET "
                                   "(feature data set with dataset.json, or recording set) and write ONNX.")
    p.add_argument("dataset", type=Path, help="data set directory")
    p.add_argument("--out", type=Path, required=True, help="ONNX file to write")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--seed", type=nonneg_int, default=None, help="split/initialisation seed (default 0)")
    p.add_argument("--folds", type=bounded_int(0, 100), default=None,
                   help="k of grouped k-fold CV (default 5, 0 = off)")
    p.add_argument("--restarts", type=bounded_int(1, 1000), default=None, help="initialisations tried (default 5)")
    p.add_argument("--target-scale", choices=["intensity", "data"], default=None,
                   help="scale targets over the 0..1 intensity scale (default) or the data range (MATLAB)")
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("dataset", help="generated data sets", description="Generated (simulated) data sets.")
    dsub = p.add_subparsers(dest="dataset_command", required=True)
    g = dsub.add_parser("generate", help="generate a data set (simulated recordings + ratings)")
    g.add_argument("out", type=Path, help="output directory")
    g.add_argument("--samples", type=bounded_int(1, MAX_SAMPLES), default=23,
                   help=f"number of samples, 1..{MAX_SAMPLES} (default 23)")
    g.add_argument("--seed", type=nonneg_int, default=None, help="generator seed (default 20221122)")
    g.add_argument("--trials", type=bounded_int(1, MAX_TRIALS), default=None,
                   help=f"trials per sample, 1..{MAX_TRIALS} (default 10)")
    g.add_argument("--raters", type=bounded_int(1, MAX_RATERS), default=None,
                   help=f"raters, 1..{MAX_RATERS} (default 10)")
    g.add_argument("--format", choices=("npz", "csv"), default="npz", help="raw trial file format")
    g.add_argument("--summary-only", action="store_true",
                   help="write only the feature tables and ratings (no raw trials)")
    g.add_argument("--materials", type=Path, default=None, help="also write a materials.json here")
    g.set_defaults(func=cmd_generate)
    gr = dsub.add_parser("growth", help="accuracy vs number of generated samples")
    gr.add_argument("--sizes", type=int_list, default=[23, 46, 92],
                    help="comma-separated sample counts, each >= 1 (default 23,46,92)")
    gr.add_argument("--seed", type=nonneg_int, default=None, help="generator seed (default 20221122)")
    gr.add_argument("--json", action="store_true")
    gr.set_defaults(func=cmd_growth)
