"""Real-time scheduling for normal users through RealtimeKit (D-Bus).

Desktop Linux grants real-time priority to unprivileged processes through RealtimeKit
(``rtkit-daemon``, service ``org.freedesktop.RealtimeKit1`` on the system bus): PipeWire
and PulseAudio get theirs this way. The servo asks it when the OS refuses
``SCHED_FIFO`` directly (no root, no ``CAP_SYS_NICE``, ``RLIMIT_RTPRIO`` 0):

1. read the daemon's properties ``MaxRealtimePriority`` (default 20), ``RTTimeUSecMax``
   (default 200 000 us) and ``MinNiceLevel``;
2. set the process's ``RLIMIT_RTTIME`` to ``RTTimeUSecMax`` (the daemon refuses a
   process without it: the kernel then stops a real-time thread that runs that long
   without sleeping, a guard the servo never meets since it sleeps every period);
3. call ``MakeThreadRealtime(thread id, priority)`` with the priority asked, at most
   ``MaxRealtimePriority``. The daemon (after asking polkit, action
   ``org.freedesktop.RealtimeKit1.acquire-real-time``) gives the thread ``SCHED_RR``
   with ``SCHED_RESET_ON_FORK``.

The D-Bus client is ``jeepney`` (pure Python; the optional extra ``hapticsdk[rt]``).
Every failure is returned as a reason, never raised: no client library, no system bus,
no daemon, polkit's refusal, the daemon's own refusal (its D-Bus error name and text).
The bus is ``DBUS_SYSTEM_BUS_ADDRESS`` when set (the tests start their own), else the
system's.
"""

from __future__ import annotations

import os
from typing import Any

SERVICE = "org.freedesktop.RealtimeKit1"
PATH = "/org/freedesktop/RealtimeKit1"
#: how long a call may wait for the daemon (s): it answers in milliseconds; a bus with
#: no daemon answers at once with an error
TIMEOUT_S = 2.0



def _rt_hint() -> str:
    """How to install the ``rt`` extra from where this SDK was installed."""
    from ..install_hints import pip_hint
    return pip_hint("hapticsdk", "rt")

def _address() -> Any:
    from jeepney import DBusAddress
    return DBusAddress(PATH, bus_name=SERVICE, interface=SERVICE)


def _connect() -> Any:
    from jeepney.io.blocking import open_dbus_connection
    return open_dbus_connection(bus="SYSTEM")


def _error(reply: Any) -> str | None:
    from jeepney import MessageType
    if reply.header.message_type == MessageType.error:
        from jeepney import HeaderFields
        name = reply.header.fields.get(HeaderFields.error_name, "error")
        text = reply.body[0] if reply.body else ""
        return f"{name}: {text}"
    return None


def properties(conn: Any = None) -> dict[str, Any]:
    """The daemon's ``MaxRealtimePriority``, ``MinNiceLevel`` and ``RTTimeUSecMax``,
    or ``{"error": reason}``."""
    try:
        from jeepney import Properties
    except ImportError:
        return {"error": f"the D-Bus client jeepney is not installed ({_rt_hint()})"}
    try:
        own = conn is None
        conn = _connect() if own else conn
    except Exception as exc:  # noqa: BLE001 - no bus
        return {"error": f"no system D-Bus ({type(exc).__name__}: {exc})"}
    try:
        out: dict[str, Any] = {}
        for name in ("MaxRealtimePriority", "MinNiceLevel", "RTTimeUSecMax"):
            reply = conn.send_and_get_reply(Properties(_address()).get(name), timeout=TIMEOUT_S)
            err = _error(reply)
            if err:
                return {"error": f"RealtimeKit: {err}"}
            out[name] = int(reply.body[0][1])
        return out
    except Exception as exc:  # noqa: BLE001
        return {"error": f"RealtimeKit: {type(exc).__name__}: {exc}"}
    finally:
        if own:
            try:
                conn.close()
            except Exception:  # noqa: BLE001
                pass


def make_thread_realtime(priority: int, tid: int | None = None) -> tuple[int | None, str]:
    """Ask RealtimeKit to make thread ``tid`` (default: the calling thread) real-time
    at ``priority`` (lowered to the daemon's maximum). Returns ``(priority granted or
    None, what happened)``; never raises."""
    import resource
    import threading
    try:
        import jeepney  # noqa: F401
    except ImportError:
        return None, f"RealtimeKit not asked: the D-Bus client jeepney is not installed ({_rt_hint()})"
    try:
        conn = _connect()
    except Exception as exc:  # noqa: BLE001
        return None, f"RealtimeKit not reached: no system D-Bus ({type(exc).__name__}: {exc})"
    try:
        props = properties(conn)
        if "error" in props:
            return None, props["error"]
        prio = max(1, min(int(priority), props["MaxRealtimePriority"]))
        rttime = props["RTTimeUSecMax"]
        soft, hard = resource.getrlimit(resource.RLIMIT_RTTIME)
        if hard == resource.RLIM_INFINITY or hard > rttime or soft > rttime or soft == resource.RLIM_INFINITY:
            resource.setrlimit(resource.RLIMIT_RTTIME, (rttime, rttime))
        from jeepney import new_method_call
        tid = threading.get_native_id() if tid is None else int(tid)
        reply = conn.send_and_get_reply(new_method_call(_address(), "MakeThreadRealtime", "tu", (tid, prio)),
                                        timeout=TIMEOUT_S)
        err = _error(reply)
        if err:
            return None, f"RealtimeKit refused: {err}"
        return prio, (f"SCHED_RR {prio} via RealtimeKit (its maximum {props['MaxRealtimePriority']}, "
                      f"RLIMIT_RTTIME {rttime} us)")
    except Exception as exc:  # noqa: BLE001 - reported, never raised
        return None, f"RealtimeKit: {type(exc).__name__}: {exc}"
    finally:
        try:
            conn.close()
        except Exception:  # noqa: BLE001
            pass


def spare_cpu() -> int | None:
    """A CPU for the servo where there is one to spare: the last CPU this process may
    run on, when it may run on at least three (one for the servo, two left for the
    application and the rest of the machine); None otherwise (with two CPUs, pinning
    the servo would leave the application one CPU shared with everything else, and
    the real-time priority alone already lets the servo preempt it)."""
    try:
        cpus = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return None
    return cpus[-1] if len(cpus) >= 3 else None


def _os_fifo_allowed() -> str:
    """Whether this process may set ``SCHED_FIFO`` itself (tried on a short-lived
    thread of its own, then undone)."""
    import threading
    out: list[str] = []

    def probe() -> None:
        try:
            pol, par = os.sched_getscheduler(0), os.sched_getparam(0)
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
            os.sched_setscheduler(0, pol, par)
            out.append("granted")
        except (AttributeError, OSError) as exc:
            out.append(f"refused ({type(exc).__name__}: {exc})")

    th = threading.Thread(target=probe, name="hapticsdk-rt-probe")
    th.start()
    th.join()
    return out[0] if out else "unknown"


def _rtprio_limit() -> int | None:
    """The soft ``RLIMIT_RTPRIO`` of this process (None where unknown)."""
    try:
        import resource
        soft = resource.getrlimit(resource.RLIMIT_RTPRIO)[0]
    except (ImportError, AttributeError, OSError, ValueError):
        return None
    return 99 if soft == getattr(resource, "RLIM_INFINITY", -1) else int(soft)


def machine_report() -> dict[str, Any]:
    """What this machine grants the servo (``hapticsdk doctor``): SCHED_FIFO directly,
    ``RLIMIT_RTPRIO``, RealtimeKit's limits (or why it cannot be asked), the CPUs and
    the one the servo would be pinned to, and how to get more."""
    direct = _os_fifo_allowed()
    rk = properties()
    try:
        cpus = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cpus = []
    how = []
    if not direct.startswith("granted"):
        if "error" in rk:
            how.append("install and start RealtimeKit (Debian/Ubuntu: apt install rtkit; it runs on the system "
                       "D-Bus and grants SCHED_RR up to its --max-realtime-priority to normal users) and "
                       + _rt_hint())
        how.append("or raise RLIMIT_RTPRIO for your user (/etc/security/limits.conf: '<user> - rtprio 40', "
                   "needs an administrator), or run the servo with CAP_SYS_NICE")
    if len(cpus) < 3:
        how.append(f"{len(cpus)} CPU(s): the servo is not pinned (pinning needs a CPU to spare, 3 or more)")
    return {"sched_fifo_directly": direct, "rlimit_rtprio": _rtprio_limit(),
            "realtimekit": rk, "cpus": cpus, "servo_cpu": spare_cpu(), "how_to_get_more": how}
