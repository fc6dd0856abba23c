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
from typing import Any, Callable, Mapping, NoReturn, Sequence

from ..errors import HapticSDKError

#: command modules, in help order
COMMAND_MODULES = ("core", "scene", "training", "calibration", "doctor", "bench_solvers", "bench_runtime",
                   "interop", "live", "cache")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``hapticsdk`` argument parser with every command module's subcommands (help with
    defaults and one example per command).

    With ``command`` (a top-level command name such as ``"render"``) only that command's
    parser and everything below it are built, exactly as in the full parser; every command
    module is still imported and registers, the other commands' parsers are skipped.
    :func:`main` parses a command line with it (the ~30 other parsers cost 10-15 ms of a
    ``hapticsdk render S7``). A name that no module registers gives the full parser, so
    an unknown command is reported with every valid choice.
    """
    from .. import __version__

    parser = Parser(
        prog="hapticsdk",
        description="Multi-modal haptic rendering: solve stimulus features for perceptual "
                    "targets and render them on (simulated) devices.",
        epilog="Exit status: 0 success; 1 a target was not reached (solve, render, plan) or a check "
               "failed; 2 bad input (the message reads 'hapticsdk: error: <field>: <reason>'); "
               "128+n after signal n (141: output pipe closed, e.g. piped into head).")
    parser.add_argument("--version", action="version", version=f"hapticsdk {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    top: Any = sub if command is None else _OnlyCommand(sub, command)
    bench = top.add_parser("bench", help="benchmarks")
    bench_sub = bench.add_subparsers(dest="bench_command", metavar="BENCH")
    bench.set_defaults(func=missing_subcommand(bench, "BENCH"))
    parser.set_defaults(func=missing_subcommand(parser, "COMMAND"))
    for name in COMMAND_MODULES:
        try:
            mod = importlib.import_module(f"{__name__}.{name}")
        except ImportError as exc:
            print(f"hapticsdk: command module {name!r} unavailable: {exc}", file=sys.stderr)
            continue
        if hasattr(mod, "register"):
            mod.register(top)
        if hasattr(mod, "register_bench"):
            mod.register_bench(bench_sub)
    if command is not None and command not in sub.choices:
        return build_parser()
    if "bench" in sub.choices:
        # the benchmarks as registered, in both help texts (a list written by hand went stale)
        benches = ", ".join(bench_sub.choices)
        for choice in sub._choices_actions:  # noqa: SLF001 - argparse keeps the help lines here
            if choice.dest == "bench":
                choice.help = f"benchmarks, run by hand ({benches})"
        bench.description = f"Benchmarks, run by hand: {benches}."
    _finish_help(parser, ())
    return parser


class _Skipped:
    """Stands in for the parser of a command that :func:`build_parser` does not build:
    every method call (``add_argument``, ``add_subparsers``, ``set_defaults`` ...) does
    nothing and returns the stand-in again."""

    def __getattr__(self, name: str) -> Callable[..., "_Skipped"]:
        return self._ignore

    def _ignore(self, *args: Any, **kwargs: Any) -> "_Skipped":
        return self


class _OnlyCommand:
    """The top-level subparsers action, passed to the command modules' ``register``, that
    builds only the parser of one command (its name or one of its aliases)."""

    def __init__(self, sub: argparse._SubParsersAction, command: str) -> None:
        self._sub = sub
        self._command = command

    def add_parser(self, name: str, **kwargs: Any) -> Any:
        if self._command != name and self._command not in kwargs.get("aliases", ()):
            return _Skipped()
        return self._sub.add_parser(name, **kwargs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._sub, name)


def command_word(argv: Sequence[str]) -> str | None:
    """The top-level command of a ``hapticsdk`` command line (``"render"`` for ``-v render
    S7``), or ``None`` when anything else comes first (``--help``, ``--version``, an
    abbreviated or unknown option, nothing): then the full parser reads it."""
    for token in argv:
        if token in ("-v", "--verbose"):
            continue
        return None if token.startswith("-") else token
    return None


#: one example per command (shown at the end of its --help)
EXAMPLES: dict[str, str] = {
    "": "hapticsdk render S7",
    "bench": "hapticsdk bench stability --quick",
    "bench solvers": "OMP_NUM_THREADS=1 hapticsdk bench solvers --quick --plot solvers.png",
    "bench stability": "hapticsdk bench stability --quick --plot stability.png",
    "bench fidelity": "hapticsdk bench fidelity --periods 0.001 0.004",
    "bench timing": "hapticsdk bench timing --seconds 10 --realtime",
    "bench live": "hapticsdk bench live --isolation process --app-load all --seconds 5",
    "plugins": "hapticsdk plugins --kind solver --check",
    "materials": "hapticsdk materials --json",
    "solve": "hapticsdk solve --hardness 0.8 --roughness 0.3 --seed 1",
    "render": "hapticsdk render --hardness 0.8 --roughness 0.3 --seconds 2 --plot render.png",
    "plan": "hapticsdk plan examples/scenes/warm-and-rough.json --plot plan.png",
    "features": "hapticsdk features recordings/",
    # {dataset}: the data set shipped in the package, wherever it was installed
    "train": "hapticsdk train {dataset} --out model.onnx",
    "dataset": "hapticsdk dataset generate data/ --samples 23",
    "dataset generate": "hapticsdk dataset generate data/ --samples 23 --materials data/materials.json",
    "dataset growth": "hapticsdk dataset growth --sizes 23,46",
    "calibrate": "hapticsdk calibrate list",
    "calibrate voicecoil": "hapticsdk calibrate voicecoil answers.csv --serial VC-001",
    "calibrate piezo": "hapticsdk calibrate piezo measurements.csv --serial PZ-001",
    "calibrate damping": "hapticsdk calibrate damping --simulate --damping 0.5 --serial OMNI-001",
    "calibrate answers": "hapticsdk calibrate answers answers.csv --people 10 --seed 0",
    "calibrate list": "hapticsdk calibrate list --json",
    "replay": "hapticsdk replay run.npz",
    "view": "hapticsdk view scene.json --seconds 30",
    "doctor": "hapticsdk doctor --json",
    "cache": "hapticsdk cache info",
    "cache info": "hapticsdk cache info --json",
    "cache clear": "hapticsdk cache clear",
    "export": "hapticsdk export plan.json -o materials.hjif",
    "import": "hapticsdk import materials.hjif",
    "play": "hapticsdk play materials.hjif --seconds 2",
}

#: help of flags every command shares, when a command gives none
COMMON_HELP = {"--json": "print the result as JSON on stdout (no progress bars)"}


class HelpFormatter(argparse.HelpFormatter):
    """Wraps description and epilog paragraphs but keeps indented lines (examples) as
    they are, and appends ``(default: X)`` to every option whose help does not already
    state its default."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        out = []
        for para in text.split("\n\n"):
            lines = para.splitlines()
            if any(ln.startswith("  ") for ln in lines):  # "Example:" + indented command
                out.append("\n".join(indent + ln for ln in lines))
            else:
                out.append(super()._fill_text(para, width, indent))
        return "\n\n".join(out)

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if ("default" in text or default in (None, False, argparse.SUPPRESS, [], ()) or not action.option_strings
                or isinstance(action, (argparse._HelpAction, argparse._VersionAction))):
            return text
        shown = " ".join(map(str, default)) if isinstance(default, (list, tuple)) else default
        return f"{text} (default: {shown})"


def example_text(command: str) -> str | None:
    """The example shown in ``command``'s help (``EXAMPLES`` with its paths filled in)."""
    example = EXAMPLES.get(command)
    if example and "{dataset}" in example:
        from pathlib import Path

        from ..install_hints import shown_path  # the shipped data set, wherever it was installed
        example = example.replace("{dataset}", shown_path(Path(__file__).resolve().parent.parent / "data" / "dataset"))
    return example


def _finish_help(parser: argparse.ArgumentParser, path: tuple[str, ...]) -> None:
    """Formatter, shared flag help and the example of every (sub)command."""
    parser.formatter_class = HelpFormatter
    for action in parser._actions:
        if not action.help and action.option_strings and action.option_strings[-1] in COMMON_HELP:
            action.help = COMMON_HELP[action.option_strings[-1]]
    example = example_text(" ".join(path))
    if example and "Example:" not in (parser.epilog or ""):
        parser.epilog = ((parser.epilog + "\n\n") if parser.epilog else "") + f"Example:\n  {example}"
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                _finish_help(sub, path + (name,))


def missing_subcommand(p: argparse.ArgumentParser, what: str) -> Callable[[argparse.Namespace], int]:
    """Handler of a command group run without its subcommand: the group's help and
    ``hapticsdk: error: <WHAT>: ...`` on stderr, exit status 2."""

    def handler(args: argparse.Namespace) -> int:
        p.print_help(sys.stderr)
        print(f"hapticsdk: error: {what}: choose one of the commands listed above", file=sys.stderr)
        return 2

    return handler


def emit(obj: object, as_json: bool, text: str | None = None) -> None:
    """Print ``obj`` as JSON, or ``text`` for humans. The JSON is written in pieces as it
    is encoded (the same text as ``json.dumps(obj, indent=2)`` and a newline), so a large
    result (``bench stability --random 50000 --json``, about 0.23 GB of text) is never
    held whole in memory beside the result itself."""
    if as_json:
        out = sys.stdout
        json.dump(obj, out, indent=2, default=_json_default)
        out.write("\n")
        out.flush()
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


class Parser(argparse.ArgumentParser):
    """``argparse`` parser whose usage errors read ``hapticsdk: error: <field>: <reason>``
    (exit status 2), like every other input error of the command."""

    def error(self, message: str) -> "NoReturn":  # type: ignore[override]
        self.print_usage(sys.stderr)
        if message.startswith("argument "):
            message = message[len("argument "):]  # "--seed: must be >= 0, got -1"
        else:  # no option to name: name the (sub)command
            message = f"{self.prog.split(' ', 1)[-1] if ' ' in self.prog else self.prog}: {message}"
        self.exit(2, f"hapticsdk: error: {message}\n")


def error_line(exc: BaseException, args: argparse.Namespace | None = None) -> str:
    """``<field>: <reason>`` for an SDK error: its ``field`` when it has one, else the
    device or plugin it names, else the command that failed."""
    if getattr(exc, "field", None):
        return str(exc)  # ValidationError puts "field: " in front already
    where = getattr(exc, "device", None) or getattr(exc, "plugin", None)
    if where:
        text = str(exc)
        return text if text.startswith(f"[{where}]") else f"{where}: {text}"
    command = " ".join(str(getattr(args, k)) for k in ("command", "bench_command", "calibrate_command",
                                                         "dataset_command")
                       if args is not None and getattr(args, k, None)) or "hapticsdk"
    return f"{command}: {exc}"


def report_error(exc: BaseException, args: argparse.Namespace | None = None) -> int:
    """Print an SDK error the command's way and return exit status 2: the line
    ``hapticsdk: error: <field>: <reason>`` on stderr, and with ``--json`` also
    ``{"error", "type", "field"}`` on stdout."""
    if args is not None and getattr(args, "json", False):
        print(json.dumps({"error": str(exc), "type": type(exc).__name__, "field": getattr(exc, "field", None)}))
    print(f"hapticsdk: error: {error_line(exc, args)}", file=sys.stderr)
    return 2


def _quiet_stdout() -> None:
    """After EPIPE: point stdout at devnull so the interpreter's final flush does not fail
    again (the recipe of the Python docs, "Note on SIGPIPE")."""
    import os
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # stdout without a file descriptor (tests)
        pass


def _interrupt_summary(signame: str, t_signal: float) -> dict[str, Any]:
    """Stop every actuator still open (the last resort), then what the stop path did
    since ``t_signal``: ``safe_state`` (labels put in their safe state, including those
    already stopped and closed on the way out), ``stop_failed`` and ``first_stop_ms``
    (after the signal; None when no actuator was open)."""
    from ..devices.actuators import stop_all, stops_since

    stop_all()
    stops = stops_since(t_signal)
    ok = list(dict.fromkeys(label for label, _, good in stops if good))
    failed = [lb for lb in dict.fromkeys(label for label, _, good in stops if not good) if lb not in ok]
    first = 1e3 * max(0.0, stops[0][1] - t_signal) if stops else None
    return {"signal": signame, "safe_state": ok, "stop_failed": failed, "first_stop_ms": first}


def _interrupt_text(summary: Mapping[str, Any]) -> str:
    signame = summary["signal"]
    if summary["first_stop_ms"] is None:
        return f"stopped by {signame}; no actuator was open"
    msg = (f"stopped by {signame}; actuators in safe state: {', '.join(summary['safe_state']) or 'none'} "
           f"(first stop {summary['first_stop_ms']:.1f} ms after the signal)")
    if summary["stop_failed"]:
        msg += f"; stop FAILED on {', '.join(summary['stop_failed'])} (see the log above)"
    return msg


def interrupt_message(signame: str, t_signal: float) -> str:
    """Stop every actuator still open (the last resort), then say which actuators the
    stop path put in their safe state since ``t_signal`` (``time.monotonic()``, s) --
    including those already stopped and closed on the way out -- and how soon."""
    return _interrupt_text(_interrupt_summary(signame, t_signal))


#: exit status after the output pipe closed early (128 + SIGPIPE, as a shell reports it)
EXIT_BROKEN_PIPE = 141


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``hapticsdk`` command; returns the exit status (never raises for bad input).

    0 success; 1 a target not reached or a check failed; 2 bad input (including usage
    errors); 128+n after stop signal n (SIGINT 130, SIGTERM 143, SIGHUP 129: every
    actuator is put in its safe state first); 141 stdout closed early (``| head``); 1 with
    ``hapticsdk: internal error: ...`` for a bug (``-v`` shows the traceback)."""
    import time

    from ..runtime.signals import SafeStop, safe_stop_on_signals

    t_start = time.monotonic()
    try:
        parser = build_parser(command_word(sys.argv[1:] if argv is None else argv))
        try:
            args = parser.parse_args(argv)
        except SystemExit as exc:  # usage error (2) or --help/--version (0)
            return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
        logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                            format="%(levelname)s %(name)s: %(message)s")
        try:
            # SIGINT, SIGTERM, SIGHUP -> SafeStop (a KeyboardInterrupt): one safe stop path
            with safe_stop_on_signals():
                code = int(args.func(args) or 0)
            sys.stdout.flush()  # a closed pipe shows up here, not at interpreter exit
            return code
        except HapticSDKError as exc:
            return report_error(exc, args)
        except KeyboardInterrupt as exc:
            if isinstance(exc, SafeStop):
                name, code, t_sig = exc.signame, exc.exit_code, exc.received_at
            else:  # Python's own SIGINT handler, outside the handled block
                name, code, t_sig = "SIGINT", 130, t_start
            summary = _interrupt_summary(name, t_sig)
            if getattr(args, "json", False):
                # a script reading --json output gets an object, as for an error
                print(json.dumps({"error": _interrupt_text(summary), "type": "Interrupted", "field": None,
                                  "exit_status": code, **summary}))
            print(f"hapticsdk: {_interrupt_text(summary)}", file=sys.stderr)
            return code
        except BrokenPipeError:
            raise
        except Exception as exc:  # last resort: a bug, not bad input
            from ..devices.actuators import stop_all
            stop_all()
            if args.verbose:
                import traceback
                traceback.print_exc()
            print(f"hapticsdk: internal error: {type(exc).__name__}: {exc} (run 'hapticsdk -v ...' for the "
                  "traceback; please report it)", file=sys.stderr)
            return 1
    except BrokenPipeError:
        _quiet_stdout()
        return EXIT_BROKEN_PIPE


def run() -> NoReturn:
    """The ``hapticsdk`` script and ``python -m hapticsdk``: :func:`main`, then exit with its
    status, without the interpreter's last garbage collection.

    When :func:`main` has returned, every command has closed its actuators and files and
    flushed its output; what is left in memory dies with the process. At exit CPython
    still runs a full collection and frees the objects held in reference cycles (modules,
    classes, functions, the argument parser): 25-35 ms of a ``hapticsdk render S7`` that
    costs 250-300 ms in all (docs/runtime.md, "Start-up"). :func:`gc.freeze` moves every
    object to the permanent generation, which no collection visits, so the exit skips that
    work. Everything else at exit runs as before: ``atexit`` handlers (the actuators'
    last-resort :func:`~hapticsdk.devices.actuators.stop_all`, ``weakref.finalize``,
    logging's flush), and objects freed by reference counting. Only finalizers of objects
    that are part of a reference cycle when the process exits do not run, which Python
    never promises anyway. :func:`main` itself, called in-process (tests, scripts), does
    not freeze.

    Before :func:`main`, the BLAS / OpenMP thread pools are held to one thread unless the
    environment sets one of ``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``,
    ``MKL_NUM_THREADS``, ``BLIS_NUM_THREADS`` (:func:`hapticsdk.threadpools.default_one_thread`:
    the SDK's arrays are too small for a second thread to shorten a call, and an idle
    OpenBLAS worker spins: 0.2 s of CPU of a ``render S7`` that needs 0.27 s).
    """
    from ..threadpools import default_one_thread
    default_one_thread()
    code = main()
    import gc
    gc.freeze()
    sys.exit(code)


from .argtypes import intensity, positive_float  # noqa: E402  (kept importable from here)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
