"""Interchange commands (MPEG-I haptics ``.hjif``):

- ``hapticsdk export PLAN_OR_SCENE --format hjif -o FILE``: solved materials to ``.hjif``;
- ``hapticsdk import FILE.hjif [--json]``: what a file holds and what the SDK plays of it;
- ``hapticsdk play FILE.hjif [--seconds S] [--device-option ACTUATOR.KEY=VALUE] [--json]``: play its
  vibrotactile content on the simulated (or real) vibration actuators.

Heavy imports stay inside the handlers. See ``docs/interop.md``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from .argtypes import positive_float


#: ``import --synth`` analyses at most this much of a file (s)
SYNTH_REPORT_S = 60.0


def register(sub: Any) -> None:
    """Add ``export``, ``import`` and ``play`` (MPEG-I haptics files) to the ``hapticsdk``
    command.
    """
    p = sub.add_parser("export", help="export solved materials (plan or scene) as MPEG-I haptics (.hjif)")
    p.add_argument("source", metavar="PLAN_OR_SCENE",
                   help="plan JSON (hapticsdk plan -o), scene JSON, or a library material name (S7)")
    p.add_argument("--format", default="hjif", choices=["hjif"], help="output format (default hjif)")
    p.add_argument("-o", "--output", required=True, metavar="FILE", help="output file (.hjif)")
    p.add_argument("--effect-seconds", type=positive_float, default=1.0, metavar="S",
                   help="nominal length of each exported effect (s, default 1)")
    p.add_argument("--no-importance", action="store_true",
                   help="when compiling a scene: keep every dimension (export roughness of smooth samples too)")
    from .argtypes import nonneg_int
    p.add_argument("--seed", type=nonneg_int, help="when compiling a scene: solver seed, a whole number >= 0")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("import", help="read an MPEG-I haptics .hjif or Apple .ahap file: what it holds and what plays")
    p.add_argument("file", metavar="FILE.hjif|FILE.ahap", help="MPEG-I haptics (.hjif) or Apple AHAP (.ahap) file")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--synth", action="store_true",
                   help="also synthesise the vibrotactile channels and report their peak frequency and envelope")
    p.set_defaults(func=cmd_import)

    p = sub.add_parser("play", help="play the vibrotactile content of an .hjif or .ahap file on the vibration actuators")
    p.add_argument("file", metavar="FILE.hjif|FILE.ahap", help="MPEG-I haptics (.hjif) or Apple AHAP (.ahap) file")
    p.add_argument("--seconds", type=positive_float, help="duration (s, default: the file's length)")
    p.add_argument("--actuators", default="piezo-virtual,voicecoil-virtual",
                   help="comma-separated actuator names (default piezo-virtual,voicecoil-virtual)")
    p.add_argument("--tick", type=positive_float, default=0.001, metavar="S", help="servo period (s, default 0.001)")
    p.add_argument("--realtime", action="store_true", help="pace ticks to the wall clock")
    p.add_argument("--piezo-table", metavar="PATH", help="piezo Tab file (default: the generated table)")
    p.add_argument("--device-option", action="append", default=[], metavar="ACTUATOR.KEY=VALUE",
                   help="option for one of --actuators (repeatable), e.g. piezo-serial.port=/dev/ttyACM0; "
                        "with $HAPTICSDK_DEVICE_OPTIONS and the user device configuration, as for render")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_play)


def _plan_from_arg(text: str, *, no_importance: bool, seed: int | None) -> Any:
    from ..plan import RenderPlan

    from .scene import _is_path

    path = Path(text)
    if _is_path(text) and path.is_file():
        from ..schemas_io import read_json
        data = read_json(path, field="plan")
        if isinstance(data, dict) and "plan_version" in data:
            return RenderPlan.from_dict(data)
    from ..compiler import compile_scene
    from ..scene import Scene
    from .scene import _scene_from_arg

    scene = _scene_from_arg(text)
    over: dict[str, Any] = {}
    if seed is not None:
        over.setdefault("solver", {})["seed"] = seed
    if no_importance:
        over.setdefault("importance", {})["enabled"] = False
    if over:
        from ..scene.model import _merge
        scene = Scene(objects=scene.objects, devices=scene.devices, settings=_merge(scene.settings, over),
                      name=scene.name)
    return compile_scene(scene)


def _is_ahap(path: str) -> bool:
    """Apple AHAP content is told by its ``.ahap`` suffix (any case)."""
    return Path(path).suffix.lower() == ".ahap"


def cmd_export(args: argparse.Namespace) -> int:
    """``export``: write the solved materials of a plan or scene as an MPEG-I haptics
    (.hjif) file. Returns the exit status.
    """
    from ..fileio import check_output_path
    from ..interop.hjif_export import export_plan, write_hjif
    from ..interop.hjif_import import sdk_materials

    check_output_path(args.output, field="output")  # before any solving
    plan = _plan_from_arg(args.source, no_importance=args.no_importance, seed=args.seed)
    hfile = export_plan(plan, effect_seconds=args.effect_seconds)
    path = write_hjif(hfile, args.output)
    from ..interop.hjif_export import FORMAT_SHAPE, FORMAT_VERSION

    out = {"saved": str(path), "format": args.format, "format_version": FORMAT_VERSION, "format_shape": FORMAT_SHAPE,
           "scene": plan.scene,
           "perceptions": [{"id": p.id, "modality": p.perception_modality,
                            "description": p.description.split(" hapticsdk-meta:")[0]} for p in hfile.perceptions],
           "materials": {k: {"features": v.get("features"), "targets": v.get("targets"), "parts": sorted(v["parts"])}
                         for k, v in sdk_materials(hfile).items()}}
    if args.json:
        from . import emit
        emit(out, True)
    else:
        lines = [f"wrote {path} (MPEG-I haptics JSON version {FORMAT_VERSION}, shape {FORMAT_SHAPE}; "
                 f"{len(hfile.perceptions)} perception(s))"]
        lines += [f"  perception {p['id']} {p['modality']}: {p['description']}" for p in out["perceptions"]]
        print("\n".join(lines))
    return 0


def cmd_import(args: argparse.Namespace) -> int:
    """``import``: read an .hjif file and print its perceptions, what the SDK plays of them
    and its SDK metadata. Returns the exit status.
    """
    from ..interop.hjif_import import format_summary, import_summary, load

    if _is_ahap(args.file):
        from ..interop import ahap

        pat = ahap.read_ahap(args.file)
        s = ahap.summary(pat, source=str(args.file))
        hfile = ahap.to_haptic_file(pat, source=str(args.file))
        fmt = ahap.format_summary
    else:
        hfile = load(args.file)
        s = import_summary(hfile, source=str(args.file))
        fmt = format_summary
    if args.synth:
        from ..interop.hjif_synth import describe_channel, file_duration_s, synthesize
        full = file_duration_s(hfile)
        syn = synthesize(hfile, seconds=min(full, SYNTH_REPORT_S))
        s["synthesis"] = {"fs_hz": syn.fs, "duration_s": syn.duration_s, "truncated": full > SYNTH_REPORT_S,
                          "channels": [describe_channel(c, syn.fs) for c in syn.channels]}
    if args.json:
        from . import emit
        emit(s, True)
    else:
        text = fmt(s)
        for c in (s.get("synthesis") or {}).get("channels", []):
            text += (f"\n  synthesised {c['path']}: peak {c['peak_frequency_hz']:g} Hz, max |x| {c['max_abs']:.4g}, "
                     f"rms {c['rms']:.4g}")
        print(text)
    return 0


def cmd_play(args: argparse.Namespace) -> int:
    """``play``: play the vibrotactile content of an .hjif file on the vibration actuators
    and print what was played. Returns the exit status.
    """
    from ..errors import ValidationError
    from ..interop.hjif_import import load
    from ..interop.hjif_play import format_report, play

    acts = [a.strip() for a in args.actuators.split(",") if a.strip()]
    if not acts:
        raise ValidationError("no actuator named", field="actuators")
    from ..devices.device_options import parse_device_option
    dev_opts: dict[str, dict[str, Any]] = {}
    for item in args.device_option:
        name, key, value = parse_device_option(item)
        if name not in acts:
            raise ValidationError(f"{name!r} is not one of --actuators {acts}", field="--device-option")
        dev_opts.setdefault(name, {})[key] = value
    is_ahap = _is_ahap(args.file)
    if is_ahap:
        from ..interop import ahap

        pat = ahap.read_ahap(args.file)  # checked whole before anything is opened
        hfile = ahap.to_haptic_file(pat, source=str(args.file))
    else:
        hfile = load(args.file)  # checked whole before anything is opened
    rep = play(hfile, seconds=args.seconds, actuators=acts, tick_s=args.tick, realtime=args.realtime,
               piezo_table=args.piezo_table, piezo_full_scale=is_ahap, actuator_options=dev_opts)
    if is_ahap:
        rep.not_played = pat.not_played + rep.not_played
        rep.notes = [f"read beyond strict JSON: {r['path']}: {r['change']}" for r in pat.relaxed] + rep.notes
    if args.json:
        print(json.dumps(rep.to_dict(), indent=2, default=str))
    else:
        print(format_report(rep))
    return 0
