"""The application side of a live session: :class:`Session` (compiles the scene,
starts the servo, reads its state and events, sends material and object changes) and
:class:`Retarget`, what a material switch sent.

Part of :mod:`hapticsdk.runtime.session`, the public home of these names.
"""

from __future__ import annotations

import logging
import math
import multiprocessing as mp
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

from ...errors import HapticSDKError, ServoProcessDied, SessionError, ValidationError
from ...fileio import check_output_path
from .protocol import (
    CLAMP_FIELDS, EVENT_KINDS, HEARTBEAT_PERIOD_S, SessionEvent, SessionState, _ACK0, _ACK_CAP,
    _ACK_REC, _Buffer, _EV0, _EV_CAP, _EV_REC, _EV_W, _FAILED, _HB_ARMED, _HEARTBEAT, _PAUSE, _PUB, _RUNNING,
    _STARTING, _STATUS, _STOP, _STOPPED, _T, _VIB0, _VIB_N, _read_state, _state_from
)
from .pipe import _grow_pipe
from .shipping import dump_renderers
from .servo import _Servo, _servo_main

_log = logging.getLogger(__name__)


ISOLATIONS = ("process", "thread")


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


def _default_rt(rt: Any, isolation: str) -> dict[str, Any] | None:
    """The servo's OS options (a mapping for the servo's spec, or None): a servo process
    asks for ``SCHED_FIFO`` (``"auto"``) unless the caller's options say otherwise."""
    from dataclasses import asdict

    from ..clock import RealtimeSettings
    if isinstance(rt, RealtimeSettings):
        return asdict(rt)
    out = dict(rt) if rt is not None else None
    if isolation == "process":
        out = out if out is not None else {}
        out.setdefault("fifo_priority", "auto")
        if "cpu" not in out:
            from ..rtkit import spare_cpu
            cpu = spare_cpu()  # pinned only where a CPU is spare (3 or more)
            if cpu is not None:
                out["cpu"] = cpu
    return out


class Session:
    """A live haptic session on a scene; see :mod:`hapticsdk.runtime.session`.

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
        from ...compiler import compile_scene
        from ...scene import Scene
        from ...argcheck import flag, number
        from ...scene.limits import check_period
        if isolation not in ISOLATIONS:
            raise ValidationError(f"isolation must be one of {list(ISOLATIONS)}, got {isolation!r}",
                                  field="isolation")
        # every argument checked here, before a process starts (a string that reads as a
        # number, a bool for a number or a switch given as "no" are the caller's bugs)
        ramp_s = number(ramp_s, "ramp_s", lo=0.0, hi=5.0)
        if heartbeat_timeout_s is not None:   # None: only the parent-process check (documented)
            heartbeat_timeout_s = number(heartbeat_timeout_s, "heartbeat_timeout_s", lo=2 * HEARTBEAT_PERIOD_S)
        if period_s is not None:
            period_s = check_period(number(period_s, "period_s"), "period_s")
        log_seconds = number(log_seconds, "log_seconds", lo=0.0, lo_open=True)
        start_timeout_s = number(start_timeout_s, "start_timeout_s", lo=0.0, lo_open=True)
        realtime = flag(realtime, "realtime")
        refine = flag(refine, "refine")
        if view is not None and not isinstance(view, bool):
            view = int(number(view, "view", lo=0, hi=65535, integer=True))   # a port
        from ..render import _check_app_options
        actuator_options = _check_app_options(actuator_options)
        from ..recorder import check_record_path
        if rt is not None:
            from ..clock import RealtimeSettings
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
        from ..callbacks import EventDispatcher
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
        from ...devices.device_options import check_data_settings
        check_data_settings(settings, field="scene.settings")  # safety is not data (issue 31)
        period = float(period_s if period_s is not None else servo.get("period_s", 0.001))
        # devices: role -> (actuator, options), one actuator per role for every material
        from ...plugins import registry
        from ..render import _actuator_options
        devices: dict[str, tuple[str, dict[str, Any]]] = {}
        for mp_ in plan.materials.values():
            for role, name in mp_.actuators.items():
                # as render_plan: the plan's options (never a privileged one: a scene file
                # may not name a library or an output file), then the user's device
                # configuration and environment, then the application's
                opts = _actuator_options(registry("actuator").load(name), name, role, mp_, actuator_options)
                if role in devices and devices[role][0] != name:
                    raise ValidationError(f"role {role!r} is mapped to {devices[role][0]!r} and {name!r} by "
                                          f"two materials; a session opens one actuator per role",
                                          field=f"scene.devices.{role}")
                devices.setdefault(role, (name, opts))
        unknown = sorted(set(actuator_options) - set(devices))
        if unknown:
            raise ValidationError(f"roles {unknown} are not roles of this scene (it has {sorted(devices)})",
                                  field="actuator_options")
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
                from ..supervisor import ServoSupervisor
                self._supervisor = ServoSupervisor(self._process, devices, on_exit=self._dispatcher.wake)
                cmd_r.close()
                done_w.close()
                _grow_pipe(self._cmd)
            else:
                cmd_r, self._cmd = mp.Pipe(duplex=False)
                self._done, done_w = mp.Pipe(duplex=False)
                _grow_pipe(self._cmd)
                # one interpreter: warm up before the servo thread starts. Beside a
                # running servo thread the warm-up's numpy calls (a table build, with a
                # cold cache) wait for the interpreter's lock after each call: next to a
                # simulated-time servo, which runs flat out, that took a cold build from
                # 1.3 s to over 3 minutes; next to a realtime one it delays the ticks
                self._warm()
                self._servo_holder: list = []
                self._thread = threading.Thread(target=_servo_main,
                                                args=(spec, cmd_r, None, done_w, self._mv, self._servo_holder),
                                                name="hapticsdk-servo", daemon=True)
                self._thread.start()
            self._hb_stop = threading.Event()
            self._hb = threading.Thread(target=self._heartbeat, name="hapticsdk-heartbeat", daemon=True)
            self._hb.start()
            if isolation == "process":
                self._warm()   # in the application while the servo process starts
            deadline = time.monotonic() + start_timeout_s
            while self._mv[_STATUS] == _STARTING:
                if not self._servo_alive():
                    break
                if time.monotonic() > deadline:
                    raise SessionError(f"the servo did not start within {start_timeout_s} s")
                time.sleep(0.002)
            self._check()
            # from here on the servo watches the heartbeat (a fresh one first): the
            # start-up above may have starved the heartbeat thread on a busy machine
            self._mv[_HEARTBEAT] = time.monotonic()
            self._mv[_HB_ARMED] = 1.0
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
        from ..recorder import part_path, recover
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
            # a call of the API is a heartbeat too: the application's thread is running. A
            # busy thread that calls state() in a tight loop may starve the heartbeat
            # thread for longer than the timeout on a loaded machine
            mv[_HEARTBEAT] = now
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
        with the calibration tables they hold (:func:`.shipping.dump_renderers`, e.g. the
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
            return dump_renderers(rs, self._tables_sent, len(self._tables_sent) + 1)
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
        from ..callbacks import SwitchHandle
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
        if not isinstance(name, str):   # a list or a dict as a name failed to hash (TypeError)
            raise ValidationError(f"must be an object's name, got {type(name).__name__} {name!r:.60}",
                                  field="object")
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
        from ...solvers.problems import solve
        return solve(dict(targets), method="amortised", seed=0, options={"polish_steps": 0},
                     **self._solve_kw())

    def _features_by_dim(self, dims: Sequence[str], x: Mapping[str, float]) -> dict[str, dict[str, float]]:
        from ...plugins import registry
        out = {}
        for d in dims:
            cls = registry("dimension").load(d)
            names = {f.name for f in cls.features}
            out[d] = {k: float(v) for k, v in x.items() if k in names}
        return out

    def _targets(self, material: Any, field: str) -> tuple[str, dict[str, float]]:
        from ...perception.dimensions import check_intensity
        if isinstance(material, str):
            from ...perception.materials import load_library
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
            from ..live_api import intensities  # numbers in 0..1, not '0.5' (issue 31)
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
            from ...solvers.problems import solve
            method = self._settings["solver"]["method"]
            res = solve(dict(targets), method=method, seed=self._settings["solver"].get("seed", 0),
                        options=dict(self._settings["solver"].get("options") or {}), **self._solve_kw())
            source = method
        return self._features_by_dim(dims, res.x_dict), source, res

    def _check_roles(self, feats: Mapping[str, Mapping[str, float]], field: str) -> None:
        from ...plugins import registry
        for d in feats:
            cls = registry("dimension").load(d)
            roles = set(getattr(cls, "default_actuators", {}) or {})
            missing = sorted(roles - set(self.devices))
            if missing:
                raise ValidationError(f"dimension {d!r} needs role(s) {missing}, which this session has not "
                                      f"opened (roles: {sorted(self.devices)})", field=field)

    def _refine(self, r: Retarget, oid: int) -> None:
        from ...solvers.problems import solve
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
        from ...argcheck import flag, number
        ramp = self.ramp_s if ramp_s is None else number(ramp_s, "ramp_s", lo=0.0, hi=5.0)
        if refine is not None:
            refine = flag(refine, "refine")
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
        from ...scene.geometry import shape_from_dict
        if not isinstance(name, str) or not name or name in self._ids:
            raise ValidationError(f"object name must be new and non-empty, got {name!r}", field="name")
        shape = shape_from_dict(geometry, pose)
        from ..live_api import check_object, session_workspace  # inside the workspace + margin
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
        from ...scene.geometry import Pose
        oid = self._object_id(name)
        p = Pose.from_dict(pose)
        from ..live_api import session_workspace
        from ...scene.bounds import check_shape  # inside the workspace + margin (issue 31)
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
        mv[_HEARTBEAT] = now   # a call is a heartbeat (see _check)
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
            from ..view import ViewServer
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
        if not isinstance(kind, str) or (kind != "*" and kind not in EVENT_KINDS):
            # a string first: an array compared with a string warns on older numpy
            raise ValidationError(f"kind must be one of {list(EVENT_KINDS)} or '*', got {kind!r}", field="kind")
        if not callable(callback):
            raise ValidationError(f"callback must be callable, got {callback!r}", field="callback")
        self._check()
        self._dispatcher.add(kind, callback)

    def off_event(self, kind: str, callback: Any) -> bool:
        """Remove a callback given to :meth:`on_event`; True when it was registered."""
        if not isinstance(kind, str):   # looked up in a dict: a list failed to hash (TypeError)
            raise ValidationError(f"kind must be one of {list(EVENT_KINDS)} or '*', got {kind!r:.60}", field="kind")
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
        from ...argcheck import flag
        on = flag(on, "on")
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
