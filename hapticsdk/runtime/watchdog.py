"""A host-side command deadline per actuator, independent of the servo thread.

A backend whose hardware keeps playing its last command until told otherwise (the
DRV2667 plays a repeat-0 synthesis waveform until GO is cleared) cannot rely on the servo
loop to stop it: a loop stalled in a renderer, a garbage-collection pause, a debugger, a
blocked recorder leaves the output on. :class:`CommandWatchdog` runs a daemon thread per
open actuator. The backend calls :meth:`~CommandWatchdog.feed` after every command it
applied; when no command was fed for longer than the deadline, the thread calls
``on_expire`` (the backend's safe-state write, e.g. DRV2667 standby) while holding the
backend's transport lock, so the write never interleaves with the servo thread's writes.
It then stays quiet until the next :meth:`~CommandWatchdog.feed` re-arms it.

If ``on_expire`` raises (the transport is gone: USB unplugged, serial port closed,
I2C wedged), the failure is counted, handed to ``on_error`` (the backend marks itself
faulted, so the servo thread's next command raises a
:class:`~hapticsdk.errors.DeviceError` and the loop stops every actuator), and never
raised in any thread; the watchdog stays armed and tries again -- the n-th retry
``min(RETRY_MAX_S, deadline * 2**(n-1))`` after the previous failure -- until a write
succeeds (a transient timeout, a link that comes back), a command arrives, or
:meth:`~CommandWatchdog.stop`.

Latency from the last command to the safe-state write: ``deadline_s`` + the thread's
wake-up (it sleeps exactly until the deadline; scheduler latency, typically < 1 ms) + up
to one GIL switch interval (``sys.getswitchinterval()``, 5 ms by default) when the
stalled servo thread is busy in Python code rather than sleeping or blocked + the
write itself. ``stats()`` reports what was measured.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable

_log = logging.getLogger(__name__)

#: longest wait between two retries of a failing safe-state write (s)
RETRY_MAX_S = 1.0
#: longest wait of :meth:`CommandWatchdog.stats` for the backend's lock (s): a holder
#: longer than the watchdog's own retry bound is a stuck transport, not a write in progress
STATS_LOCK_WAIT_S = RETRY_MAX_S


class CommandWatchdog:
    """Call ``on_expire`` when no command was fed for ``deadline_s()`` seconds.

    Args:
        on_expire: the safe-state write; called in the watchdog thread with ``lock`` held.
        deadline_s: the deadline (s), a number or a callable read at every check (so a
            backend can follow the servo period it is told later).
        lock: the backend's transport lock (``threading.RLock``), also held by the
            servo thread around its writes.
        on_error: called with the exception when ``on_expire`` raised (lock held).
        name: thread name (``"watchdog <label>"``).
    """

    def __init__(self, on_expire: Callable[[], None], *, deadline_s: float | Callable[[], float],
                 lock: Any, on_error: Callable[[BaseException], None] | None = None,
                 name: str = "watchdog") -> None:
        self._on_expire = on_expire
        self._deadline = deadline_s if callable(deadline_s) else (lambda v=float(deadline_s): v)
        self._lock = lock
        self._on_error = on_error
        self._name = name
        self._last = time.monotonic()
        self._armed = False
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None
        self.trips = 0
        self.failures = 0
        self._failing = 0
        self.last_error: str | None = None
        #: age of the last command when the safe-state write finished (s), per trip
        self.trip_ages_s: list[float] = []

    @property
    def deadline_s(self) -> float:
        """Time (s) the next command is due before the watchdog stops the actuators."""
        return float(self._deadline())

    @property
    def armed(self) -> bool:
        """Whether the watchdog is watching (it arms with the first command and disarms when
        stopped).
        """
        return self._armed

    def start(self, *, armed: bool = True) -> "CommandWatchdog":
        """Start the thread; ``armed``: the deadline counts from now, else from the
        first :meth:`feed`."""
        if self._thread is not None and self._thread.is_alive():
            return self
        self._stop.clear()
        if armed:
            self.feed()
        self._thread = threading.Thread(target=self._run, name=self._name, daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout: float = 1.0) -> None:
        """Stop the thread (never raises; safe to call from ``close``)."""
        self._stop.set()
        self._wake.set()
        th = self._thread
        if th is not None and th is not threading.current_thread():
            th.join(timeout)
        self._thread = None

    def feed(self, now: float | None = None) -> None:
        """A command was applied now: re-arm and restart the deadline."""
        self._last = time.monotonic() if now is None else float(now)
        self._failing = 0            # a command went through: the link works again
        if not self._armed:
            self._armed = True
            self._wake.set()

    def disarm(self) -> None:
        """The backend is in its safe state by other means (``stop``): nothing to watch
        until the next :meth:`feed`."""
        self._armed = False

    def stats(self) -> dict[str, Any]:
        """Counters as a dict: the deadline (s), trips, stop failures, the last error and
        the ages (s) of the commands that tripped it.
        """
        # read under the backend's lock: a trip (the safe-state write and its count) is one
        # step for a reader, who never sees the actuator stopped with the trip not counted;
        # a lock held for longer than a stats call should wait (a stuck transport) gives
        # the values as they are
        locked = self._lock.acquire(timeout=STATS_LOCK_WAIT_S)
        try:
            ages = list(self.trip_ages_s)
            return {"deadline_s": self.deadline_s, "trips": self.trips, "failures": self.failures,
                    "last_error": self.last_error,
                    "max_trip_age_s": max(ages) if ages else None,
                    "running": self._thread is not None and self._thread.is_alive()}
        finally:
            if locked:
                self._lock.release()

    # ------------------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            if not self._armed:
                self._wake.wait(0.1)
                self._wake.clear()
                continue
            deadline = self.deadline_s
            left = self._last + deadline - time.monotonic()
            if left > 0:
                self._stop.wait(left + 1e-4)
                continue
            with self._lock:  # serialised with the servo thread's writes
                if self._stop.is_set() or not self._armed:
                    continue
                age = time.monotonic() - self._last
                if age <= deadline:          # a command arrived while we waited for the lock
                    continue
                try:
                    self._on_expire()
                except BaseException as exc:  # noqa: BLE001 - never raise in any thread
                    self.last_error = f"{type(exc).__name__}: {exc}"
                    if self._on_error is not None:
                        try:
                            self._on_error(exc)
                        except BaseException:  # noqa: BLE001
                            pass
                    self.failures += 1         # after on_error: a reader seeing it sees the fault
                    # the first failure of a series as an error, the retries quietly
                    _log.log(logging.ERROR if self._failing == 0 else logging.DEBUG,
                             "%s: safe-state write after %.1f ms without a command failed (%d so far; "
                             "retrying, first after %.0f ms, backing off to %.0f s): %s", self._name, age * 1e3,
                             self.failures, deadline * 1e3, RETRY_MAX_S, self.last_error)
                    self._failing += 1
                    # stay armed: try again (a link that comes back, a transient timeout)
                    # until a write succeeds, a command arrives or stop(); the n-th retry
                    # waits min(RETRY_MAX_S, deadline * 2**(n-1))
                    delay = min(RETRY_MAX_S, deadline * 2.0 ** min(self._failing - 1, 30))
                    self._last = time.monotonic() + delay - deadline
                    continue
                self._armed = False
                self.trips += 1
                if self._failing:
                    _log.warning("%s: safe-state write succeeded after %d failed attempts", self._name,
                                 self._failing)
                    self._failing = 0
                self.trip_ages_s.append(time.monotonic() - self._last)
                if len(self.trip_ages_s) > 1024:
                    del self.trip_ages_s[:512]
