"""Servo death puts the devices in their safe state from the application's side.

A live session (:class:`~hapticsdk.runtime.session.Session`, ``isolation="process"``)
runs the servo in its own process, which opens the devices. If that process dies without
its stop path (SIGKILL, the OOM killer, a crash in native code), nothing in it can write
a standby any more: the piezo went quiet only when the DRV2667's synthesis sequence ran
out, and the serial bridge's firmware watchdog turned the boost off 250 ms later.

:class:`ServoSupervisor` is a thread of the application that waits on the servo process's
sentinel (a file descriptor the kernel makes readable the moment the process is gone:
no polling period). It is the session's one watcher of the servo process: it reaps the
process at once (``waitpid``; the session's own liveness checks ask it, so there is one
``waitpid`` caller and a dead servo never stays a zombie), then does what follows below,
then calls ``on_exit`` (the session wakes its callback dispatcher). The kernel closes the
dead process's descriptors, releasing the
serial port or the USB interface it held; the supervisor then reopens each device's
transport and writes its safe state, through the actuator class's ``standby_detached``
hook (``hapticsdk_roughness``'s DRV2667 backends: open the bus, CONTROL2 = STANDBY,
close; nothing else is written). Actuators without the hook are simulated or have a
safe state of their own (a device-side servo thread's stale-command rule); they are
listed as such.

When the application closes the session, :meth:`ServoSupervisor.expect_exit` is called
first: a servo that exits after its own stop path is not reopened.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

__all__ = ["ServoSupervisor", "SupervisorReport", "HOOK"]

_log = logging.getLogger(__name__)

#: the actuator method the supervisor calls on a fresh instance (never opened) built with
#: the options the servo used: reopen the transport, write the safe state, close
HOOK = "standby_detached"


@dataclass
class SupervisorReport:
    """What the supervisor did after the servo died.

    Attributes:
        died_at: ``time.monotonic()`` when the sentinel fired.
        standby: role -> seconds from ``died_at`` to the end of its standby write.
        failed: role -> why its standby could not be written.
        no_hook: roles whose actuator has no ``standby_detached`` hook (simulated or
            safe by itself).
    """

    died_at: float
    standby: dict[str, float] = field(default_factory=dict)
    failed: dict[str, str] = field(default_factory=dict)
    no_hook: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (times in ms)."""
        return {"standby_ms": {r: t * 1e3 for r, t in self.standby.items()}, "failed": dict(self.failed),
                "no_hook": list(self.no_hook)}


class ServoSupervisor:
    """Watch a servo process: reap it the moment it ends; on an unexpected exit, put every
    device in standby.

    Args:
        process: the servo's :class:`multiprocessing.Process` (started).
        devices: role -> ``(actuator name, options)``, as the servo opened them.
        retry_s: how long to keep trying to reopen a transport the dead process still
            held (the kernel releases it as it reaps the process's files; normally at once).
        on_exit: called (no arguments) on the supervisor thread after the process was
            reaped and, when its exit was unexpected, the standby written.
    """

    def __init__(self, process: Any, devices: Mapping[str, tuple[str, Mapping[str, Any]]], *,
                 retry_s: float = 0.25, on_exit: Callable[[], Any] | None = None) -> None:
        self._process = process
        self._devices = {r: (n, dict(o)) for r, (n, o) in devices.items()}
        self._retry_s = float(retry_s)
        self._on_exit = on_exit
        self._expected = threading.Event()
        #: set once the process is reaped (or cannot be waited on): it is not running
        self._exited = threading.Event()
        self.report: SupervisorReport | None = None
        self.done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="hapticsdk-supervisor", daemon=True)
        self._thread.start()

    def expect_exit(self) -> None:
        """The application is closing the session: the servo's exit is expected."""
        self._expected.set()

    def servo_alive(self) -> bool:
        """Whether the servo process still runs (False once reaped)."""
        return not self._exited.is_set()

    def wait_exit(self, timeout: float | None = None) -> bool:
        """Wait until the process is reaped; True then, False after ``timeout`` s."""
        return self._exited.wait(timeout)

    def is_watcher(self) -> bool:
        """Whether the calling thread is the supervisor's own."""
        return threading.current_thread() is self._thread

    def stop(self, timeout: float = 1.0) -> None:
        """After :meth:`expect_exit` and the process's end: wait for the thread to finish."""
        self._expected.set()
        if not self.is_watcher():
            self._thread.join(timeout)

    def _run(self) -> None:
        from multiprocessing.connection import wait
        try:
            try:
                sentinel = self._process.sentinel
            except (AttributeError, ValueError):
                return
            self._prepare()  # classes loaded and instances built now, not after the death
            try:
                wait([sentinel])
                died = time.monotonic()
                self._process.join()  # reap it now: the one waitpid caller
            except (ValueError, OSError, AssertionError):
                return
        finally:
            self._exited.set()
        if not self._expected.is_set():
            self.report = self.standby_all(died)
        self.done.set()
        if self._on_exit is not None:
            self._on_exit()

    def _prepare(self) -> None:
        """Per role: the actuator class, and an instance (never opened) when it has the hook."""
        from ..plugins import registry
        self._prepared: dict[str, tuple[Any, Any]] = {}
        for role, (name, opts) in self._devices.items():
            try:
                cls = registry("actuator").load(name)
                inst = cls(**opts) if callable(getattr(cls, HOOK, None)) else None
            except Exception:  # noqa: BLE001 - standby_all retries and reports it
                continue
            self._prepared[role] = (cls, inst)

    def standby_all(self, died: float) -> SupervisorReport:
        """Reopen every device the servo held and write its safe state."""
        from ..plugins import registry
        rep = SupervisorReport(died_at=died)
        prepared = getattr(self, "_prepared", {})
        for role, (name, opts) in sorted(self._devices.items()):
            try:
                cls, act = prepared[role] if role in prepared else (registry("actuator").load(name), None)
            except Exception as exc:  # noqa: BLE001 - reported, the others still tried
                rep.failed[role] = f"{type(exc).__name__}: {exc}"
                continue
            if not callable(getattr(cls, HOOK, None)):
                rep.no_hook.append(role)
                continue
            last: BaseException | None = None
            while True:
                try:
                    act = act if act is not None else cls(**opts)
                    getattr(act, HOOK)()
                    rep.standby[role] = time.monotonic() - died
                    break
                except Exception as exc:  # noqa: BLE001 - e.g. the port not yet released: retried
                    last = exc
                if time.monotonic() - died > self._retry_s:
                    rep.failed[role] = f"{type(last).__name__}: {last}"
                    break
                time.sleep(0.001)
        if rep.failed:
            _log.error("servo died; standby from the application failed for %s", rep.failed)
        else:
            _log.warning("servo died; the application put %s in standby (%s)", sorted(rep.standby),
                         ", ".join(f"{r} {t * 1e3:.1f} ms" for r, t in rep.standby.items()))
        return rep
