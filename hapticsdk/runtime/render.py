"""Render a compiled plan: open its actuators, run the servo loop, report.

:func:`render_plan` renders one material of a :class:`~hapticsdk.plan.RenderPlan`
without solving again: it builds each kept dimension's renderer from the plan's
features (``dimension.renderer(features)``) plus the replacements the plan names (a
constant 1 N force in place of a dropped hardness), imports and opens only the
actuators the plan maps the renderers' roles to (each in a context manager, so every
one is stopped and closed on any error), picks the sensing device (an actuator of the
plan that is a :class:`~hapticsdk.devices.actuators.HapticDevice`, such as ``omni-virtual``;
otherwise the kinematic ``probe-virtual``), runs :class:`hapticsdk.runtime.ServoLoop`,
and calls the ``hapticsdk_render_started`` / ``hapticsdk_render_finished`` hooks of the
distributions the plan uses only.
"""

from __future__ import annotations

import inspect
import json
import logging
import math
import time
from contextlib import ExitStack
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..devices.actuators import Actuator, HapticDevice
from ..perception.dimensions import DimensionRenderer
from ..errors import DeviceError, PluginError, ValidationError
from ..plan import FALLBACK_SENSOR, MaterialPlan, RenderPlan
from ..plugin_api import check_plugin_api
from ..scene.limits import check_period, check_seconds
from .replacements import make_replacement

log = logging.getLogger(__name__)


@dataclass
class RenderReport:
    """What one render did.

    Attributes:
        material: the material rendered.
        scene: the plan's scene name.
        dimensions: dimensions rendered; ``replacements``: what replaced dropped ones.
        actuators: role -> actuator name opened; ``sensor``: the sensing device's name.
        seconds: requested duration (s); ``wall_s``: wall time of the loop (s).
        tick_median_us, tick_p99_us: tick computation time statistics (us).
        overruns: ticks that took longer than the period; ``fault``: the fault, if any.
        renderers: each renderer's ``describe()`` after the run.
        safety: actuator label -> safety report (limit hits).
        devices: actuator label -> its ``describe()`` at the end of the run (before closing).
        hooks: distributions whose hook modules were registered.
        loop: the :class:`~hapticsdk.runtime.LoopReport` (``to_dict`` in JSON).
        calibrations: dimension -> the actuator calibration its renderer used (``kind``,
            ``origin``, ``file``, ``sha256``, ``source``; ``changed_since_plan`` when the
            file differs from the one the plan was compiled with).
    """

    material: str
    scene: str
    dimensions: list[str]
    replacements: list[dict[str, Any]]
    actuators: dict[str, str]
    sensor: str
    seconds: float
    wall_s: float
    tick_median_us: float | None
    tick_p99_us: float | None
    overruns: int | None
    fault: dict[str, Any] | None
    renderers: dict[str, Any] = field(default_factory=dict)
    safety: dict[str, Any] = field(default_factory=dict)
    hooks: list[str] = field(default_factory=list)
    loop: Any = None
    ticks: int | None = None
    devices: dict[str, Any] = field(default_factory=dict)
    features: dict[str, float] = field(default_factory=dict)
    dropped: list[dict[str, Any]] = field(default_factory=list)
    solve: dict[str, Any] = field(default_factory=dict)
    calibrations: dict[str, dict[str, Any]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The report as JSON-ready data (the servo loop's report without its per-tick log).
        """
        loop = self.loop.to_dict() if hasattr(self.loop, "to_dict") else self.loop
        return json.loads(json.dumps({
            "material": self.material, "scene": self.scene, "dimensions": list(self.dimensions),
            "replacements": list(self.replacements), "actuators": dict(self.actuators),
            "sensor": self.sensor, "seconds": self.seconds, "wall_s": self.wall_s,
            "tick_median_us": self.tick_median_us, "tick_p99_us": self.tick_p99_us,
            "overruns": self.overruns, "fault": self.fault, "renderers": self.renderers,
            "tick": {"ticks": self.ticks, "median_us": self.tick_median_us,
                     "p99_us": self.tick_p99_us, "overruns": self.overruns},
            "features": dict(self.features), "dropped": list(self.dropped), "solve": dict(self.solve),
            "calibrations": dict(self.calibrations),
            "safety": self.safety, "devices": self.devices, "hooks": list(self.hooks), "loop": loop}, default=_jsonable))


def _jsonable(o: Any) -> Any:
    import numpy as np
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if hasattr(o, "to_dict"):
        return o.to_dict()
    return str(o)


def _accepts(cls: type, kw: str) -> bool:
    try:
        params = inspect.signature(getattr(cls, "__init__")).parameters
    except (TypeError, ValueError):
        return False
    return kw in params or any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()
                               if p.name != "options")


def build_renderers(mp: MaterialPlan, settings: Mapping[str, Any] | None = None, *,
                    calibrations: Mapping[str, Mapping[str, Any]] | None = None,
                    capabilities: Mapping[str, Any] | None = None) -> list[DimensionRenderer]:
    """Renderers of one material plan: kept dimensions from the plan's features, then the
    replacements of dropped ones (no solving). ``calibrations``: dimension -> renderer
    options holding saved calibrations (:func:`hapticsdk.calibration.selection.select_calibrations`);
    ``capabilities``: role -> :class:`~hapticsdk.devices.actuators.DriveCapability` of the actuator
    on that role (an actuator's own drive table goes to the renderer, as at compile time:
    the scene's ``renderer_options`` win, then the actuator's own table, then calibrations)."""
    from ..plugins import registry
    ropts = dict((settings or {}).get("renderer_options") or {})
    out: list[DimensionRenderer] = []
    for d in mp.dimensions:
        cls = registry("dimension").load(d)
        check_plugin_api(cls, name=d)
        dim = cls() if isinstance(cls, type) else cls
        given = dict(ropts.get(d, {}))
        from ..argcheck import refuse_file_options
        refuse_file_options(dim, given, f"plan.settings.renderer_options.{d}")
        opts = {**given, **dict((calibrations or {}).get(d, {}))}
        if capabilities and hasattr(dim, "capability_options"):
            roles = list(getattr(dim, "roles", {}) or {}) or list(dim.default_actuators)
            own = dim.capability_options({ro: capabilities[ro] for ro in roles if ro in capabilities})
            opts.update({k: v for k, v in own.items() if k not in given})
        from ..argcheck import call_with_options  # an unknown option is named, not a TypeError
        r = call_with_options(dim.renderer, dict(mp.features), options=opts,
                              field=f"plan.settings.renderer_options.{d}")
        missing = [role for role in r.roles if role not in mp.actuators]
        if missing:
            raise ValidationError(f"renderer of {d!r} commands roles {missing} that the plan maps to "
                                  f"no actuator (plan roles {sorted(mp.actuators)}); compile again",
                                  field=f"plan.materials.{mp.name}.actuators")
        out.append(r)
    for dd in mp.replacements:
        out.append(make_replacement(dd.replacement or {}, dd.dimension))
    return out


def _capabilities(chosen: Mapping[str, tuple[Any, dict[str, Any]]]) -> dict[str, Any]:
    """role -> what the actuator that will be opened there can produce (asked of its class
    with the same options); roles whose actuator publishes nothing are absent."""
    out: dict[str, Any] = {}
    for role, (cls, opts) in chosen.items():
        if not hasattr(cls, "capability_for"):
            continue
        try:
            cap = cls.capability_for(dict(opts))
        except Exception:   # the real instance reports the problem when it is created
            continue
        if cap is not None:
            out[role] = cap
    return out


def render_plan(plan: RenderPlan | Mapping[str, Any], *, seconds: float, material: str | None = None,
                trajectory: Any = None, recorder: Any = None, realtime: bool | None = None,
                period_s: float | None = None, hooks: bool = True,
                raise_on_fault: bool = True,
                actuator_options: Mapping[str, Mapping[str, Any]] | None = None,
                passivity: bool | None = None) -> RenderReport:
    """Render one material of ``plan`` for ``seconds`` (s) of servo time.

    Args:
        plan: a :class:`RenderPlan` or its dict form.
        seconds: duration (s) of the servo loop.
        material: which material (default: the plan's first).
        trajectory: scripted hand path (:class:`hapticsdk.sim.finger.Trajectory`) given to
            the sensing device when it is simulated and accepts one (default: its own,
            a press then a slide at 80 mm/s).
        recorder, realtime, period_s: passed to the servo loop (defaults: the plan's servo
            settings; ``realtime`` defaults to True whenever an actuator of the material
            is real, i.e. not ``simulated``, whatever the plan says).
        hooks: call the render hooks of the plan's distributions.
        raise_on_fault: re-raise a device fault after the safe stop.
        actuator_options: role -> options from the application (code or command line),
            merged over the plan's options, the user's device configuration file and
            ``$HAPTICSDK_DEVICE_OPTIONS``. The only way, with those two, to give an actuator's
            privileged options (a native library, an output file, a port): a plan may not
            (:mod:`hapticsdk.devices.device_options`).
        passivity: ``False`` switches the passivity controller off (code only: a plan
            whose ``settings.servo.passivity`` is not ``true`` is refused,
            :func:`hapticsdk.devices.device_options.check_data_settings`). Default on.
    """
    if isinstance(plan, Mapping):
        plan = RenderPlan.from_dict(plan)
    if not isinstance(plan, RenderPlan):
        raise ValidationError("plan must be a RenderPlan or its dict", field="plan")
    # ranges checked before any actuator opens or any buffer is allocated (scene.limits)
    secs = check_seconds(seconds, "seconds")
    mp = plan.material(material)
    app_options = _check_app_options(actuator_options)
    unknown = sorted(set(app_options) - set(mp.actuators))
    if unknown:
        raise ValidationError(f"roles {unknown} are not roles of material {mp.name!r} "
                              f"(it has {sorted(mp.actuators)})", field="actuator_options")
    servo = dict(plan.settings.get("servo") or {})
    period = check_period(period_s if period_s is not None else servo.get("period_s", 0.001),
                          "period_s" if period_s is not None else "plan.settings.servo.period_s")
    from ..devices.device_options import check_data_settings
    check_data_settings(plan.settings, field="plan.settings")  # safety is not data
    # every flag a bool: realtime="no" is true, and would pace a render the caller meant unpaced
    for flag, value in (("passivity", passivity), ("realtime", realtime)):
        if value is not None and not isinstance(value, bool):
            raise ValidationError(f"{flag} must be True or False, got {value!r:.60}", field=flag)
    for flag, value in (("hooks", hooks), ("raise_on_fault", raise_on_fault)):
        if not isinstance(value, bool):
            raise ValidationError(f"{flag} must be True or False, got {value!r:.60}", field=flag)
    if recorder is not None and not callable(getattr(recorder, "record", None)):
        # the servo calls recorder.record(t, state, sent) every tick and counts a failure as
        # a renderer error: an object without it recorded nothing, without a word
        raise ValidationError(f"recorder must have a record(t, state, sent) method (e.g. "
                              f"hapticsdk.runlog.RunRecorder), got {type(recorder).__name__}", field="recorder")
    passivity = True if passivity is None else passivity

    from ..plugins import manager, registry

    # actuator options per role (privileged ones refused when they come from the plan),
    # checked for every role before any actuator is created
    chosen: dict[str, tuple[Any, dict[str, Any]]] = {}
    for role in sorted(mp.actuators):
        cls = registry("actuator").load(mp.actuators[role])
        check_plugin_api(cls, name=mp.actuators[role])
        chosen[role] = (cls, _actuator_options(cls, mp.actuators[role], role, mp, app_options))

    # paced on the clock: as code asks; by default as the plan asks, and always when an
    # actuator is real (a plan's data cannot run a real device unpaced, commands
    # back to back and the servo's seconds over in a fraction of the wall time)
    real = any(not getattr(cls, "simulated", False) for cls, _ in chosen.values())
    rt = bool(realtime) if realtime is not None else (bool(servo.get("realtime", False)) or real)
    cal_opts, cal_records = _calibrations(mp, plan.settings, {r: o for r, (_, o) in chosen.items()})
    renderers = build_renderers(mp, plan.settings, calibrations=cal_opts,
                                capabilities=_capabilities(chosen))
    roles_used = {role for r in renderers for role in r.roles}
    used_dists = plan.distributions(mp.name)
    pm = manager().load_for(used_dists) if hooks else None
    one = RenderPlan(scene=plan.scene, materials={mp.name: mp}, settings=plan.settings,
                     plugins=plan.plugins, unused_plugins=plan.unused_plugins,
                     plugin_api_version=plan.plugin_api_version)

    from .loop import ServoLoop

    with ExitStack() as stack:
        instances: dict[tuple[str, str], Actuator] = {}
        by_role: dict[str, Actuator] = {}
        for role in sorted(roles_used):
            name = mp.actuators[role]
            cls, opts = chosen[role]
            key = (name, json.dumps(opts, sort_keys=True, default=repr))
            if key not in instances:
                if (trajectory is not None and isinstance(cls, type) and issubclass(cls, HapticDevice)
                        and getattr(cls, "simulated", False) and _accepts(cls, "trajectory")):
                    opts.setdefault("trajectory", trajectory)
                from ..argcheck import call_with_options  # a bad option is named by its path
                act = call_with_options(cls, options=opts,
                                        field=f"plan.materials.{mp.name}.actuator_options.{role}")
                if not isinstance(act, Actuator):
                    raise PluginError(f"actuator plugin {name!r} did not create an Actuator",
                                      plugin=name, kind="actuator")
                stack.enter_context(act)
                instances[key] = act
            by_role[role] = instances[key]
        sensors = [a for a in instances.values() if isinstance(a, HapticDevice)]
        if sensors:
            device = sensors[0]
            sensor_name = device.name
        else:
            cls = registry("actuator").load(FALLBACK_SENSOR)
            device = cls(**({"trajectory": trajectory} if trajectory is not None else {}))
            stack.enter_context(device)
            sensor_name = FALLBACK_SENSOR
        if pm is not None:
            pm.call_safely("hapticsdk_render_started", plan=one)
        loop = ServoLoop(device, renderers, by_role, period_s=period, realtime=rt, recorder=recorder,
                         passivity=passivity, raise_on_fault=raise_on_fault)
        t0 = time.perf_counter()
        try:
            lr = loop.run(secs)
        except DeviceError as exc:  # every actuator is already stopped by the loop
            if pm is not None:
                pm.call_safely("hapticsdk_device_fault", device=exc.device or "", error=exc)
            raise
        wall = time.perf_counter() - t0
        lr_fault = getattr(lr, "fault", None)
        if pm is not None and lr_fault:
            pm.call_safely("hapticsdk_device_fault", device=str(lr_fault.get("device", "")),
                           error=DeviceError(str(lr_fault.get("message", "")), device=lr_fault.get("device")))
        everyone = list(instances.values()) + ([device] if device not in instances.values() else [])
        safety = {a.label: a.safety.report() for a in everyone}
        devices = {a.label: a.describe() for a in everyone}   # as the run left them, before the stop
        left = _left_driving(everyone, period)
    fault = getattr(lr, "fault", None)
    if fault is None and left:
        label, what = next(iter(left.items()))
        fault = {"device": label, "message": f"left driving after stop(): {what}", "left_driving": left}
    report = RenderReport(
        material=mp.name, scene=plan.scene, dimensions=list(mp.dimensions),
        replacements=[{"dimension": d.dimension, **(d.replacement or {})} for d in mp.replacements],
        actuators={role: by_role[role].name for role in sorted(by_role)}, sensor=sensor_name,
        seconds=secs, wall_s=wall,
        tick_median_us=_num(getattr(lr, "tick_median_us", None)),
        tick_p99_us=_num(getattr(lr, "tick_p99_us", None)),
        overruns=int(lr.overruns) if getattr(lr, "overruns", None) is not None else None,
        fault=None if fault is None else (dict(fault) if isinstance(fault, Mapping) else {"message": str(fault)}),
        renderers={(f"replacement:{rep}" if (rep := getattr(r, "replaces", None)) else d): r.describe()
                   for d, r in zip(list(mp.dimensions) + [x.dimension for x in mp.replacements], renderers)},
        safety=safety, devices=devices, hooks=used_dists if hooks else [], loop=lr, ticks=_ticks(lr),
        features=dict(mp.features), dropped=[d.to_dict() for d in mp.dropped], solve=dict(mp.solve),
        calibrations=cal_records)
    if pm is not None:
        pm.call_safely("hapticsdk_render_finished", plan=one, report=report)
    return report


def _left_driving(actuators: list[Actuator], period_s: float) -> dict[str, str]:
    """Stop every actuator, then name those still driving (label -> what, from
    :meth:`Actuator.still_driving`). One whose read-back is its physical output gets its declared
    settle time to come to rest (simulated ones are stepped through it, real ones waited
    for) before it counts."""
    out: dict[str, str] = {}
    for a in actuators:
        a.stop()   # the run is over: every actuator to its safe state now (idempotent, never raises)
        what = a.still_driving()
        wait = a.settle_time_s if getattr(a, "readback_source", "drive") == "output" else 0.0
        for _ in range(int(math.ceil(wait / period_s)) if what and wait > 0 else 0):
            step = getattr(a, "step", None)
            if getattr(a, "simulated", False) and callable(step):
                step(period_s)
            else:
                time.sleep(period_s)
            what = a.still_driving()
            if what is None:
                break
        if what is not None:
            log.error("%s: left driving after stop(): %s", a.label, what)
            out[a.label] = what
    return out


def _calibrations(mp: MaterialPlan, settings: Mapping[str, Any], role_options: Mapping[str, Mapping[str, Any]]
                  ) -> tuple[dict[str, dict[str, Any]], dict[str, dict[str, Any]]]:
    """Saved calibrations for the kept dimensions' renderers (loaded from the store now)
    and their records; a record whose file differs from the plan's says so."""
    from ..calibration.selection import select_calibrations
    from ..plugins import registry
    ropts = dict((settings or {}).get("renderer_options") or {})
    opts: dict[str, dict[str, Any]] = {}
    records: dict[str, dict[str, Any]] = {}
    for d in mp.dimensions:
        cls = registry("dimension").load(d)
        dim = cls() if isinstance(cls, type) else cls
        o, recs = select_calibrations(d, dim, renderer_options=ropts.get(d, {}), role_options=role_options)
        opts[d] = o
        for k, rec in recs.items():
            planned = mp.calibrations.get(k)
            if planned is not None and (planned.get("file"), planned.get("sha256")) != (rec["file"], rec["sha256"]):
                rec["changed_since_plan"] = {"file": planned.get("file"), "sha256": planned.get("sha256")}
            records[k] = rec
    return opts, records


def _check_app_options(options: Mapping[str, Mapping[str, Any]] | None) -> dict[str, dict[str, Any]]:
    if options is None:
        return {}
    if not isinstance(options, Mapping) or not all(isinstance(v, Mapping) for v in options.values()):
        raise ValidationError("expected role -> {option: value}", field="actuator_options")
    return {str(r): dict(v) for r, v in options.items()}


def _actuator_options(cls: Any, name: str, role: str, mp: MaterialPlan,
                      app_options: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """The options actuator ``name`` gets for ``role``: the plan's (never a privileged
    one), then the user's configuration and environment, then the application's."""
    from ..devices.device_options import check_data_options, trusted_options
    from_plan = dict(mp.actuator_options.get(role, {}))
    check_data_options(cls, name, role, from_plan, field=f"plan.materials.{mp.name}.actuator_options.{role}")
    return {**from_plan, **trusted_options(name), **dict(app_options.get(role, {}))}


def _ticks(lr: Any) -> int | None:
    for k in ("ticks", "n_ticks"):
        v = getattr(lr, k, None)
        if v is not None:
            return int(v)
    return None


def _num(v: Any) -> float | None:
    return None if v is None else float(v)
