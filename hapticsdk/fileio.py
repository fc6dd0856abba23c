"""Atomic file writes: every file the SDK writes goes through here.

A write goes to a temporary file in the target's directory, is flushed and
``fsync``-ed, and is then renamed over the target (``os.replace``, atomic on POSIX
and Windows). So:

- a reader sees the old file or the new one, never a partial one;
- a write that fails (disk full, ``ulimit -f``, SIGKILL, an exception while
  producing the content) leaves the old file intact and no temporary file behind
  (except after SIGKILL, where a ``.<name>.<random>.tmp`` may remain; it is never
  read as the target, and the next write of the same file, holding the directory's
  lock, removes it, so killed writers do not pile up copies);
- writers into the same directory, in this process and in other processes, are
  serialised by an advisory lock on the directory (POSIX ``fcntl.flock``; on other
  systems the rename alone keeps readers safe);
- a symbolic link at the target is replaced by the new regular file; its old target
  is not written through (a link planted in a calibration folder cannot redirect a
  write elsewhere);
- a target that is neither a regular file nor a link (a device such as ``/dev/null``, a
  named pipe, a socket) is refused before anything is written: a replace would put a
  regular file where the device or pipe was (run as root with ``--out /dev/null``, that
  removed the machine's ``/dev/null``).

- with ``verify=`` (every writer of a file the SDK reads back passes its reader), the
  finished temporary file is read back by that reader, with the reader's own limits,
  before the rename: content the SDK would refuse to read (too large, too deep, not
  valid) raises :class:`UnreadableWriteError` and the old file stays as it was. So
  neither an error nor a SIGKILL at any point can leave a file the SDK does not read
  where a good one was.

Failures raise :class:`~hapticsdk.errors.FileWriteError` (a ``ValidationError`` whose
``field`` is the path), so the CLI reports them as ``hapticsdk: error: <path>: ...``
with exit status 2.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import stat
import tempfile
from pathlib import Path
from typing import IO, Any, Callable, Iterator

from .cache import cache_dir, prune
from .errors import FileWriteError, ValidationError

__all__ = ["UnreadableWriteError", "cache_dir", "atomic_writer", "atomic_write_bytes", "atomic_write_text", "atomic_write_json", "atomic_savez",
           "check_output_path", "FileWriteError"]


class UnreadableWriteError(FileWriteError):
    """The content was not written: the SDK's own reader of this kind of file refuses it
    (``reason`` is the reader's message). The file at the target is unchanged."""

    def __init__(self, message: str, *, field: str, reason: str = "") -> None:
        self.reason = reason
        super().__init__(message, field=field)


def _verify(verify: Callable[[Path], Any], tmp: str, name: str) -> None:
    """Read the finished temporary file back with the reader ``verify``; any refusal
    becomes :class:`UnreadableWriteError` (the caller removes the temporary file)."""
    try:
        verify(Path(tmp))
    except Exception as exc:  # the reader's refusal, whatever its type, stops the replace
        reason = str(exc) or type(exc).__name__
        reason = reason.replace(tmp, "<new content>")
        raise UnreadableWriteError(f"not written: the SDK could not read it back ({type(exc).__name__}: "
                                   f"{reason}); the old file is unchanged", field=name,
                                   reason=reason) from None


def _refuse_special(p: Path, field: str) -> None:
    """Refuse ``p`` where it exists and is neither a regular file, a symbolic link nor a
    directory (a device such as ``/dev/null``, a named pipe, a socket): the SDK writes a
    file by replacing it whole, and a replace puts a regular file where the device or pipe
    was."""
    try:
        mode = os.lstat(p).st_mode
    except OSError:
        return
    if not (stat.S_ISREG(mode) or stat.S_ISLNK(mode) or stat.S_ISDIR(mode)):
        raise FileWriteError(f"{str(p)!r} is not a regular file (a device, a pipe or a socket): the SDK writes "
                             "a file by replacing it whole, which would put a file in its place; give a file "
                             "path", field=field)


def check_output_path(path: str | os.PathLike[str], *, field: str = "output", overwrite: bool = True) -> Path:
    """Check, before any work is done, that ``path`` can be written.

    The parent directory must exist and be a directory, the path must not be a
    directory, and with ``overwrite=False`` it must not exist yet.

    Returns:
        the path as a :class:`~pathlib.Path`.

    Raises:
        FileWriteError: naming ``field`` and the reason.
    """
    if isinstance(path, str) and path == "":
        raise FileWriteError("empty output path", field=field)
    from .argcheck import file_path
    try:
        p = file_path(path, field)
    except ValidationError as exc:
        raise FileWriteError(exc.reason, field=field) from None
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.exists():
        raise FileWriteError(f"directory {str(parent)!r} does not exist", field=field)
    if not parent.is_dir():
        raise FileWriteError(f"{str(parent)!r} is not a directory", field=field)
    if p.is_dir():
        raise FileWriteError(f"{str(p)!r} is a directory", field=field)
    _refuse_special(p, field)
    if not overwrite and (p.exists() or p.is_symlink()):
        raise FileWriteError(f"{str(p)!r} exists already (refusing to overwrite)", field=field)
    if not os.access(parent, os.W_OK):
        raise FileWriteError(f"directory {str(parent)!r} is not writable", field=field)
    return p


@contextlib.contextmanager
def _lock(target: Path) -> Iterator[bool]:
    """Serialise writers of one directory (an advisory ``flock`` on the directory
    itself, so no lock file is left behind). Yields whether the lock is held."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - non-POSIX: the rename alone keeps readers safe
        yield False
        return
    parent = target.parent if str(target.parent) else Path(".")
    try:
        fd = os.open(parent, os.O_RDONLY)
    except OSError:
        yield False
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            held = True
        except OSError:
            held = False
        yield held
    finally:
        with contextlib.suppress(OSError):
            fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


@contextlib.contextmanager
def atomic_writer(path: str | os.PathLike[str], mode: str = "wb", *, encoding: str | None = "utf-8",
                  newline: str | None = None, field: str | None = None,
                  verify: Callable[[Path], Any] | None = None) -> Iterator[IO[Any]]:
    """Context manager yielding a file object whose content replaces ``path`` on success.

    Args:
        path: the file to (re)place.
        mode: ``"wb"`` (bytes) or ``"w"`` (text).
        encoding, newline: for text mode.
        field: names the path in errors (default: the path itself).
        verify: the SDK's reader of this kind of file, called with the finished
            temporary file before it replaces ``path``; if it raises, nothing is replaced
            (:class:`UnreadableWriteError`).

    On an exception inside the block, or a failure to write, flush or rename, the
    temporary file is removed and the old content of ``path`` is untouched; OS errors
    are raised as :class:`FileWriteError`, other exceptions propagate unchanged.
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"atomic_writer mode must be 'wb' or 'w', got {mode!r}")
    from .argcheck import file_path
    try:
        target = file_path(path, field or "path")
    except ValidationError as exc:
        raise FileWriteError(exc.reason, field=field or str(path)[:200]) from None
    name = field or str(target)
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise FileWriteError(f"directory {str(parent)!r} does not exist", field=name)
    if target.is_dir() and not target.is_symlink():
        raise FileWriteError(f"{str(target)!r} is a directory", field=name)
    _refuse_special(target, name)
    with _lock(target) as held:
        if held:
            _remove_orphans(parent, target.name)
        try:
            fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=parent)
        except OSError as exc:
            raise FileWriteError(f"cannot create a file in {str(parent)!r}: {exc.strerror or exc}",
                                 field=name) from exc
        ok = False
        try:
            try:
                # keep the permissions of the file being replaced (mkstemp makes 0600)
                os.chmod(tmp, (os.stat(target).st_mode & 0o777) if target.exists() and not target.is_symlink()
                         else 0o644 & ~_umask())
            except OSError:
                pass
            raw = os.fdopen(fd, "wb")
            fh: IO[Any] = raw if mode == "wb" else io.TextIOWrapper(raw, encoding=encoding or "utf-8",
                                                                     newline=newline)
            with fh:
                yield fh
                fh.flush()
                os.fsync(raw.fileno())
            if verify is not None:
                _verify(verify, tmp, name)
            os.replace(tmp, target)
            ok = True
            _fsync_dir(parent)
            if _in_cache(parent):
                prune()
        except OSError as exc:
            raise FileWriteError(f"write failed, the old file is unchanged: {exc.strerror or exc}",
                                 field=name) from exc
        finally:
            if not ok:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)


def _remove_orphans(parent: Path, name: str) -> None:
    """Remove the temporary files of ``name`` that a writer killed before its rename
    (SIGKILL, power loss) left in ``parent``. Called with the directory's lock held:
    every SDK writer of the folder takes it before it creates its temporary file, so
    none is being written now."""
    pattern = re.compile(rf"\.{re.escape(name)}\.[A-Za-z0-9_]{{8}}\.tmp")  # mkstemp's names
    try:
        names = os.listdir(parent)
    except OSError:
        return
    for n in names:
        if pattern.fullmatch(n):
            with contextlib.suppress(OSError):
                os.unlink(parent / n)


def _in_cache(folder: Path) -> bool:
    """Whether ``folder`` is in the cache folder (a write there may need a prune)."""
    try:
        return folder.resolve().is_relative_to(cache_dir().resolve())
    except (OSError, ValueError):
        return False


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m


def _fsync_dir(d: Path) -> None:
    if os.name != "posix":  # pragma: no cover
        return
    try:
        dfd = os.open(d, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dfd)
    except OSError:
        pass
    finally:
        os.close(dfd)


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes, *, field: str | None = None,
                       verify: Callable[[Path], Any] | None = None) -> Path:
    """Replace ``path`` with ``data`` atomically (read back with ``verify`` first, see
    :func:`atomic_writer`); returns the path."""
    with atomic_writer(path, "wb", field=field, verify=verify) as fh:
        fh.write(data)
    return Path(os.fspath(path))


def atomic_write_text(path: str | os.PathLike[str], text: str, *, encoding: str = "utf-8",
                      field: str | None = None, verify: Callable[[Path], Any] | None = None) -> Path:
    """Replace ``path`` with ``text`` atomically; returns the path."""
    return atomic_write_bytes(path, text.encode(encoding), field=field, verify=verify)


def atomic_write_json(path: str | os.PathLike[str], obj: Any, *, indent: int | None = 1,
                      field: str | None = None, verify: Callable[[Path], Any] | None = None,
                      **dumps_kw: Any) -> Path:
    """Serialise ``obj`` to JSON (``allow_nan=False``: NaN is refused, not written) and
    replace ``path`` atomically. The whole document is serialised before the file is
    touched, so a serialisation error leaves the old file as it was."""
    dumps_kw.setdefault("allow_nan", False)
    try:
        text = json.dumps(obj, indent=indent, **dumps_kw) + "\n"
    except ValueError as exc:
        raise FileWriteError(f"not written: {exc}", field=field or str(path)) from exc
    return atomic_write_text(path, text, field=field, verify=verify)


def atomic_savez(path: str | os.PathLike[str], *, compressed: bool = True, field: str | None = None,
                 verify: Callable[[Path], Any] | None = None, **arrays: Any) -> Path:
    """The ``.npz`` of ``numpy.savez[_compressed]`` to ``path`` atomically (the name is kept
    as given: no ``.npz`` suffix is appended). An array of Python objects, which only
    pickling could store, is refused with :class:`FileWriteError`.

    The archive is written here, in a ``with`` block, rather than by ``numpy.savez``: numpy
    before 1.25 leaves its ``ZipFile`` open when a write fails (a full disk, a file-size
    limit), and its ``__del__`` then prints "Exception ignored ... seek of closed file"
    after :func:`atomic_writer` has closed the file and reported the error."""
    import zipfile

    import numpy as np

    values = {name: np.asanyarray(value) for name, value in arrays.items()}
    for name, value in values.items():
        if value.dtype.hasobject:   # the SDK's readers load with allow_pickle=False
            raise FileWriteError(f"not written: array {name!r} holds Python objects (dtype {value.dtype}), "
                                 "which an .npz stores only by pickling", field=field or str(path))
    method = zipfile.ZIP_DEFLATED if compressed else zipfile.ZIP_STORED
    with atomic_writer(path, "wb", field=field, verify=verify) as fh:
        with zipfile.ZipFile(fh, "w", compression=method, allowZip64=True) as zf:
            for name, value in values.items():
                with zf.open(name + ".npy", "w", force_zip64=True) as member:
                    np.lib.format.write_array(member, value, allow_pickle=False)
    return Path(os.fspath(path))
