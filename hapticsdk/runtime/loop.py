"""The servo loop: read the probe, run every renderer, send the commands, step the
simulation, once per period.

Each tick of :class:`ServoLoop`:

1. ``state`` = the device's sensed state; non-finite or huge readings and velocity
   spikes are replaced by safe values and counted (never raised);
2. every actuator's safety layer observes the state;
3. a :class:`~hapticsdk.dimensions.TickInput` goes to every renderer; force commands
   of the same role are summed, a renderer that raises or returns NaN is counted and
   contributes nothing;
4. the force role goes through the passivity observer/controller
   (:class:`~hapticsdk.passivity.PassivityController`, on by default);
5. each role's command is sent with ``actuator.command(cmd, now=t)`` (the safety
   layer clamps it) and optionally recorded;
6. simulated devices are stepped (``device.step(dt)``, then every other simulated
   actuator with a ``step`` method).

Delay accounting: the force computed from the state of tick ``n`` is held from tick
``n`` to ``n+1``, so the loop's computational delay is ``d = 0`` (one zero-order hold);
``delay_ticks`` adds ``d`` more ticks for tests of the delay law.

Time: by default simulated time (``t = n T``, as fast as possible, each tick's compute
time measured with ``perf_counter`` and, as on-CPU time of the servo thread, with
``thread_time_ns``; a tick whose wall time exceeds its CPU time by more than 100 us was
preempted); with ``realtime=True`` the loop paces itself on a
clock (hybrid sleep-then-spin) against a fixed deadline grid, hands renderers the
*measured* ``dt``, catches up after a late tick without skipping a deadline, and
re-anchors the grid (counting the skipped ticks) only when more than
``max_catchup_ticks`` behind. A :class:`DeviceError` from any actuator stops *all*
actuators, ends the run cleanly with ``report.fault`` set, and is re-raised from
:meth:`ServoLoop.run` when ``raise_on_fault``. Optional OS options for the servo
thread (CPU pinning, ``SCHED_FIFO``, ``mlockall``; ``rt=``) report their outcome in
``report.rt`` and never raise.
"""

from __future__ import annotations

import logging
import gc
import math
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

_log = logging.getLogger(__name__)

import numpy as np

from ..actuators import Actuator, DeviceState, HapticDevice
from ..dimensions import ChannelCommand, DimensionRenderer, TickInput
from ..errors import DeviceError, ValidationError
from ..passivity import ControllerSettings, PassivityController
from .clock import MonotonicClock, RealtimeSettings, apply_realtime, thread_cpu_clock_cost_s
from .stats import PREEMPT_THRESHOLD_S, jitter_stats, preemption_stats, tick_stats

#: event counters every report carries (0 when nothing happened)
EVENT_KEYS = ("nonfinite_state", "huge_state", "velocity_spike", "renderer_error", "nonfinite_command",
              "negative_force", "role_conflict", "overrun", "clamp", "skipped_ticks", "passivity_active")


@dataclass
class LoopReport:
    """What a servo run did.

    Attributes:
        ticks: ticks executed.
        period_s: nominal period (s).
        realtime: paced on a clock (True) or simulated time.
        tick_median_us, tick_p99_us, tick_max_us: per-tick compute time of the control
            path (read, renderers, passivity, commands, logging), excluding simulated
            physics (us), wall clock (``perf_counter``): includes time the thread was
            off the CPU (preempted by another process).
        tick_p999_us: p99.9 of the same (us).
        tick_cpu_median_us, tick_cpu_p99_us, tick_cpu_p999_us, tick_cpu_max_us: the same
            ticks' on-CPU time of the servo thread (``thread_time_ns``), what the tick
            code costs (us); NaN when ``cpu_time=False``.
        preempted_ticks: ticks whose wall compute exceeded their CPU compute by more
            than ``preempt_threshold_us`` (100 us); None when ``cpu_time=False``.
        off_cpu_max_us: largest wall - CPU compute of a tick (us).
        cpu_clock_cost_us: measured cost of the two CPU-clock reads a tick makes (us).
        rt: outcome of the OS options: ``cpu_affinity``, ``rt_priority``, ``mlockall``,
            ``gc`` (``"off"``, ``"applied: ..."``, ``"refused: <reason>"``,
            ``"unavailable: <reason>"``) and ``applied`` (names applied).
        sim_step_median_us: median time spent stepping simulated devices (us).
        overruns: ticks whose compute time exceeded the period.
        jitter: |period - T| statistics and missed-tick rate (realtime mode), else None.
        events: counts of unsafe inputs replaced, clamps, skipped ticks ...
        passivity: observer/controller figures per force role (J), or {} when off.
        fault: ``{"device", "message"}`` of the failure that stopped the run, or None.
        log: numpy arrays per tick: ``t`` (s), ``dt`` (s), ``penetration_mm``,
            ``position_mm`` (n, 3), ``velocity_mm_s`` (n, 3), ``force_n`` (sent), and per
            vibration role ``<role>.frequency_hz`` / ``<role>.amplitude``.
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
        for k in ("preempted_ticks", "preempt_threshold_us", "off_cpu_max_us", "cpu_clock_cost_us", "rt"):
            d[k] = getattr(self, k)
        d["log_keys"] = sorted(self.log)
        return d


def _distinct(acts: Any) -> list:
    """The actuators of ``acts`` once each (by identity), in order."""
    return list({id(a): a for a in acts}.values())


class _Slot:
    """Per-role bookkeeping."""

    __slots__ = ("role", "act", "force", "pc", "log_f", "log_a", "is_force", "pending")

    def __init__(self, role: str, act: Actuator, is_force: bool) -> None:
        self.role = role
        self.act = act
        self.is_force = is_force
        self.pc: PassivityController | None = None
        self.pending: deque | None = None


class ServoLoop:
    """Run renderers against a device and actuators at a fixed period.

    Args:
        device: the sensing device (its state drives the renderers).
        renderers: one :class:`DimensionRenderer` per rendered dimension.
        actuators: role -> actuator; the device may serve the role ``"force"``. Default
            ``{"force": device}``. Every role a renderer commands must be mapped.
        period_s: servo period T (s).
        realtime: pace on a clock instead of simulated time.
        recorder: object with ``record(t, state, sent)`` called every tick.
        passivity: passivity observer/controller on the force roles (default on).
        raise_on_fault: re-raise the :class:`DeviceError` that stopped a run.
        clock: clock for realtime mode (default :class:`MonotonicClock`).
        delay_ticks: extra computational delay d of the force path (ticks, default 0).
        max_position_mm, max_speed_mm_s: readings beyond these are "huge" (unsafe).
        max_accel_mm_s2: a velocity change faster than this is a spike (held).
        max_catchup_ticks: realtime: how far behind the loop may run before it re-anchors.
        passivity_settings: :class:`~hapticsdk.passivity.ControllerSettings`.
        drop_unmapped_roles: ignore commands for roles with no actuator (counted as
            ``role_conflict``) instead of refusing to build the loop.
        cpu_time: also measure each tick's on-CPU time of the servo thread (default on;
            two ``thread_time_ns`` reads per tick, ~1-2 us on Linux).
        rt: :class:`~hapticsdk.runtime.clock.RealtimeSettings` or a mapping of its
            fields (``cpu``, ``fifo_priority``, ``gc_freeze``, ``mlockall``): OS options
            applied to the thread calling :meth:`run` for the run and undone after;
            refusals are reported in ``report.rt``, never raised. Default: none (GC is
            collected, frozen and disabled as always).
    """

    def __init__(self, device: HapticDevice, renderers: Sequence[DimensionRenderer],
                 actuators: Mapping[str, Actuator] | None = None, *, period_s: float = 0.001,
                 realtime: bool = False, recorder: Any = None, passivity: bool = True,
                 raise_on_fault: bool = True, clock: Any = None, delay_ticks: int = 0,
                 max_position_mm: float = 1000.0, max_speed_mm_s: float = 5000.0,
                 max_accel_mm_s2: float = 2.0e6, max_catchup_ticks: int = 5,
                 passivity_settings: ControllerSettings | None = None,
                 drop_unmapped_roles: bool = False, cpu_time: bool = True,
                 rt: RealtimeSettings | Mapping[str, Any] | None = None) -> None:
        if not isinstance(device, HapticDevice):
            raise ValidationError("device must be a HapticDevice", field="device")
        if not (isinstance(period_s, (int, float)) and math.isfinite(period_s) and 0 < period_s <= 1.0):
            raise ValidationError(f"period must be in (0, 1] s, got {period_s!r}", field="period_s")
        if int(delay_ticks) < 0:
            raise ValidationError("delay_ticks must be >= 0", field="delay_ticks")
        self.device = device
        self.renderers = list(renderers)
        self.actuators: dict[str, Actuator] = dict(actuators) if actuators is not None else {"force": device}
        for r in self.renderers:
            if not isinstance(r, DimensionRenderer):
                raise ValidationError(f"{r!r} is not a DimensionRenderer", field="renderers")
            missing = [role for role in r.roles if role not in self.actuators]
            if missing and not drop_unmapped_roles:
                raise ValidationError(f"renderer {type(r).__name__} commands role(s) {missing} with no "
                                      f"actuator; mapped roles: {sorted(self.actuators)}", field="actuators")
        self.period_s = float(period_s)
        self.realtime = bool(realtime)
        self.recorder = recorder
        self.passivity = bool(passivity)
        self.raise_on_fault = bool(raise_on_fault)
        self.clock = clock if clock is not None else (MonotonicClock() if realtime else None)
        self.delay_ticks = int(delay_ticks)
        self.max_position_mm = float(max_position_mm)
        self.max_speed_mm_s = float(max_speed_mm_s)
        self.max_accel_mm_s2 = float(max_accel_mm_s2)
        self.max_catchup_ticks = int(max_catchup_ticks)
        if passivity_settings is None:
            # the device's apparent mass (if it declares one) bounds the in-period push
            # and its declared physical damping is credited (device + wall passivity)
            passivity_settings = ControllerSettings(
                device_mass_kg=getattr(device, "apparent_mass_kg", None),
                device_damping_ns_per_m=float(getattr(device, "damping_ns_per_m", 0.0) or 0.0),
                position_resolution_mm=float(getattr(device, "encoder_resolution_mm", 0.0) or 0.0))
        self.passivity_settings = passivity_settings
        self.cpu_time = bool(cpu_time)
        self.rt = RealtimeSettings.coerce(rt)

    # ------------------------------------------------------------------
    def _stop_all(self) -> None:
        """Every actuator to its safe state. Each one is tried even when another one's
        ``stop()`` raises (a backend that breaks the never-raise contract, or a second
        Ctrl-C); the first such exception is re-raised after all were tried."""
        first: BaseException | None = None
        for act in _distinct([self.device, *self.actuators.values()]):
            act.stop()
        if first is not None:
            raise first

    def run(self, seconds: float) -> LoopReport:
        """Run for ``seconds`` of (simulated or real) time; return a :class:`LoopReport`."""
        if not (isinstance(seconds, (int, float)) and math.isfinite(seconds) and seconds > 0):
            raise ValidationError(f"seconds must be > 0, got {seconds!r}", field="seconds")
        T = self.period_s
        # ticks at t = 0, T, ..., seconds - T: a run of `seconds` at period T has seconds/T ticks
        n_max = max(1, int(math.floor(seconds / T + 1e-9)))
        device = self.device
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
            slots.append(s)
        by_role = {s.role: s for s in slots}
        stepped = [a for a in _distinct(self.actuators.values())
                   if a is not device and getattr(a, "simulated", False) and callable(getattr(a, "step", None))]
        sim_device = bool(getattr(device, "simulated", False))
        hits0 = {id(a): sum(a.safety.hits.values()) if hasattr(a.safety, "hits") else 0
                 for a in _distinct([device, *self.actuators.values()])}

        # logs
        L_t = np.zeros(n_max)
        L_dt = np.zeros(n_max)
        L_pen = np.zeros(n_max)
        L_pos = np.zeros((n_max, 3))
        L_vel = np.zeros((n_max, 3))
        L_f = np.zeros(n_max)
        L_compute = np.zeros(n_max)
        L_cpu = np.zeros(n_max)
        L_sim = np.zeros(n_max)
        L_start = np.zeros(n_max)
        for s in slots:
            if not s.is_force:
                s.log_f = np.zeros(n_max)
                s.log_a = np.zeros(n_max)
        events = dict.fromkeys(EVENT_KEYS, 0)

        observers = [a.safety for a in _distinct(self.actuators.values())]
        renderers = self.renderers
        recorder = self.recorder
        max_pos, max_spd = self.max_position_mm, self.max_speed_mm_s
        max_acc, max_catchup = self.max_accel_mm_s2, self.max_catchup_ticks
        clock = self.clock
        realtime = self.realtime
        fault: dict[str, str] | None = None
        fault_exc: BaseException | None = None

        last_pos = np.zeros(3)
        last_vel = np.zeros(3)
        have_good = False
        good_state: DeviceState | None = None
        perf = time.perf_counter
        cpu_time = self.cpu_time
        tcpu = time.thread_time_ns
        cpu_cost_us = 2e6 * thread_cpu_clock_cost_s() if cpu_time else float("nan")

        gc_was_enabled = gc.isenabled()
        gc.collect()
        froze = False
        if self.rt.gc_freeze and hasattr(gc, "freeze"):
            gc.freeze()
            froze = True
        gc.disable()
        rt_status, rt_restore = apply_realtime(self.rt)
        rt_status["gc"] = ("applied: collected, frozen and disabled" if froze else
                           "applied: collected and disabled (freeze off)" if not self.rt.gc_freeze else
                           "applied: collected and disabled (gc.freeze unavailable)")
        rt_status["applied"] = sorted(k for k, v in rt_status.items() if v.startswith("applied"))
        k = 0
        t_prev = 0.0
        try:
            if realtime:
                t_origin = clock.now()
                deadline = t_origin
            while k < n_max:
                if realtime:
                    clock.wait_until(deadline)
                    now = clock.now()
                    t = now - t_origin
                    dt = t - t_prev if k else T
                    if k and sim_device:
                        # physics advances by the time that really passed
                        s0 = perf()
                        device.step(dt)
                        for a in stepped:
                            a.step(dt)
                        L_sim[k - 1] = perf() - s0
                else:
                    t = k * T
                    dt = T
                c0 = perf()
                if cpu_time:
                    q0 = tcpu()
                L_start[k] = t
                # ---- 1. sense -------------------------------------------------
                try:
                    # the backend read: the loop does its own checks of the values
                    st = device._read_state()
                except Exception as exc:
                    fault_exc = exc if isinstance(exc, DeviceError) else DeviceError(
                        f"read failed: {type(exc).__name__}: {exc}", device=device.label)
                    fault = {"device": getattr(fault_exc, "device", None) or device.label, "message": str(fault_exc)}
                    break
                pos = st.position_mm
                vel = st.velocity_mm_s
                bad = False
                p0, p1, p2 = float(pos[0]), float(pos[1]), float(pos[2])
                v0, v1, v2 = float(vel[0]), float(vel[1]), float(vel[2])
                if not (math.isfinite(p0 + p1 + p2) and math.isfinite(v0 + v1 + v2)):
                    events["nonfinite_state"] += 1
                    bad = True
                elif (abs(p0) > max_pos or abs(p1) > max_pos or abs(p2) > max_pos
                      or v0 * v0 + v1 * v1 + v2 * v2 > max_spd * max_spd):
                    events["huge_state"] += 1
                    bad = True
                elif have_good:
                    lim = max_acc * dt
                    if (abs(v0 - last_vel[0]) > lim or abs(v1 - last_vel[1]) > lim or abs(v2 - last_vel[2]) > lim):
                        events["velocity_spike"] += 1
                        v0, v1, v2 = float(last_vel[0]), float(last_vel[1]), float(last_vel[2])
                        st = DeviceState(t=st.t, position_mm=pos, velocity_mm_s=last_vel.copy(),
                                         force_n=st.force_n, buttons=st.buttons)
                if bad:
                    st = good_state if good_state is not None else DeviceState(
                        t=t, position_mm=np.array([0.0, max_pos, 0.0]), velocity_mm_s=np.zeros(3))
                else:
                    have_good = True
                    good_state = st
                    last_pos[0], last_pos[1], last_pos[2] = p0, p1, p2
                    last_vel[0], last_vel[1], last_vel[2] = v0, v1, v2
                for obs in observers:
                    obs.observe(st)
                # ---- 2. render ------------------------------------------------
                pen = -p1 if not bad else 0.0
                forces: dict[str, float] = {}
                vib: dict[str, ChannelCommand] = {}
                if not bad:
                    inp = TickInput(t=t, dt=dt, penetration_mm=pen, velocity_mm_s=st.velocity_mm_s,
                                    in_contact=pen > 0.0)
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
                                if f is None:
                                    continue
                                if f != f or f in (math.inf, -math.inf):
                                    events["nonfinite_command"] += 1
                                    continue
                                if f < 0.0:
                                    events["negative_force"] += 1
                                    f = 0.0
                                forces[c.role] = forces.get(c.role, 0.0) + f
                            else:
                                fr, am = c.frequency_hz, c.amplitude
                                if (fr is not None and not math.isfinite(fr)) or (am is not None and not math.isfinite(am)):
                                    events["nonfinite_command"] += 1
                                    c = ChannelCommand(c.role, frequency_hz=None, amplitude=0.0)
                                if c.role in vib:
                                    events["role_conflict"] += 1
                                    continue
                                vib[c.role] = c
                # ---- 3. passivity + send ------------------------------------
                sent: dict[str, ChannelCommand] = {}
                for s in slots:
                    if s.is_force:
                        f = forces.get(s.role, 0.0)
                        if s.pending is not None:
                            s.pending.append(f)
                            f = s.pending.popleft()
                        if s.pc is not None:
                            f = s.pc.step(p1 if not bad else float(last_pos[1]), dt, f)
                        cmd = ChannelCommand(s.role, force_n=f)
                    else:
                        cmd = vib.get(s.role)
                        if cmd is None:
                            last = s.act.last_command
                            cmd = ChannelCommand(s.role, frequency_hz=last.frequency_hz if last else None,
                                                 amplitude=0.0)
                    try:
                        out = s.act.command(cmd, now=t)
                    except DeviceError as exc:
                        fault_exc = exc
                        fault = {"device": exc.device or s.act.label, "message": str(exc)}
                        break
                    except Exception as exc:  # validation of a value we should have caught
                        fault_exc = DeviceError(f"command rejected: {type(exc).__name__}: {exc}",
                                                device=s.act.label)
                        fault = {"device": s.act.label, "message": str(fault_exc)}
                        break
                    sent[s.role] = out
                    if s.is_force:
                        if s.pc is not None:
                            s.pc.commit(out.force_n if out.force_n is not None else 0.0)
                        L_f[k] = out.force_n or 0.0
                    else:
                        s.log_f[k] = out.frequency_hz if out.frequency_hz is not None else np.nan
                        s.log_a[k] = out.amplitude or 0.0
                if fault is not None:
                    break
                if recorder is not None:
                    try:
                        recorder.record(t, st, sent)
                    except Exception:
                        events["renderer_error"] += 1
                L_t[k] = t
                L_dt[k] = dt
                L_pen[k] = pen
                L_pos[k] = st.position_mm
                L_vel[k] = st.velocity_mm_s
                if cpu_time:
                    L_cpu[k] = (tcpu() - q0) * 1e-9
                c1 = perf()
                L_compute[k] = c1 - c0
                if c1 - c0 > T:
                    events["overrun"] += 1
                # ---- 4. pace / step ------------------------------------------
                if realtime:
                    clock.work(k, c1 - c0)
                    t_prev = t
                    deadline += T
                    now = clock.now()
                    behind = (now - deadline) / T
                    if behind > max_catchup:
                        skipped = int(behind)
                        events["skipped_ticks"] += skipped
                        deadline += skipped * T
                else:
                    s0 = perf()
                    try:
                        if sim_device:
                            device.step(T)
                        for a in stepped:
                            a.step(T)
                    except DeviceError as exc:
                        fault_exc = exc
                        fault = {"device": exc.device or device.label, "message": str(exc)}
                        k += 1
                        break
                    L_sim[k] = perf() - s0
                k += 1
        except BaseException as exc:
            # safety (issue 13, item 3): ANY exception leaving the loop -- KeyboardInterrupt,
            # SystemExit, SafeStop (SIGTERM/SIGHUP), an OSError from a sink or a device
            # step, anything from a renderer, recorder or actuator -- stops every actuator
            # first, then propagates unchanged
            try:
                self._stop_all()
            except BaseException as stop_exc:  # noqa: BLE001 - the original exception wins
                _log.error("stopping after %s: %s", type(exc).__name__, stop_exc)
            raise
        finally:
            rt_restore()
            if gc_was_enabled:
                gc.enable()
            close = getattr(recorder, "close", None)
            if callable(close):
                try:
                    close()
                except Exception as exc:  # the run's outcome matters more than the log
                    _log.warning("recorder.close() failed: %s", exc)
            if froze and hasattr(gc, "unfreeze"):
                gc.unfreeze()
            if fault is not None:
                self._stop_all()

        n = k
        for a in _distinct([device, *self.actuators.values()]):
            if hasattr(a.safety, "hits"):
                events["clamp"] += sum(a.safety.hits.values()) - hits0.get(id(a), 0)
        pas: dict[str, Any] = {}
        for s in slots:
            if s.pc is not None:
                rep = s.pc.report()
                events["passivity_active"] += rep["active_ticks"]
                pas[s.role] = rep
        comp = tick_stats(L_compute[:n])
        if cpu_time:
            cpu = tick_stats(L_cpu[:n])
            pre = preemption_stats(L_compute[:n], L_cpu[:n])
        else:
            cpu = tick_stats(np.zeros(0))
            pre = {"preempted_ticks": None, "off_cpu_max_us": float("nan")}
        jit = None
        if realtime and n > 1:
            jit = jitter_stats(np.diff(L_start[:n]), T)
        log = {"t": L_t[:n].copy(), "dt": L_dt[:n].copy(), "penetration_mm": L_pen[:n].copy(),
               "position_mm": L_pos[:n].copy(), "velocity_mm_s": L_vel[:n].copy(), "force_n": L_f[:n].copy(),
               "compute_s": L_compute[:n].copy()}
        if cpu_time:
            log["compute_cpu_s"] = L_cpu[:n].copy()
        for s in slots:
            if not s.is_force:
                log[f"{s.role}.frequency_hz"] = s.log_f[:n].copy()
                log[f"{s.role}.amplitude"] = s.log_a[:n].copy()
        sim_us = float(np.median(L_sim[:n]) * 1e6) if n else float("nan")
        report = LoopReport(ticks=n, period_s=T, realtime=realtime, tick_median_us=comp["median_us"],
                            tick_p99_us=comp["p99_us"], tick_max_us=comp["max_us"], tick_p999_us=comp["p999_us"],
                            overruns=events["overrun"], jitter=jit, events=events, passivity=pas,
                            fault=fault, sim_step_median_us=sim_us, log=log,
                            tick_cpu_median_us=cpu["median_us"], tick_cpu_p99_us=cpu["p99_us"],
                            tick_cpu_p999_us=cpu["p999_us"], tick_cpu_max_us=cpu["max_us"],
                            preempted_ticks=pre["preempted_ticks"], off_cpu_max_us=pre["off_cpu_max_us"],
                            cpu_clock_cost_us=cpu_cost_us, rt=rt_status)
        self.report = report
        if fault_exc is not None and self.raise_on_fault:
            if isinstance(fault_exc, DeviceError):
                fault_exc.report = report  # type: ignore[attr-defined]
                raise fault_exc
            raise DeviceError(str(fault_exc), device=fault["device"] if fault else None) from fault_exc
        return report
