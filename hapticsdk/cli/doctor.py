"""``hapticsdk doctor [--json]``: backends, devices, optional libraries, calibrations."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``doctor`` to the ``hapticsdk`` command."""
    p = sub.add_parser("doctor", help="check which actuator backends, devices, libraries and "
                                      "calibrations are usable here")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=handle_doctor)


def handle_doctor(args: argparse.Namespace) -> int:
    """Print the report; exit 0 (a missing optional device is not an error)."""
    from ..doctor import collect, format_report
    from . import emit

    rep = collect()
    as_json = getattr(args, "json", False)
    emit(rep, as_json, None if as_json else format_report(rep))
    return 0
