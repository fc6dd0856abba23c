"""Progress of long work, shown on stderr: the one progress facility of the SDK (tqdm).

Long functions (data set generation, training, benchmarks) accept an optional
``progress`` callable, ``progress(stage, done, total)``: ``stage`` a short text
("simulating trials"), ``done`` of ``total`` steps finished. They never print
themselves. The command line passes a :class:`Progress`, which draws one bar per stage
on stderr -- only when stderr is a terminal and the command does not print JSON, so
pipes, log files and ``--json`` output stay clean.
"""

from __future__ import annotations

import sys
from typing import IO, Any, Callable, Optional

#: ``progress(stage, done, total)``: what long functions accept
ProgressFn = Callable[[str, int, int], None]


def report(progress: Optional[ProgressFn], stage: str, done: int, total: int) -> None:
    """Call ``progress`` if given (the helper long functions use)."""
    if progress is not None:
        progress(stage, done, total)


def shown(*, quiet: bool = False, stream: Optional[IO[str]] = None) -> bool:
    """Whether progress is drawn: not ``quiet`` (``--json``) and ``stream`` (stderr) is a
    terminal."""
    stream = sys.stderr if stream is None else stream
    if quiet:
        return False
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):  # closed or fake streams
        return False


class Progress:
    """A :data:`ProgressFn` drawing a tqdm bar per stage on ``stream`` (stderr).

    Args:
        title: what the command does ("dataset generate"); the bar reads
            ``title: stage``.
        quiet: never draw (the command prints JSON).
        stream: where to draw (default ``sys.stderr``); nothing is drawn unless it is a
            terminal.

    Use as a context manager (the last bar is closed on exit) and pass the object as the
    ``progress`` argument of a long function. :meth:`note` prints a line above the bar
    (only when the bar is shown).
    """

    def __init__(self, title: str, *, quiet: bool = False, stream: Optional[IO[str]] = None) -> None:
        self.title = title
        self.stream = sys.stderr if stream is None else stream
        self.enabled = shown(quiet=quiet, stream=self.stream)
        self._bar: Any = None
        self._stage: Optional[str] = None

    def __call__(self, stage: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        if stage != self._stage or self._bar is None:
            self._close_bar()
            from tqdm import tqdm

            self._bar = tqdm(total=max(int(total), 0), desc=f"{self.title}: {stage}", file=self.stream,
                             leave=False, dynamic_ncols=True, mininterval=0.2)
            self._stage = stage
        bar = self._bar
        if int(total) != bar.total:
            bar.total = int(total)
        bar.update(max(int(done) - bar.n, 0))

    def note(self, text: str) -> None:
        """A line of text above the bar (kept when the bar moves on)."""
        if not self.enabled:
            return
        from tqdm import tqdm

        tqdm.write(f"{self.title}: {text}", file=self.stream)

    def _close_bar(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def close(self) -> None:
        """Close the bar (it disappears: the command's own output follows)."""
        self._close_bar()
        self._stage = None

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
