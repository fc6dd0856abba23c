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
