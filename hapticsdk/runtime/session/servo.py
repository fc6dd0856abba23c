"""The servo side of a live session: :class:`_Servo` (devices, the loop, publishing,
the commands done in each period's slack) and :func:`_servo_main`, the entry point of
the servo process (or thread), with its safe stop and its thread-pool limits.

Part of :mod:`hapticsdk.runtime.session`.
"""

from __future__ import annotations

import logging
import math
import multiprocessing as mp
import os
import pickle
import sys
import time
from typing import Any, Mapping

from ...errors import HapticSDKError
from .protocol import (
    CLAMP_FIELDS, CLAMP_REPORT_S, Slots, _ACK0, _ACK_CAP, _ACK_REC, _CLAMPS, _CLAMP_INDEX, _EV0,
    _EV_CAP, _EV_REC, _EV_W, _F, _FAILED, _HB_ARMED, _HEARTBEAT, _KIND, _MISSED, _NEAR, _OBJ, _OVERRUNS,
    _PAUSE, _PAUSED_S, _PEN, _PID, _PUB, _PX, _PY, _PZ, _READY, _REASON, _RERR, _RUNNING, _SEQ,
    _SEQ_END, _SKIPPED, _STATUS, _STOP, _STOPPED, _STOP_REASONS, _SWITCHED_AT, _SWITCHES, _T,
    _TICKS, _TICK_MAX_US, _TICK_US, _VIB0, _VIB_N, _VX, _VY, _VZ, _attach
)
from .pipe import _CommandReader
from .shipping import _load_renderers
from ...threadpools import one_thread, one_thread_environment

_log = logging.getLogger(__name__)


#: a command's build waits at most this many ticks for a slack long enough for it
_MAX_WAIT_TICKS = 3
#: kept free before the next deadline (s)
_SLACK_MARGIN_S = 100e-6
#: estimated cost of building one dimension's renderers never measured yet (s)
_UNKNOWN_BUILD_S = 1e-3
#: estimated cost of a command with nothing to build (s)
_SMALL_S = 30e-6


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
        from ...plan import MaterialPlan
        from ..render import _calibrations, build_renderers
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
        from ...plan import RenderPlan
        from ...plugins import registry
        from ..render import _capabilities
        spec = self.spec
        if plan is None:
            plan = RenderPlan.from_dict(spec["plan"], validate=False)
        self._settings = plan.settings
        chosen = {role: (registry("actuator").load(name), dict(opts)) for role, (name, opts) in spec["devices"].items()}
        self._role_options = {r: o for r, (_, o) in chosen.items()}
        self._caps = _capabilities(chosen)

    def build(self) -> None:
        from contextlib import ExitStack

        from ...devices.actuators import Actuator, HapticDevice
        from ...plan import FALLBACK_SENSOR, RenderPlan
        from ...plugins import registry
        from ...scene.geometry import HitTester, shape_from_dict
        from ..clock import MonotonicClock
        from ..loop import ServoLoop
        from ..render import _calibrations, build_renderers

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
            from ..recorder import LiveRecorder
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
            from ...scene.geometry import shape_from_dict
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
            from ...scene.geometry import Pose
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
                if watch and hb_timeout is not None and mv[_HB_ARMED] != 0.0:
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
        from ...devices.actuators import stops_since
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

                        from ...fileio import atomic_savez
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
    from ..signals import SafeStop, safe_stop_on_signals
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
        one_thread_environment()  # pools loaded while building: one thread from the start
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
                    servo.pools = one_thread()  # after build(): scipy.linalg is loaded by now
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
