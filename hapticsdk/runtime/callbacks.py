"""Callbacks and acknowledgements of a live session (the application side).

:class:`SwitchHandle` is what :meth:`Session.set_material
<hapticsdk.runtime.session.Session.set_material>` hands back for the switch it sent:
it resolves when the servo publishes the first tick that rendered the new material,
with that tick's number, its servo time and the machine's monotonic time of its
publication. :class:`EventDispatcher` is the application thread the SDK owns that runs
the callbacks given to :meth:`Session.on_event
<hapticsdk.runtime.session.Session.on_event>`: the servo never runs application code.

Both only read the session's shared block (the event ring and the acknowledgement
ring); neither sends anything to the servo.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import TYPE_CHECKING, Any, Callable

from ..errors import ServoProcessDied, SessionError

if TYPE_CHECKING:  # pragma: no cover
    from .session import Session, SessionEvent

_log = logging.getLogger(__name__)

#: how often the dispatcher looks at the event ring (s). A person notices a delay of
#: about 100 ms between an action and its feedback; 2 ms keeps a callback's delay two
#: servo periods above the servo's own at 1 kHz, at a cost to the application of one
#: short wake-up per 2 ms
DISPATCH_PERIOD_S = 0.002
#: how long :meth:`SwitchHandle.wait` sleeps between looks at the acknowledgement (s):
#: a fifth of a 1 ms servo period
_WAIT_POLL_S = 0.0002


class SwitchHandle:
    """A material switch sent to the servo, resolved when it took effect.

    Attributes (None until resolved):
        tick: index of the first servo tick that rendered the new material (0-based,
            as ``state().ticks - 1`` after that tick).
        t: that tick's servo time (s).
        monotonic: ``time.monotonic()`` when the servo published that tick (s; the
            machine's clock, the same in both processes).
        sent_at: ``time.monotonic()`` when the application sent the switch.
    """

    def __init__(self, session: "Session", seq: int, sent_at: float) -> None:
        self._session = session
        self.seq = seq
        self.sent_at = sent_at
        self.tick: int | None = None
        self.t: float | None = None
        self.monotonic: float | None = None

    def done(self) -> bool:
        """True once the switch took effect (never blocks). Raises
        :class:`~hapticsdk.errors.ServoProcessDied` when the servo died first."""
        if self.tick is not None:
            return True
        got = self._session._ack_of(self.seq)  # noqa: SLF001 - the session's own ring
        if got is None:
            self._session._check()  # noqa: SLF001 - raises when the servo is gone
            return False
        self.tick, self.t, self.monotonic = int(got[0]), got[1], got[2]
        return True

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until the switch took effect; True then, False after ``timeout`` s
        (None: no limit). Raises :class:`~hapticsdk.errors.ServoProcessDied` when the
        servo died before, :class:`~hapticsdk.errors.SessionError` when the session was
        closed before."""
        end = None if timeout is None else time.monotonic() + float(timeout)
        while not self.done():
            if end is not None and time.monotonic() >= end:
                return False
            time.sleep(_WAIT_POLL_S)
        return True

    @property
    def latency_s(self) -> float | None:
        """From sending the switch to the servo's publication of the tick that
        rendered it first (s), None until resolved."""
        return None if self.monotonic is None else self.monotonic - self.sent_at

    def __repr__(self) -> str:
        state = "pending" if self.tick is None else f"tick {self.tick}, t {self.t:.6f} s"
        return f"SwitchHandle(seq={self.seq}, {state})"


class EventDispatcher:
    """Runs callbacks for a session's events on a thread of its own (``hapticsdk-events``),
    started by the first :meth:`add`, which also gets the events published since the
    session started (at most the last 1024).

    Every :data:`DISPATCH_PERIOD_S` it reads the events that arrived since its last look
    (with its own read position: :meth:`Session.events` still sees every event), and
    calls the callbacks of each one's kind, then those of ``"*"``, in order. A callback
    that raises is logged and counted (:attr:`errors`), never stops the dispatcher.
    When the servo dies, the callbacks of ``"servo_died"`` (and ``"*"``) get one last
    event whose ``message`` is the reason, and the thread ends; it ends silently when
    the session is closed."""

    def __init__(self, session: "Session") -> None:
        self._session = session
        self._callbacks: dict[str, list[Callable[["SessionEvent"], Any]]] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._cursor = 0
        self._closing = False
        #: callbacks that raised
        self.errors = 0
        #: events delivered (to at least one callback)
        self.delivered = 0

    def add(self, kind: str, callback: Callable[["SessionEvent"], Any]) -> None:
        """Register ``callback`` for ``kind`` (starts the thread on the first call)."""
        with self._lock:
            self._callbacks.setdefault(kind, []).append(callback)
            if self._thread is None:
                # from the session's start (at most the ring's last 1024 events): the servo
                # ticks while the application is still setting up (a cold cache can take a
                # second), and the first contact must not be lost to that
                self._cursor = 0
                self._thread = threading.Thread(target=self._run, name="hapticsdk-events", daemon=True)
                self._thread.start()

    def remove(self, kind: str, callback: Callable[["SessionEvent"], Any]) -> bool:
        """Unregister ``callback`` for ``kind``; True when it was registered."""
        with self._lock:
            cbs = self._callbacks.get(kind, [])
            if callback in cbs:
                cbs.remove(callback)
                return True
            return False

    def wake(self) -> None:
        """Look at the session now (the session's supervisor calls it when the servo process ends)."""
        self._stop.set()

    def stop(self, timeout: float = 1.0) -> None:
        """End the thread (the session's ``close()``); no callback runs after it returns,
        unless it is called from a callback."""
        self._closing = True
        self._stop.set()
        th = self._thread
        if th is not None and th is not threading.current_thread():
            th.join(timeout)

    def _deliver(self, ev: "SessionEvent") -> None:
        with self._lock:
            cbs = list(self._callbacks.get(ev.kind, ())) + list(self._callbacks.get("*", ()))
        if cbs:
            self.delivered += 1
        for cb in cbs:
            try:
                cb(ev)
            except Exception:  # noqa: BLE001 - an application bug must not end the dispatcher
                self.errors += 1
                _log.exception("session callback %r for %r raised", cb, ev.kind)

    def _run(self) -> None:
        s = self._session
        while True:
            self._stop.wait(DISPATCH_PERIOD_S)
            woken = self._stop.is_set()
            self._stop.clear()
            if self._closing:
                return
            try:
                evs, self._cursor = s._events_since(self._cursor)  # noqa: SLF001
                for ev in evs:
                    self._deliver(ev)
                s._check()  # noqa: SLF001
            except ServoProcessDied as exc:
                self._deliver(s._servo_died_event(exc))  # noqa: SLF001
                return
            except SessionError:
                return  # closed
            except (ValueError, TypeError):
                return  # the shared block was released under us: closed
            if woken and self._closing:
                return
