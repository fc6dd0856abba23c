"""The per-user cache folder, its size bound and ``hapticsdk cache clear``.

Everything in :func:`cache_dir` (also :func:`hapticsdk.fileio.cache_dir`) can be rebuilt: amortised solver tables
(``amortised/``, ~0.4-0.6 MB each, one per model and constraint set), model descriptions
(``onnx-desc/``, ``onnx-chain/``, tens of kB), validation markers (``validated/``,
empty files, one per JSON file content that passed its schema) and entry-point indexes
(``plugin-index/``, a few kB, one per set of installed distributions and ``sys.path``:
:mod:`hapticsdk.plugin_index`).

**Bound.** The folder is kept at or under ``HAPTICSDK_CACHE_MAX_MB`` megabytes
(default :data:`DEFAULT_MAX_MB`); every file counts at least one filesystem block
(:data:`BLOCK_BYTES`), so the empty markers are bounded too. After each write into the
cache (:func:`~hapticsdk.fileio.atomic_writer` calls :func:`prune`) the oldest files
(by modification time) are removed until the folder fits. ``HAPTICSDK_CACHE_MAX_MB=0``
keeps nothing beyond the file just written.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from pathlib import Path
from typing import Any


#: default bound (MB): a few hundred amortised tables, far more than one user's
#: models x constraint sets; a policy, overridden by ``HAPTICSDK_CACHE_MAX_MB``
DEFAULT_MAX_MB = 256.0
#: the least a file costs on disk (the common filesystem block), so empty markers count
BLOCK_BYTES = 4096
#: the standard cache-directory tag (backup tools skip a folder holding it)
TAG_NAME = "CACHEDIR.TAG"
TAG_TEXT = ("Signature: 8a477f597d28d172789f06886806bc55\n"
            "# This file is a cache directory tag created by hapticsdk.\n"
            "# Its contents can be rebuilt; `hapticsdk cache clear` empties it.\n")


def cache_dir() -> Path:
    """The SDK's cache folder (amortised tables, model descriptions, validation markers):
    ``$HAPTICSDK_CACHE_DIR``, else the per-user cache folder of the platform
    (``platformdirs``: ``$XDG_CACHE_HOME/hapticsdk`` or ``~/.cache/hapticsdk`` on Linux,
    ``~/Library/Caches/hapticsdk`` on macOS, ``%LOCALAPPDATA%\\hapticsdk\\Cache`` on
    Windows). Not created here; writers create their sub-folder."""
    env = os.environ.get("HAPTICSDK_CACHE_DIR")
    if env:
        return Path(env)
    import platformdirs
    return Path(platformdirs.user_cache_dir("hapticsdk", appauthor=False))


def max_bytes() -> int:
    """The bound in bytes (``HAPTICSDK_CACHE_MAX_MB``, default :data:`DEFAULT_MAX_MB`)."""
    raw = os.environ.get("HAPTICSDK_CACHE_MAX_MB")
    try:
        mb = float(raw) if raw not in (None, "") else DEFAULT_MAX_MB
    except ValueError:
        mb = DEFAULT_MAX_MB
    return int(max(mb, 0.0) * 1e6)


def _entries(root: Path) -> list[tuple[float, int, Path]]:
    out = []
    for dirpath, _dirs, files in os.walk(root):
        for f in files:
            if f == TAG_NAME or f.startswith("."):  # the tag; a write in progress (.name.tmp)
                continue
            p = Path(dirpath) / f
            with contextlib.suppress(OSError):
                st = p.lstat()
                out.append((st.st_mtime, max(st.st_size, BLOCK_BYTES), p))
    return out


def info(root: Path | None = None) -> dict[str, Any]:
    """``{"path", "exists", "files", "bytes", "max_bytes"}`` of the cache folder."""
    root = cache_dir() if root is None else root
    entries = _entries(root) if root.is_dir() else []
    return {"path": str(root), "exists": root.is_dir(), "files": len(entries),
            "bytes": sum(e[1] for e in entries), "max_bytes": max_bytes()}


def prune(limit: int | None = None, root: Path | None = None) -> int:
    """Remove the oldest files until the folder holds at most ``limit`` bytes (default
    :func:`max_bytes`); the newest file always stays. Returns the files removed.
    Never raises (a file another process removed first is skipped)."""
    root = cache_dir() if root is None else root
    limit = max_bytes() if limit is None else limit
    try:
        _tag(root)
        entries = sorted(_entries(root), key=lambda e: e[0])
    except OSError:
        return 0
    total = sum(e[1] for e in entries)
    removed = 0
    for _, cost, path in entries[:-1]:
        if total <= limit:
            break
        with contextlib.suppress(OSError):
            path.unlink()
            removed += 1
            total -= cost
    return removed


def _tag(root: Path) -> None:
    tag = root / TAG_NAME
    if root.is_dir() and not tag.exists():
        with contextlib.suppress(OSError):
            tag.write_text(TAG_TEXT)


def clear(root: Path | None = None) -> dict[str, Any]:
    """Empty the cache folder; returns :func:`info` from before. Refuses (``ValueError``)
    a folder that is neither named ``hapticsdk`` nor tagged as this cache, so a mistyped
    ``HAPTICSDK_CACHE_DIR`` cannot empty an unrelated folder."""
    root = cache_dir() if root is None else root
    before = info(root)
    if not root.is_dir():
        return before
    if root.name.lower() != "hapticsdk" and not (root / TAG_NAME).is_file() and any(root.iterdir()):
        raise ValueError(f"{root} does not look like the hapticsdk cache (no {TAG_NAME}); not emptied")
    for child in root.iterdir():
        if child.name == TAG_NAME:
            continue
        if child.is_dir() and not child.is_symlink():
            shutil.rmtree(child, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                child.unlink()
    return before
