"""``hapticsdk doctor [--json]``: backends, devices, optional libraries, calibrations."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("doctor", help="check which actuator backends, devices, libraries and "
                                      "calibrations are usable here")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=handle_doctor)


def handle_doctor(args: argparse.Namespace) -> int:
    """Print the report; exit 0 (a missing optional device is not an error)."""
    import json

    from ..doctor import collect, format_report

    rep = collect()
    if getattr(args, "json", False):
        print(json.dumps(rep, indent=2, default=str))
    else:
        print(format_report(rep))
    return 0
