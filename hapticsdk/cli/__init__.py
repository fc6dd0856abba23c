"""The ``hapticsdk`` command.

Each command group lives in its own module under :mod:`hapticsdk.cli`, which exposes
``register(sub)`` (top-level subcommands) and/or ``register_bench(bench_sub)``
(subcommands of ``hapticsdk bench``). Modules keep heavy imports inside their handlers,
so ``hapticsdk --help`` imports no plugin and no device library.
"""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import sys
from typing import Sequence

from ..errors import HapticSDKError, ValidationError

#: command modules, in help order
COMMAND_MODULES = ("core", "scene", "training", "calibration", "doctor", "bench_solvers", "bench_runtime")


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog="hapticsdk",
        description="Multi-modal haptic rendering: solve stimulus features for perceptual "
                    "targets and render them on (simulated) devices.")
    parser.add_argument("--version", action="version", version=f"hapticsdk {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    bench = sub.add_parser("bench", help="benchmarks (solvers, stability, fidelity, timing)")
    bench_sub = bench.add_subparsers(dest="bench_command", metavar="BENCH")
    bench.set_defaults(func=lambda args: (bench.print_help(), 2)[1])
    parser.set_defaults(func=lambda args: (parser.print_help(), 2)[1])
    for name in COMMAND_MODULES:
        try:
            mod = importlib.import_module(f"{__name__}.{name}")
        except ImportError as exc:
            print(f"hapticsdk: command module {name!r} unavailable: {exc}", file=sys.stderr)
            continue
        if hasattr(mod, "register"):
            mod.register(sub)
        if hasattr(mod, "register_bench"):
            mod.register_bench(bench_sub)
    return parser


def emit(obj: object, as_json: bool, text: str | None = None) -> None:
    """Print ``obj`` as JSON, or ``text`` for humans."""
    if as_json:
        print(json.dumps(obj, indent=2, default=_json_default))
    else:
        print(text if text is not None else json.dumps(obj, indent=2, default=_json_default))


def _json_default(o: object) -> object:
    import numpy as np

    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    if hasattr(o, "to_dict"):
        return o.to_dict()
    return str(o)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args) or 0)
    except HapticSDKError as exc:
        field = getattr(exc, "field", None)
        if getattr(args, "json", False):
            print(json.dumps({"error": str(exc), "type": type(exc).__name__, "field": field}))
        else:
            print(f"hapticsdk: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        from ..actuators import stop_all
        stopped = stop_all()
        print(f"hapticsdk: interrupted; stopped {stopped or 'no actuators'}", file=sys.stderr)
        return 130


def positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0: {text!r}")
    return v


def intensity(text: str) -> float:
    """argparse type for a 0..1 intensity: NaN and out-of-range values are rejected."""
    from ..dimensions import check_intensity
    try:
        return check_intensity(text, "intensity")
    except ValidationError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
