"""Live haptic sessions: the servo loop runs apart from the application, materials and
objects change while a person touches them.

:class:`Session` compiles a scene, starts the servo (by default in its own process,
``isolation="process"``; ``"thread"`` runs it in a thread of the application's process,
for tests and pure simulation), and returns at once. The servo side owns the devices:
it opens the scene's actuators, runs :class:`~hapticsdk.runtime.loop.ServoLoop` on the
machine clock (every command through the safety layer and the passivity controller)
and closes them. The application side never blocks on the servo:

* :meth:`Session.state` reads the latest probe position, velocity, force, the object in
  contact and tick statistics from shared memory (a seqlock: the servo bumps a sequence
  number before and after each write; a reader retries while it is odd or changed);
* :meth:`Session.events` drains the event ring (contact enter/leave with the object's
  name, renderer errors, clamps, overruns, skipped ticks, material switches, faults);
* :meth:`Session.set_material`, :meth:`add_object`, :meth:`remove_object`,
  :meth:`move_object` send a message on a pipe. :meth:`Session.set_material` builds
  the new renderers in the application (as the servo would: same settings, actuator
  options, capabilities and calibrations) and sends them pickled, so the servo only
  unpickles them (a calibration table they hold, such as the piezo's 300 kB drive
  table, crosses the pipe once per session and is referred to afterwards, so a
  switch unpickles about a kilobyte); renderers that cannot be pickled here go as features, and the servo
  builds them. The servo process has one thread of its own: it reads the pipe without
  blocking, before each sleep of its clock and after each tick, and does a command's
  work in the slack left before the next deadline (see :class:`_Servo`); the new
  renderers take over at the start of the next tick, and ``state().switched_at`` says
  when;
* :meth:`pause`, :meth:`resume` and :meth:`close` set flags in shared memory.

Live retargeting: :meth:`Session.set_material` answers new intensities at once with the
amortised inverse (the ``amortised`` solver of ``hapticsdk-ga``, a table lookup of about
a millisecond) and sends those features; a background thread of the application then
solves again with the scene's solver (``settings.solver.method``) and, when the answer
differs, sends the refined features. The servo switches by the loop's rule
(:meth:`~hapticsdk.runtime.loop.ServoLoop.set_renderers`, docs/runtime.md, "Material
switch"): a force the new material raises keeps its value and takes the new slope (no
step), one it lowers is ramped over ``ramp_s`` (default 50 ms, at most 0.1 N per tick),
vibration amplitudes are ramped too, and the passivity controller of the force channel
runs across the switch unchanged. Each switch is acknowledged: the returned
:class:`Retarget` waits (:meth:`Retarget.wait`) for the tick that rendered it first
(:class:`~hapticsdk.runtime.callbacks.SwitchHandle`). :meth:`Session.on_event` runs
callbacks on an application thread the SDK owns; ``Session(record=...)`` streams every
tick to disk (:mod:`hapticsdk.runtime.recorder`).

Failure semantics (each one tested in ``tests/runtime/test_session.py``):

* the application process dies (SIGKILL, or SIGTERM/SIGHUP with no handler): the servo
  process checks every tick that its parent is still its parent and that the command
  pipe still has a writer (end of file once the application's descriptors are closed),
  and watches the heartbeat an application thread writes every 10 ms; any one lost
  stops every actuator (``heartbeat_timeout_s``, default 0.25 s, for a hung
  application; the parent and pipe checks answer within a tick of the kernel tearing
  the application down) and the servo exits. (``prctl(PR_SET_PDEATHSIG)`` is not used:
  the kernel sends it at the same moment the parent check sees the new parent, and it
  also fires when the *thread* that started the servo ends while the application
  lives on);
* the servo process dies: the next call on the session raises
  :class:`~hapticsdk.errors.ServoProcessDied` with the reason (exit status, signal,
  device fault);
* SIGINT, SIGTERM or SIGHUP to the servo process: safe stop (every actuator stopped,
  devices closed, shared memory released by the application's ``close()``), the servo
  exits with ``128 + signal``; to the application: Ctrl-C raises ``KeyboardInterrupt``
  whose ``with`` exit calls :meth:`close`, and the default SIGTERM/SIGHUP kill the
  application, which the servo notices as above;
* a renderer raising: counted (``renderer_error`` events and ``state().renderer_errors``);
* :meth:`close` always leaves every actuator stopped, the servo process reaped and the
  shared-memory segment unlinked (also after any of the above).

Only the standard library crosses the process boundary (``multiprocessing`` with the
``spawn`` start method, ``multiprocessing.shared_memory``, pipes). The servo process
limits its BLAS / OpenMP thread pools to one thread (:func:`_one_pool_thread`): a pool
worker that busy-waits between the servo's small matrix calls would take a CPU from
the servo.
"""

from __future__ import annotations

import io
import logging
import math
import multiprocessing as mp
import os
import pickle
import struct
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, NamedTuple, Sequence

from ..errors import HapticSDKError, ServoProcessDied, SessionError, ValidationError
from ..fileio import check_output_path

_log = logging.getLogger(__name__)

#: the slots viewed as float64 (``memoryview.cast("d")``; typeshed types a memoryview's
#: items as int whatever its format, so the view is typed loosely)
Slots = Any

ISOLATIONS = ("process", "thread")

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


@dataclass
class Retarget:
    """What :meth:`Session.set_material` sent.

    Attributes:
        object: the object's name; ``targets``: intensities asked (0..1).
        features: the features sent now (physical units) and ``source`` (``"amortised"``,
            ``"plan"``, or the solver's name when no amortised table covers the
            dimensions).
        success, error: the answer's success and sum of absolute intensity errors.
        intensities: the perception model's intensities for the features sent (0..1).
        refined: set when the background solve has finished; ``refined_features`` its
            answer (None before, or when it failed), ``refined_sent`` whether it was sent.
        switch: the acknowledgement of the switch sent now
            (:class:`~hapticsdk.runtime.callbacks.SwitchHandle`): :meth:`wait` for it,
            then :attr:`tick` and :attr:`t` say where it took effect;
            ``refined_switch`` the same for the refined answer, when one was sent.
    """

    object: str
    targets: dict[str, float]
    features: dict[str, dict[str, float]]
    source: str
    success: bool
    error: float
    intensities: dict[str, float] = field(default_factory=dict)
    refined: threading.Event = field(default_factory=threading.Event, repr=False)
    refined_features: dict[str, dict[str, float]] | None = None
    refined_sent: bool = False
    switch: Any = field(default=None, repr=False)
    refined_switch: Any = field(default=None, repr=False)

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until the servo rendered the switch (True), or ``timeout`` s passed
        (False); raises :class:`~hapticsdk.errors.ServoProcessDied` when the servo died
        first. See :class:`~hapticsdk.runtime.callbacks.SwitchHandle`."""
        return self.switch.wait(timeout)

    @property
    def tick(self) -> int | None:
        """Index of the first servo tick that rendered this switch (None until then)."""
        return self.switch.tick if self.switch is not None and self.switch.done() else None

    @property
    def t(self) -> float | None:
        """Servo time (s) of that tick (None until then)."""
        return self.switch.t if self.switch is not None and self.switch.done() else None


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


def _grow_pipe(conn: Any) -> None:
    """Linux: give the command pipe 1 MiB (the default limit for an unprivileged
    process), so that a message of pickled renderers or tables (the piezo's table is
    about 300 kB) is written at once instead of as the servo drains 64 kB at a time. Elsewhere, or when refused,
    the servo's reader takes a message in as many ticks as it needs."""
    try:
        import fcntl
        fcntl.fcntl(conn.fileno(), fcntl.F_SETPIPE_SZ, 1 << 20)
    except (ImportError, AttributeError, OSError, ValueError):
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


# =====================================================================================
# servo side
# =====================================================================================
#: BLAS / OpenMP thread-pool setters tried on every already-loaded library (first found wins)
_POOL_SETTERS = ("openblas_set_num_threads", "openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
                 "scipy_openblas_set_num_threads64_", "MKL_Set_Num_Threads", "bli_thread_set_num_threads",
                 "omp_set_num_threads")
_POOL_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")


def _pool_env_one_thread() -> None:
    """BLAS / OpenMP libraries loaded from now on start one thread (environment)."""
    for k in _POOL_ENV:
        os.environ[k] = "1"


def _one_pool_thread() -> str:
    """Limit the BLAS / OpenMP thread pools of this process (the servo process) to one
    thread; returns what was done (for the servo's summary).

    Why: a BLAS call the servo makes every tick (the simulated arm's exact step calls
    ``scipy.linalg.expm`` for each measured period) hands work to the pool's worker
    thread, which then busy-waits for the next job, and with one job per millisecond it
    never goes to sleep: it kept a whole CPU busy (measured with ``perf``:
    ``blas_thread_server``), so on a 2-CPU machine with a busy application thread the
    servo thread itself waited for a CPU for milliseconds. The environment variables
    cover libraries loaded from now on; libraries already loaded (the spawn start method
    imports the application's main module, and with it numpy, before the servo runs)
    get their ``*_set_num_threads(1)``. Only libraries already in the process are
    touched (``RTLD_NOLOAD``): no native code is loaded by this."""
    _pool_env_one_thread()
    if not sys.platform.startswith("linux"):
        return f"environment only ({', '.join(_POOL_ENV)} = 1; loaded libraries not inspected on {sys.platform})"
    import ctypes
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as fh:
            paths = sorted({ln.split(None, 5)[5].strip() for ln in fh if len(ln.split(None, 5)) == 6})
    except OSError as exc:
        return f"environment only (/proc/self/maps: {exc})"
    done = []
    for p in paths:
        base = os.path.basename(p)
        low = base.lower()
        if ".so" not in low or not any(k in low for k in ("blas", "mkl", "blis", "omp", "lapack")):
            continue
        try:
            lib = ctypes.CDLL(p, mode=os.RTLD_NOLOAD | os.RTLD_LOCAL)
        except OSError:
            continue
        for sym in _POOL_SETTERS:
            fn = getattr(lib, sym, None)
            if fn is None:
                continue
            try:
                fn.argtypes = [ctypes.c_int]
                fn.restype = None
                fn(1)
                done.append(f"{base}: {sym}(1)")
            except Exception as exc:  # noqa: BLE001 - reported, never fatal
                done.append(f"{base}: {sym} failed: {exc}")
            break
    return "; ".join(done) if done else "no thread pool loaded (environment set for later ones)"


class _CommandReader:
    """The servo's end of the command pipe, read without ever blocking.

    POSIX: the pipe's descriptor is made non-blocking and whatever has arrived is read
    into a buffer each call; complete messages are cut out of it with
    ``multiprocessing.connection``'s framing (a 4-byte big-endian length, or -1 and an
    8-byte length, then the pickle), so a message the application is still writing
    (larger than the pipe's atomic write) waits for the next call instead of stalling
    the servo. Elsewhere ``Connection.poll(0)`` / ``recv()``. ``eof`` turns True when
    every writer has closed the pipe (the application exited)."""

    def __init__(self, conn: Any) -> None:
        self.conn = conn
        self.fd: int | None = None
        self.buf = bytearray()
        self.eof = False
        if os.name == "posix":
            try:
                fd = conn.fileno()
                os.set_blocking(fd, False)
                self.fd = fd
            except (OSError, AttributeError, ValueError):
                self.fd = None

    def read(self) -> list:
        """The messages complete now (possibly none); never blocks."""
        if self.fd is None:
            out = []
            if not self.eof:
                try:
                    while self.conn.poll(0):
                        out.append(self.conn.recv())
                except (EOFError, OSError):
                    self.eof = True
            return out
        buf = self.buf
        while not self.eof:
            try:
                chunk = os.read(self.fd, 65536)
            except BlockingIOError:
                break
            except OSError:
                self.eof = True
                break
            if not chunk:
                self.eof = True
                break
            buf += chunk
            if len(chunk) < 65536:
                break
        msgs = []
        while len(buf) >= 4:
            n = int.from_bytes(buf[:4], "big", signed=True)
            head = 4
            if n == -1:
                if len(buf) < 12:
                    break
                n = int.from_bytes(buf[4:12], "big")
                head = 12
            if len(buf) < head + n:
                break
            msgs.append(pickle.loads(bytes(buf[head:head + n])))
            del buf[:head + n]
        return msgs


#: a command's build waits at most this many ticks for a slack long enough for it
_MAX_WAIT_TICKS = 3
#: kept free before the next deadline (s)
_SLACK_MARGIN_S = 100e-6
#: estimated cost of building one dimension's renderers never measured yet (s)
_UNKNOWN_BUILD_S = 1e-3
#: estimated cost of a command with nothing to build (s)
_SMALL_S = 30e-6
#: persistent-id tag of a calibration table the servo keeps (see Session._prebuilt)
_TABLE_PID = "hapticsdk-table"


class _RendererUnpickler(pickle.Unpickler):
    """Unpickles renderers whose calibration tables were sent before (references
    ``(_TABLE_PID, key)`` into ``tables``)."""

    def __init__(self, data: bytes, tables: dict[int, Any]) -> None:
        super().__init__(io.BytesIO(data))
        self.tables = tables

    def persistent_load(self, pid: Any) -> Any:
        if isinstance(pid, tuple) and len(pid) == 2 and pid[0] == _TABLE_PID and pid[1] in self.tables:
            return self.tables[pid[1]]
        raise pickle.UnpicklingError(f"unknown table reference {pid!r} (its table was never received)")


def _load_renderers(payload: bytes, tables: dict[int, Any]) -> Any:
    """Renderers pickled by :meth:`Session._prebuilt`, their tables taken from ``tables``."""
    return _RendererUnpickler(payload, tables).load()


def _shared_table_types() -> tuple:
    """Types pickled once per session and then referred to (material independent,
    large): the piezo drive table."""
    from ..calibration.piezo import PiezoTable
    return (PiezoTable,)


class _Servo:
    """The servo side: devices, the loop, publishing, and the commands.

    One thread (the servo's) does everything: before each sleep of its clock
    (:class:`~hapticsdk.runtime.clock.MonotonicClock` with ``serve``) and after each
    tick has published, it reads the command pipe without blocking and does a command's
    work in the slack left before the next deadline: unpickling renderers the
    application built, or building them from features (one dimension at a time) when
    the application could not. The estimated cost of a slice is the CPU time the last
    build of that dimension took (rising at once, falling by half per build). A slice that does not
    fit in what is left waits for a later period, at most ``_MAX_WAIT_TICKS`` ticks, then
    runs anyway; a slice longer than any period's slack runs at once (both counted as
    ``forced_slices``: the next tick starts late by the excess; at most one forced slice
    per tick). There is no second
    thread that could hold the interpreter lock while the OS has descheduled it (the
    control thread this replaced woke on every command and built the renderers beside
    the servo thread, competing with it for the lock)."""

    def __init__(self, spec: dict[str, Any], mv: Slots, cmd_conn: Any, thread_mode: bool) -> None:
        self.spec = spec
        self.mv = mv
        self.cmd_conn = cmd_conn
        self.thread_mode = thread_mode
        self.loop: Any = None
        self.tags: list[int] = []
        self.names: list[str] = []
        self._cal: dict[str, dict] = {}
        self._settings: dict[str, Any] = {}
        self._role_options: dict[str, dict[str, Any]] = {}
        self._caps: dict[str, Any] = {}
        self._stack: Any = None
        self.reason = ""
        self.message = ""
        self.stopped_labels: list[str] = []
        self.pools = "not limited (thread isolation: the application's process)"
        # commands
        self._reader: _CommandReader = None  # type: ignore[assignment]  # set in start(), before any serve()
        self._queue: Any = None
        self._job: Any = None
        self._job_est = 0.0
        self._job_waited = 0
        self._job_msg: tuple = ()
        self._build_s: dict[str, float] = {}
        #: calibration tables the application sent (key -> table), referred to by later
        #: pickled renderers
        self._tables: dict[int, Any] = {}
        self._job_t0 = 0.0
        self._wait_tick: Any = None
        #: sequence numbers of switches installed, acknowledged after the next tick
        self._acks: list[int] = []
        self._clamp_src: list = []
        self._clamps_seen: dict[tuple[int, str], int] = {}
        #: (actuator index, limit) -> [actuator, ticks not yet reported, last report t, last bite t]
        self._clamp_live: dict[tuple[int, str], list[Any]] = {}
        self.recorder: Any = None
        #: commands received / done / failed; build slices run, forced (did not fit) and
        #: longer than the slack they had, the longest (us); from receipt to done (ms)
        self.cmd_stats = {"received": 0, "done": 0, "failed": 0, "slices": 0, "forced_slices": 0,
                          "slice_over_slack": 0, "slice_max_us": 0.0, "wait_ms_sum": 0.0, "wait_ms_max": 0.0}

    # -- building ------------------------------------------------------------------
    def _renderers_dim(self, features: Mapping[str, Mapping[str, float]], d: str) -> list:
        """Renderers of dimension ``d`` for live features ``{dimension: {feature:
        value}}``, built as :func:`~hapticsdk.runtime.render.render_plan` builds them
        (scene renderer options, the actuators' own drive tables, saved calibrations)."""
        from ..plan import MaterialPlan
        from .render import _calibrations, build_renderers
        mp = MaterialPlan(name="live", targets={d: 0.0}, dimensions=[d],
                          features={k: float(v) for f in features.values() for k, v in f.items()},
                          actuators={r: n for r, (n, _) in self.spec["devices"].items()})
        cal = self._cal.get(d)
        if cal is None:
            cal = self._cal[d] = _calibrations(mp, self._settings, self._role_options)[0]
        return build_renderers(mp, self._settings, calibrations=cal, capabilities=self._caps)

    def _note_cost(self, key: str, took: float) -> None:
        """Update the estimate of the next slice of kind ``key`` (a dimension, or
        ``<unpickle>`` / ``<table>``) with the CPU time ``took`` (s) this one took: it
        rises at once and falls by half per slice. CPU time, because time the servo was
        descheduled is not the work's cost."""
        old = self._build_s.get(key)
        self._build_s[key] = took if old is None else max(took, 0.5 * (old + took))

    def _timed_dim(self, features: Mapping[str, Mapping[str, float]], d: str) -> list:
        t0 = time.thread_time()
        rs = self._renderers_dim(features, d)
        self._note_cost(d, time.thread_time() - t0)
        return rs

    def renderers_for(self, features: Mapping[str, Mapping[str, float]]) -> list:
        """Renderers for live features ``{dimension: {feature: value}}`` (every dimension)."""
        out: list = []
        for d in features:
            out.extend(self._timed_dim(features, d))
        return out

    def prepare(self, plan: Any = None) -> None:
        """What building renderers needs (settings, actuator options, the actuators'
        capabilities), without opening anything: the servo calls it from :meth:`build`,
        the application to build renderers itself (see :meth:`Session.set_material`)."""
        from ..plan import RenderPlan
        from ..plugins import registry
        from .render import _capabilities
        spec = self.spec
        if plan is None:
            plan = RenderPlan.from_dict(spec["plan"], validate=False)
        self._settings = plan.settings
        chosen = {role: (registry("actuator").load(name), dict(opts)) for role, (name, opts) in spec["devices"].items()}
        self._role_options = {r: o for r, (_, o) in chosen.items()}
        self._caps = _capabilities(chosen)

    def build(self) -> None:
        from contextlib import ExitStack

        from ..actuators import Actuator, HapticDevice
        from ..plan import FALLBACK_SENSOR, RenderPlan
        from ..plugins import registry
        from ..scene.geometry import HitTester, shape_from_dict
        from .clock import MonotonicClock
        from .loop import ServoLoop
        from .render import _calibrations, build_renderers

        spec = self.spec
        plan = RenderPlan.from_dict(spec["plan"], validate=False)
        self.prepare(plan)
        objects = []
        shapes = []
        for o in spec["objects"]:
            if o.get("features") is not None:
                rs = self.renderers_for(o["features"])
            else:
                mp = plan.material(o["material"])
                cal = _calibrations(mp, plan.settings, self._role_options)[0]
                rs = build_renderers(mp, plan.settings, calibrations=cal, capabilities=self._caps)
                # warm the per-dimension calibrations and build-cost estimates a live
                # set_material of these dimensions will use
                feats = {d: dict(mp.features) for d in mp.dimensions}
                for d in mp.dimensions:
                    try:
                        self._timed_dim(feats, d)
                    except Exception:  # noqa: BLE001 - only an estimate; the live build reports
                        pass
            objects.append((o["name"], rs))
            shapes.append((o["name"], shape_from_dict(o["geometry"], o["pose"])))
            self.tags.append(o["id"])
            self.names.append(o["name"])
        self._stack = ExitStack()
        acts: dict[str, Any] = {}
        made: dict[tuple, Any] = {}
        traj = spec.get("trajectory")
        for role, (name, opts) in spec["devices"].items():
            key = (name, repr(sorted(opts.items())))
            if key not in made:
                cls = registry("actuator").load(name)
                kw = dict(opts)
                if (traj is not None and isinstance(cls, type) and issubclass(cls, HapticDevice)
                        and getattr(cls, "simulated", False)):
                    kw.setdefault("trajectory", traj)
                act = cls(**kw)
                if not isinstance(act, Actuator):
                    raise HapticSDKError(f"actuator plugin {name!r} did not create an Actuator")
                self._stack.enter_context(act)
                made[key] = act
            acts[role] = made[key]
        sensors = [a for a in made.values() if isinstance(a, HapticDevice)]
        if sensors:
            device = sensors[0]
        else:
            cls = registry("actuator").load(FALLBACK_SENSOR)
            device = cls(**({"trajectory": traj} if traj is not None else {}))
            self._stack.enter_context(device)
        clock = MonotonicClock(serve=self._serve_if_ready) if spec["realtime"] else None
        self.loop = ServoLoop(device, (), acts, period_s=spec["period_s"], realtime=spec["realtime"],
                              clock=clock, passivity=spec["passivity"], raise_on_fault=False, objects=objects,
                              hit_tester=HitTester(shapes), log_seconds=spec["log_seconds"],
                              switch_ramp_s=spec["ramp_s"], drop_unmapped_roles=True, rt=spec.get("rt"))
        from collections import deque
        self._queue = deque()
        self._reader = _CommandReader(self.cmd_conn)
        self._all_names = dict(zip(self.tags, self.names))

    def start_recording(self) -> None:
        """After the loop started (its channels are known): the recorder, when asked."""
        path = self.spec.get("record_path")
        if path:
            from .recorder import LiveRecorder
            self.recorder = LiveRecorder(path, [sl.role for sl in self.loop._slots],  # noqa: SLF001
                                         self.spec["period_s"], objects=self._all_names)

    # -- commands (in the servo thread, in the slack of a period) ------------------------
    def _slack(self) -> float:
        """Seconds left before the next tick must start, minus a margin; unlimited on
        simulated time. (Work may use the clock's final spin: the spin only covers the
        sleep's wake-up latency, and a slice that ends before the deadline leaves the
        clock to spin the rest.)"""
        loop = self.loop
        if not loop.realtime:
            return math.inf
        return loop._deadline - loop.clock.now() - _SLACK_MARGIN_S  # noqa: SLF001

    def _room(self) -> float:
        """What a period leaves for commands after a tick that computes twice as long as
        the last one, minus the margin (s)."""
        loop = self.loop
        return loop.period_s - _SLACK_MARGIN_S - 2.0 * loop.last_compute_s

    def _est(self, d: str) -> float:
        return self._build_s.get(d, _UNKNOWN_BUILD_S)

    def _index(self, oid: int) -> int:
        try:
            return self.tags.index(oid)
        except ValueError:
            return -1

    def _command(self, msg: tuple) -> Any:
        """A command as a generator: each ``yield`` gives the estimated cost (s) of the
        work up to the next ``yield``; the first one comes before any work."""
        kind = msg[0]
        loop = self.loop
        seq = msg[4] if kind in ("material", "renderers") and len(msg) > 4 else -1
        if kind == "material":
            _, oid, feats, ramp = msg[:4]
            built: list = []
            for d in feats:
                yield self._est(d)
                built.extend(self._timed_dim(feats, d))
            i = self._index(oid)
            if i >= 0:
                loop.set_renderers(self.names[i], built, ramp)  # applied at the start of the next tick
                self.event("material_switched", oid, ramp)
                if seq >= 0:
                    self._acks.append(seq)
        elif kind == "renderers":
            # renderers the application built and pickled: only unpickling is left
            _, oid, payload, ramp = msg[:4]
            yield self._build_s.get("<unpickle>", _SMALL_S)
            t0 = time.thread_time()
            built = _load_renderers(payload, self._tables)
            self._note_cost("<unpickle>", time.thread_time() - t0)
            i = self._index(oid)
            if i >= 0:
                loop.set_renderers(self.names[i], built, ramp)
                self.event("material_switched", oid, ramp)
                if seq >= 0:
                    self._acks.append(seq)
        elif kind == "tables":
            # calibration tables later renderers refer to: one slice per table
            for key, blob in msg[1].items():
                # never measured: 1 ns per byte (a 300 kB table took ~0.1 ms, cold)
                yield self._build_s.get("<table>", len(blob) * 1e-9)
                t0 = time.thread_time()
                self._tables[key] = pickle.loads(blob)
                self._note_cost("<table>", time.thread_time() - t0)
        elif kind == "add":
            from ..scene.geometry import shape_from_dict
            _, oid, name, feats, geom, pose = msg
            built = []
            for d in feats:
                yield self._est(d)
                built.extend(self._timed_dim(feats, d))
            loop.add_object(name, built, shape_from_dict(geom, pose))
            self.tags.append(oid)
            self.names.append(name)
            self._all_names[oid] = name
        elif kind == "remove":
            yield _SMALL_S
            i = self._index(msg[1])
            if i >= 0:
                loop.remove_object(self.names[i])
                del self.tags[i]
                del self.names[i]
        elif kind == "pose":
            from ..scene.geometry import Pose
            yield _SMALL_S
            i = self._index(msg[1])
            if i >= 0:
                loop.set_pose(self.names[i], Pose.from_dict(msg[2]))
        else:
            raise HapticSDKError(f"unknown session command {kind!r}")

    def _serve_if_ready(self) -> None:
        if self._reader is not None and self.loop is not None:
            self.serve()

    def serve(self) -> None:
        """Read the commands that have arrived and do their work while it fits in this
        period's slack (see the class docstring). Never blocks on the pipe."""
        stats = self.cmd_stats
        new = self._reader.read()
        if new:
            now = time.monotonic()
            self._queue.extend((now, m) for m in new)
            stats["received"] += len(new)
        perf = time.perf_counter
        while self._job is not None or self._queue:
            if self._job is None:
                self._job_t0, msg = self._queue.popleft()
                try:
                    self._job = self._command(msg)
                    self._job_est = next(self._job)
                except StopIteration:
                    self._job = None
                    continue
                except Exception as exc:  # noqa: BLE001 - a bad message must not end the servo
                    self._failed(msg, exc)
                    continue
                self._job_waited = 0
                self._wait_tick = None
                self._job_msg = msg
            left = self._slack()
            forced = False
            if self._job_est > left:
                # wait for a later period only when a normal one has room for it: serve()
                # runs right after a tick, so a slice longer than a whole period's slack
                # would never fit, and waiting would only delay it
                tick = getattr(self.loop, "_deadline", None)  # count periods, not calls
                if tick != self._wait_tick:
                    self._wait_tick = tick
                    self._job_waited += 1
                if self._job_waited <= _MAX_WAIT_TICKS and self._job_est <= self._room():
                    return
                forced = True
            t0 = perf()
            done = False
            try:
                self._job_est = next(self._job)
            except StopIteration:
                done = True
            except Exception as exc:  # noqa: BLE001
                self._failed(self._job_msg, exc)
            took = perf() - t0
            stats["slices"] += 1
            stats["forced_slices"] += forced
            stats["slice_over_slack"] += took > left
            stats["slice_max_us"] = max(stats["slice_max_us"], took * 1e6)
            self._job_waited = 0
            self._wait_tick = None
            if done:
                self._job = None
                wait = (time.monotonic() - self._job_t0) * 1e3
                stats["done"] += 1
                stats["wait_ms_sum"] += wait
                stats["wait_ms_max"] = max(stats["wait_ms_max"], wait)
            if forced:
                return  # the next tick is due (or late): never two forced slices in a row

    def _failed(self, msg: tuple, exc: BaseException) -> None:
        self._job = None
        self.cmd_stats["failed"] += 1
        _log.error("session command %r failed: %s: %s", msg[:1], type(exc).__name__, exc)
        self.event("fault", -1.0, 0.0)

    # -- publishing ---------------------------------------------------------------------
    def event(self, kind: str, oid: float, value: float, detail: float = -1.0, count: float = 0.0) -> None:
        mv = self.mv
        w = int(mv[_EV_W])
        j = _EV0 + (w % _EV_CAP) * _EV_REC
        mv[j] = (self.loop.last_t or 0.0) if self.loop is not None else 0.0
        mv[j + 1] = _KIND[kind]
        mv[j + 2] = oid
        mv[j + 3] = value
        mv[j + 4] = detail
        mv[j + 5] = count
        mv[_EV_W] = w + 1

    def _ack(self, tick: int, t: float, now: float) -> None:
        """Acknowledge the material switches that took effect on ``tick`` (their
        renderers were installed at its start): one ring entry each, the sequence number
        written last, so an entry whose sequence number matches is complete."""
        mv = self.mv
        for seq in self._acks:
            j = _ACK0 + (seq % _ACK_CAP) * _ACK_REC
            mv[j + 1] = tick
            mv[j + 2] = t
            mv[j + 3] = now
            mv[j] = seq
        self._acks.clear()

    def _clamp_sources(self) -> list:
        """(role index, actuator) of every distinct actuator whose safety layer counts
        limit hits: the roles in the order of the spec's devices (the application
        decodes a clamp event's role from the same order); the sensing device alone,
        when it is not one of them, gets the index after the last role."""
        loop = self.loop
        out: list = []
        seen: set[int] = set()
        roles = list(self.spec["devices"])
        for i, role in enumerate(roles):
            a = loop.actuators.get(role)
            if a is not None and id(a) not in seen and hasattr(getattr(a, "safety", None), "hits"):
                seen.add(id(a))
                out.append((i, a))
        dev = loop.device
        if id(dev) not in seen and hasattr(getattr(dev, "safety", None), "hits"):
            out.append((len(roles), dev))
        return out

    def _clamp_events(self, final: bool = False) -> None:
        """``clamp`` events: one per (actuator, limit) at the onset of its biting, then the
        ticks it bit since, at most once per :data:`CLAMP_REPORT_S` while it keeps biting
        and once when it has been quiet that long (``final``: whatever is pending, at the
        end of the run). Every tick a limit bit is counted in exactly one event."""
        last = self._clamps_seen
        live = self._clamp_live
        t = (self.loop.last_t or 0.0) if self.loop is not None else 0.0
        for ri, act in self._clamp_src:
            for key, n in list(act.safety.hits.items()):
                k = (ri, key)
                d = n - last.get(k, 0)
                if d <= 0:
                    continue
                last[k] = n
                st = live.get(k)
                if st is None:   # onset: reported at once
                    live[k] = [act, 0, t, t]
                    self._clamp_event(ri, act, key, d)
                else:
                    st[1] += d
                    st[3] = t
        for k, st in list(live.items()):
            act, pending, t_rep, t_bite = st
            quiet = t - t_bite >= CLAMP_REPORT_S
            if pending and (final or quiet or t - t_rep >= CLAMP_REPORT_S):
                self._clamp_event(k[0], act, k[1], pending)
                st[1], st[2] = 0, t
            if final or quiet:
                del live[k]

    def _clamp_event(self, ri: int, act: Any, key: str, count: int) -> None:
        nf = len(CLAMP_FIELDS)
        fi = _CLAMP_INDEX.get(key, nf - 1)
        attr = CLAMP_FIELDS[fi][1]
        cmd = getattr(act, "last_command", None)
        v = getattr(cmd, attr, None) if (cmd is not None and attr) else None
        self.event("clamp", -1.0, float(v) if v is not None else math.nan, ri * nf + fi, count)

    def run(self) -> None:
        """The servo thread: tick, publish, watch the application, serve its commands,
        until told to stop."""
        loop = self.loop
        mv = self.mv
        tags = self.tags
        ev = loop.events
        ppid = self.spec["ppid"]
        hb_timeout = self.spec["heartbeat_timeout_s"]
        watch = not self.thread_mode
        getppid = os.getppid
        mono = time.monotonic
        reader = self._reader
        last_contact = -1
        seen = {"renderer_error": 0, "overrun": 0, "skipped_ticks": 0}
        switches_seen = 0
        clamps_seen = 0
        paused = False
        acks = self._acks
        self._clamp_src = self._clamp_sources()
        rec = self.recorder
        roles = list(self.spec["devices"])
        vib = [(_VIB0 + 3 * k, sl) for k, sl in
               enumerate([sl for sl in loop._slots if not sl.is_force][:_VIB_N])]  # noqa: SLF001
        for k in range(_VIB_N):
            mv[_VIB0 + 3 * k] = -1.0
        for j, sl in vib:
            mv[j] = roles.index(sl.role) if sl.role in roles else -1.0
        cap = loop._cap  # noqa: SLF001
        mv[_PID] = os.getpid()
        mv[_STATUS] = _RUNNING
        mv[_READY] = mono()
        n = 0
        while True:
            ok = loop.tick()
            n += 1
            st = loop.last_state
            # ---- publish (seqlock) ----
            seq = mv[_SEQ]
            mv[_SEQ_END] = seq + 1.0  # odd before the state changes (readers read 0..24 ascending)
            if st is not None:
                # the loop keeps a SensedState: its floats (its array fields would be built)
                mv[_PX] = st.px
                mv[_PY] = st.py
                mv[_PZ] = st.pz
                mv[_VX] = st.vx
                mv[_VY] = st.vy
                mv[_VZ] = st.vz
            c = loop.contact
            mv[_T] = loop.last_t or 0.0
            mv[_F] = loop.last_force_n
            mv[_OBJ] = tags[c] if 0 <= c < len(tags) else -1.0
            near = loop.last_index
            mv[_NEAR] = tags[near] if 0 <= near < len(tags) else -1.0
            mv[_PEN] = loop.last_penetration_mm
            mv[_TICKS] = loop.ticks
            mv[_OVERRUNS] = ev["overrun"]
            mv[_SKIPPED] = ev["skipped_ticks"]
            mv[_RERR] = ev["renderer_error"]
            mv[_TICK_US] = loop.last_compute_s * 1e6
            mv[_TICK_MAX_US] = loop.max_compute_s * 1e6
            mv[_MISSED] = loop.missed_ticks
            sw = ev["material_switches"]
            now = mono()
            if sw != switches_seen:
                switches_seen = sw
                mv[_SWITCHED_AT] = now  # this tick rendered the new material first
            mv[_SWITCHES] = sw
            mv[_PUB] = now
            mv[_SEQ] = seq + 2.0
            mv[_SEQ_END] = seq + 2.0
            if acks:
                self._ack(loop.ticks - 1, loop.last_t or 0.0, now)
            if rec is not None:
                rec.add(loop, mv[_OBJ])
            if vib:
                i = (loop.ticks - 1) % cap
                for j, sl in vib:
                    mv[j + 1] = sl.log_f[i]
                    mv[j + 2] = sl.log_a[i]
            # ---- events ----
            if c != last_contact:
                if last_contact >= 0 and last_contact < len(tags):
                    self.event("contact_leave", tags[last_contact], 0.0)
                if c >= 0:
                    self.event("contact_enter", tags[c], loop.last_penetration_mm)
                last_contact = c
            if not ok:
                f = loop._fault  # noqa: SLF001
                self.reason = "fault"
                self.message = f"device fault: {f['device']}: {f['message']}" if f else "the servo loop ended"
                self.event("fault", -1.0, 0.0)
                return
            if watch and (getppid() != ppid or reader.eof):
                self.reason = "app_lost"
                now = mono()
                how = "is gone" if getppid() != ppid else "closed its command pipe"
                self.message = (f"the application process ({ppid}) {how} (noticed at monotonic "
                                f"{now:.6f} s); last heartbeat {(now - mv[_HEARTBEAT]) * 1e3:.1f} ms before")
                self.event("app_lost", -1.0, mono() - mv[_HEARTBEAT])
                return
            if n % 10 == 0:
                for key in seen:
                    if ev[key] != seen[key]:
                        self.event(key, tags[c] if 0 <= c < len(tags) else -1.0, ev[key] - seen[key])
                        seen[key] = ev[key]
                cl = loop.clamp_count()
                mv[_CLAMPS] = cl
                if cl != clamps_seen or self._clamp_live:
                    self._clamp_events()
                    clamps_seen = cl
                if watch and hb_timeout is not None:
                    age = mono() - mv[_HEARTBEAT]
                    if age > hb_timeout:
                        self.reason = "heartbeat"
                        self.message = f"no heartbeat from the application for {age * 1e3:.0f} ms"
                        self.event("app_lost", -1.0, age)
                        return
            pz = mv[_PAUSE] != 0.0
            if pz != paused:
                paused = pz
                loop.paused = pz
                mv[_PAUSED_S] = 1.0 if pz else 0.0
                self.event("paused" if pz else "resumed", -1.0, 0.0)
            if mv[_STOP] != 0.0:
                self.reason = "close"
                return
            # ---- commands, in what is left of this period ----
            self.serve()

    def shutdown(self) -> dict[str, Any]:
        """Stop every actuator, end the loop, close the devices; a small summary."""
        from ..actuators import stops_since
        t0 = time.monotonic()
        out: dict[str, Any] = {"reason": self.reason, "message": self.message,
                               "commands": {**self.cmd_stats,
                                            "build_estimate_us": {d: v * 1e6 for d, v in self._build_s.items()}},
                               "thread_pools": self.pools}
        loop = self.loop
        if loop is not None:
            loop.stop_all()
            out["stop_all_s"] = time.monotonic() - t0  # every actuator told to stop
            try:   # the clamp ticks not reported yet (after the stop: no actuator waits on it)
                self._clamp_events(final=True)
            except Exception as exc:  # noqa: BLE001 - the stop matters more than a report
                _log.warning("final clamp events: %s", exc)
            try:
                if loop._running:  # noqa: SLF001
                    rep = loop.finish()
                    out["report"] = {k: v for k, v in rep.to_dict().items()
                                     if k in ("ticks", "tick_median_us", "tick_p99_us", "tick_max_us", "overruns",
                                              "jitter", "events", "fault", "rt")}
                    path = self.spec.get("log_path")
                    if path:
                        import numpy as np

                        from ..fileio import atomic_savez
                        obj = rep.log["object"]
                        ids = np.array([self.tags[i] if 0 <= i < len(self.tags) else -1 for i in obj.tolist()])
                        atomic_savez(path, field="log_path", object_id=ids,
                                     **{k: v for k, v in rep.log.items() if k != "object"})
                        out["log_path"] = str(path)
            except Exception as exc:  # noqa: BLE001
                out["finish_error"] = f"{type(exc).__name__}: {exc}"
        if self._stack is not None:
            self._stack.close()  # closes every actuator (stop, then release)
        if self.recorder is not None:
            try:
                out["record_path"] = str(self.recorder.close(self._all_names))
            except Exception as exc:  # noqa: BLE001 - reported; the stream stays for recover()
                out["record_error"] = f"{type(exc).__name__}: {exc}"
        out["stopped"] = sorted({lab for lab, _, ok in stops_since(t0) if ok})
        out["stop_s"] = time.monotonic() - t0
        return out


def _servo_main(spec: dict[str, Any], cmd_conn: Any, shm_name: str | None, done_conn: Any,
                local_mv: Slots | None = None, holder: list | None = None) -> None:
    """Entry point of the servo (process or thread)."""
    from .signals import SafeStop, safe_stop_on_signals
    thread_mode = local_mv is not None
    shm = None
    mv: Slots
    if thread_mode:
        mv = local_mv
    else:
        shm, mv = _attach(shm_name)  # type: ignore[arg-type]
        # the servo process runs one Python thread of its own; a plugin's thread (a
        # transport reader) hands the interpreter lock back within 50 us
        sys.setswitchinterval(5e-5)
        _pool_env_one_thread()  # pools loaded while building: one thread from the start
    servo = _Servo(spec, mv, cmd_conn, thread_mode)
    if holder is not None:
        holder.append(servo)  # thread isolation: the application may inspect its servo
    summary: dict[str, Any] = {}
    code = 0
    with safe_stop_on_signals() as sig:
        try:
            try:
                servo.build()
                if not thread_mode:
                    servo.pools = _one_pool_thread()  # after build(): scipy.linalg is loaded by now
                servo.loop.start(None)
                servo.start_recording()
                servo.run()
            except SafeStop as exc:
                servo.reason = "signal"
                servo.message = f"stopped by {exc.signame}"
                code = exc.exit_code
                if servo.loop is not None and servo.loop.last_t is not None:
                    servo.event("signal", -1.0, exc.signum)
            except BaseException as exc:  # noqa: BLE001 - report it, after the safe stop
                servo.reason = "error"
                servo.message = f"{type(exc).__name__}: {exc}"
                code = 1
            finally:
                summary = servo.shutdown()
        except SafeStop as exc:  # a signal during the shutdown itself: stop again, quickly
            servo.loop and servo.loop.stop_all()
            code = exc.exit_code
            summary = {"reason": "signal", "message": f"stopped by {exc.signame}"}
    if sig.signum is not None and code == 0:
        code = 128 + sig.signum
    mv[_REASON] = _STOP_REASONS.index(servo.reason) if servo.reason in _STOP_REASONS else 6
    mv[_STATUS] = _STOPPED if servo.reason in ("close", "") else _FAILED
    if servo.reason == "app_lost" or servo.reason == "heartbeat":
        print(f"hapticsdk servo: {summary.get('message', '')}; every actuator stopped "
              f"({', '.join(summary.get('stopped', []))}): stop commands after "
              f"{summary.get('stop_all_s', 0) * 1e3:.1f} ms, devices closed after {summary.get('stop_s', 0) * 1e3:.1f} ms",
              file=sys.stderr, flush=True)
    try:
        done_conn.send(summary)
    except Exception:  # noqa: BLE001 - the application is gone
        pass
    if shm is not None:
        try:
            mv.release()
            shm.close()
        except Exception:  # noqa: BLE001
            pass
    if not thread_mode and code:
        sys.exit(code)


# =====================================================================================
# application side
# =====================================================================================
def _default_rt(rt: Any, isolation: str) -> dict[str, Any] | None:
    """The servo's OS options (a mapping for the servo's spec, or None): a servo process
    asks for ``SCHED_FIFO`` (``"auto"``) unless the caller's options say otherwise."""
    from dataclasses import asdict

    from .clock import RealtimeSettings
    if isinstance(rt, RealtimeSettings):
        return asdict(rt)
    out = dict(rt) if rt is not None else None
    if isolation == "process":
        out = out if out is not None else {}
        out.setdefault("fifo_priority", "auto")
        if "cpu" not in out:
            from .rtkit import spare_cpu
            cpu = spare_cpu()  # pinned only where a CPU is spare (3 or more)
            if cpu is not None:
                out["cpu"] = cpu
    return out


class Session:
    """A live haptic session on a scene; see the module docstring.

    Args:
        scene: a :class:`~hapticsdk.scene.Scene`, its dict form or a path.
        isolation: ``"process"`` (default: the servo in its own process, started with
            ``spawn``) or ``"thread"``.
        trajectory: scripted finger for simulated devices
            (:class:`~hapticsdk.sim.finger.Trajectory`, e.g.
            :func:`hapticsdk.sim.finger.walk_over` of the scene).
        actuator_options: role -> options from the application, merged over the plan's.
        realtime: pace the servo on the machine clock (default True; False runs
            simulated time as fast as possible, for tests).
        period_s: servo period (s); default the scene's ``settings.servo.period_s``.
        ramp_s: cross-fade of a material switch (s), default 0.05.
        heartbeat_timeout_s: the servo stops when the application's heartbeat is older
            than this (s, default 0.25); None: only the parent-process check.
        refine: refine :meth:`set_material` answers with the scene's solver in a
            background thread (default True).
        log_seconds: servo log window (s).
        log_path: when given, the servo writes its log window (the last ``log_seconds``
            of ticks: ``t``, ``force_n``, ``penetration_mm``, ``object_id``,
            ``<role>.frequency_hz`` / ``<role>.amplitude``, ...) to this ``.npz`` file
            (atomically) when the session closes; ``object_id`` maps to names through
            :attr:`object_ids`.
        rt: OS options for the servo thread, as ``ServoLoop(rt=...)``: ``{"cpu": 1,
            "fifo_priority": 50, "mlockall": True}`` (each reported, never raised, when
            the OS refuses; the outcome is in ``close()``'s ``report["rt"]``); e.g. pin
            the servo to a CPU the application does not use. With
            ``isolation="process"``, a mapping without ``fifo_priority`` (and None, the
            default) asks for ``fifo_priority="auto"``: the servo process runs under
            ``SCHED_FIFO`` where the OS lets it (root, ``CAP_SYS_NICE`` or an
            ``RLIMIT_RTPRIO``), else at normal priority; ``{"fifo_priority": None}``
            turns it off. Thread isolation asks for nothing by default (a real-time
            thread in the application's interpreter would wait on the interpreter
            lock held by normal-priority threads).
        start_timeout_s: how long to wait for the servo to be running (s).
        record: a ``.npz`` path, or ``.h5`` / ``.hdf5`` with the optional h5py
            (``hapticsdk[h5]``): the servo streams every tick to ``<record>.part`` with
            bounded memory and turns it into ``record`` (a ``hapticsdk-run`` file that
            ``hapticsdk replay`` plays back) when the session ends; see
            :mod:`hapticsdk.runtime.recorder` (what a session cut short leaves).
        view: True (or a port number) serves the live view in the browser
            (:meth:`open_view`, :mod:`hapticsdk.runtime.view`) on 127.0.0.1; its
            address is logged and in ``session.view.url``.
    """

    def __init__(self, scene: Any, *, isolation: str = "process", trajectory: Any = None,
                 actuator_options: Mapping[str, Mapping[str, Any]] | None = None, realtime: bool = True,
                 period_s: float | None = None, ramp_s: float = 0.05, heartbeat_timeout_s: float | None = 0.25,
                 refine: bool = True, log_seconds: float = 60.0, log_path: "str | Path | None" = None,
                 rt: Mapping[str, Any] | None = None, start_timeout_s: float = 120.0,
                 record: "str | Path | None" = None, view: "bool | int" = False) -> None:
        from ..compiler import compile_scene
        from ..scene import Scene
        if isolation not in ISOLATIONS:
            raise ValidationError(f"isolation must be one of {list(ISOLATIONS)}, got {isolation!r}",
                                  field="isolation")
        if not (isinstance(ramp_s, (int, float)) and math.isfinite(ramp_s) and 0 <= ramp_s <= 5):
            raise ValidationError(f"ramp_s must be in [0, 5] s, got {ramp_s!r}", field="ramp_s")
        if heartbeat_timeout_s is not None and not (
                isinstance(heartbeat_timeout_s, (int, float)) and 2 * HEARTBEAT_PERIOD_S <= heartbeat_timeout_s):
            raise ValidationError(f"heartbeat_timeout_s must be >= {2 * HEARTBEAT_PERIOD_S} s or None",
                                  field="heartbeat_timeout_s")
        from .recorder import check_record_path
        if rt is not None:
            from .clock import RealtimeSettings
            RealtimeSettings.coerce(rt)  # unknown option names fail here, not in the servo
        rt = _default_rt(rt, isolation)
        if isolation == "thread" and rt and rt.get("fifo_priority") is not None:
            _log.warning("a SCHED_FIFO servo thread shares the application's interpreter lock with "
                         "normal-priority threads, which then hold it up (set_material took up to 0.85 s in "
                         "hapticsdk bench live): real-time scheduling is meant for isolation='process'")
        if isinstance(scene, (str, Path)):
            scene = Scene.load(scene)
        elif isinstance(scene, Mapping):
            scene = Scene.from_dict(scene)
        if not isinstance(scene, Scene):
            raise ValidationError("scene must be a Scene, its dict form or a path", field="scene")
        self.scene = scene
        self.isolation = isolation
        self.ramp_s = float(ramp_s)
        self.refine = bool(refine)
        self._closed = False
        self._alive_checked = -1.0
        self._library: Any = None
        self._lock = threading.Lock()
        self._events_r = 0
        self._local_events: list[SessionEvent] = []
        self._summary: dict[str, Any] | None = None
        self._threads: list[threading.Thread] = []
        self._seq = 0
        from .callbacks import EventDispatcher
        self._dispatcher = EventDispatcher(self)
        #: the one watcher of a process servo (reaps it, standby on its death; issues 27, 31)
        self._supervisor: Any = None
        #: the live view's server (:meth:`open_view`), None until opened
        self.view: Any = None
        plan = compile_scene(scene)
        self.plan = plan
        settings = plan.settings
        self._settings = settings
        servo = dict(settings.get("servo") or {})
        from ..device_options import check_data_settings
        check_data_settings(settings, field="scene.settings")  # safety is not data (issue 31)
        period = float(period_s if period_s is not None else servo.get("period_s", 0.001))
        # devices: role -> (actuator, options), one actuator per role for every material
        from ..plugins import registry
        from .render import _actuator_options
        devices: dict[str, tuple[str, dict[str, Any]]] = {}
        for mp_ in plan.materials.values():
            for role, name in mp_.actuators.items():
                # as render_plan: the plan's options (never a privileged one: a scene file
                # may not name a library or an output file), then the user's device
                # configuration and environment, then the application's
                opts = _actuator_options(registry("actuator").load(name), name, role, mp_,
                                         dict(actuator_options or {}))
                if role in devices and devices[role][0] != name:
                    raise ValidationError(f"role {role!r} is mapped to {devices[role][0]!r} and {name!r} by "
                                          f"two materials; a session opens one actuator per role",
                                          field=f"scene.devices.{role}")
                devices.setdefault(role, (name, opts))
        self.devices = {r: n for r, (n, _) in devices.items()}
        self._roles = list(devices)  # the servo numbers a clamp's actuator by this order
        self._names: dict[int, str] = {}
        self._ids: dict[str, int] = {}
        self._next_id = 0
        objects = []
        material_of = {o: m.name for m in plan.materials.values() for o in m.objects}
        self._materials: dict[str, Any] = {}
        for o in scene.objects:
            oid = self._new_id(o.name)
            shape = o.shape()
            objects.append({"id": oid, "name": o.name, "material": material_of[o.name], "features": None,
                            "geometry": shape.geometry_dict(), "pose": shape.pose.to_dict()})
            self._materials[o.name] = material_of[o.name]
        spec = {"plan": plan.to_dict(), "objects": objects, "devices": devices,
                "renderer_options": dict(settings.get("renderer_options") or {}), "trajectory": trajectory,
                "period_s": period, "realtime": bool(realtime), "passivity": bool(servo.get("passivity", True)),
                "ramp_s": self.ramp_s, "heartbeat_timeout_s": heartbeat_timeout_s, "log_seconds": float(log_seconds),
                "log_path": str(check_output_path(log_path, field="log_path")) if log_path is not None else None,
                "ppid": os.getpid(), "rt": rt,
                "record_path": str(check_record_path(record)) if record is not None else None}
        self._spec = spec
        self._builder: _Servo | None = None
        self._build_lock = threading.Lock()
        #: tables sent to the servo: id -> (the table, its key); see _prebuilt
        self._tables_sent: dict[int, tuple[Any, int]] = {}
        self._buf: _Buffer | None = _Buffer(shared=isolation == "process")
        self._mv = self._buf.mv
        self._bytes = self._buf.bytes
        self._mv[_HEARTBEAT] = time.monotonic()
        self._process: Any = None
        self._thread: threading.Thread | None = None
        try:
            if isolation == "process":
                ctx = mp.get_context("spawn")
                cmd_r, self._cmd = ctx.Pipe(duplex=False)
                self._done, done_w = ctx.Pipe(duplex=False)
                self._process = ctx.Process(target=_servo_main, args=(spec, cmd_r, self._buf.name, done_w),
                                            name="hapticsdk-servo", daemon=True)
                self._process.start()
                # reaps the servo the moment it ends; servo death -> the application
                # reopens the devices and writes standby (issue 31), then callbacks hear of it
                from .supervisor import ServoSupervisor
                self._supervisor = ServoSupervisor(self._process, devices, on_exit=self._dispatcher.wake)
                cmd_r.close()
                done_w.close()
                _grow_pipe(self._cmd)
            else:
                cmd_r, self._cmd = mp.Pipe(duplex=False)
                self._done, done_w = mp.Pipe(duplex=False)
                _grow_pipe(self._cmd)
                self._servo_holder: list = []
                self._thread = threading.Thread(target=_servo_main,
                                                args=(spec, cmd_r, None, done_w, self._mv, self._servo_holder),
                                                name="hapticsdk-servo", daemon=True)
                self._thread.start()
            self._hb_stop = threading.Event()
            self._hb = threading.Thread(target=self._heartbeat, name="hapticsdk-heartbeat", daemon=True)
            self._hb.start()
            self._warm()
            deadline = time.monotonic() + start_timeout_s
            while self._mv[_STATUS] == _STARTING:
                if not self._servo_alive():
                    break
                if time.monotonic() > deadline:
                    raise SessionError(f"the servo did not start within {start_timeout_s} s")
                time.sleep(0.002)
            self._check()
            if view is not False and view is not None:
                url = self.open_view(0 if view is True else int(view))
                _log.info("hapticsdk live view: %s", url)
        except BaseException:
            self.close()
            raise

    # -- helpers ----------------------------------------------------------------------
    def _new_id(self, name: str) -> int:
        oid = self._next_id
        self._next_id += 1
        self._names[oid] = name
        self._ids[name] = oid
        return oid

    def _heartbeat(self) -> None:
        mv = self._mv
        while not self._hb_stop.wait(HEARTBEAT_PERIOD_S):
            try:
                mv[_HEARTBEAT] = time.monotonic()
            except (ValueError, TypeError):  # released
                return

    def _servo_alive(self) -> bool:
        if self._process is not None:
            if self._supervisor is not None:
                return self._supervisor.servo_alive()  # False once it has reaped the servo
            return self._process.is_alive()
        return self._thread is not None and self._thread.is_alive()

    @property
    def servo_death_report(self) -> Any:
        """What the application's supervisor did when the servo process died unexpectedly
        (:class:`~hapticsdk.runtime.supervisor.SupervisorReport`), or ``None``."""
        sup = getattr(self, "_supervisor", None)
        return None if sup is None else sup.report

    @property
    def servo_pid(self) -> int | None:
        """Process id of the servo (None in thread isolation)."""
        return self._process.pid if self._process is not None else None

    def _finish_recording(self) -> None:
        """After a process servo ended: when its recording stream is still there (the
        servo was stopped before it finished turning a long stream into the run file:
        ``close(timeout_s)`` waits that long, then SIGTERM), the application does it
        (:func:`~hapticsdk.runtime.recorder.recover`: the stream stays whole until the
        run file is in place, so a cut-short conversion loses nothing)."""
        path = self._spec.get("record_path")
        if not path or self._process is None:
            return
        from .recorder import part_path, recover
        if not part_path(path).exists():
            return
        summary = self._summary if self._summary is not None else {}
        self._summary = summary
        try:
            summary["record_path"] = str(recover(part_path(path), path, objects=dict(self._names)))
            summary["record_finished_by"] = "application"
            summary.pop("record_error", None)
        except Exception as exc:  # noqa: BLE001 - reported; the stream stays for recover()
            summary["record_error"] = f"{type(exc).__name__}: {exc}"

    def _fetch_summary(self, timeout: float = 0.0) -> dict[str, Any]:
        if self._summary is None:
            try:
                if self._done.poll(timeout):
                    self._summary = self._done.recv()
            except (EOFError, OSError):
                pass
        return self._summary or {}

    def _check(self) -> None:
        if self._closed:
            raise SessionError("the session is closed")
        mv = self._mv
        status = mv[_STATUS]
        if status == _RUNNING:
            now = time.monotonic()
            if now - mv[_PUB] < 0.02 or now - self._alive_checked < 0.02:
                # the servo published within 20 ms (it does every tick), or the process
                # was checked (a waitpid) less than 20 ms ago
                return
            if self._servo_alive():
                self._alive_checked = now
                return
        self._fetch_summary(0.5 if status in (_STOPPED, _FAILED) else 0.05)
        s = self._summary or {}
        code = None
        if self._process is not None:
            sup = self._supervisor
            if sup is not None and not sup.is_watcher():
                sup.wait_exit(1.0)  # the supervisor reaps the servo (two waitpid calls would race)
            else:
                self._process.join(1.0)
            code = self._process.exitcode
        if s.get("message"):
            reason = s["message"]
        elif code is not None and code < 0:
            import signal as _signal
            try:
                reason = f"killed by {_signal.Signals(-code).name}"
            except ValueError:
                reason = f"killed by signal {-code}"
        elif code is not None:
            reason = f"exited with status {code}"
            if code == 1 and not s:
                reason += (" before it started (isolation='process' starts the servo with 'spawn', which "
                           "imports the application's main module again: guard its top-level code with "
                           "if __name__ == '__main__':)")
        else:
            reason = s.get("reason") or "stopped"
        raise ServoProcessDied(f"the session's servo is gone: {reason}", reason=reason, exitcode=code)

    def _send(self, msg: tuple) -> None:
        with self._lock:
            self._check()
            try:
                self._cmd.send(msg)
            except (OSError, EOFError, BrokenPipeError) as exc:
                self._check()
                raise SessionError(f"the servo does not take commands: {exc}") from None

    def _prebuilt(self, feats: Mapping[str, Mapping[str, float]]
                  ) -> "tuple[bytes, dict[int, bytes], dict[int, Any]] | None":
        """The renderers of ``feats``, built here exactly as the servo would build them
        (same settings, actuator options and capabilities, calibrations) and pickled,
        with the calibration tables they hold (:func:`_shared_table_types`, e.g. the
        piezo's 300 kB drive table, the same for every material) pickled as references
        ``(_TABLE_PID, key)``; the tables the servo has not been sent yet, ``{key:
        pickled table}``; and those tables themselves, ``{key: table}``. None when they cannot be built or pickled here (the servo then
        builds them from the features). Building here keeps the build (about 1.4 ms of
        CPU for S7, more with cold caches, longer than a servo period's slack) out of the
        servo, and the references keep a switch's unpickling there to about a kilobyte
        (the table alone took ~0.2 ms of the servo's CPU, cold, on every switch). Call with
        ``_build_lock`` held, and mark the new keys sent (``_tables_sent``) only once sent."""
        try:
            if self._builder is None:
                b = _Servo(self._spec, memoryview(bytearray(8)).cast("d"), None, True)
                b.prepare()
                self._builder = b
            rs = self._builder.renderers_for(feats)
            new: dict[int, bytes] = {}
            known = self._tables_sent
            kinds = _shared_table_types()

            class _Pickler(pickle.Pickler):
                def persistent_id(self, obj: Any) -> Any:
                    if type(obj) not in kinds:
                        return None
                    hit = known.get(id(obj))
                    if hit is not None and hit[0] is obj:
                        return (_TABLE_PID, hit[1])
                    for k, o in pending.items():
                        if o is obj:
                            return (_TABLE_PID, k)
                    key = len(known) + len(new) + 1
                    new[key] = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
                    pending[key] = obj
                    return (_TABLE_PID, key)

            pending: dict[int, Any] = {}
            out = io.BytesIO()
            _Pickler(out, protocol=pickle.HIGHEST_PROTOCOL).dump(rs)
            return out.getvalue(), new, pending
        except Exception as exc:  # noqa: BLE001 - the servo builds them instead
            _log.debug("building renderers in the application failed (%s: %s); the servo builds them",
                       type(exc).__name__, exc)
            return None

    def _send_material(self, oid: int, feats: Mapping[str, Mapping[str, float]], ramp: float) -> Any:
        """Send a material switch: the tables the servo has not got yet (their own
        command, unpickled in its own slice, kept by the servo), then the renderers
        (pickled with references to them), or the features when the renderers could not
        be built here. Under ``_build_lock``, so that another thread's switch never
        refers to a table before the command carrying it is sent."""
        from .callbacks import SwitchHandle
        with self._build_lock:
            built = self._prebuilt(feats)
            self._seq += 1
            seq = self._seq
            if built is None:
                sent_at = time.monotonic()
                self._send(("material", oid, feats, ramp, seq))
                return SwitchHandle(self, seq, sent_at)
            payload, new, tables = built
            if new:
                self._send(("tables", new))
                for key, obj in tables.items():
                    self._tables_sent[id(obj)] = (obj, key)
            sent_at = time.monotonic()  # before the send: the servo may render it before we return
            self._send(("renderers", oid, payload, ramp, seq))
            return SwitchHandle(self, seq, sent_at)

    def _object_id(self, name: str) -> int:
        if name not in self._ids:
            raise ValidationError(f"no object {name!r}; objects: {sorted(self._ids)}", field="object")
        return self._ids[name]

    # -- material answers ---------------------------------------------------------------
    def _solve_kw(self) -> dict[str, Any]:
        s = self._settings["solver"]
        return {"model": self._settings.get("model"), "penalty": s.get("penalty", "paper"),
                "tolerance": s.get("tolerance", 0.01), "data_support": bool(s.get("data_support", True))}

    def _warm(self) -> None:
        """Load (or build once and cache) the amortised tables of the scene's dimensions,
        and set up the application's renderer builder (actuator capabilities, saved
        calibrations) with the scene's own materials, while the servo starts."""
        dims = sorted({d for m in self.plan.materials.values() for d in m.dimensions})
        for group in ([d] for d in dims) if len(dims) > 2 else [dims]:
            try:
                self._amortised({d: 0.5 for d in group})
            except HapticSDKError:
                pass
        for m in self.plan.materials.values():
            with self._build_lock:
                self._prebuilt({d: dict(m.features) for d in m.dimensions})

    def _amortised(self, targets: Mapping[str, float]) -> Any:
        """The table's interpolated answer alone (``polish_steps`` 0): the background
        refine does the polishing."""
        from ..problems import solve
        return solve(dict(targets), method="amortised", seed=0, options={"polish_steps": 0},
                     **self._solve_kw())

    def _features_by_dim(self, dims: Sequence[str], x: Mapping[str, float]) -> dict[str, dict[str, float]]:
        from ..plugins import registry
        out = {}
        for d in dims:
            cls = registry("dimension").load(d)
            names = {f.name for f in cls.features}
            out[d] = {k: float(v) for k, v in x.items() if k in names}
        return out

    def _targets(self, material: Any, field: str) -> tuple[str, dict[str, float]]:
        from ..dimensions import check_intensity
        if isinstance(material, str):
            from ..materials import load_library
            if self._library is None:
                self._library = load_library()
            try:
                m = self._library.get(material)
            except (KeyError, LookupError, ValidationError):
                try:
                    m = load_library(with_plugins=True).get(material)
                except (KeyError, LookupError, ValidationError) as exc:
                    raise ValidationError(getattr(exc, "reason", str(exc)), field=field) from None
            return m.name, {d: check_intensity(v, f"{field}.{d}") for d, v in m.intensities.items()}
        if isinstance(material, Mapping) and material:
            from .live_api import intensities  # numbers in 0..1, not '0.5' (issue 31)
            return "intensities", intensities(material, field)
        raise ValidationError(f"expected a material name or {{dimension: intensity}}, got {material!r}", field=field)

    def _answer(self, targets: Mapping[str, float]) -> tuple[dict[str, dict[str, float]], str, Any]:
        dims = list(targets)
        res = None
        source = "amortised"
        if len(dims) <= 2:
            try:
                res = self._amortised(targets)
            except HapticSDKError:
                res = None
        if res is None:
            from ..problems import solve
            method = self._settings["solver"]["method"]
            res = solve(dict(targets), method=method, seed=self._settings["solver"].get("seed", 0),
                        options=dict(self._settings["solver"].get("options") or {}), **self._solve_kw())
            source = method
        return self._features_by_dim(dims, res.x_dict), source, res

    def _check_roles(self, feats: Mapping[str, Mapping[str, float]], field: str) -> None:
        from ..plugins import registry
        for d in feats:
            cls = registry("dimension").load(d)
            roles = set(getattr(cls, "default_actuators", {}) or {})
            missing = sorted(roles - set(self.devices))
            if missing:
                raise ValidationError(f"dimension {d!r} needs role(s) {missing}, which this session has not "
                                      f"opened (roles: {sorted(self.devices)})", field=field)

    def _refine(self, r: Retarget, oid: int) -> None:
        from ..problems import solve
        try:
            s = self._settings["solver"]
            res = solve(dict(r.targets), method=s["method"], seed=s.get("seed", 0),
                        options=dict(s.get("options") or {}), **self._solve_kw())
            feats = self._features_by_dim(list(r.targets), res.x_dict)
            r.refined_features = feats
            if res.success and feats != r.features and not self._closed:
                r.refined_switch = self._send_material(oid, feats, self.ramp_s)
                r.refined_sent = True
                self._local_events.append(SessionEvent(self._mv[_T], "material_refined", r.object,
                                                       float(res.error)))
        except Exception as exc:  # noqa: BLE001 - the amortised answer stays in force
            _log.warning("refining %s failed: %s", r.object, exc)
        finally:
            r.refined.set()

    # -- public API -------------------------------------------------------------------
    def set_material(self, object: str, material: "str | Mapping[str, float]", *,
                     ramp_s: float | None = None, refine: bool | None = None) -> Retarget:
        """Give ``object`` a new material: a library name (``"S7"``) or intensities
        (``{"hardness": 0.9, "roughness": 0.2}``). The amortised inverse answers at once
        and the servo switches with a ``ramp_s`` cross-fade; the scene's solver refines
        the answer in a background thread (``refine``). Returns a :class:`Retarget`."""
        oid = self._object_id(object)
        label, targets = self._targets(material, "material")
        feats, source, res = self._answer(targets)
        self._check_roles(feats, "material")
        ramp = self.ramp_s if ramp_s is None else float(ramp_s)
        if not (math.isfinite(ramp) and 0 <= ramp <= 5):
            raise ValidationError(f"ramp_s must be in [0, 5] s, got {ramp_s!r}", field="ramp_s")
        handle = self._send_material(oid, feats, ramp)
        self._materials[object] = label
        ints = getattr(res, "intensities", None)
        r = Retarget(object=object, targets=dict(targets), features=feats, source=source,
                     success=bool(res.success), error=float(res.error),
                     intensities=({str(k): float(v) for k, v in ints.items()} if isinstance(ints, Mapping)
                                  else {d: float(v) for d, v in zip(targets, list(ints))} if ints is not None
                                  else {}), switch=handle)
        if (self.refine if refine is None else refine) and source == "amortised":
            th = threading.Thread(target=self._refine, args=(r, oid), name="hapticsdk-refine", daemon=True)
            self._threads.append(th)
            th.start()
        else:
            r.refined.set()
        return r

    def add_object(self, name: str, material: "str | Mapping[str, float]", geometry: Mapping[str, Any],
                   pose: Mapping[str, Any] | None = None) -> None:
        """Add an object: a material (as for :meth:`set_material`), a geometry in the
        scene-file form (``{"shape": "sphere", "radius_mm": 15}``) and a pose
        (``{"position_mm": [x, y, z]}``)."""
        from ..scene.geometry import shape_from_dict
        if not isinstance(name, str) or not name or name in self._ids:
            raise ValidationError(f"object name must be new and non-empty, got {name!r}", field="name")
        shape = shape_from_dict(geometry, pose)
        from .live_api import check_object, session_workspace  # inside the workspace + margin
        check_object(shape, f"objects.{name}", session_workspace(self.devices))
        label, targets = self._targets(material, "material")
        feats, _, _ = self._answer(targets)
        self._check_roles(feats, "material")
        self._check()
        oid = self._new_id(name)
        self._send(("add", oid, name, feats, shape.geometry_dict(), shape.pose.to_dict()))
        self._materials[name] = label

    def remove_object(self, name: str) -> None:
        """Remove an object from the scene the servo renders."""
        oid = self._object_id(name)
        self._send(("remove", oid))
        del self._ids[name]
        self._materials.pop(name, None)

    def move_object(self, name: str, pose: Mapping[str, Any]) -> None:
        """Move an object to ``pose`` (``{"position_mm": [x, y, z], "rotation": ...}``, mm)."""
        from ..scene.geometry import Pose
        oid = self._object_id(name)
        p = Pose.from_dict(pose)
        from .live_api import session_workspace
        from ..scene.bounds import check_shape  # inside the workspace + margin (issue 31)
        check_shape({}, p.to_dict(), f"objects.{name}", workspace=session_workspace(self.devices))
        self._send(("pose", oid, p.to_dict()))

    @property
    def object_ids(self) -> dict[int, str]:
        """Object id (as in a ``log_path`` file's ``object_id``) -> name, every object
        the session has had."""
        return dict(self._names)

    @property
    def objects(self) -> dict[str, str]:
        """Object name -> the material it was last given."""
        return dict(self._materials)

    def state(self) -> SessionState:
        """The servo's latest state (never blocks; a few microseconds)."""
        if self._closed:
            self._check()  # raises SessionError
        mv = self._mv
        buf = self._bytes
        for i in range(10000):
            # one struct read of the sequence number, the 23 state slots and the
            # sequence copy: equal and even = a consistent copy (see _Servo.run)
            vals = _read_state(buf)
            s1 = vals[0]
            if s1 == vals[24] and s1 % 2.0 == 0.0:
                break
            if i >= 2:
                time.sleep(0)  # let a writer in this process (thread isolation) finish
        else:  # a servo that died mid-write
            self._check()
            raise SessionError("the servo's state is being written and never settled")
        now = time.monotonic()
        # _check()'s fast path on the values just read (one clock read, no call): a running
        # servo that published within 20 ms, or whose process was checked within 20 ms
        if not (mv[_STATUS] == _RUNNING and (now - vals[_PUB] < 0.02 or now - self._alive_checked < 0.02)):
            self._check()
        return _state_from(vals, self._names, now)

    # -- events, acknowledgements, callbacks ----------------------------------------------
    def _event_write_index(self) -> int:
        return int(self._mv[_EV_W])

    def _servo_died_event(self, exc: ServoProcessDied) -> SessionEvent:
        """The ``servo_died`` event of a servo that ended without being asked (the exit
        status in ``value``, NaN when unknown; the reason in ``message``)."""
        code = exc.exitcode
        return SessionEvent(self._last_t(), "servo_died", None, float(code) if code is not None else math.nan,
                            message=str(exc.reason or exc))

    def _last_t(self) -> float:
        try:
            return float(self._mv[_T])
        except (ValueError, TypeError):
            return math.nan

    def _events_since(self, r: int) -> tuple[list[SessionEvent], int]:
        """The servo's events from ring position ``r`` on (at most the last 1024) and the
        next position. Clamp events get their actuator and field decoded."""
        mv = self._mv
        w = int(mv[_EV_W])
        r = max(r, w - _EV_CAP)
        names = self._names
        out: list[SessionEvent] = []
        nf = len(CLAMP_FIELDS)
        while r < w:
            j = _EV0 + (r % _EV_CAP) * _EV_REC
            t, kind, oid, val, detail, count = mv[j], mv[j + 1], mv[j + 2], mv[j + 3], mv[j + 4], mv[j + 5]
            k = EVENT_KINDS[int(kind)]
            obj = names.get(int(oid)) if oid >= 0 else None
            if k == "clamp" and detail >= 0:
                ri, fi = divmod(int(detail), nf)
                roles = self._roles
                out.append(SessionEvent(t, k, obj, val, roles[ri] if ri < len(roles) else "device",
                                        CLAMP_FIELDS[fi][0], int(count)))
            else:
                out.append(SessionEvent(t, k, obj, val))
            r += 1
        return out, w

    def _vibration(self) -> dict[str, list[float | None]]:
        """Role -> [frequency Hz, amplitude] of the vibration channels on the last tick
        (for the live view; not under the seqlock)."""
        mv = self._mv
        out: dict[str, list[float | None]] = {}
        for k in range(_VIB_N):
            j = _VIB0 + 3 * k
            ri = int(mv[j])
            if 0 <= ri < len(self._roles):
                f, a = mv[j + 1], mv[j + 2]
                out[self._roles[ri]] = [f if math.isfinite(f) else None, a if math.isfinite(a) else None]
        return out

    def open_view(self, port: int = 0) -> str:
        """Serve the live view (:mod:`hapticsdk.runtime.view`) on 127.0.0.1 and return
        its address; once per session (later calls return the same address)."""
        self._check()
        if self.view is None:
            from .view import ViewServer
            self.view = ViewServer(self, port)
        return self.view.url

    def _ack_of(self, seq: int) -> tuple[float, float, float] | None:
        """(tick, servo time, monotonic time) of switch ``seq`` once acknowledged, else None."""
        mv = self._mv
        j = _ACK0 + (seq % _ACK_CAP) * _ACK_REC
        if mv[j] != seq:
            return None
        tick, t, mono = mv[j + 1], mv[j + 2], mv[j + 3]
        if mv[j] != seq:  # overwritten while read (256 later switches): gone
            return None
        return tick, t, mono

    def on_event(self, kind: str, callback: Any) -> None:
        """Call ``callback(event)`` for every event of ``kind`` (one of
        :data:`EVENT_KINDS`, or ``"*"`` for all) on the SDK's own application thread
        ``hapticsdk-events`` (within about 2 ms of the servo publishing it; never in the
        servo). The first callback registered also gets the events published since the
        session started (at most the last 1024), so a contact made while the application
        was still setting up is not lost; a callback added later gets them from then on. ``"servo_died"`` is delivered once when the
        servo process ends without :meth:`close` (``message`` says why). Callbacks run
        one at a time, in the order given; one that raises is logged and skipped."""
        if kind != "*" and kind not in EVENT_KINDS:
            raise ValidationError(f"kind must be one of {list(EVENT_KINDS)} or '*', got {kind!r}", field="kind")
        if not callable(callback):
            raise ValidationError(f"callback must be callable, got {callback!r}", field="callback")
        self._check()
        self._dispatcher.add(kind, callback)

    def off_event(self, kind: str, callback: Any) -> bool:
        """Remove a callback given to :meth:`on_event`; True when it was registered."""
        return self._dispatcher.remove(kind, callback)

    def events(self) -> list[SessionEvent]:
        """Events since the last call, oldest first (never blocks). When more than 1024
        arrived in between, the oldest are lost and a ``"lost"`` count is not kept.
        Raises :class:`~hapticsdk.errors.ServoProcessDied` once the servo is gone (as
        every call does); after :meth:`close`, returns what was left."""
        out: list[SessionEvent] = []
        if not self._closed:
            mv = self._mv
            now = time.monotonic()
            # as state(): the fast path on a servo that published within 20 ms
            if not (mv[_STATUS] == _RUNNING and (now - mv[_PUB] < 0.02 or now - self._alive_checked < 0.02)):
                self._check()
            out, self._events_r = self._events_since(self._events_r)
        if self._local_events:
            loc, self._local_events = self._local_events, []
            out.extend(loc)
            out.sort(key=lambda e: e.t)
        return out

    def pause(self, on: bool = True) -> None:
        """Pause (True) or resume (False): while paused no renderer runs, force 0 and
        vibration amplitude 0 are sent; the probe is still read."""
        self._check()
        self._mv[_PAUSE] = 1.0 if on else 0.0

    def resume(self) -> None:
        """Resume after :meth:`pause`."""
        self.pause(False)

    def close(self, timeout_s: float = 5.0) -> dict[str, Any]:
        """Stop every actuator, end the servo (reap its process), release the shared
        memory. Idempotent; never raises for a servo that is already gone. Returns the
        servo's summary (``reason``, ``stopped`` actuator labels, ``report``)."""
        if self._closed:
            return self._summary or {}
        self._closed = True
        sup = getattr(self, "_supervisor", None)
        if sup is not None:
            sup.expect_exit()  # the servo stops the devices itself on this path
        disp = getattr(self, "_dispatcher", None)
        if disp is not None:
            disp.stop()
        if getattr(self, "view", None) is not None:
            try:
                self.view.close()
            except Exception:  # noqa: BLE001
                pass
        buf = getattr(self, "_buf", None)
        try:
            if buf is not None:
                try:
                    self._mv[_STOP] = 1.0
                except (ValueError, TypeError):
                    pass
            if self._thread is not None:
                self._thread.join(timeout_s)
            if self._process is not None and getattr(self._process, "_popen", None) is not None:
                # the supervisor waits on the process (one waitpid caller: a second
                # one could see "no such child" and take a reaped servo for alive)
                wait = sup.wait_exit if sup is not None else self._process.join
                alive = sup.servo_alive if sup is not None else self._process.is_alive
                wait(timeout_s)
                if alive():
                    self._process.terminate()  # SIGTERM: the servo's safe stop
                    wait(2.0)
                if alive():
                    self._process.kill()
                    wait(2.0)
                    if sup is not None:  # killed without its stop path: standby from here
                        sup.standby_all(time.monotonic())
            self._fetch_summary(0.1)
            if sup is not None:
                sup.stop()
            self._finish_recording()
        finally:
            hb = getattr(self, "_hb_stop", None)
            if hb is not None:
                hb.set()
                self._hb.join(1.0)
            for c in ("_cmd", "_done"):
                conn = getattr(self, c, None)
                if conn is not None:
                    try:
                        conn.close()
                    except OSError:
                        pass
            if self._process is not None and getattr(self._process, "_popen", None) is not None:
                try:
                    self._process.close()
                except ValueError:
                    pass
            if buf is not None:
                try:   # what the servo wrote after the application's last events(): kept for it
                    tail, self._events_r = self._events_since(self._events_r)
                    self._local_events.extend(tail)
                except Exception as exc:  # noqa: BLE001 - the close matters more
                    _log.warning("events left at close: %s", exc)
                self._buf = None
                buf.release()
        return self._summary or {}

    def __enter__(self) -> "Session":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __del__(self) -> None:  # pragma: no cover - best effort
        try:
            if not self._closed:
                self.close(1.0)
        except Exception:  # noqa: BLE001
            pass


def session(scene: Any, **options: Any) -> Session:
    """Open a live :class:`Session` on ``scene`` (same keywords)."""
    return Session(scene, **options)
