"""Stop signals: SIGTERM and SIGHUP get the same safe stop as Ctrl-C (SIGINT).

Python turns SIGINT into :class:`KeyboardInterrupt`, so the ``finally``/``except``
paths of the servo loop and the context managers that own actuators stop every device.
SIGTERM (``kill``, systemd, a container stop) and SIGHUP (the terminal closed) kill the
interpreter by default, and none of those paths run: an actuator keeps playing its last
command. :func:`safe_stop_on_signals` installs, for the duration of a ``with`` block in
the main thread, one handler for SIGINT, SIGTERM and SIGHUP that raises
:class:`SafeStop` (a :class:`KeyboardInterrupt`) at the point the main thread is
executing, so every stop path for Ctrl-C serves the other two as well::

    with safe_stop_on_signals():
        render_plan(plan, seconds=30)       # SIGTERM -> SafeStop -> every actuator stopped

Only the *first* signal raises. Later ones (a second Ctrl-C while devices are being
stopped) are counted in :attr:`StopSignals.repeats` and otherwise ignored, so they
cannot interrupt the safe stop half-way. The previous handlers are restored when the
block exits. Outside the main thread (where Python cannot install handlers) the block
runs unchanged and :attr:`StopSignals.installed` is False.

The CLI maps a :class:`SafeStop` to the shell's convention ``128 + signal number``:
SIGINT 130, SIGTERM 143, SIGHUP 129.
"""

from __future__ import annotations

import signal
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Iterator, Sequence

#: names of the signals handled by default (those this platform has)
STOP_SIGNAL_NAMES = ("SIGINT", "SIGTERM", "SIGHUP")


def stop_signals() -> tuple[int, ...]:
    """Numbers of SIGINT, SIGTERM and SIGHUP on this platform (Windows: no SIGHUP)."""
    return tuple(int(getattr(signal, n)) for n in STOP_SIGNAL_NAMES if hasattr(signal, n))


def signal_name(signum: int) -> str:
    """``"SIGTERM"`` for 15, ``"signal 42"`` for a number with no name."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


class SafeStop(KeyboardInterrupt):
    """A stop signal arrived: unwind, stopping every actuator on the way.

    Attributes:
        signum: the signal number; ``signame`` its name.
        received_at: ``time.monotonic()`` when the handler ran (s).
        exit_code: ``128 + signum``, the exit status a shell expects.
    """

    def __init__(self, signum: int, received_at: float | None = None) -> None:
        self.signum = int(signum)
        self.signame = signal_name(self.signum)
        self.received_at = time.monotonic() if received_at is None else float(received_at)
        super().__init__(f"stopped by {self.signame}")

    @property
    def exit_code(self) -> int:
        """Exit status after this signal: 128 + its number."""
        return 128 + self.signum


@dataclass
class StopSignals:
    """What :func:`safe_stop_on_signals` saw.

    Attributes:
        installed: the handlers were installed (main thread only).
        signum: the first signal received, or None.
        received_at: ``time.monotonic()`` of the first signal (s), or None.
        repeats: signals received after the first one (ignored).
        signals: the signal numbers handled.
    """

    installed: bool = False
    signum: int | None = None
    received_at: float | None = None
    repeats: int = 0
    signals: tuple[int, ...] = field(default_factory=tuple)


@contextmanager
def safe_stop_on_signals(signals: Sequence[int] | None = None) -> Iterator[StopSignals]:
    """Turn ``signals`` (default SIGINT, SIGTERM, SIGHUP) into :class:`SafeStop` in the
    main thread for the duration of the block; see the module docstring."""
    sigs = tuple(int(s) for s in (signals if signals is not None else stop_signals()))
    state = StopSignals(signals=sigs)
    if threading.current_thread() is not threading.main_thread():
        yield state
        return

    def handler(signum: int, frame: object) -> None:
        if state.signum is not None:
            state.repeats += 1          # a stop is already under way: never interrupt it
            return
        state.signum = signum
        state.received_at = time.monotonic()
        raise SafeStop(signum, state.received_at)

    previous: dict[int, object] = {}
    try:
        for s in sigs:
            previous[s] = signal.signal(s, handler)
        state.installed = True
        yield state
    finally:
        for s, h in previous.items():
            try:
                signal.signal(s, h)  # type: ignore[arg-type]
            except (TypeError, ValueError, OSError):
                pass
