"""Core commands: ``plugins``, ``materials``, ``solve``, ``render``."""

from __future__ import annotations

import argparse
import re
from typing import Any

from . import emit
from .argtypes import figure_file, intensity, nonneg_int, positive_float


#: the exit-status rule shared by ``solve``, ``render`` and ``plan`` (also in docs/app-developers.md)
UNREACHED_RULE = ("Exit status: 0 when every target was reached; 1 when a target was not reached "
                  "(the nearest reachable answer is still printed, and rendered); 2 for bad input.")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``plugins``, ``materials``, ``solve`` and ``render`` to the ``hapticsdk``
    command.
    """
    p = sub.add_parser("plugins", help="list installed plugins (without importing them)")
    p.add_argument("--kind", choices=["dimension", "actuator", "solver", "model", "importance", "hooks"],
                   action="append", help="only these kinds (repeatable)")
    p.add_argument("--check", action="store_true", help="import each plugin and report import errors")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_plugins)

    p = sub.add_parser("materials", help="list the named material library")
    p.add_argument("--library", help="a materials JSON file instead of the shipped library")
    p.add_argument("--with-plugins", action="store_true",
                   help="add the materials installed plugins contribute (hapticsdk_materials hook)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_materials)

    p = sub.add_parser("solve", help="solve stimulus features for perceptual targets",
                       epilog=UNREACHED_RULE)
    p.add_argument("--hardness", type=intensity, help="target hardness 0..1")
    p.add_argument("--roughness", type=intensity, help="target roughness 0..1")
    p.add_argument("--target", action="append", default=[], metavar="DIM=VALUE",
                   help="target of any other dimension (repeatable)")
    p.add_argument("--method", default="ga-polish",
                   help="solver name (see `hapticsdk plugins --kind solver`; `ga` is the paper's GA alone)")
    p.add_argument("--model", default=None, help="model name or .onnx path (default: the dimensions' model)")
    p.add_argument("--penalty", default="paper", choices=["paper", "normalised"],
                   help="constraint penalty of formula (6): the paper's raw form, or each constraint "
                        "normalised by its own scale")
    p.add_argument("--tolerance", type=positive_float, default=0.01,
                   help="a target counts as reached when sum |target - predicted| is at most this "
                        "(intensity units, 0..1 scale)")
    p.add_argument("--data-support", action="store_true",
                   help="keep the answer where the model's recordings were (e.g. recorded press-force range)")
    p.add_argument("--seed", type=nonneg_int, default=None,
                   help="random seed, a whole number >= 0 (default: none, a fresh seed each run)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_solve)

    p = sub.add_parser("render", help="render a named material or a scene on (simulated) devices",
                       epilog=UNREACHED_RULE)
    p.add_argument("material", nargs="?", help="material name (see `hapticsdk materials`)")
    p.add_argument("--scene", help="scene JSON file instead of a material")
    p.add_argument("--hardness", type=intensity, help="render targets instead of a named material")
    p.add_argument("--roughness", type=intensity, help="render targets instead of a named material")
    p.add_argument("--seconds", type=positive_float, default=3.0, help="render duration (s)")
    p.add_argument("--realtime", action="store_true",
                   help="pace the servo loop on the machine clock (wall time = --seconds); by default "
                        "simulated devices run as fast as they compute (a real device given with --device "
                        "always runs on the machine clock)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="solver seed, a whole number >= 0")
    p.add_argument("--plot", metavar="PNG", type=figure_file,
                   help="save a figure of the render (needs matplotlib; .png, .pdf, .svg ...)")
    p.add_argument("--device", action="append", default=[], metavar="ROLE=ACTUATOR",
                   help="actuator plugin for a channel role (repeatable), e.g. coil=voicecoil-audio or "
                        "force=dhd (see `hapticsdk plugins --kind actuator`); with --scene it replaces the "
                        "scene's device for that role")
    p.add_argument("--device-option", action="append", default=[], metavar="ROLE.KEY=VALUE",
                   help="actuator option for a channel role (repeatable), e.g. force.library=/opt/libHD.so or "
                        "coil.sink=wav:out.wav; the only place, with $HAPTICSDK_DEVICE_OPTIONS and the user "
                        "device configuration, for options naming libraries, files or ports")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_render)


def cmd_plugins(args: argparse.Namespace) -> int:
    """``plugins``: list installed plugins (kind, name, distribution, version) from entry-
    point metadata; with ``--check`` import each and report broken ones. Returns the exit
    status.
    """
    from ..plugins import list_plugins

    rows = list_plugins(args.kind, check=args.check)
    if args.json:
        emit(rows, True)
        return 0
    if not rows:
        print("no plugins installed")
        return 0
    width = max(len(r["name"]) for r in rows)
    for r in rows:
        err = f"  BROKEN: {r['error']}" if r.get("error") else ""
        print(f"{r['kind']:<10} {r['name']:<{width}}  {r['distribution']} {r['version']}{err}")
    return 0


def cmd_materials(args: argparse.Namespace) -> int:
    """``materials``: print the material library (name, label, intensities), marked
    GENERATED when it is. Returns the exit status.
    """
    from ..perception.materials import load_library

    lib = load_library(args.library, with_plugins=args.with_plugins)
    rows = [m.to_dict() for m in lib]
    if args.json:
        emit({"generated": lib.generated, "source": lib.source, "materials": rows}, True)
        return 0
    note = " (GENERATED data: see docs/perception-models.md)" if lib.generated else ""
    print(f"{len(rows)} materials{note}")
    for m in lib:
        its = ", ".join(f"{k} {v:.3f}" for k, v in m.intensities.items())
        src = f"  [{m.source}]" if m.source.startswith("plugin") else ""
        print(f"{m.name:<5} {m.label:<22} {its}{src}")
    return 0


def _targets(args: argparse.Namespace) -> dict[str, float]:
    from ..perception.dimensions import check_intensity
    from ..errors import ValidationError

    targets: dict[str, float] = {}
    if getattr(args, "hardness", None) is not None:
        targets["hardness"] = args.hardness
    if getattr(args, "roughness", None) is not None:
        targets["roughness"] = args.roughness
    for item in getattr(args, "target", []) or []:
        if "=" not in item:
            raise ValidationError(f"expected DIM=VALUE, got {item!r}", field="target")
        k, v = item.split("=", 1)
        targets[k.strip()] = check_intensity(v.strip(), f"targets.{k.strip()}", text=True)
    return targets


def cmd_solve(args: argparse.Namespace) -> int:
    """``solve``: solve features for the targets given and print them (or JSON). Returns 0
    when reached, 1 when not.
    """
    from ..errors import ValidationError
    from ..solvers.problems import solve

    targets = _targets(args)
    if not targets:
        raise ValidationError("give at least one target: --hardness, --roughness or --target DIM=V",
                              field="targets")
    res = solve(targets, method=args.method, seed=args.seed, model=args.model,
                penalty=args.penalty, tolerance=args.tolerance, data_support=args.data_support)
    out = res.to_json()
    if args.json:
        emit(out, True)
    else:
        print(format_solve(out))
    return 0 if res.success else 1


def format_solve(out: dict[str, Any]) -> str:
    """Text of one solve result (``SolveResult.to_json()``): features, predicted against
    target intensities, error, constraint violation, evaluations and time.
    """
    feats = ", ".join(f"{k}={v:.4g}" for k, v in out["x"].items())
    its = ", ".join(f"{k} {v:.4f} (target {out['targets'].get(k, float('nan')):.4f})"
                    for k, v in out["intensities"].items() if k in out["targets"])
    return (f"solved by {out['method']}: {'success' if out['success'] else 'NOT REACHED'}\n"
            f"  features:    {feats}\n  intensities: {its}\n"
            f"  error {out['error']:.4g} (sum |target - predicted|), constraint violation "
            f"{out['constraint_violation']:.3g}, {out['nfev']} evaluations in {out['time_s'] * 1e3:.1f} ms\n"
            f"  {out['message']}"
            + (f"\n  {out['model']['statement']}" if out.get("model") else ""))


def cmd_render(args: argparse.Namespace) -> int:
    """``render``: compile a material, intensities or a scene, render it on its devices
    (paced on the clock with ``--realtime``), print what was rendered and optionally save
    a figure. Returns 0 when every target was reached, 1 when not.
    """
    from ..errors import ValidationError
    from ..compiler import compile_scene
    from ..runtime.render import render_plan
    from ..scene import Scene, load_scene
    from ..scene.model import DeviceSpec

    from ..scene.limits import check_seconds

    check_seconds(args.seconds, "--seconds")   # before solving, opening or allocating anything
    targets = _targets(args)
    given = [bool(args.material), bool(args.scene), bool(targets)]
    if sum(given) != 1:
        raise ValidationError("give exactly one of MATERIAL, --scene FILE, or --hardness/--roughness",
                              field="render")
    if args.plot:  # before the work: a figure that cannot be written fails now, not after the render
        from ..fileio import check_output_path
        check_output_path(args.plot, field="--plot")
    from ..devices.device_options import parse_device, parse_device_option
    devices = dict(parse_device(item) for item in args.device)
    if args.scene:
        scene = load_scene(args.scene)
        for role, actuator in devices.items():
            scene.devices[role] = DeviceSpec(actuator=actuator)
    else:
        scene = Scene.for_material(args.material if args.material else targets, devices, seed=args.seed)
    dev_opts: dict[str, dict[str, Any]] = {}
    for item in args.device_option:
        role, key, value = parse_device_option(item)
        dev_opts.setdefault(role, {})[key] = value
    plan = compile_scene(scene)
    # paced on the clock with --realtime, and always when an actuator is real (render_plan)
    report = render_plan(plan, seconds=args.seconds, actuator_options=dev_opts,
                         realtime=True if args.realtime else None)
    out = report.to_dict()
    if args.plot:
        from ..plotting import plot_render
        plot_render(report, args.plot)
        out["plot"] = args.plot
    if args.json:
        emit(out, True)
    else:
        print(format_render(out))
    return 0 if all_reached(out) else 1


def all_reached(out: dict[str, Any]) -> bool:
    """Whether every solve in a render or plan report reached its targets (the
    :data:`UNREACHED_RULE`); a material rendered without a solve counts as reached."""
    mats = out.get("materials", [out])
    mats = list(mats.values()) if isinstance(mats, dict) else list(mats)
    return all((m.get("solve") or {}).get("success") is not False for m in mats)


_TARGETS_NAME = re.compile(r"[A-Za-z_][\w-]* [0-9.eE+-]+(, [A-Za-z_][\w-]* [0-9.eE+-]+)*")


def format_render(out: dict[str, Any]) -> str:
    """Text of a render report: per material what was rendered on which actuators, what was
    left out and why, the solve, then the servo tick statistics.
    """
    lines = []
    for mat in out.get("materials", [out]):
        acts = mat["actuators"]
        acts = ", ".join(f"{r}={a}" for r, a in acts.items()) if isinstance(acts, dict) else ", ".join(acts)
        # a library material reads "material S7"; intensity targets ("hardness 0.8,
        # roughness 0.3", the name Scene.for_material gives them) read "targets ..."
        name = str(mat["material"])
        label = f"targets {name}" if _TARGETS_NAME.fullmatch(name) else f"material {name}"
        lines.append(f"{label}: rendered {', '.join(mat.get('dimensions', [])) or 'nothing'}; "
                     f"actuators {acts}")
        for d in mat.get("dropped", []):
            lines.append(f"  left out {d['dimension']}: {d['reason']}")
        if mat.get("solve"):
            lines.append("  " + format_solve(mat["solve"]).replace("\n", "\n  "))
    t = out["tick"]
    lines.append(f"servo loop: {t['ticks']} ticks, compute median {t['median_us']:.1f} us, "
                 f"p99 {t['p99_us']:.1f} us, overruns {t['overruns']}")
    if out.get("plot"):
        lines.append(f"figure saved to {out['plot']}")
    return "\n".join(lines)
