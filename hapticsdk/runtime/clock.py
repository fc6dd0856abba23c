"""Clocks for the servo loop: the machine's monotonic clock with a hybrid
sleep-then-spin wait, and a simulated clock for deterministic timing tests.

A clock has ``now() -> float`` (s), ``wait_until(deadline)`` and ``work(tick, seconds)``;
``work`` is where a simulated clock charges the compute time of a tick (and any stall
injected by a test). On the real clock the compute has already taken real time, so
``work`` does nothing.

Also here: :func:`thread_cpu_clock_cost_s` (cost of reading the servo thread's CPU-time
clock) and :class:`RealtimeSettings` / :func:`apply_realtime`, the optional OS options
of the servo thread (CPU pinning, ``SCHED_FIFO``, GC freeze, ``mlockall``) that report
their outcome instead of raising.
"""

from __future__ import annotations

import errno
import functools
import logging
import os
import platform
import sys
import time
from dataclasses import dataclass, fields
from typing import Any, Callable, Mapping

from ..errors import ValidationError
from .rtkit import _rtprio_limit

_log = logging.getLogger(__name__)


class MonotonicClock:
    """``time.perf_counter`` with a hybrid wait: sleep while more than ``spin_s`` remains
    (sleeping half the remaining time each round), then busy-wait to the deadline.

    ``serve`` (optional): called before each sleep, to do work in time that would
    otherwise be slept (a live session's servo reads its command pipe there, so a
    command is taken up within one sleep of arriving); the wait then goes on from
    wherever ``serve`` left the clock, and returns at once if it used up the time.

    ``busy_share`` (optional, 0 < share <= 1): the largest share of each interval from
    one return of :meth:`wait_until` to its next deadline that the thread may spend on
    the CPU, its own work (the tick) and the spin together; the spin is cut to what is
    left. Default (None): :func:`rt_busy_share` of the waiting thread, read at its first
    wait: no cap at normal priority; under ``SCHED_FIFO`` / ``SCHED_RR``, half the
    real-time bandwidth the kernel grants. A real-time thread that spins through more
    than that bandwidth is throttled: stopped for the rest of the kernel's period (at
    4 kHz, a 200 us spin after a 20 us tick is 88 % of every period; the servo stopped
    for 30-50 ms once a second). :meth:`reset` reads it again (a new run).
    """

    simulated = False

    def __init__(self, spin_s: float = 200e-6, serve: Callable[[], None] | None = None,
                 busy_share: float | None = None) -> None:
        self.spin_s = float(spin_s)
        self.serve = serve
        if busy_share is not None and not (isinstance(busy_share, (int, float)) and not isinstance(busy_share, bool)
                                           and 0.0 < busy_share <= 1.0):
            raise ValidationError(f"busy_share must be in (0, 1] or None, got {busy_share!r}", field="busy_share")
        self._busy_share_set = None if busy_share is None else float(busy_share)
        self.reset()

    def reset(self) -> None:
        """Start afresh: the busy share is read again at the next wait (the thread's
        scheduling policy may have changed), and the first wait has no interval yet."""
        self.busy_share: float | None = self._busy_share_set
        self._resolved = self._busy_share_set is not None
        self._t_ret: float | None = None

    def now(self) -> float:
        """Current time (s) of :func:`time.perf_counter`."""
        return time.perf_counter()

    def wait_until(self, deadline: float) -> None:
        """Return at ``deadline`` (s, on :meth:`now`'s clock): sleep while far from it
        (calling ``serve`` before each sleep), then spin the last ``spin_s``, less
        where the busy share would be exceeded; returns at once when already past.
        """
        pc = time.perf_counter
        spin = self.spin_s
        if not self._resolved:
            self.busy_share = rt_busy_share()
            self._resolved = True
        share = self.busy_share
        t_ret = self._t_ret
        if share is not None and t_ret is not None:
            # on the CPU since the last return: the tick; what the share leaves of this
            # interval is the most the spin may take
            now = pc()
            left = share * (deadline - t_ret) - (now - t_ret)
            if left < spin:
                spin = left if left > 0.0 else 0.0
        serve = self.serve
        while True:
            remaining = deadline - pc()
            if remaining <= spin:
                break
            if serve is not None:
                serve()
                remaining = deadline - pc()
                if remaining <= spin:
                    break
            time.sleep((remaining - spin) * 0.5 if remaining > 2 * spin else remaining - spin)
        while pc() < deadline:
            pass
        self._t_ret = pc()

    def work(self, tick: int, seconds: float) -> None:
        """Real time already passed while the tick computed."""


#: The share of the kernel's real-time bandwidth a paced real-time thread takes at most
#: (:func:`rt_busy_share`): half, the other half left to the other real-time tasks of
#: the CPU (the threaded interrupt handlers run at ``SCHED_FIFO`` 50 and share the same
#: bandwidth) and to the sleeps' own system calls. docs/runtime.md, "Real-time scheduling".
RT_BANDWIDTH_SHARE = 0.5

#: Linux's default real-time bandwidth, ``sched_rt_runtime_us / sched_rt_period_us``
#: (950 000 / 1 000 000), where ``/proc`` does not tell.
_RT_BANDWIDTH_DEFAULT = 0.95
_RT_RUNTIME = "/proc/sys/kernel/sched_rt_runtime_us"
_RT_PERIOD = "/proc/sys/kernel/sched_rt_period_us"


def rt_bandwidth() -> float:
    """The share of each period of the kernel's real-time throttling that real-time tasks
    may run (``/proc/sys/kernel/sched_rt_runtime_us`` over ``sched_rt_period_us``): 1.0
    where throttling is off (runtime ``-1``), Linux's default 0.95 where ``/proc`` does
    not tell."""
    try:
        with open(_RT_RUNTIME) as f:
            runtime = int(f.read().strip())
        with open(_RT_PERIOD) as f:
            period = int(f.read().strip())
    except (OSError, ValueError):
        return _RT_BANDWIDTH_DEFAULT
    if runtime < 0 or period <= 0:
        return 1.0
    return min(runtime / period, 1.0)


def rt_busy_share() -> float | None:
    """The busy share of :class:`MonotonicClock` for the calling thread: None (no cap) at
    normal priority or where the policy cannot be read; under ``SCHED_FIFO`` or
    ``SCHED_RR``, :data:`RT_BANDWIDTH_SHARE` x :func:`rt_bandwidth` (0.475 with Linux's
    defaults)."""
    rt = {getattr(os, "SCHED_FIFO", None), getattr(os, "SCHED_RR", None)} - {None}
    try:
        policy = os.sched_getscheduler(0)
    except (AttributeError, OSError):
        return None
    if policy not in rt:
        return None
    return RT_BANDWIDTH_SHARE * rt_bandwidth()


class SimulatedClock:
    """A clock that only moves when told to: ``wait_until`` jumps to the deadline and
    ``work`` charges a fixed compute cost per tick plus any injected stall.

    Args:
        compute_s: simulated compute time of every tick (s).
        stalls: tick index -> extra seconds that tick takes (a late tick).
        wake_latency_s: how late every wake-up is (s), like a scheduler's latency.
    """

    simulated = True

    def __init__(self, *, compute_s: float = 20e-6, stalls: Mapping[int, float] | None = None,
                 wake_latency_s: float = 0.0, start: float = 0.0) -> None:
        self.t = float(start)
        self.compute_s = float(compute_s)
        self.stalls = dict(stalls or {})
        self.wake_latency_s = float(wake_latency_s)

    def now(self) -> float:
        """Current simulated time (s)."""
        return self.t

    def wait_until(self, deadline: float) -> None:
        """Jump to ``deadline`` (plus the wake-up latency) when it is ahead; nothing when
        already past.
        """
        if deadline > self.t:
            self.t = deadline + self.wake_latency_s

    def work(self, tick: int, seconds: float) -> None:
        """Charge a tick's computation: the fixed compute time plus any stall injected for
        tick ``tick``; ``seconds`` (what the tick measured) is ignored.
        """
        self.t += self.compute_s + self.stalls.get(tick, 0.0)


# ----------------------------------------------------------------------
# CPU time of the servo thread
# ----------------------------------------------------------------------

def thread_cpu_clock_cost_s(samples: int = 256) -> float:
    """Wall time (s) of one ``time.thread_time_ns()`` call on this machine (median of
    ``samples`` batched readings; on Linux it is a system call, not a vDSO read). The
    loop reads it twice per tick, so the per-tick cost of CPU-time measurement is about
    twice this."""
    tt = time.thread_time_ns
    pc = time.perf_counter
    per: list[float] = []
    batch = 16
    for _ in range(max(1, samples // batch)):
        t0 = pc()
        for _ in range(batch):
            tt()
        per.append((pc() - t0) / batch)
    per.sort()
    return per[len(per) // 2]


# ----------------------------------------------------------------------
# Real-time options of the servo thread (goal 14)
# ----------------------------------------------------------------------

@dataclass(frozen=True)
class RealtimeSettings:
    """Operating-system options applied to the thread that runs
    :meth:`~hapticsdk.runtime.ServoLoop.run`, for the duration of the run.

    Every option is opt-in except the GC freeze (the loop always collects and disables
    the garbage collector). None of them raises when the OS refuses: the outcome is a
    string in ``LoopReport.rt`` (``"applied: ..."``, ``"refused: <reason>"``,
    ``"unavailable: <reason>"`` or ``"off"``), and whatever was applied is undone after
    the run.

    Attributes:
        cpu: pin the servo thread to this CPU index (``os.sched_setaffinity``); None = off.
        fifo_priority: request ``SCHED_FIFO`` at this priority (1..99,
            ``os.sched_setscheduler``); None = off. Needs ``CAP_SYS_NICE`` or an
            ``RLIMIT_RTPRIO`` at least this high. A FIFO thread that never sleeps holds
            its CPU (the kernel leaves others 5 % by default): use it with paced
            (``realtime=True``) loops. ``"auto"``: priority :data:`AUTO_FIFO_PRIORITY`
            where the process may (root, ``CAP_SYS_NICE``), else the highest its
            ``RLIMIT_RTPRIO`` allows, else normal scheduling; reported like the others
            (the default of a process-isolated :class:`~hapticsdk.runtime.session.Session`).
        gc_freeze: ``gc.freeze()`` the surviving objects before the loop (default on;
            GC is disabled in the loop regardless).
        mlockall: lock the process's current and future pages in RAM (``mlockall``
            through ctypes, Linux only); undone with ``munlockall`` after the run.
    """

    cpu: int | None = None
    fifo_priority: int | str | None = None
    gc_freeze: bool = True
    mlockall: bool = False

    def __post_init__(self) -> None:
        if self.cpu is not None and not (isinstance(self.cpu, int) and not isinstance(self.cpu, bool)
                                         and self.cpu >= 0):
            raise ValidationError(f"cpu must be a CPU index >= 0 or None, got {self.cpu!r}", field="cpu")
        if self.fifo_priority is not None and self.fifo_priority != "auto" and not (
                isinstance(self.fifo_priority, int) and not isinstance(self.fifo_priority, bool)
                and 1 <= self.fifo_priority <= 99):
            raise ValidationError(f"fifo_priority must be in 1..99, 'auto' or None, got {self.fifo_priority!r}",
                                  field="fifo_priority")

    @classmethod
    def coerce(cls, value: RealtimeSettings | Mapping[str, Any] | None) -> RealtimeSettings:
        """Settings from an instance, a mapping of the same field names, or None (defaults)."""
        if value is None:
            return cls()
        if isinstance(value, cls):
            return value
        if isinstance(value, Mapping):
            unknown = sorted(set(value) - {f.name for f in fields(cls)})
            if unknown:
                raise ValidationError(f"unknown realtime option(s) {unknown}; known: cpu, fifo_priority, "
                                      f"gc_freeze, mlockall", field="rt")
            return cls(**dict(value))
        raise ValidationError(f"rt must be RealtimeSettings, a mapping or None, got {type(value).__name__}",
                              field="rt")

    @property
    def requested(self) -> bool:
        """True when any OS option beyond the default GC handling is asked for."""
        return self.cpu is not None or self.fifo_priority is not None or self.mlockall


#: ``SCHED_FIFO`` priority of ``fifo_priority="auto"``: above every normal task and the
#: default priority of user real-time threads (JACK, PipeWire ask for 20-88), below the
#: kernel's threaded interrupt handlers (50) so a device's interrupts still run first.
AUTO_FIFO_PRIORITY = 40


def _os_error(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.errno is not None:
        return f"{errno.errorcode.get(exc.errno, exc.errno)} ({os.strerror(exc.errno)})"
    return f"{type(exc).__name__}: {exc}"


def _libc() -> Any:
    import ctypes
    import ctypes.util
    return ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)


def _is_linux() -> bool:
    return sys.platform.startswith("linux")


def _mcl_flags() -> tuple[int, int]:
    """``MCL_CURRENT``, ``MCL_FUTURE`` of this Linux architecture."""
    m = platform.machine().lower()
    if m.startswith(("ppc", "powerpc", "sparc")):
        return 0x2000, 0x4000
    return 1, 2


def apply_realtime(settings: RealtimeSettings) -> tuple[dict[str, str], Callable[[], None]]:
    """Apply the OS options of ``settings`` to the calling thread (and, for mlockall,
    the process); never raises.

    Returns ``(status, restore)``: ``status`` maps ``cpu_affinity``, ``rt_priority`` and
    ``mlockall`` to ``"off"``, ``"applied: ..."``, ``"refused: <reason>"`` or
    ``"unavailable: <reason>"``; ``restore()`` undoes what was applied (also never
    raises). GC handling is the loop's (key ``gc``).
    """
    status: dict[str, str] = {"cpu_affinity": "off", "rt_priority": "off", "mlockall": "off"}
    undo: list[Callable[[], None]] = []

    # (a) pin the thread to one CPU
    if settings.cpu is not None:
        if not (hasattr(os, "sched_setaffinity") and hasattr(os, "sched_getaffinity")):
            status["cpu_affinity"] = "unavailable: os.sched_setaffinity is not on this platform"
        else:
            try:
                before = os.sched_getaffinity(0)
                if settings.cpu not in before:
                    status["cpu_affinity"] = (f"refused: cpu {settings.cpu} is not in this thread's allowed "
                                              f"set {sorted(before)}")
                else:
                    os.sched_setaffinity(0, {settings.cpu})
                    undo.append(functools.partial(os.sched_setaffinity, 0, before))
                    status["cpu_affinity"] = f"applied: cpu {settings.cpu} (was {sorted(before)})"
            except Exception as exc:  # never raise for an OS refusal
                status["cpu_affinity"] = f"refused: {_os_error(exc)}"

    # (b) SCHED_FIFO priority
    if settings.fifo_priority is not None:
        if not (hasattr(os, "sched_setscheduler") and hasattr(os, "SCHED_FIFO")):
            status["rt_priority"] = "unavailable: os.sched_setscheduler / SCHED_FIFO is not on this platform"
        else:
            auto = settings.fifo_priority == "auto"
            prio = AUTO_FIFO_PRIORITY if auto else int(settings.fifo_priority)  # type: ignore[arg-type]
            try:
                pol0 = os.sched_getscheduler(0)
                par0 = os.sched_getparam(0)
                lo = os.sched_get_priority_min(os.SCHED_FIFO)
                hi = os.sched_get_priority_max(os.SCHED_FIFO)
                if auto:
                    prio = max(lo, min(prio, hi))
                if not lo <= prio <= hi:
                    status["rt_priority"] = (f"refused: priority {prio} outside this "
                                             f"system's SCHED_FIFO range {lo}..{hi}")
                else:
                    try:
                        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(prio))
                    except PermissionError:
                        # auto: an unprivileged process may still go as high as its limit
                        limit = _rtprio_limit() if auto else None
                        if not (limit is not None and lo <= limit < prio):
                            raise
                        prio = limit
                        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(prio))
                    undo.append(functools.partial(os.sched_setscheduler, 0, pol0, par0))
                    status["rt_priority"] = f"applied: SCHED_FIFO {prio}" + (" (auto)" if auto else "")
            except Exception as exc:
                hint = (" (needs CAP_SYS_NICE or RLIMIT_RTPRIO >= the priority)"
                        if isinstance(exc, PermissionError) else "")
                then = "; the servo runs at normal priority" if auto else ""
                status["rt_priority"] = f"refused: {_os_error(exc)}{hint}{then}"
                if auto and isinstance(exc, PermissionError):
                    # a normal user: ask RealtimeKit over D-Bus (hapticsdk.runtime.rtkit)
                    from .rtkit import make_thread_realtime
                    pol0, par0 = os.sched_getscheduler(0), os.sched_getparam(0)
                    got, how = make_thread_realtime(prio)
                    if got is not None:
                        # RealtimeKit sets SCHED_RESET_ON_FORK, which an unprivileged thread
                        # may not clear: keep it when going back
                        keep = getattr(os, "SCHED_RESET_ON_FORK", 0)
                        undo.append(functools.partial(os.sched_setscheduler, 0, pol0 | keep, par0))
                        status["rt_priority"] = f"applied: {how} (auto; the OS refused SCHED_FIFO directly)"
                    else:
                        status["rt_priority"] = (f"refused: {_os_error(exc)}{hint}; {how}; the servo runs at "
                                                 f"normal priority")

    # (d) lock memory
    if settings.mlockall:
        if not _is_linux():
            status["mlockall"] = f"unavailable: mlockall is used on Linux only (platform {sys.platform})"
        else:
            try:
                import ctypes
                libc = _libc()
                cur, fut = _mcl_flags()
                if libc.mlockall(cur | fut) != 0:
                    e = ctypes.get_errno()
                    hint = (" (needs CAP_IPC_LOCK or RLIMIT_MEMLOCK >= the process size)"
                            if e in (errno.EPERM, errno.ENOMEM) else "")
                    status["mlockall"] = f"refused: {errno.errorcode.get(e, e)} ({os.strerror(e)}){hint}"
                else:
                    undo.append(lambda: libc.munlockall())
                    status["mlockall"] = "applied: MCL_CURRENT | MCL_FUTURE"
            except Exception as exc:
                status["mlockall"] = f"refused: {_os_error(exc)}"

    def restore() -> None:
        for fn in reversed(undo):
            try:
                fn()
            except Exception as exc:  # restoring is best effort
                _log.warning("could not undo a realtime option: %s", exc)
        undo.clear()

    return status, restore
