"""``hapticsdk cache info | clear [--json]``: the per-user cache folder."""

from __future__ import annotations

import argparse

from . import missing_subcommand


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``cache info`` and ``cache clear`` to the ``hapticsdk`` command."""
    p = sub.add_parser("cache", help="the cache folder: where it is, its size and bound; clear it")
    csub = p.add_subparsers(dest="cache_command", metavar="ACTION")
    p.set_defaults(func=missing_subcommand(p, "ACTION"))
    i = csub.add_parser("info", help="where the cache is, how much it holds and its bound")
    i.add_argument("--json", action="store_true")
    i.set_defaults(func=handle_info)
    c = csub.add_parser("clear", help="remove everything in the cache (it is rebuilt when needed)")
    c.add_argument("--json", action="store_true")
    c.set_defaults(func=handle_clear)


def _mb(n: int) -> str:
    return f"{n / 1e6:.1f} MB"


def handle_info(args: argparse.Namespace) -> int:
    """Print the folder, its size and its bound."""
    from ..cache import info
    from . import emit
    rep = info()
    emit(rep, args.json, f"cache: {rep['path']}{'' if rep['exists'] else ' (not created yet)'}\n"
                         f"  {rep['files']} files, {_mb(rep['bytes'])} of at most {_mb(rep['max_bytes'])} "
                         f"(HAPTICSDK_CACHE_MAX_MB)")
    return 0


def handle_clear(args: argparse.Namespace) -> int:
    """Empty the folder; say what was removed."""
    from ..cache import clear
    from ..errors import ValidationError
    from . import emit
    try:
        before = clear()
    except ValueError as exc:
        raise ValidationError(str(exc), field="HAPTICSDK_CACHE_DIR") from None
    emit({"path": before["path"], "removed_files": before["files"], "removed_bytes": before["bytes"]}, args.json,
         f"cache cleared: {before['path']} ({before['files']} files, {_mb(before['bytes'])})")
    return 0
