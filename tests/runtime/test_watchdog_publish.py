"""A watchdog trip is one step for a reader of ``stats()``: the safe state and its count.

The class of race this guards (issue 29): a test (or an application) waits until the
device is in its safe state, then reads the trip count; the count must already be there.
"""

from __future__ import annotations

import threading
import time

from hapticsdk.runtime.watchdog import CommandWatchdog


def test_a_reader_that_sees_the_safe_state_sees_the_trip_counted():
    lock = threading.RLock()
    safe = threading.Event()

    def on_expire():
        safe.set()            # observable to other threads at once ...
        time.sleep(0.05)      # ... while the write (and the lock) is still in progress

    wd = CommandWatchdog(on_expire, deadline_s=0.01, lock=lock, name="watchdog publish-test").start()
    try:
        assert safe.wait(10.0), "the watchdog never tripped"
        assert wd.stats()["trips"] == 1
    finally:
        wd.stop()


def test_stats_answers_while_the_lock_is_stuck():
    lock = threading.RLock()
    wd = CommandWatchdog(lambda: None, deadline_s=60.0, lock=lock, name="watchdog stuck-test")
    held = threading.Event()
    release = threading.Event()
    letting_go = threading.Event()

    def holder():
        with lock:
            held.set()
            release.wait(30.0)
            letting_go.set()  # set before the lock is released
    th = threading.Thread(target=holder, daemon=True)
    th.start()
    try:
        assert held.wait(10.0)
        assert wd.stats()["trips"] == 0     # after STATS_LOCK_WAIT_S, without the lock
        # ... while the lock was still held (a stats() that waits for the lock returns
        # only after the holder let go, at 30 s)
        assert not letting_go.is_set()
    finally:
        release.set()
        th.join(10.0)


def test_a_failing_safe_state_write_is_retried_on_the_doubling_schedule_then_trips_once():
    """The n-th retry of a failing write comes min(RETRY_MAX_S, deadline x 2^(n-1)) after
    the failure before it (module docs): with a 0.3 s deadline, 0.3 s, then 0.6 s. A thread
    is never early, so each gap is at least its delay; the first is also below the next
    step of the schedule (0.6 s: 300 ms of slack for a busy machine's scheduler, where a
    retry one deadline late would come at 0.9 s). The third write succeeds: one trip, two
    failures counted, and the watchdog is quiet until fed again."""
    from hapticsdk.runtime.watchdog import RETRY_MAX_S
    calls: list[float] = []
    done = threading.Event()

    def on_expire():
        calls.append(time.monotonic())
        if len(calls) < 3:
            raise OSError("link down")
        done.set()

    deadline = 0.3
    assert RETRY_MAX_S >= 2 * deadline   # the schedule below is not capped
    wd = CommandWatchdog(on_expire, deadline_s=deadline, lock=threading.RLock(), name="watchdog retry-test")
    t0 = time.monotonic()
    wd.start()
    try:
        assert done.wait(20.0), f"the write was tried {len(calls)} times"
        time.sleep(0.05)
        st = wd.stats()
    finally:
        wd.stop()
    first, g1, g2 = calls[0] - t0, calls[1] - calls[0], calls[2] - calls[1]
    assert first >= deadline
    assert deadline <= g1 < 2 * deadline, (g1, g2)
    assert g2 >= 2 * deadline, (g1, g2)
    assert st["trips"] == 1 and st["failures"] == 2 and st["last_error"] == "OSError: link down"
    assert not wd.armed and len(calls) == 3
