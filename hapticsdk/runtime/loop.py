"""The servo loop: read the probe, find the object it touches, run that object's
renderers, send the commands, step the simulation, once per period.

:class:`ServoLoop` is steppable: :meth:`ServoLoop.start` opens the actuators and sets up
the run, :meth:`ServoLoop.tick` runs one period, :meth:`ServoLoop.finish` restores the
process state and returns the :class:`LoopReport`. :meth:`ServoLoop.run` (the batch path
of :func:`hapticsdk.render` and :func:`~hapticsdk.runtime.render.render_plan`) is
``start`` + ``tick`` until the duration is reached + ``finish``; a live
:class:`~hapticsdk.runtime.session.Session` drives the same ``tick`` for as long as the
application wants.

Each tick:

1. ``state`` = the device's sensed state; non-finite or huge readings and velocity
   spikes are replaced by safe values and counted (never raised);
2. the hit test (a :class:`hapticsdk.scene.geometry.HitTester`, or without one the
   version-1 scene: the plane y = 0 with normal +y, penetration ``-y``) gives the
   object under the probe, the penetration along its outward normal and the normal;
   every actuator's safety layer observes the state (with that penetration);
3. that object's renderers get a :class:`~hapticsdk.perception.dimensions.TickInput` in the contact
   frame (penetration along the normal; velocity index 0 the sliding speed, index 1 the
   normal component; ``normal`` and ``object`` set); force commands of the same role
   are summed, a renderer that raises or returns NaN is counted and contributes nothing.
   While an object's material is being switched (:meth:`ServoLoop.set_renderers`) its
   old and new renderers both run. A force that the switch would raise keeps its value
   and takes the new law's slope (``F = max(F_new - D, 0)``, ``D = F_new - F_old`` at the
   switch: the rest point moved inwards, released at zero force and when the contact
   ends), so stiffening a pressed material creates no energy and makes no step; a force
   the switch lowers, and every vibration amplitude (at the new frequency), is
   cross-faded linearly over the switch ramp (``switch_ramp_s``, default 50 ms):
   ``(1 - a) F_old + a F_new``, ``a`` rising from 0 to 1 (see :meth:`ServoLoop._law`);
4. the force role goes through the passivity observer/controller
   (:class:`~hapticsdk.passivity.PassivityController`, on by default) along the contact
   normal (its position is the signed distance ``-penetration``; the observer restarts
   when the probe moves from one object to another, as when a wall is met from outside,
   and out of contact in a spatial scene it holds its last position); the force command
   carries the normal as ``direction``;
5. each role's command is sent as ``actuator.command(cmd, now=t)`` would send it (bound
   once per run: :func:`~hapticsdk.devices.actuators.servo_sender`; the safety layer
   clamps it) and optionally recorded;
6. simulated devices are stepped (``device.step(dt)``, then every other simulated
   actuator with a ``step`` method).

In a steady state (every renderer offers a law on plain floats, every actuator a compiled
send, its safety layer running, nothing switching or queued) steps 3 and 5 run through
those instead of ``tick`` and ``command``, with the same outputs bit for bit
(``fast_tick``, :meth:`ServoLoop._build_steady`; docs/runtime.md, "Tick cost, round 11").

Delay accounting: the force computed from the state of tick ``n`` is held from tick
``n`` to ``n+1``, so the loop's computational delay is ``d = 0`` (one zero-order hold);
``delay_ticks`` adds ``d`` more ticks for tests of the delay law.

Memory: the per-tick log is a ring buffer holding the last ``log_seconds`` (default
60 s, at most :data:`MAX_LOG_TICKS` ticks) of ticks, whatever the duration (``report.log`` is that window, oldest first),
written through once by :meth:`ServoLoop.start` so that no tick waits for a fresh page;
counts, the overrun total and the maximum tick time cover the whole run, the percentiles
the window. A recorder (``recorder=``, e.g. :class:`hapticsdk.runlog.RunRecorder`)
streams every tick to a run file.

Time: by default simulated time (``t = n T``, as fast as possible, each tick's compute
time measured with ``perf_counter`` and, as on-CPU time of the servo thread, with
``thread_time_ns``; a tick whose wall time exceeds its CPU time by more than 100 us was
preempted); with ``realtime=True`` the loop paces itself on a
clock (hybrid sleep-then-spin) against a fixed deadline grid, hands renderers the
*measured* ``dt``, catches up after a late tick without skipping a deadline, and
re-anchors the grid (counting the skipped ticks) only when more than
``max_catchup_ticks`` behind.

Stops: a :class:`DeviceError` from any actuator stops *all* actuators, ends the run
cleanly with ``report.fault`` set, and is re-raised from :meth:`ServoLoop.run` when
``raise_on_fault``. ANY other exception leaving a tick (KeyboardInterrupt, SystemExit,
:class:`~hapticsdk.runtime.signals.SafeStop` for SIGTERM/SIGHUP, an OSError from a sink,
anything from a renderer's caller, recorder or actuator) stops every actuator first and
then propagates unchanged. Optional OS options for the servo thread (CPU pinning,
``SCHED_FIFO``, ``mlockall``; ``rt=``) report their outcome in ``report.rt`` and never
raise.
"""

from __future__ import annotations

import gc
import logging
import math
import struct
import sys
import time
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ..devices.safety import SafetyLayer
from ..devices.actuators import Actuator, DeviceState, HapticDevice, SensedState, _frozen3, force_axes_of, servo_sender
from ..perception.dimensions import ChannelCommand, DimensionRenderer, TickInput, _steady_law_of
from ..errors import DeviceError, ValidationError
from ..passivity import ControllerSettings, PassivityController
from ..quantiles import median
from .clock import MonotonicClock, RealtimeSettings, apply_realtime, thread_cpu_clock_cost_s
from .turns import NormalTurns, carrier
from .stats import PREEMPT_THRESHOLD_S, jitter_stats, preemption_stats, tick_stats

_log = logging.getLogger(__name__)

_NAN = float("nan")
# bound once (the tick's checks of renderer outputs and states): the same comparisons and
# calls as ``f in (math.inf, -math.inf)`` and ``math.isfinite``, without building the tuple
# and looking the names up on every command (~1.4k instructions a tick)
_INFS = (math.inf, -math.inf)
_isfinite = math.isfinite
_new = object.__new__

#: event counters every report carries (0 when nothing happened)
EVENT_KEYS = ("nonfinite_state", "huge_state", "velocity_spike", "renderer_error", "nonfinite_command",
              "negative_force", "role_conflict", "overrun", "clamp", "skipped_ticks", "passivity_active",
              "contact_changes", "material_switches")

#: default length of the per-tick log window (s)
DEFAULT_LOG_SECONDS = 60.0
#: the log window never holds more ticks than this (2**17: 131 s at 1 kHz, ~18 MB)
MAX_LOG_TICKS = 2 ** 17
#: default duration of the cross-fade when an object's renderers are replaced (s)
DEFAULT_SWITCH_RAMP_S = 0.05
#: rules of :meth:`ServoLoop.set_renderers` for the force roles
SWITCH_RULES = ("passive", "cross-fade")
#: default bound on what a switch's cross-fade moves a force in one tick (N)
DEFAULT_SWITCH_MAX_STEP_N = 0.1

_UP = (0.0, 1.0, 0.0)

#: the log ring's first columns; three per role follow (force_n, frequency_hz, amplitude),
#: then compute, cpu, sim (s)
_COLS = ("t", "dt", "pen", "obj", "f", "px", "py", "pz", "vx", "vy", "vz")
_NCOL = len(_COLS)


@dataclass
class LoopReport:
    """What a servo run did.

    Attributes:
        ticks: ticks executed.
        period_s: nominal period (s).
        realtime: paced on a clock (True) or simulated time.
        tick_median_us, tick_p99_us: per-tick compute time of the control path (read,
            hit test, renderers, passivity, commands, logging), excluding simulated
            physics (us), wall clock (``perf_counter``): includes time the thread was off
            the CPU (preempted by another process); percentiles over the log window.
        tick_max_us: the largest of the whole run (us).
        tick_p999_us: p99.9 of the same (us).
        tick_cpu_median_us, tick_cpu_p99_us, tick_cpu_p999_us, tick_cpu_max_us: the same
            ticks' on-CPU time of the servo thread (``thread_time_ns``), what the tick
            code costs (us); NaN when ``cpu_time=False``.
        preempted_ticks: ticks of the window whose wall compute exceeded their CPU compute
            by more than ``preempt_threshold_us`` (100 us); None when ``cpu_time=False``.
        off_cpu_max_us: largest wall - CPU compute of a tick (us).
        cpu_clock_cost_us: measured cost of the two CPU-clock reads a tick makes (us).
        rt: outcome of the OS options: ``cpu_affinity``, ``rt_priority``, ``mlockall``,
            ``gc`` (``"off"``, ``"applied: ..."``, ``"refused: <reason>"``,
            ``"unavailable: <reason>"``) and ``applied`` (names applied).
        sim_step_median_us: median time spent stepping simulated devices (us).
        overruns: ticks of the whole run whose compute time exceeded the period.
        jitter: |period - T| statistics and missed-tick rate over the window (realtime
            mode), plus ``missed_ticks_total`` over the whole run; else None.
        events: counts of unsafe inputs replaced, clamps, skipped ticks, contact changes,
            material switches ...
        passivity: observer/controller figures per force role (J), or {} when off.
        fault: ``{"device", "message"}`` of the failure that stopped the run, or None.
        log: numpy arrays per tick of the last ``log_window_s``: ``t`` (s), ``dt`` (s),
            ``penetration_mm`` (along the contact normal), ``object`` (index of the object
            under the probe, -1 none), ``position_mm`` (n, 3), ``velocity_mm_s`` (n, 3),
            ``force_n`` (sent, along the normal), and per role every field it was sent:
            ``<role>.force_n`` (N, NaN when the command carried none),
            ``<role>.frequency_hz`` (Hz, NaN when none) and ``<role>.amplitude``.
        log_window_s: length of the log window (s); ``objects``: object names by index.
    """

    ticks: int
    period_s: float
    realtime: bool
    tick_median_us: float
    tick_p99_us: float
    tick_max_us: float
    overruns: int
    jitter: dict[str, float] | None
    events: dict[str, int]
    passivity: dict[str, Any]
    fault: dict[str, str] | None
    sim_step_median_us: float = float("nan")
    tick_p999_us: float = float("nan")
    tick_cpu_median_us: float = float("nan")
    tick_cpu_p99_us: float = float("nan")
    tick_cpu_p999_us: float = float("nan")
    tick_cpu_max_us: float = float("nan")
    preempted_ticks: int | None = None
    preempt_threshold_us: float = PREEMPT_THRESHOLD_S * 1e6
    off_cpu_max_us: float = float("nan")
    cpu_clock_cost_us: float = float("nan")
    rt: dict[str, Any] = field(default_factory=dict)
    log: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    log_window_s: float = DEFAULT_LOG_SECONDS
    objects: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the log is summarised by its keys and length)."""
        d = {k: getattr(self, k) for k in ("ticks", "period_s", "realtime", "tick_median_us", "tick_p99_us",
                                            "tick_p999_us", "tick_max_us", "sim_step_median_us", "overruns",
                                            "jitter", "events", "passivity", "fault")}
        d["compute_us"] = {"median_us": self.tick_median_us, "p99_us": self.tick_p99_us,
                           "p999_us": self.tick_p999_us, "max_us": self.tick_max_us, "clock": "wall"}
        d["compute_cpu_us"] = {"median_us": self.tick_cpu_median_us, "p99_us": self.tick_cpu_p99_us,
                               "p999_us": self.tick_cpu_p999_us, "max_us": self.tick_cpu_max_us,
                               "clock": "thread_cpu"}
        for k in ("preempted_ticks", "preempt_threshold_us", "off_cpu_max_us", "cpu_clock_cost_us", "rt",
                  "log_window_s", "objects"):
            d[k] = getattr(self, k)
        d["log_keys"] = sorted(self.log)
        return d


def _distinct(acts: Any) -> list:
    """The actuators of ``acts`` once each (by identity), in order."""
    return list({id(a): a for a in acts}.values())


class _Slot:
    """Per-role bookkeeping."""

    __slots__ = ("role", "act", "force", "pc", "col", "is_force", "pending", "cmd", "send", "log_n", "log_f",
                 "log_a", "f_in", "v_in", "v_fast")
    #: what the role was sent, by tick: (cap,) views of the loop's log ring (set by start)
    log_n: np.ndarray
    log_f: np.ndarray
    log_a: np.ndarray

    def __init__(self, role: str, act: Actuator, is_force: bool) -> None:
        self.role = role
        self.act = act
        self.is_force = is_force
        #: what the renderers commanded this tick, read (and reset) when the role is sent:
        #: the sum of the force commands (N), the vibration command (None: none)
        self.f_in = 0.0
        self.v_in: ChannelCommand | None = None
        #: the steady-state tick's vibration command, ``(force_n, frequency_hz, amplitude)``
        self.v_fast: tuple | None = None
        self.pc: PassivityController | None = None
        self.pending: deque | None = None
        #: first of this role's three log columns (force_n, frequency_hz, amplitude)
        self.col = 0
        #: the loop's command record of this role, reused every tick (the actuator keeps
        #: only what its safety layer returns, a new record)
        self.cmd = ChannelCommand(role, 0.0 if is_force else None, None, None if is_force else 0.0)
        #: ``send(cmd, now)``: the actuator's command path, bound when the run starts
        self.send = servo_sender(act)


class _Switch:
    """A material switch in progress on one object (see :meth:`ServoLoop.set_renderers`).

    ``old`` and ``old_sw`` are the force law in effect before the switch (renderers, and
    the switch that was still in progress on them, if any); ``t0`` the time of the last
    tick that rendered the switch (None before the first); ``a`` the cross-fade's progress
    (0 .. 1); ``offset`` (set on that tick) maps each
    force role that stiffened to the force (N) the new law holds back, ``fade`` the force
    roles cross-faded (softened, or every role under the ``"cross-fade"`` rule);
    ``touched``: the probe was on the object when the switch was made (else the forces
    take the new law at once: nothing was pressed into the old one)."""

    __slots__ = ("old", "old_sw", "ramp_s", "t0", "a", "offset", "fade", "touched")

    def __init__(self, old: list | None, old_sw: "_Switch | None", ramp_s: float, touched: bool) -> None:
        self.old: list[DimensionRenderer] | None = old
        self.old_sw = old_sw
        self.ramp_s = ramp_s
        self.touched = touched
        self.t0: float | None = None
        self.a = 0.0
        self.offset: dict[str, float] | None = None
        self.fade: tuple[str, ...] = ()

    def end_contact(self) -> None:
        """Contact with the object ended: every held-back force is released (the moved
        rest point is back on the surface), here and in the switch it started from."""
        sw: _Switch | None = self
        while sw is not None:
            if sw.offset:
                sw.offset.clear()
            sw = sw.old_sw


class _Obj:
    """One object's renderers and its material switch in progress."""

    __slots__ = ("name", "renderers", "sw")

    def __init__(self, name: str, renderers: Sequence[DimensionRenderer]) -> None:
        self.name = name
        self.renderers = list(renderers)
        self.sw: _Switch | None = None


class _ContactState(SensedState):
    """The device state as the safety layers see it: with the penetration along the
    contact normal of the object under the probe (``DeviceState.penetration_mm`` is the
    version-1 ``-y``)."""

    __slots__ = ("_pen",)
    _pen: float

    @property
    def penetration_mm(self) -> float:
        """Depth along the contact normal of the object under the probe (mm)."""
        return self._pen

    @classmethod
    def at(cls, st: SensedState, pen: float) -> "_ContactState":
        c = cls.of(st.t, st.px, st.py, st.pz, st.vx, st.vy, st.vz, st.fx, st.fy, st.fz, st.buttons)
        c._pen = pen
        return c


class _LoopInput(TickInput):
    """The loop's :class:`~hapticsdk.perception.dimensions.TickInput`: ``velocity_mm_s`` is built
    from ``velocity_floats_mm_s`` on its first read and kept (the same read-only (3,)
    array the input carried before, the same numbers), so a tick whose renderers read
    the floats makes no numpy array: on the benchmark's tick, creating one array and
    indexing it cost ~8 % of the tick's CPU time, most of it in re-loading numpy's code
    into the CPU caches each tick (docs/runtime.md, "Tick figures")."""

    _va: "np.ndarray | None"

    @property   # type: ignore[override]
    def velocity_mm_s(self) -> np.ndarray:
        """Probe velocity in the contact frame, (3,) read-only (mm/s): see TickInput."""
        a = self._va
        if a is None:
            v = self.velocity_floats_mm_s
            a = self._va = _frozen3(v[0], v[1], v[2])   # type: ignore[index]
        return a

    @velocity_mm_s.setter
    def velocity_mm_s(self, value: Any) -> None:
        # TickInput's __init__ (also dataclasses.replace) assigns the field: None = build on read
        self._va = value


def _rendered_force(f: float | None, events: dict) -> float | None:
    """A force a renderer commanded, as the loop adds it to its role: None for none (not
    commanded, or not finite: counted), a negative one counted and taken as 0."""
    if f is None:
        return None
    if f != f or f in _INFS:
        events["nonfinite_command"] += 1
        return None
    if f < 0.0:
        events["negative_force"] += 1
        return 0.0
    return f


def _rendered_vibration_ok(fr: float | None, am: float | None, events: dict) -> bool:
    """Whether a vibration command's frequency and amplitude are finite (or absent); a
    command that is not is counted (the loop then sends amplitude 0)."""
    if (fr is not None and not _isfinite(fr)) or (am is not None and not _isfinite(am)):
        events["nonfinite_command"] += 1
        return False
    return True


def _check_renderers(renderers: Sequence[DimensionRenderer], actuators: Mapping[str, Actuator],
                     drop_unmapped: bool) -> list[DimensionRenderer]:
    out = list(renderers)
    for r in out:
        if not isinstance(r, DimensionRenderer):
            raise ValidationError(f"{r!r} is not a DimensionRenderer", field="renderers")
        missing = [role for role in r.roles if role not in actuators]
        if missing and not drop_unmapped:
            raise ValidationError(f"renderer {type(r).__name__} commands role(s) {missing} with no "
                                  f"actuator; mapped roles: {sorted(actuators)}", field="actuators")
    return out


class ServoLoop:
    """Run renderers against a device and actuators at a fixed period.

    Args:
        device: the sensing device (its state drives the renderers).
        renderers: the renderers of the version-1 scene (one material on the plane
            y = 0). Ignored when ``objects`` is given.
        actuators: role -> actuator; the device may serve the role ``"force"``. Default
            ``{"force": device}``. Every role a renderer commands must be mapped.
        period_s: servo period T (s).
        realtime: pace on a clock instead of simulated time.
        recorder: object with ``record(t, state, sent)`` called every tick (and
            ``close()`` at the end), e.g. a run-file writer.
        passivity: passivity observer/controller on the force roles (default on).
        raise_on_fault: re-raise the :class:`DeviceError` that stopped a run.
        clock: clock for realtime mode (default :class:`MonotonicClock`).
        delay_ticks: extra computational delay d of the force path (ticks, default 0).
        max_position_mm, max_speed_mm_s: readings beyond these are "huge" (unsafe).
        max_accel_mm_s2: a velocity change faster than this is a spike (held).
        max_catchup_ticks: realtime: how far behind the loop may run before it re-anchors.
        passivity_settings: :class:`~hapticsdk.passivity.ControllerSettings` (default: the
            device's, :meth:`~hapticsdk.passivity.ControllerSettings.for_device`). Without a
            ``period_s`` the loop uses a copy with its own period (``passivity_settings``
            holds it).
        drop_unmapped_roles: ignore commands for roles with no actuator (counted as
            ``role_conflict``) instead of refusing to build the loop.
        cpu_time: also measure each tick's on-CPU time of the servo thread (default on;
            two ``thread_time_ns`` reads per tick, ~1-2 us on Linux).
        rt: :class:`~hapticsdk.runtime.clock.RealtimeSettings` or a mapping of its
            fields (``cpu``, ``fifo_priority``, ``gc_freeze``, ``mlockall``): OS options
            applied to the thread calling :meth:`run` for the run and undone after;
            refusals are reported in ``report.rt``, never raised. Default: none (GC is
            collected, frozen and disabled as always).
        objects: ``[(name, renderers), ...]``: the objects of a spatial scene, in the
            order of ``hit_tester``'s indices.
        hit_tester: object with ``query(x_mm, y_mm, z_mm) -> (index or -1,
            penetration_mm, nx, ny, nz)`` (:class:`hapticsdk.scene.geometry.HitTester`).
            None: the version-1 plane y = 0 (penetration ``-y``, normal +y).
        log_seconds: length of the per-tick log window (s), default 60.
        velocity_filter_hz: corner (Hz) of the first-order low-pass giving renderers
            ``TickInput.velocity_filtered_mm_s`` (default 30 Hz; the raw velocity stays in
            ``velocity_mm_s``).
        switch_ramp_s: default cross-fade of :meth:`set_renderers` (s), default 0.05.
        switch_rule: ``"passive"`` (default): a force a material switch raises is held
            at its value with the new law's slope, one it lowers is ramped (see
            :meth:`set_renderers`); ``"cross-fade"``: every force cross-faded linearly
            (the earlier rule, kept for comparison: stiffening a pressed material then
            hands the finger up to ``(K2 - K1) p^2 / 2``).
        switch_max_step_n: the cross-fade of a switch moves a force by at most this much
            per tick (N, default 0.1): a ramp that would step more is slowed (lasts
            longer than ``ramp_s``).
        fast_tick: use the steady-state parts of the tick where every part offers them
            (renderers' laws on plain floats, actuators' compiled sends; default on; the
            outputs are the same bit for bit, see :meth:`_build_steady`); False: the
            general parts on every tick.
    """

    def __init__(self, device: HapticDevice, renderers: Sequence[DimensionRenderer] = (),
                 actuators: Mapping[str, Actuator] | None = None, *, period_s: float = 0.001,
                 realtime: bool = False, recorder: Any = None, passivity: bool = True,
                 raise_on_fault: bool = True, clock: Any = None, delay_ticks: int = 0,
                 max_position_mm: float = 1000.0, max_speed_mm_s: float = 5000.0,
                 max_accel_mm_s2: float = 2.0e6, max_catchup_ticks: int = 5,
                 passivity_settings: ControllerSettings | None = None,
                 drop_unmapped_roles: bool = False, cpu_time: bool = True,
                 rt: RealtimeSettings | Mapping[str, Any] | None = None,
                 objects: Sequence[tuple[str, Sequence[DimensionRenderer]]] | None = None,
                 hit_tester: Any = None, log_seconds: float = DEFAULT_LOG_SECONDS,
                 switch_ramp_s: float = DEFAULT_SWITCH_RAMP_S, velocity_filter_hz: float = 30.0,
                 switch_rule: str = "passive", switch_max_step_n: float = DEFAULT_SWITCH_MAX_STEP_N,
                 fast_tick: bool = True) -> None:
        if not isinstance(device, HapticDevice):
            raise ValidationError("device must be a HapticDevice", field="device")
        if not (isinstance(period_s, (int, float)) and math.isfinite(period_s) and 1e-5 <= period_s <= 1.0):
            raise ValidationError(f"period must be in [1e-5, 1] s, got {period_s!r}", field="period_s")
        if int(delay_ticks) < 0:
            raise ValidationError("delay_ticks must be >= 0", field="delay_ticks")
        if not (isinstance(log_seconds, (int, float)) and math.isfinite(log_seconds) and 0 < log_seconds <= 3600):
            raise ValidationError(f"log_seconds must be in (0, 3600] s, got {log_seconds!r}", field="log_seconds")
        if not (isinstance(switch_ramp_s, (int, float)) and math.isfinite(switch_ramp_s) and switch_ramp_s >= 0):
            raise ValidationError(f"switch_ramp_s must be >= 0 s, got {switch_ramp_s!r}", field="switch_ramp_s")
        if switch_rule not in SWITCH_RULES:
            raise ValidationError(f"must be one of {list(SWITCH_RULES)}, got {switch_rule!r}", field="switch_rule")
        self.switch_rule = switch_rule
        if not (isinstance(switch_max_step_n, (int, float)) and math.isfinite(switch_max_step_n)
                and switch_max_step_n > 0):
            raise ValidationError(f"must be a force > 0 N, got {switch_max_step_n!r}", field="switch_max_step_n")
        self.switch_max_step_n = float(switch_max_step_n)
        self.device = device
        self.actuators: dict[str, Actuator] = dict(actuators) if actuators is not None else {"force": device}
        self.drop_unmapped_roles = bool(drop_unmapped_roles)
        if objects is None:
            objs = [_Obj("surface", _check_renderers(renderers, self.actuators, self.drop_unmapped_roles))]
        else:
            objs = [_Obj(str(n), _check_renderers(rs, self.actuators, self.drop_unmapped_roles))
                    for n, rs in objects]
            if hit_tester is None and len(objs) != 1:
                raise ValidationError("several objects need a hit_tester", field="hit_tester")
        self._objs = objs
        #: the steady-state parts of the tick (None: the general parts run; see
        #: _build_steady), whether to try building them at the end of the next tick, and
        #: the count of changes that made them out of date (see _try_fuse)
        self._steady: tuple | None = None
        self._fuse_want = False
        self._fuse_gen = 0
        self._watched: list = []
        self.fast_tick = bool(fast_tick)
        self.hit_tester = hit_tester
        self.renderers = objs[0].renderers if objs else []
        self.period_s = float(period_s)
        self.realtime = bool(realtime)
        self.recorder = recorder
        self.passivity = bool(passivity)
        self.raise_on_fault = bool(raise_on_fault)
        #: the pacing clock (now, wait_until, work): set when realtime, read only then
        self.clock: Any = clock if clock is not None else (MonotonicClock() if realtime else None)
        self._pc_obj: int = -2   # the object whose passivity controllers are active (-2: none)
        self.delay_ticks = int(delay_ticks)
        self.max_position_mm = float(max_position_mm)
        self.max_speed_mm_s = float(max_speed_mm_s)
        self.max_accel_mm_s2 = float(max_accel_mm_s2)
        self.max_catchup_ticks = int(max_catchup_ticks)
        self.log_seconds = float(log_seconds)
        if not (isinstance(velocity_filter_hz, (int, float)) and not isinstance(velocity_filter_hz, bool)
                and math.isfinite(velocity_filter_hz) and velocity_filter_hz > 0):
            raise ValidationError(f"must be a number of Hz > 0, got {velocity_filter_hz!r}",
                                  field="velocity_filter_hz")
        self.velocity_filter_hz = float(velocity_filter_hz)
        self._vf0 = self._vf1 = self._vf2 = 0.0
        self._vf_a = 1.0
        self._v_step = 0.0  # speed step of one encoder count through the filter (mm/s)
        # the device's declared encoder count (mm; 0: an exact position)
        q = float(getattr(device, "encoder_resolution_mm", 0.0) or 0.0)
        self.switch_ramp_s = float(switch_ramp_s)
        if passivity_settings is None:
            # the energy bound from what the device declares (mass, damping, encoder, force limit)
            passivity_settings = ControllerSettings.for_device(device)
            if (passivity_settings.measured_damping_ns_per_m is None
                    and passivity_settings.trusted_damping_ns_per_m() == 0.0
                    and passivity_settings.device_damping_ns_per_m > 0.0):
                _log.info("%s declares a damping of %g N s/m, which the stiff-wall controller does not credit until "
                          "it is measured hands off (hapticsdk calibrate damping --device NAME --save; docs/runtime.md, Passivity item 2): "
                          "a stiff wall is what the energy bound allows an undamped arm",
                          getattr(device, "label", type(device).__name__), passivity_settings.device_damping_ns_per_m)
        if passivity_settings.period_s is None:
            # the Colgate spring sized on this loop's period, not on each measured one (a
            # jittery stiffness stores energy while compressed): a copy, the caller's
            # settings object is left as it was
            passivity_settings = replace(passivity_settings, period_s=self.period_s)
        self.passivity_settings = passivity_settings
        #: contact gate hysteresis (mm): contact begins at penetration > 0 and ends at
        #: penetration <= -one encoder count of the device (0 for an exact position;
        #: times |nx| + |ny| + |nz| on a surface whose normal n is not +y), so a probe
        #: resting at a surface, whose reading flips between two adjacent counts, never
        #: toggles contact (docs/runtime.md, "Gates with hysteresis")
        self.contact_hysteresis_mm = q
        self.cpu_time = bool(cpu_time)
        self.rt = RealtimeSettings.coerce(rt)
        #: operations handed in from other threads, applied at the start of a tick
        self._ops: deque = deque()
        #: pause: renderers are not run, force 0 and vibration amplitude 0 are sent
        self.paused = False
        #: index of the object in contact (penetration > 0), -1 none; updated every tick
        self.contact = -1
        #: last good sensed state, penetration (mm) and sent force (N) of the last tick
        self.last_state: DeviceState | None = None
        self.last_penetration_mm = 0.0
        self.last_force_n = 0.0
        self._pcs: list[PassivityController] = []
        self._turns: NormalTurns | None = None
        self._last_p: tuple[float, float, float] | None = None   # the last position of the one-axis reading
        #: servo time (s) of the last tick (None before the first), the hit test's object
        #: index (-1 none) and the compute time (s) of that tick
        self.last_t: float | None = None
        self.last_index = -1
        self.last_compute_s = 0.0
        self._running = False

    # ------------------------------------------------------------------
    @property
    def object_names(self) -> list[str]:
        """Names of the scene objects the loop renders, in index order (the ``object`` log
        column).
        """
        return [o.name for o in self._objs]

    def _stop_all(self) -> None:
        """Every actuator to its safe state. Each one is tried even when another one's
        ``stop()`` raises (a backend that breaks the never-raise contract, or a second
        Ctrl-C); the first such exception is re-raised after all were tried."""
        first: BaseException | None = None
        for act in _distinct([self.device, *self.actuators.values()]):
            try:
                act.stop()
            except BaseException as exc:  # noqa: BLE001 - keep stopping the others
                _log.error("%s: stop() raised %s: %s", getattr(act, "label", act), type(exc).__name__, exc)
                first = first or exc
        if first is not None:
            raise first

    def stop_all(self) -> None:
        """Put every actuator of the loop in its safe state now (never raises an
        :class:`Exception`; see :meth:`_stop_all`)."""
        try:
            self._stop_all()
        except Exception as exc:  # noqa: BLE001 - logged by _stop_all
            _log.error("stop_all: %s", exc)

    # -- changes while running (thread-safe: applied at the start of the next tick) --
    def set_renderers(self, obj: "int | str", renderers: Sequence[DimensionRenderer],
                      ramp_s: float | None = None) -> None:
        """Replace the renderers of object ``obj`` (index or name): a new material.
        Callable from any thread; applied at the start of the next tick.

        From that tick both materials run and, per force role, at the probe's input of
        that tick:

        * the new force is higher (stiffening while pressed): the force keeps its value
          and follows the new law's changes, ``F = max(F_new - D, 0)`` with
          ``D = F_new - F_old`` (for springs ``F_old(p0) + K2 (p - p0)``: the rest point
          moved inwards, so the switch stores no energy and the force has no step). ``D``
          falls only where that force is zero (``D = min(D, F_new)``, the rest point
          following a withdrawing finger) and is released when the contact ends: the
          full new force is felt from the next touch on, and no energy the finger did
          not put in is ever handed back;
        * the new force is lower (softening): linear cross-fade ``(1 - a) F_old + a F_new``
          over ``ramp_s`` (default ``switch_ramp_s``, 50 ms), a step of
          ``|F_old - F_new| T / ramp_s`` per tick, slowed so that it never exceeds
          ``switch_max_step_n`` (0.1 N: the ramp lasts longer than ``ramp_s`` when the
          forces differ by more than 5 N at 1 kHz); for springs a stiffness falling in
          time, which only removes stored energy.

        Vibration amplitudes cross-fade over the same ramp at the new frequency. A switch
        made while the probe is not in contact with the object puts the forces on the new
        law at once (they start with the next contact, as a wall met from outside). With
        ``ramp_s = 0`` a softening force drops at once. The passivity controller keeps
        running across the switch. A switch made during another one starts from the
        force the first one gives."""
        rs = _check_renderers(renderers, self.actuators, self.drop_unmapped_roles)
        r = self.switch_ramp_s if ramp_s is None else float(ramp_s)
        if not (math.isfinite(r) and r >= 0):
            raise ValidationError(f"ramp_s must be >= 0 s, got {ramp_s!r}", field="ramp_s")
        self._ops.append(("renderers", obj, rs, r))

    def add_object(self, name: str, renderers: Sequence[DimensionRenderer], shape: Any = None) -> None:
        """Append an object (its index is the next one); ``shape`` goes to the hit
        tester's ``add(name, shape)``. Callable from any thread."""
        rs = _check_renderers(renderers, self.actuators, self.drop_unmapped_roles)
        self._ops.append(("add", str(name), rs, shape))

    def remove_object(self, name: str) -> None:
        """Remove an object (later objects move down one index, as in the hit tester)."""
        self._ops.append(("remove", str(name), None, None))

    def set_pose(self, obj: "int | str", pose: Any) -> None:
        """Move object ``obj`` (index or name; the hit tester's ``set_pose``). Callable
        from any thread. The move is the scene's: on the next reading the stiff-wall
        controller gets the stylus's own motion and takes its damping credit on it
        (docs/runtime.md, Passivity, "A moving wall")."""
        self._ops.append(("pose", obj, pose, None))

    def call_in_loop(self, fn: Callable[[], None]) -> None:
        """Run ``fn()`` in the servo thread at the start of the next tick."""
        self._ops.append(("call", 0, fn, None))

    def _index(self, obj: "int | str") -> int:
        if isinstance(obj, str):
            for i, o in enumerate(self._objs):
                if o.name == obj:
                    return i
            return -1
        return int(obj) if 0 <= int(obj) < len(self._objs) else -1

    def _apply_ops(self, t: float) -> None:
        ops = self._ops
        while ops:
            kind, a, b, c = ops.popleft()
            if kind == "renderers":
                i = self._index(a)
                if i >= 0:
                    o = self._objs[i]
                    # the law in effect (with its own switch still in progress) becomes
                    # the old law; the rule is set on the first tick that renders it. A
                    # switch never rendered (the probe was elsewhere) was never felt: the
                    # new one starts from its old law, so the chain stays short
                    sw = o.sw
                    touched = self.contact == i
                    if sw is not None and sw.t0 is None:
                        o.sw = _Switch(sw.old, sw.old_sw, c, touched)
                    else:
                        o.sw = _Switch(o.renderers, sw, c, touched)
                    o.renderers = b
                    self._events["material_switches"] += 1
            elif kind == "add":
                if self.hit_tester is not None and c is not None:
                    self.hit_tester.add(a, c)
                self._objs.append(_Obj(a, b))
            elif kind == "remove":
                i = self._index(a)
                if i >= 0:
                    if self.hit_tester is not None:
                        self.hit_tester.remove(a)
                    del self._objs[i]
                    self.contact = -1
                    self._pc_obj = -2 if self._pc_obj == i else (
                        self._pc_obj - 1 if self._pc_obj > i else self._pc_obj)
            elif kind == "pose":
                i = self._index(a)
                if self.hit_tester is not None and i >= 0:
                    was = self.hit_tester.shapes[i].pose
                    self.hit_tester.set_pose(i, b)
                    self._moved = True
                    if i == self._pc_obj or (self._pc_obj == -2 and len(self._objs) == 1):
                        # the object the controllers observe (or the only one, before the
                        # first contact): the positions remembered are carried with it, so
                        # a reading built from them is of the stylus's motion relative to
                        # it, as the distance is (docs/runtime.md, Passivity, "A moving wall")
                        move = carrier(was, b)
                        if self._last_p is not None:
                            self._last_p = move(self._last_p)
                        if self._turns is not None:
                            self._turns.carry(move)
            elif kind == "call":
                b()
        # renderers, objects or poses changed (or a call may have changed anything)
        self._unfuse()

    # ------------------------------------------------------------------
    def start(self, seconds: float | None = None) -> None:
        """Open every actuator and set up a run of ``seconds`` (s; None: until
        :meth:`finish`). Disables the garbage collector and applies the ``rt`` options
        until :meth:`finish`. Raises :class:`ValidationError` while a run is going (call
        :meth:`finish` first)."""
        if self._running:
            raise ValidationError("the loop is running: finish() it before start() again", field="start")
        T = self.period_s
        if seconds is None:
            n_max = sys.maxsize
        else:
            if not (isinstance(seconds, (int, float)) and math.isfinite(seconds) and seconds > 0):
                raise ValidationError(f"seconds must be > 0, got {seconds!r}", field="seconds")
            # ticks at t = 0, T, ..., seconds - T: a run of `seconds` at period T has seconds/T ticks
            n_max = max(1, int(math.floor(seconds / T + 1e-9)))
        cap = max(2, min(n_max, int(math.ceil(self.log_seconds / T)), MAX_LOG_TICKS))
        device = self.device
        # the axes the force role renders a direction along, checked before anything opens
        axes = next((force_axes_of(a) for a in self.actuators.values() if a.channel == "force"), (0, 1, 2))
        # open everything (idempotent); commands older than one period become stale
        for act in _distinct([device, *self.actuators.values()]):
            act.open()
            if hasattr(act.safety, "set_period"):
                act.safety.set_period(T)
        slots: list[_Slot] = []
        for role, act in self.actuators.items():
            is_force = act.channel == "force"
            s = _Slot(role, act, is_force)
            if is_force and self.passivity:
                s.pc = PassivityController(self.passivity_settings)
            if is_force and self.delay_ticks:
                s.pending = deque([0.0] * self.delay_ticks)
            # every field the role was sent: force (N), frequency (Hz), amplitude
            s.col = _NCOL + 3 * len(slots)
            slots.append(s)
        self._slots = slots
        self._by_role = {s.role: s for s in slots}
        self._stepped = [a for a in _distinct(self.actuators.values())
                         if a is not device and getattr(a, "simulated", False) and callable(getattr(a, "step", None))]
        self._sim_device = bool(getattr(device, "simulated", False))
        self._hits0 = {id(a): sum(a.safety.hits.values()) if hasattr(a.safety, "hits") else 0
                       for a in _distinct([device, *self.actuators.values()])}
        self._observers = [a.safety for a in _distinct(self.actuators.values())]
        self._n_max = n_max
        self._cap = cap
        # the log ring: one row of float64 per tick (columns _COLS, then three per role),
        # written with one struct.pack_into per tick (a numpy scalar store costs ~50 ns,
        # and a tick logs ~25 values) plus three stores through a memoryview
        ncol = _NCOL + 3 * len(slots) + 3
        self._ncol = ncol
        self._log = np.zeros((cap, ncol))
        # every page of the ring written now, before the first tick: np.zeros maps pages
        # that the kernel fills on first touch, and numpy asks for huge pages on large
        # arrays, so a tick that first touched a 2 MB page waited for the kernel to find
        # and zero one (2-6 ms at 4 kHz on a 24 MB ring, once a second or so)
        self._log.fill(0.0)
        #: the ring as one flat run of doubles: the row's pack_into (a byte offset) and the
        #: three late stores (an index) both write through it
        self._log_mv: memoryview[float] = self._log.data.cast("B").cast("d")
        # every column but the last three (compute, cpu, sim: measured after the row is
        # written), native byte order as numpy's float64
        self._log_row = struct.Struct(f"={ncol - 3}d").pack_into
        for s in slots:
            # each role's columns as (cap,) views of the ring: what it was sent, by tick
            s.log_n, s.log_f, s.log_a = (self._log[:, s.col + j] for j in range(3))
        self._events = dict.fromkeys(EVENT_KEYS, 0)
        self._fault: dict[str, str] | None = None
        self._fault_exc: BaseException | None = None
        self._last_vel = [0.0, 0.0, 0.0]
        self._last_x = 0.0
        self._x_off = 0.0    # the reading's offset from -pen (a force rendered along some axes)
        self._last_p = None
        self._held_n: tuple[float, float, float] | None = None   # the direction sent last tick (None: +y)
        # an object moved since the last reading in contact (set_pose): the controller gets
        # the stylus's own motion since _own_st, the state read at the last good reading
        self._moved = False
        self._own_st: SensedState | None = None
        self._force_axes: tuple[int, ...] | None = None if axes == (0, 1, 2) else axes
        self._pcs = [s.pc for s in slots if s.pc is not None]
        self._turns = NormalTurns(axes) if self._pcs else None
        self._have_good = False
        self._vf0 = self._vf1 = self._vf2 = 0.0
        self._vf_dt = -1.0   # the filter's coefficient and speed step: computed on the first tick
        self._good_state: SensedState | None = None
        self._cpu_cost_us = 2e6 * thread_cpu_clock_cost_s() if self.cpu_time else float("nan")
        self._max_compute = 0.0
        self._max_cpu = 0.0
        self._missed = 0
        self._pc_obj = -2
        self.contact = -1
        self._gc_was_enabled = gc.isenabled()
        # paced on the machine clock, a collection now spares the loop one later; in
        # simulated time a pause costs nothing but the run's length (10-35 ms saved)
        collected = "collected, " if self.realtime else ""
        if self.realtime:
            gc.collect()
        self._froze = False
        if self.rt.gc_freeze and hasattr(gc, "freeze"):
            gc.freeze()
            self._froze = True
        gc.disable()
        applied, self._rt_restore = apply_realtime(self.rt)
        rt_status: dict[str, Any] = dict(applied)
        rt_status["gc"] = (f"applied: {collected}frozen and disabled" if self._froze else
                           f"applied: {collected}disabled (freeze off)" if not self.rt.gc_freeze else
                           f"applied: {collected}disabled (gc.freeze unavailable)")
        rt_status["applied"] = sorted(k for k, v in rt_status.items() if v.startswith("applied"))
        self._rt_status = rt_status
        self._k = 0
        self._t_prev = 0.0
        if self.realtime:
            if isinstance(self.clock, MonotonicClock):
                self.clock.reset()   # its busy share follows the policy just applied
            self._t_origin = self.clock.now()
            self._deadline = self._t_origin
        # the steady-state tick: built at the end of a general tick once the safety layers
        # run; each layer tells the loop when its configuration or phase changes
        self._steady = None
        self._watched = [a.safety for a in _distinct([device, *self.actuators.values()])
                         if hasattr(a.safety, "_watch")]
        for layer in self._watched:
            layer._watch(self._unfuse)
        self._fuse_want = True
        self._running = True

    @property
    def max_compute_s(self) -> float:
        """Largest compute time of a tick so far in this run (s)."""
        return getattr(self, "_max_compute", 0.0)

    @property
    def missed_ticks(self) -> int:
        """Realtime: periods longer than 1.5 T so far in this run."""
        return getattr(self, "_missed", 0)

    def clamp_count(self) -> int:
        """Limit hits of every actuator's safety layer since :meth:`start`."""
        n = 0
        for a in _distinct([self.device, *self.actuators.values()]):
            if hasattr(a.safety, "hits"):
                n += sum(a.safety.hits.values()) - self._hits0.get(id(a), 0)
        return n

    @property
    def ticks(self) -> int:
        """Ticks executed so far in this run."""
        return getattr(self, "_k", 0)

    @property
    def events(self) -> dict[str, int]:
        """Event counters of the run so far (live; clamps are added by :meth:`finish`)."""
        return getattr(self, "_events", {})

    def tick(self) -> bool:
        """Run one servo period. Returns False when the run is over (the duration given
        to :meth:`start` was reached, or a device fault stopped every actuator: see
        ``report.fault``). Any exception leaving the tick stops every actuator first."""
        if not self._running or self._k >= self._n_max or self._fault is not None:
            return False
        try:
            more = self._tick()
            if self._fuse_want and more:
                self._try_fuse()
            return more
        except BaseException as exc:
            # safety (issue 13, item 3): ANY exception leaving the loop -- KeyboardInterrupt,
            # SystemExit, SafeStop (SIGTERM/SIGHUP), an OSError from a sink or a device
            # step, anything from a renderer, recorder or actuator -- stops every actuator
            # first, then propagates unchanged
            try:
                self._stop_all()
            except BaseException as stop_exc:  # noqa: BLE001 - the original exception wins
                _log.error("stopping after %s: %s", type(exc).__name__, stop_exc)
            # what this tick's renderers commanded and no role was sent is dropped (a tick
            # that ends normally sends it all): the next tick starts from none
            self._drop_rendered()
            raise

    def _set_fault(self, exc: BaseException, device: str | None) -> None:
        self._fault_exc = exc
        self._fault = {"device": getattr(exc, "device", None) or device or self.device.label,
                       "message": str(exc)}

    def _tick(self) -> bool:
        k = self._k
        T = self.period_s
        device = self.device
        perf = time.perf_counter
        i = k % self._cap
        ncol = self._ncol
        base = i * ncol
        lm = self._log_mv
        events = self._events
        realtime = self.realtime
        if realtime:
            clock = self.clock
            clock.wait_until(self._deadline)
            now = clock.now()
            if k == 0:
                # the grid starts at the first tick: t = 0 there, so a simulated device's
                # time (the sum of the measured dt) is the loop's time
                self._t_origin = self._deadline = now
            t = now - self._t_origin
            dt = t - self._t_prev if k else T
            if k and self._sim_device:
                # physics advances by the time that really passed
                s0 = perf()
                device.step(dt)
                for a in self._stepped:
                    a.step(dt)
                lm[((k - 1) % self._cap) * ncol + ncol - 1] = perf() - s0
            if k and dt > 1.5 * T:
                self._missed += 1
        else:
            t = k * T
            dt = T
        c0 = perf()
        cpu_time = self.cpu_time
        if cpu_time:
            q0 = time.thread_time_ns()
        if self._ops:
            self._apply_ops(t)
        # the steady-state parts (None: the general ones), read once the operations,
        # which drop them, were applied
        steady = self._steady
        # ---- 1. sense -------------------------------------------------
        try:
            # the backend read: the loop does its own checks of the values
            st = device._read_state()
        except Exception as exc:
            self._set_fault(exc if isinstance(exc, DeviceError) else DeviceError(
                f"read failed: {type(exc).__name__}: {exc}", device=device.label), device.label)
            return False
        if type(st) is not SensedState:
            # a backend's DeviceState: its arrays read once, as floats
            st = SensedState.from_state(st)
        p0, p1, p2 = st.px, st.py, st.pz
        v0, v1, v2 = st.vx, st.vy, st.vz
        bad = False
        max_pos = self.max_position_mm
        last_vel = self._last_vel
        if not (_isfinite(p0 + p1 + p2) and _isfinite(v0 + v1 + v2)):
            events["nonfinite_state"] += 1
            bad = True
        elif (abs(p0) > max_pos or abs(p1) > max_pos or abs(p2) > max_pos
              or v0 * v0 + v1 * v1 + v2 * v2 > self.max_speed_mm_s * self.max_speed_mm_s):
            events["huge_state"] += 1
            bad = True
        elif self._have_good:
            lim = self.max_accel_mm_s2 * dt
            l0, l1, l2 = last_vel
            if abs(v0 - l0) > lim or abs(v1 - l1) > lim or abs(v2 - l2) > lim:
                events["velocity_spike"] += 1
                v0, v1, v2 = l0, l1, l2
                st = SensedState.of(st.t, p0, p1, p2, l0, l1, l2, st.fx, st.fy, st.fz, st.buttons)
        if bad:
            st = self._good_state if self._good_state is not None else SensedState.of(
                t, 0.0, max_pos, 0.0, 0.0, 0.0, 0.0)
            p0, p1, p2 = st.px, st.py, st.pz
            v0, v1, v2 = st.vx, st.vy, st.vz
        else:
            self._have_good = True
            self._good_state = st
            last_vel[0] = v0
            last_vel[1] = v1
            last_vel[2] = v2
        # ---- 2. hit test ------------------------------------------------
        ht = self.hit_tester
        direction = None
        if bad:
            idx, pen = -1, 0.0
        elif ht is None:
            idx, pen = 0, -p1
        else:
            idx, pen, nx, ny, nz = ht.query(p0, p1, p2)
            if idx >= len(self._objs):
                idx = -1
            if not (nx == 0.0 and nz == 0.0 and ny == 1.0):
                direction = (nx, ny, nz)
        in_contact = pen > 0.0
        pen_in = pen
        if not in_contact and idx >= 0 and idx == self.contact:
            h = self.contact_hysteresis_mm
            if direction is not None:
                # one count on each axis moves the distance along the normal by up to
                # q (|nx| + |ny| + |nz|) (q alone on the version-1 plane, normal +y)
                h *= abs(direction[0]) + abs(direction[1]) + abs(direction[2])
            if pen > -h:
                in_contact = True  # within the gate's hysteresis: held, rendered at the surface
                pen_in = 0.0
        contact = idx if in_contact else -1
        if contact != self.contact:
            events["contact_changes"] += 1
            prev = self.contact
            sw_prev = self._objs[prev].sw if 0 <= prev < len(self._objs) else None
            if sw_prev is not None:
                sw_prev.end_contact()
            self.contact = contact
        obs_state = st if (direction is None and ht is None) or bad else _ContactState.at(st, pen)
        if steady is not None and steady[3] is not None:
            # the steady state's observers: each layer stores the state (no speed limit
            # declared, SafetyLayer._steady_observer), in one call
            steady[3](obs_state)
        else:
            for obs in self._observers:
                obs.observe(obs_state)
        # ---- 3. render ------------------------------------------------
        if idx >= 0 and not self.paused:
            o = self._objs[idx]
            if direction is None:
                normal = _UP
                w0, w1, w2 = v0, v1, v2
            else:
                nx, ny, nz = direction
                vn = v0 * nx + v1 * ny + v2 * nz
                tx, ty, tz = v0 - vn * nx, v1 - vn * ny, v2 - vn * nz
                w0, w1, w2 = math.sqrt(tx * tx + ty * ty + tz * tz), vn, 0.0
                normal = direction
            if dt != self._vf_dt:   # the coefficient changes only with dt (realtime mode)
                self._vf_dt = dt
                self._vf_a = 1.0 - math.exp(-6.283185307179586 * self.velocity_filter_hz * dt)
                self._v_step = self._vf_a * self.contact_hysteresis_mm / dt if dt > 0 else 0.0
            a = self._vf_a
            f0 = self._vf0 = self._vf0 + a * (w0 - self._vf0)
            f1 = self._vf1 = self._vf1 + a * (w1 - self._vf1)
            f2 = self._vf2 = self._vf2 + a * (w2 - self._vf2)
            if steady is not None:
                # the steady state: each renderer's law on the same input as floats;
                # what it commands goes to the role's slot, checked and counted as
                # _render does (a role's force summed, its vibration as (force_n,
                # frequency_hz, amplitude))
                vstep = self._v_step
                for law, outs in steady[0][idx]:
                    try:
                        out = law(t, dt, pen_in, in_contact, w0, w1, w2, f0, f1, f2, vstep)
                    except Exception:
                        events["renderer_error"] += 1
                        continue
                    for slot, j, is_force in outs:
                        if is_force:
                            f = out[j]
                            # an ordinary force (finite, >= 0) as it is; anything else
                            # through the rules of _rendered_force
                            if f is not None and f - f == 0.0 and f >= 0.0:
                                slot.f_in += f
                            else:
                                f = _rendered_force(f, events)
                                if f is not None:
                                    slot.f_in += f
                        else:
                            fr, am = out[j + 1], out[j + 2]
                            if ((fr is None or fr - fr == 0.0) and (am is None or am - am == 0.0)
                                    or _rendered_vibration_ok(fr, am, events)):
                                slot.v_fast = (out[j], fr, am)
                            else:
                                slot.v_fast = (None, None, 0.0)
            else:
                # Every renderer of the object gets this one input; its velocity array
                # (read-only) is built on the first read. Its fields are stored here as
                # TickInput's __init__ stores them, in its order (the array as the unbuilt
                # _va, which the velocity_mm_s setter stores): the same object without the
                # call through the class, which runs __init__ and the setter in frames of
                # their own (~1.7k instructions a tick; tests/runtime/test_tick_fast_paths.py)
                inp = _new(_LoopInput)
                inp.t = t
                inp.dt = dt
                inp.penetration_mm = pen_in
                inp._va = None
                inp.in_contact = in_contact
                inp.normal = normal
                inp.object = o.name
                inp.velocity_filtered_mm_s = (f0, f1, f2)
                inp.speed_step_mm_s = self._v_step
                inp.velocity_floats_mm_s = (w0, w1, w2)
                if o.sw is None:
                    self._render(o.renderers, inp, events)
                else:
                    over, forces, vib = self._law(o.renderers, o.sw, inp, events, t)
                    self._give(forces, vib)
                    if over:
                        o.sw = None   # the switch is over: the new law alone
                        self._fuse_want = True
        # ---- 4. passivity + send --------------------------------------
        last_x = self._last_x
        own: float | None = None   # the stylus's own motion (mm) where an object moved, else None
        turned = 0.0               # and where the force's direction turned, the move's part that turn takes
        if bad:
            # no position: the controller books nothing and sends 0; its next booking spans
            # this tick too (the damping credit over the whole span)
            x_n = _NAN
        elif ht is not None and idx < 0:
            # a spatial scene out of contact: the distance to the nearest object jumps
            # when another object becomes the nearest, so the observer holds its last
            # in-contact position (no motion booked, no damping in free space)
            x_n = self._last_x
        else:
            x_n = -pen
            axes = self._force_axes
            lpc = None   # the last position on the object, carried with it (the reading of fewer axes)
            if axes is not None and ht is not None:
                # a device that renders the force only along some axes (the simulated
                # Omni: y) does work on the motion along those axes alone: the reading's
                # change is the held direction's part on them times the displacement, not
                # the distance's change (docs/runtime.md, Passivity, "A force rendered
                # along one axis"). The offset from -pen starts at 0 with each object and
                # where no force is held out of contact; on a +y normal held and seen it
                # does not change (the version-1 plane's reading, bit for bit)
                lp = self._last_p
                hn = self._held_n
                if idx != self._pc_obj or lp is None or (pen <= 0.0 and self.last_force_n == 0.0):
                    self._x_off = 0.0
                elif hn is not None or direction is not None:
                    lpc = lp
                    n = hn if hn is not None else _UP
                    dp = (p0 - lp[0], p1 - lp[1], p2 - lp[2])
                    w = 0.0
                    for i in axes:
                        w += n[i] * dp[i]
                    self._x_off = self._last_x + w - x_n   # the reading moves by w
                x_n += self._x_off
                self._last_p = (p0, p1, p2)
            self._last_x = x_n
            if self._moved:
                # an object moved since the last reading: the reading's change is the
                # stylus's and the wall's, and the arm's damper dissipates only the
                # stylus's; its own motion along the force (on the axes the device renders
                # it along), for the damping credit (docs/runtime.md, Passivity, "A moving
                # wall")
                self._moved = False
                op = self._own_st
                hn = self._held_n
                # only where the reading is the distance to one surface of one object: the
                # normal held and the one seen less than a right angle apart (another face of
                # a box is a right angle or more away, and the reading that switches to it
                # jumps with no wall move); the reading of "A force rendered along one axis"
                # is the held force's work on the motion relative to the object (its last
                # position carried with the move, _apply_ops), continuous at any turn
                n = hn if hn is not None else _UP
                m = direction if direction is not None else _UP
                if op is not None and idx == self._pc_obj and (
                        lpc is not None or n[0] * m[0] + n[1] * m[1] + n[2] * m[2] > 0.0):
                    o3 = (op.px, op.py, op.pz)
                    dp = (p0 - o3[0], p1 - o3[1], p2 - o3[2])
                    own = 0.0
                    for i in (axes or (0, 1, 2)):
                        own += n[i] * dp[i]
                    if lpc is not None and axes is not None and n != m:
                        # a turn on fewer axes: the move of the object's point at the stylus,
                        # dw = lpc - op, taken by the frame at the mean of the force vectors
                        # before and after it; the book pairs it with the held one
                        # (docs/runtime.md, Passivity, "A turn on a device that renders one axis")
                        for i in axes:
                            turned += (n[i] - m[i]) * (lpc[i] - o3[i])
        if not bad:
            # (also out of contact: the booking spans one tick, or the ticks without a reading;
            # the state itself, not a tuple of it: nothing allocated a tick)
            self._own_st = st
        turns = self._turns
        if turns is not None and ht is not None:
            # the history re-read along a normal that turns (on the axes rendered: a device
            # that renders fewer keeps its book, the held force's exact work); with all
            # three, the held force's work booked out of contact (hapticsdk.runtime.turns)
            if bad:
                turns.forget()
            else:
                # (the first object of a run: the controllers go on from the readings out
                # of contact, as on the object they observe)
                x_n = self._last_x = turns.reading(self._pcs, x_n, last_x, idx >= 0, idx == self._pc_obj or
                                                   self._pc_obj == -2,
                                                   (p0, p1, p2), direction, self._held_n, self.last_force_n)
        self._held_n = direction
        if idx != self._pc_obj and idx >= 0:
            if self._pc_obj != -2:
                # another object: its observer starts afresh, as a wall met from outside,
                # keeping a debt (a bound per run, not per object)
                for s in self._slots:
                    if s.pc is not None:
                        s.pc.reset(keep_debt=True)
            self._pc_obj = idx
        recorder = self.recorder
        sent: dict[str, ChannelCommand] | None = {} if recorder is not None else None
        f_sent = 0.0
        if steady is not None:
            # the steady state: each role through its compiled send, or, when that
            # declines (its part is not in its steady state now), through the general one
            row = steady[2]
            pen_obs = -st.py if obs_state is st else pen   # what the safety layers observed
            for s, role, is_force, send, pc, act, general, cmd, j in steady[1]:
                if is_force:
                    f = s.f_in
                    s.f_in = 0.0
                    if pc is not None:
                        # (the stylus's own motion only where an object moved: a still scene
                        # calls the controller as before)
                        f = pc.step(x_n, dt, f) if own is None else pc.step(x_n, dt, f, own, turned)
                    if bad:
                        f = 0.0
                    try:
                        out = send(role, f, direction, t, pen_obs)
                        if out is None:
                            cmd.force_n = f
                            cmd.direction = direction
                            out = general(cmd, t)
                    except Exception as exc:
                        return self._rejected(exc, act)
                else:
                    v = s.v_fast
                    try:
                        if v is not None:
                            s.v_fast = None
                            fn, fr, am = v
                            out = send(role, fr, am, t) if fn is None else None
                            if out is None:
                                out = general(ChannelCommand(role, fn, fr, am), t)
                        else:
                            last = act.last_command
                            fr = last.frequency_hz if last is not None else None
                            out = send(role, fr, cmd.amplitude, t)
                            if out is None:
                                cmd.frequency_hz = fr
                                out = general(cmd, t)
                    except Exception as exc:
                        return self._rejected(exc, act)
                fn, fr = out.force_n, out.frequency_hz
                if sent is not None:
                    sent[role] = out
                if is_force:
                    if pc is not None:
                        pc.commit(fn if fn is not None else 0.0)
                    f_sent = fn or 0.0
                row[j] = fn if fn is not None else _NAN
                row[j + 1] = fr if fr is not None else _NAN
                row[j + 2] = out.amplitude or 0.0
        else:
            row = []
            for s in self._slots:
                cmd = s.cmd
                if s.is_force:
                    f = s.f_in
                    s.f_in = 0.0
                    if s.pending is not None:
                        s.pending.append(f)
                        f = s.pending.popleft()
                    if s.pc is not None:
                        f = s.pc.step(x_n, dt, f) if own is None else s.pc.step(x_n, dt, f, own, turned)
                    if bad:
                        f = 0.0   # an unknown position gets no force (the controller ramps from what was applied)
                    # the role's own record, refilled (the actuator keeps only its safety
                    # layer's output)
                    cmd.force_n = f
                    cmd.direction = direction
                else:
                    c = s.v_in
                    if c is not None:
                        s.v_in = None
                        cmd = c
                    else:
                        last = s.act.last_command
                        cmd.frequency_hz = last.frequency_hz if last is not None else None
                try:
                    out = s.send(cmd, t)
                except DeviceError as exc:
                    self._set_fault(exc, s.act.label)
                    return False
                except Exception as exc:  # validation of a value we should have caught
                    self._set_fault(DeviceError(f"command rejected: {type(exc).__name__}: {exc}",
                                                device=s.act.label), s.act.label)
                    return False
                fn, fr = out.force_n, out.frequency_hz
                if sent is not None:
                    sent[s.role] = out
                if s.is_force:
                    if s.pc is not None:
                        s.pc.commit(fn if fn is not None else 0.0)
                    f_sent = fn or 0.0
                row.append(fn if fn is not None else _NAN)
                row.append(fr if fr is not None else _NAN)
                row.append(out.amplitude or 0.0)
        if recorder is not None:
            try:
                recorder.record(t, st, sent)
            except Exception:
                events["renderer_error"] += 1
        self._log_row(lm, base * 8, t, dt, pen, idx, f_sent, p0, p1, p2, v0, v1, v2, *row)
        self.last_state = st
        self.last_penetration_mm = pen
        self.last_force_n = f_sent
        self.last_t = t
        self.last_index = idx
        if cpu_time:
            q = (time.thread_time_ns() - q0) * 1e-9
            lm[base + ncol - 2] = q
            if q > self._max_cpu:
                self._max_cpu = q
        c1 = perf()
        comp = c1 - c0
        lm[base + ncol - 3] = comp
        self.last_compute_s = comp
        if comp > self._max_compute:
            self._max_compute = comp
        if comp > T:
            events["overrun"] += 1
        # ---- 5. pace / step ------------------------------------------
        if realtime:
            clock.work(k, comp)
            self._t_prev = t
            self._deadline += T
            behind = (clock.now() - self._deadline) / T
            if behind > self.max_catchup_ticks:
                skipped = int(behind)
                events["skipped_ticks"] += skipped
                self._deadline += skipped * T
        else:
            s0 = perf()
            try:
                if self._sim_device:
                    device.step(T)
                for a in self._stepped:
                    a.step(T)
            except DeviceError as exc:
                self._set_fault(exc, device.label)
                self._k = k + 1
                return False
            lm[base + ncol - 1] = perf() - s0
        self._k = k + 1
        return self._k < self._n_max

    def _rejected(self, exc: Exception, act: Actuator) -> bool:
        """A send of the steady state raised ``exc``: as the general send's handling in
        :meth:`_tick`, a :class:`DeviceError` stops the run; any other error is a command
        the checks should have caught."""
        if isinstance(exc, DeviceError):
            self._set_fault(exc, act.label)
        else:
            self._set_fault(DeviceError(f"command rejected: {type(exc).__name__}: {exc}", device=act.label),
                            act.label)
        return False

    # -- the steady-state tick ------------------------------------------------
    def _unwatch(self) -> None:
        """The run is over: no steady-state tick, the safety layers no longer tell the loop."""
        self._steady = None
        for layer in self._watched:
            layer._unwatch(self._unfuse)
        self._watched = []

    def _unfuse(self) -> None:
        """Something the steady-state tick was built from changed (or may have): drop it;
        the general tick runs and tries to build a new one at its end."""
        self._fuse_gen += 1
        self._steady = None
        self._fuse_want = True

    def _try_fuse(self) -> None:
        """At the end of a general tick, when a change may have made the steady-state
        tick possible: build it (:meth:`_build_steady`) and use it from the next tick on.
        A change made meanwhile by another thread (it counts ``_fuse_gen``) leaves it
        unused."""
        self._fuse_want = False
        if not self._running:
            return
        gen = self._fuse_gen
        try:
            steady = self._build_steady()
        except Exception as exc:   # a plugin's hook that fails: the general tick, as always
            _log.warning("steady-state tick not built (%s: %s); the general tick runs", type(exc).__name__, exc)
            return
        if steady is None:
            return
        self._steady = steady
        if self._fuse_gen != gen:
            self._steady = None
            self._fuse_want = True

    def _build_steady(self) -> tuple | None:
        """The steady-state parts of the tick for the configuration in force, or None
        when some part does not offer them or the loop is not in a steady state.

        With them :meth:`_tick` renders each object through its renderers' laws on plain
        floats (:meth:`~hapticsdk.perception.dimensions.DimensionRenderer._fast_law`)
        instead of their ``tick`` and the records it returns, and sends each role
        through its actuator's compiled send
        (:meth:`~hapticsdk.devices.actuators.Actuator._steady_sender`, the safety
        layer's limits captured) instead of ``command``; everything else is the same
        code, and the outputs are the general parts' bit for bit (log rows, every sent
        record and ``last_command``, what the recorder gets, events, clamp counts, the
        passivity controllers' and the safety layers' state). Built only when
        ``fast_tick`` is on, no operation is queued, there is no extra delay, no material
        switch is in progress, every object's renderers offer a law whose roles all have
        an actuator and no vibration role is commanded twice on one object, and every
        actuator offers a compiled send, with a safety layer the loop observes that is
        ``running``. A part that leaves its steady state during a tick (a safety layer's
        phase, a command gap, a value that is not finite, an actuator closed or faulted
        or given another safety layer) is sent through its general path that tick; every
        change of configuration (:meth:`_unfuse`: the safety layers tell the loop, and so
        do its operations) drops them, and the general parts run until they are built
        again at the end of a tick.

        Returns ``(laws by object index, sends, row, observe_all)``: each law with its
        outputs ``(slot, index, is_force)``; each send ``(slot, role, is_force, steady
        send, pc, actuator, general send, the role's record, first log column)``; the
        roles' log values, refilled every tick; one call observing every safety layer
        (:meth:`~hapticsdk.devices.safety.SafetyLayer._steady_observer`), or None: each
        layer's ``observe`` is called."""
        if (not self.fast_tick or self._ops or self.delay_ticks or not self._objs
                or any(s.pending is not None for s in self._slots)):
            # (the delay line the run started with, whatever delay_ticks says now)
            return None
        by_role = self._by_role
        laws_of: list = []
        for o in self._objs:
            if o.sw is not None:
                return None
            laws = []
            vib_roles: set[str] = set()
            for r in o.renderers:
                law = _steady_law_of(r)
                if law is None:
                    return None
                outs = []
                for j, role in enumerate(r.roles):
                    slot = by_role.get(role)
                    if slot is None:
                        return None
                    if not slot.is_force:
                        if role in vib_roles:
                            return None
                        vib_roles.add(role)
                    outs.append((slot, 3 * j, slot.is_force))
                laws.append((law, tuple(outs)))
            laws_of.append(tuple(laws))
        observed = self._observers
        sends: list[tuple] = []
        for s in self._slots:
            act = s.act
            layer = act.safety
            if (s.send != act._servo_command or not any(layer is o for o in observed)
                    or layer.phase != "running" or layer._overspeed):
                return None
            steady = act._steady_sender(s.is_force)
            if steady is None:
                return None
            sends.append((s, s.role, s.is_force, steady, s.pc, act, s.send, s.cmd, 3 * len(sends)))
        observe_all = SafetyLayer._steady_observer(tuple(observed))
        return tuple(laws_of), tuple(sends), [0.0] * (3 * len(sends)), observe_all

    def _take(self) -> tuple[dict[str, float], dict[str, ChannelCommand]]:
        """What the slots hold from the renderers (every force role's sum, each vibration
        command rendered), as ``(forces, vib)`` by role; the slots are emptied."""
        forces: dict[str, float] = {}
        vib: dict[str, ChannelCommand] = {}
        for s in self._slots:
            if s.is_force:
                forces[s.role] = s.f_in
                s.f_in = 0.0
            elif s.v_in is not None:
                vib[s.role] = s.v_in
                s.v_in = None
        return forces, vib

    def _give(self, forces: dict[str, float], vib: dict[str, ChannelCommand]) -> None:
        """Put ``forces`` and ``vib`` (by role; a role not there: none) in the slots."""
        for s in self._slots:
            if s.is_force:
                s.f_in = forces.get(s.role, 0.0)
            else:
                s.v_in = vib.get(s.role)

    def _drop_rendered(self) -> None:
        """Empty every slot of what the renderers commanded (a tick that ended early)."""
        for s in self._slots:
            s.f_in = 0.0
            s.v_in = None
            s.v_fast = None

    def _law(self, renderers: list, sw: _Switch, inp: TickInput, events: dict,
             t: float) -> tuple[bool, dict[str, float], dict[str, ChannelCommand]]:
        """Render ``renderers`` with the material switch ``sw`` in progress; return
        ``(over, forces, vib)``: True when the switch is over (the new law alone from now
        on), and the commands by role (the slots are left empty).

        First tick of the switch: both laws are rendered at the same input and, under the
        ``"passive"`` rule, each force role whose new force ``F_new`` exceeds the old one
        ``F_old`` keeps the old force and the new law's slope: ``F = max(F_new - D, 0)``
        with ``D = F_new - F_old`` held back (a spring whose rest point moved inwards:
        ``F = F_old(p0) + K2 (p - p0)`` for springs), so stiffening creates no energy and
        makes no step. ``D`` only ever falls to ``F_new`` where the held-back law gives no
        force (``D = min(D, F_new)``: the rest point follows a withdrawing finger at zero
        force) and is released when the contact ends, so the rest point returns to the
        surface without adding energy. A force role that softened (``F_new < F_old``) is
        cross-faded ``(1 - a) F_old + a F_new`` with ``a`` rising linearly from 0 to 1 over
        ``ramp_s`` (for springs a stiffness falling in time, which only removes stored
        energy): the documented ramp, ``|F_old - F_new| T / ramp_s`` per tick, slowed to
        at most ``switch_max_step_n`` per tick. Vibration
        roles cross-fade their amplitude over the same ramp at the new frequency. The
        ``"cross-fade"`` rule (for comparison only; not passive when stiffening)
        cross-fades every force role."""
        self._render(renderers, inp, events)
        forces, vib = self._take()
        first = sw.offset is None
        if first:
            da = 0.0
            a = sw.a = 0.0 if sw.ramp_s > 0 else 1.0
        else:
            da = (t - sw.t0) / sw.ramp_s if sw.ramp_s > 0 else 1.0   # type: ignore[operator]
            a = sw.a
        sw.t0 = t
        f_old: dict[str, float] = {}
        v_old: dict[str, ChannelCommand] = {}
        if sw.old is not None and (first or a < 1.0):
            if sw.old_sw is None:
                self._render(sw.old, inp, events)
                f_old, v_old = self._take()
            else:
                old_over, f_old, v_old = self._law(sw.old, sw.old_sw, inp, events, t)
                if old_over:
                    sw.old_sw = None
        if first:
            held: dict[str, float] = {}
            fade = []
            passive = self.switch_rule == "passive"
            # a switch made while the probe was off the object: the forces start with the
            # contact (a wall met from outside), on the new law at once
            roles = set(forces) | set(f_old) if sw.touched or not passive else ()
            for role in roles:
                fn, fo = forces.get(role, 0.0), f_old.get(role, 0.0)
                if passive and fn > fo:
                    held[role] = fn - fo
                elif fn != fo:
                    fade.append(role)
            sw.offset = held
            sw.fade = tuple(fade)
        offset = sw.offset
        if offset:
            # (the contact's end releases every offset: _Switch.end_contact from _tick)
            for role in list(offset):
                fn = forces.get(role, 0.0)
                d = offset[role]
                if fn <= d:
                    # no force from the held-back law: the rest point follows the finger
                    # out at zero force (no energy)
                    forces[role] = 0.0
                    if fn <= 0.0:
                        del offset[role]
                    else:
                        offset[role] = fn
                else:
                    forces[role] = fn - d
        if a < 1.0 and da > 0.0:
            # the ramp advances by dt / ramp_s, slowed where that would move a cross-faded
            # force by more than switch_max_step_n this tick
            cap = self.switch_max_step_n
            for role in sw.fade:
                gap = abs(forces.get(role, 0.0) - f_old.get(role, 0.0))
                if gap * da > cap:
                    da = cap / gap
            a = sw.a = min(a + da, 1.0)
        if a < 1.0:
            b = 1.0 - a
            for role in sw.fade:
                forces[role] = a * forces.get(role, 0.0) + b * f_old.get(role, 0.0)
            for role in set(vib) | set(v_old):
                cn, co = vib.get(role), v_old.get(role)
                fr = cn.frequency_hz if cn is not None and cn.frequency_hz is not None else (
                    co.frequency_hz if co is not None else None)
                am = a * ((cn.amplitude or 0.0) if cn is not None else 0.0) + b * (
                    (co.amplitude or 0.0) if co is not None else 0.0)
                vib[role] = ChannelCommand(role, frequency_hz=fr, amplitude=am)
            return False, forces, vib
        sw.old = None
        sw.old_sw = None
        return not offset, forces, vib

    def _render(self, renderers: list, inp: TickInput, events: dict) -> None:
        """Run ``renderers`` on ``inp``; each role's commands go to its slot (``f_in``: the
        sum of the forces, ``v_in``: the vibration command), checked and counted: a
        renderer that raises, a non-finite value, a negative force, a role with no
        actuator or a second vibration command of a role are counted in ``events``."""
        by_role = self._by_role
        for r in renderers:
            try:
                cmds = r.tick(inp)
            except Exception:
                events["renderer_error"] += 1
                continue
            for c in cmds:
                slot = by_role.get(c.role)
                if slot is None:
                    events["role_conflict"] += 1
                    continue
                if slot.is_force:
                    f = c.force_n
                    # an ordinary force (finite, >= 0) as it is; anything else through
                    # the rules of _rendered_force
                    if f is not None and f - f == 0.0 and f >= 0.0:
                        slot.f_in += f
                    else:
                        f = _rendered_force(f, events)
                        if f is not None:
                            slot.f_in += f
                    continue
                fr, am = c.frequency_hz, c.amplitude
                if not ((fr is None or fr - fr == 0.0) and (am is None or am - am == 0.0)
                        or _rendered_vibration_ok(fr, am, events)):
                    c = ChannelCommand(c.role, frequency_hz=None, amplitude=0.0)
                if slot.v_in is not None:
                    events["role_conflict"] += 1
                    continue
                slot.v_in = c

    def _window(self, a: np.ndarray, n: int) -> np.ndarray:
        """The logged ticks of ``a`` (a column or columns of the log ring), oldest first
        (a contiguous copy)."""
        cap = self._cap
        if n <= cap:
            return np.ascontiguousarray(a[:n])
        j = n % cap
        return np.concatenate([a[j:], a[:j]])

    def finish(self) -> LoopReport:
        """End the run: restore GC and the OS options, close the recorder, stop every
        actuator after a fault, build the :class:`LoopReport` (also ``self.report``) and,
        with ``raise_on_fault``, re-raise the fault."""
        if not self._running:
            raise ValidationError("finish() without start()", field="loop")
        self._running = False
        self._unwatch()
        fault = self._fault
        try:
            self._rt_restore()
            if self._gc_was_enabled:
                gc.enable()
            close = getattr(self.recorder, "close", None)
            if callable(close):
                try:
                    close()
                except Exception as exc:  # the run's outcome matters more than the log
                    _log.warning("recorder.close() failed: %s", exc)
            if self._froze and hasattr(gc, "unfreeze"):
                gc.unfreeze()
        finally:
            if fault is not None:
                self._stop_all()
        report = self._report()
        self.report = report
        fault_exc = self._fault_exc
        if fault_exc is not None and self.raise_on_fault:
            if isinstance(fault_exc, DeviceError):
                fault_exc.report = report  # type: ignore[attr-defined]
                raise fault_exc
            raise DeviceError(str(fault_exc), device=fault["device"] if fault else None) from fault_exc
        return report

    def _report(self) -> LoopReport:
        n = self._k
        T = self.period_s
        events = dict(self._events)
        for a in _distinct([self.device, *self.actuators.values()]):
            if hasattr(a.safety, "hits"):
                events["clamp"] += sum(a.safety.hits.values()) - self._hits0.get(id(a), 0)
        pas: dict[str, Any] = {}
        for s in self._slots:
            if s.pc is not None:
                rep = s.pc.report()
                events["passivity_active"] += int(rep["active_ticks"])
                pas[s.role] = rep
        W = self._window
        L = self._log
        nc = self._ncol
        comp_w = W(L[:, nc - 3], n)
        comp = tick_stats(comp_w)
        if n:
            comp["max_us"] = self._max_compute * 1e6
        if self.cpu_time:
            cpu_w = W(L[:, nc - 2], n)
            cpu = tick_stats(cpu_w)
            if n:
                cpu["max_us"] = self._max_cpu * 1e6
            pre: dict[str, Any] = preemption_stats(comp_w, cpu_w)
        else:
            cpu = tick_stats(np.zeros(0))
            pre = {"preempted_ticks": None, "off_cpu_max_us": float("nan")}
        jit = None
        if self.realtime and n > 1:
            jit = jitter_stats(np.diff(W(L[:, 0], n)), T)
            jit["missed_ticks_total"] = self._missed
        log = {"t": W(L[:, 0], n), "dt": W(L[:, 1], n), "penetration_mm": W(L[:, 2], n),
               "object": W(L[:, 3], n).astype(np.int32),
               "position_mm": W(L[:, 5:8], n), "velocity_mm_s": W(L[:, 8:11], n), "force_n": W(L[:, 4], n),
               "compute_s": comp_w}
        if self.cpu_time:
            log["compute_cpu_s"] = cpu_w
        for s in self._slots:   # every commanded field of every role
            log[f"{s.role}.force_n"] = W(L[:, s.col], n)
            log[f"{s.role}.frequency_hz"] = W(L[:, s.col + 1], n)
            log[f"{s.role}.amplitude"] = W(L[:, s.col + 2], n)
        sim_w = W(L[:, nc - 1], n)
        sim_us = median(sim_w) * 1e6 if n else float("nan")
        return LoopReport(ticks=n, period_s=T, realtime=self.realtime, tick_median_us=comp["median_us"],
                          tick_p99_us=comp["p99_us"], tick_max_us=comp["max_us"], tick_p999_us=comp["p999_us"],
                          overruns=events["overrun"], jitter=jit, events=events, passivity=pas,
                          fault=self._fault, sim_step_median_us=sim_us, log=log,
                          tick_cpu_median_us=cpu["median_us"], tick_cpu_p99_us=cpu["p99_us"],
                          tick_cpu_p999_us=cpu["p999_us"], tick_cpu_max_us=cpu["max_us"],
                          preempted_ticks=pre["preempted_ticks"], off_cpu_max_us=pre["off_cpu_max_us"],
                          cpu_clock_cost_us=self._cpu_cost_us, rt=self._rt_status,
                          log_window_s=self._cap * T, objects=self.object_names)

    def run(self, seconds: float) -> LoopReport:
        """Run for ``seconds`` of (simulated or real) time; return a :class:`LoopReport`."""
        if not (isinstance(seconds, (int, float)) and math.isfinite(seconds) and seconds > 0):
            raise ValidationError(f"seconds must be > 0, got {seconds!r}", field="seconds")
        self.start(seconds)
        try:
            tick = self.tick
            while tick():
                pass
        except BaseException:
            # the tick already stopped every actuator; restore GC / OS options / recorder
            try:
                if self._running:
                    self._finish_quietly()
            finally:
                raise
        return self.finish()

    def _finish_quietly(self) -> None:
        self._running = False
        self._unwatch()
        try:
            self._rt_restore()
        finally:
            if self._gc_was_enabled:
                gc.enable()
            if self._froze and hasattr(gc, "unfreeze"):
                gc.unfreeze()
            close = getattr(self.recorder, "close", None)
            if callable(close):
                try:
                    close()
                except Exception as exc:
                    _log.warning("recorder.close() failed: %s", exc)
