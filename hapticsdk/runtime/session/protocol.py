"""The shared-memory protocol of a live session: the float64 slots both sides map (a
seqlock-guarded state record, control slots, the event ring, the switch
acknowledgements), the records read from them (:class:`SessionState`,
:class:`SessionEvent`) and the buffer that holds them (a shared-memory segment for a
servo process, a local buffer for a servo thread).

Part of :mod:`hapticsdk.runtime.session`, which re-exports the public names.
"""

from __future__ import annotations

import struct
import time
from dataclasses import dataclass, field
from typing import Any, Mapping, NamedTuple, Sequence


#: the slots viewed as float64 (``memoryview.cast("d")``; typeshed types a memoryview's
#: items as int whatever its format, so the view is typed loosely)
Slots = Any


# -- shared-memory layout (float64 slots) ----------------------------------------------
_SEQ = 0
_STATE = slice(1, 24)
#: a copy of the sequence number after the state: the servo sets it odd *before* it
#: writes the state and even after, slot 0 even after the state (see ``_Servo.run``), so
#: one ascending read of slots 0..24 is consistent when slots 0 and 24 are equal and even
_SEQ_END = 24
#: reads slots 0..24 (sequence number, state, sequence copy) from the buffer's bytes in one call
_read_state = struct.Struct(f"={_SEQ_END + 1}d").unpack_from
_new_tuple = tuple.__new__
(_T, _PX, _PY, _PZ, _VX, _VY, _VZ, _F, _OBJ, _PEN, _TICKS, _OVERRUNS, _SKIPPED, _RERR, _CLAMPS,
 _TICK_US, _TICK_MAX_US, _MISSED, _PUB, _NEAR, _PAUSED_S, _SWITCHES, _SWITCHED_AT) = range(1, 24)
_HEARTBEAT, _STOP, _PAUSE, _STATUS, _PID, _REASON, _READY = range(32, 39)
#: 1 once ``Session()`` has returned: the servo watches the heartbeat from then on. The
#: session's own start-up in the application (the warm-up's table build, which can hold
#: the interpreter lock for long stretches) is not a hung application; the servo
#: watches the application's process throughout
_HB_ARMED = 39
#: vibration channels for the live view (outside the seqlock: a view frame may mix two
#: ticks): up to two (role index, frequency Hz, amplitude) triples, role index -1 unused
_VIB0, _VIB_N = 25, 2
_EV_W = 64
_EV0 = 65
_EV_CAP = 1024
_EV_REC = 6  # t, kind, object id, value, detail (clamps: actuator and field), count
#: acknowledgements of material switches: a ring of (sequence number, tick, servo time,
#: monotonic time of the tick's publication); entry ``seq % _ACK_CAP``
_ACK0 = _EV0 + _EV_CAP * _EV_REC
_ACK_CAP = 256
_ACK_REC = 4
_NSLOTS = _ACK0 + _ACK_CAP * _ACK_REC

# servo status
_STARTING, _RUNNING, _STOPPED, _FAILED = 0.0, 1.0, 2.0, 3.0

#: event kinds (the ``kind`` of a :class:`SessionEvent`)
EVENT_KINDS = ("contact_enter", "contact_leave", "renderer_error", "clamp", "overrun", "skipped_ticks",
               "fault", "material_switched", "app_lost", "signal", "stopped", "paused", "resumed",
               "material_refined", "servo_died")
_KIND = {k: i for i, k in enumerate(EVENT_KINDS)}

_STOP_REASONS = ("", "close", "app_lost", "heartbeat", "signal", "fault", "error")

#: how often the application's heartbeat thread writes (s)
HEARTBEAT_PERIOD_S = 0.01


class SessionState(NamedTuple):
    """The servo's latest published state (a named tuple: built in well under a
    microsecond).

    Attributes:
        t: servo time (s since the servo started).
        position_mm, velocity_mm_s: probe position (mm) and velocity (mm/s), device frame.
        force_n: force sent on the last tick, along the contact normal (N).
        object: name of the object in contact (penetration > 0), or None.
        near: name of the object nearest the probe (the hit test's answer), or None.
        penetration_mm: penetration along that object's normal (mm; < 0 outside).
        ticks, overruns, skipped_ticks, missed_ticks, renderer_errors, clamps,
        material_switches: counts since the servo started.
        tick_us, tick_max_us: compute time of the last tick and the largest so far (us).
        age_s: how long ago the servo published this state (s).
        paused: the session is paused.
        switched_at: ``time.monotonic()`` (s, the machine's clock, the same in both
            processes) when the servo published the first tick that rendered the latest
            material switch; 0.0 before any.
    """

    t: float
    position_mm: tuple[float, float, float]
    velocity_mm_s: tuple[float, float, float]
    force_n: float
    object: str | None
    near: str | None
    penetration_mm: float
    ticks: int
    overruns: int
    skipped_ticks: int
    missed_ticks: int
    renderer_errors: int
    clamps: int
    material_switches: int
    tick_us: float
    tick_max_us: float
    age_s: float
    paused: bool
    switched_at: float


#: limits of an actuator's safety layer a ``clamp`` event can name (``SessionEvent.field``),
#: with the command field each one bounds; other names are reported as ``"other"``
CLAMP_FIELDS = (("max_force_n", "force_n"), ("max_velocity_mm_s", "force_n"),
                ("max_stiffness_n_per_mm", "force_n"), ("max_force_rate_n_per_tick", "force_n"),
                ("negative_amplitude", "amplitude"), ("max_amplitude", "amplitude"),
                ("min_amplitude", "amplitude"), ("frequency_range_hz", "frequency_hz"), ("other", ""))
_CLAMP_INDEX = {k: i for i, (k, _) in enumerate(CLAMP_FIELDS)}
#: a limit that keeps biting is reported at its onset (within 10 ticks), then at most
#: once per this period of servo time per (actuator, limit), and a last time once it has
#: not bitten for as long (s). A clamp that persists is a state, not news: at 1 Hz the
#: 1024-event ring still holds over half a minute of reports with every limit of three
#: actuators biting at once (3 x 9 pairs), where one report per 10 ticks filled it in
#: about 0.4 s and a slow ``events()`` reader lost its contact events (docs/runtime.md)
CLAMP_REPORT_S = 1.0


@dataclass(frozen=True)
class SessionEvent:
    """One event: ``kind`` (one of :data:`EVENT_KINDS`), servo time ``t`` (s), the
    ``object`` it concerns (name, or None) and a ``value`` (a count for counters, the
    signal number for ``signal``, ...).

    ``clamp`` events name the ``actuator`` (its role, e.g. ``"force"``), the safety
    limit that bit (``field``, one of :data:`CLAMP_FIELDS`' names, e.g.
    ``"max_force_n"``), the ``value`` of the bounded command field actually sent on the
    last tick (N, Hz or the actuator's amplitude unit) and how many ticks it bit since
    the last such event (``count``; the servo reports every 10 ticks). ``servo_died``
    (delivered to callbacks, :meth:`Session.on_event`) carries the reason in
    ``message`` and the exit status in ``value`` (NaN when unknown)."""

    t: float
    kind: str
    object: str | None
    value: float
    actuator: str | None = None
    field: str | None = None
    count: int = 0
    message: str | None = None


def _state_from(vals: Sequence[float], names: Mapping[int, str], now: float | None = None) -> SessionState:
    """A :class:`SessionState` from slots 0..24 of the buffer (the sequence number
    first and last) and the object names by id; ``age_s`` against ``now``
    (``time.monotonic()``, read here when None)."""
    (_, t, px, py, pz, vx, vy, vz, f, obj, pen, ticks, ovr, skipped, rerr, clamps, tick_us, tick_max,
     missed, pub, near, paused, switches, switched_at, _) = vals
    # positional, in SessionState's field order (a keyword call costs a cold call more)
    return _new_tuple(SessionState, (
        t, (px, py, pz), (vx, vy, vz), f, names.get(int(obj)) if obj >= 0 else None,
        names.get(int(near)) if near >= 0 else None, pen, int(ticks), int(ovr), int(skipped), int(missed),
        int(rerr), int(clamps), int(switches), tick_us, tick_max,
        (time.monotonic() if now is None else now) - pub, paused != 0.0, switched_at))


class _Buffer:
    """The state/event/control slots: a shared-memory segment (process) or a local
    buffer (thread), viewed as float64."""

    def __init__(self, shared: bool) -> None:
        size = _NSLOTS * 8
        self.shm: Any
        self.name: str | None
        self.mv: Slots
        if shared:
            from multiprocessing import shared_memory
            self.shm = shared_memory.SharedMemory(create=True, size=size)
            self.name = self.shm.name
            self.mv = self.shm.buf.cast("d")
            #: the same slots as bytes (``struct`` reads the state in one call)
            self.bytes: memoryview = self.shm.buf
        else:
            self.shm = None
            self.name = None
            self._raw = bytearray(size)
            self.mv = memoryview(self._raw).cast("d")
            self.bytes = memoryview(self._raw)

    def release(self) -> None:
        for v in (self.mv, self.bytes if self.shm is None else None):
            try:
                if v is not None:
                    v.release()
            except Exception:  # noqa: BLE001 - a view still exported elsewhere
                pass
        if self.shm is not None:
            try:
                self.shm.close()
            except Exception:  # noqa: BLE001
                pass
            try:
                self.shm.unlink()
            except FileNotFoundError:
                pass


def _attach(name: str) -> tuple[Any, Slots]:
    """Attach the application's segment. A spawned child shares the application's
    resource tracker, so its registration is the same entry: the application's
    ``close()`` unlinks it, and if the application is killed the tracker unlinks it when
    both processes are gone."""
    from multiprocessing import shared_memory
    shm = shared_memory.SharedMemory(name=name)
    buf = shm.buf
    assert buf is not None  # an attached segment has its buffer until close()
    return shm, buf.cast("d")
