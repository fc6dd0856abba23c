"""Scene commands: ``hapticsdk plan SCENE [--json] [-o PLAN.json]``.

``SCENE`` is a scene JSON file (``schemas/scene.schema.json``) or the name of a library
material (a one-object scene). The plan lists, per material, the dimensions kept, those
dropped with the importance model's predicted realism loss, the solved features and the
actuator per channel role; ``-o`` saves the full plan for ``render_plan`` later.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def register(sub: Any) -> None:
    """Add ``plan`` to the ``hapticsdk`` command."""
    from .argtypes import figure_file, nonneg_float, nonneg_int
    from .core import UNREACHED_RULE

    p = sub.add_parser("plan", help="compile a scene into a render plan (what is rendered, what is left out)",
                       epilog=UNREACHED_RULE)
    p.add_argument("scene", metavar="SCENE", nargs="?",
                   help="scene JSON file, or a library material name (S7); not with --compare-paper")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("-o", "--output", metavar="PLAN", help="save the full plan (JSON) to this file")
    p.add_argument("--seed", type=nonneg_int, help="solver seed (overrides the scene's), a whole number >= 0")
    p.add_argument("--threshold", type=nonneg_float, metavar="PERCENT",
                   help="importance threshold: drop a dimension whose predicted realism loss is below it (%%)")
    p.add_argument("--no-importance", action="store_true", help="keep every dimension")
    p.add_argument("--plot", metavar="PNG", type=figure_file, help="write a figure: the materials in intensity space, what "
                                                 "is left out of each and why (needs matplotlib)")
    p.add_argument("--compare-paper", action="store_true",
                   help="compile the paper's 8 evaluated samples (library, GENERATED data) and compare the "
                        "leave-out decisions with the paper's significant removals, explaining each "
                        "disagreement (--plot: the intervals against the threshold)")
    p.set_defaults(func=cmd_plan)


def _is_path(text: str) -> bool:
    """``text`` names an existing file or folder (a name the file system cannot hold,
    e.g. longer than its limit, names none: it is then read as a material name)."""
    from ..argcheck import file_path
    from ..errors import ValidationError

    try:
        return file_path(text).exists()
    except ValidationError:
        return False


def _scene_from_arg(text: str) -> Any:
    from ..errors import ValidationError
    from ..scene import Scene

    path = Path(text)
    if path.suffix.lower() == ".json" or _is_path(text):
        return Scene.load(path)
    from ..perception.materials import load_library
    lib = load_library()
    if text in lib.names():
        return Scene.for_material(text)
    raise ValidationError(f"{text!r} is neither a scene file nor a library material "
                          f"({', '.join(lib.names())})", field="scene")


def cmd_plan(args: argparse.Namespace) -> int:
    """``plan``: compile a scene (or a library material) into a render plan, print what is
    kept and dropped and why, optionally save the plan (``-o``) and a figure
    (``--plot``). Returns 0 when every target was reached, 1 when not.
    """
    from ..compiler import compile_scene
    from ..scene import Scene

    if args.output:  # before the work: an output that cannot be written fails now
        from ..fileio import check_output_path
        check_output_path(args.output, field="--output")
    if args.plot:
        from ..fileio import check_output_path
        check_output_path(args.plot, field="--plot")
    if args.compare_paper:
        if args.scene:
            from ..errors import ValidationError
            raise ValidationError("--compare-paper compiles the paper's 8 evaluated samples: give no SCENE",
                                  field="scene")
        from ..compiler.paper_findings import paper_comparison_scene
        scene = Scene.from_dict(paper_comparison_scene())
    elif not args.scene:
        from ..errors import ValidationError
        raise ValidationError("give a SCENE (file or library material name), or --compare-paper", field="scene")
    else:
        scene = _scene_from_arg(args.scene)
    over: dict[str, Any] = {}
    if args.seed is not None:
        over.setdefault("solver", {})["seed"] = args.seed
    if args.threshold is not None:
        over.setdefault("importance", {})["threshold_percent"] = args.threshold
    if args.no_importance:
        over.setdefault("importance", {})["enabled"] = False
    if over:
        from ..scene.model import _merge
        scene = Scene(objects=scene.objects, devices=scene.devices,
                      settings=_merge(scene.settings, over), name=scene.name)
    plan = compile_scene(scene)
    if args.compare_paper:
        return _compare_paper(plan, args)
    if args.output:
        plan.save(args.output)
    out = plan.summary()
    if args.output:
        out["saved"] = str(args.output)
    if args.plot:
        from ..plotting import plot_plan
        plot_plan(plan.to_dict(), args.plot)
        out["plot"] = str(args.plot)
    if args.json:
        from . import emit
        emit(out, True)
    else:
        print(format_plan(out))
    from .core import all_reached
    return 0 if all_reached(out) else 1


def _compare_paper(plan: Any, args: argparse.Namespace) -> int:
    from ..compiler.paper_findings import compare_with_paper, format_comparison
    cmp = compare_with_paper(plan)
    if args.output:
        plan.save(args.output)
        cmp["saved"] = str(args.output)
    if args.plot:
        from ..plotting import plot_paper_comparison
        plot_paper_comparison(cmp, args.plot)
        cmp["plot"] = str(args.plot)
    if args.json:
        from . import emit
        emit(cmp, True)
    else:
        print(format_comparison(cmp))
        for k, what in (("saved", "plan saved to"), ("plot", "figure saved to")):
            if cmp.get(k):
                print(f"{what} {cmp[k]}")
    return 0


def format_plan(out: dict[str, Any]) -> str:
    """Text of a plan summary: per material the dimensions rendered and on which actuators,
    the features, what was dropped or kept and why, the solve; then the plugins used.
    """
    lines = [f"scene {out['scene']}"]
    for name, m in out["materials"].items():
        feats = ", ".join(f"{k}={v:.4g}" for k, v in m["features"].items())
        acts = ", ".join(f"{r}->{a}" for r, a in m["actuators"].items())
        lines.append(f"material {name}: renders {', '.join(m['dimensions']) or '(nothing)'} on {acts}")
        lines.append(f"  features: {feats}")
        if m["pinned_features"]:
            at = ("the full solve's values: the model's defaults miss the kept targets"
                  if (m.get("solve") or {}).get("pinned_from") == "full solve" else "the model's defaults")
            lines.append("  left out of the solve (no kept dimension reads them): "
                         + ", ".join(sorted(m["pinned_features"])) + f"; pinned at {at}")
        for role, c in (m.get("role_contracts") or {}).items():
            acc = ", ".join(f"{k} {u}" for k, u in c["accepts"].items())
            for who, spec in c["commanded_by"].items():
                what = (f"{spec['channel']} ({', '.join(f'{k} {u}' for k, u in spec['fields'].items())})"
                        if spec else "undeclared (plugin API 1.0: not checked)")
                lines.append(f"  role {role}: {who} commands {what} -> {c['actuator']} "
                             f"({c['actuator_channel']}; accepts {acc})")
        dev = m.get("device") or {}
        for dim, res in (dev.get("residual") or {}).items():
            listed = [f"{role}: {_limits_text(c)}"
                      for role, c in (dev.get("capabilities", {}).get(dim) or {}).items() if _limits_text(c)]
            caps = "; ".join(listed)
            if caps or abs(res) > 0 or dev.get("binding"):
                tol = dev.get("binding_rtol")
                within = f" (within {100 * tol:g} % of their bound)" if tol is not None else ""
                lines.append(f"  on the mapped device{'s' if len(listed) > 1 else ''} ({caps or 'no limits published'}): "
                             f"{dim} predicted {dev['predicted'][dim]:.4f} for target {dev['predicted'][dim] + res:.4f}, "
                             f"residual {res:+.4f}; binding device constraints{within}: "
                             f"{', '.join(dev.get('binding') or []) or 'none'}")
        for d in m["dropped"]:
            lines.append(f"  dropped {d['dimension']}: {d['reason']}")
        for dim, e in (m.get("importance") or {}).items():
            if e.get("decision") == "keep":
                lines.append(f"  kept {dim}: {keep_words(e)}")
        s = m["solve"]
        if s.get("success") is not None:
            lines.append(f"  solve: {'success' if s['success'] else 'NOT REACHED'}, error {s['error']:.3g}")
    used = sorted({f"{p['kind']}:{p['name']}" for p in out["plugins_loaded"]})
    lines.append("plugins used: " + ", ".join(used))
    if out.get("saved"):
        lines.append(f"plan saved to {out['saved']}")
    if out.get("plot"):
        lines.append(f"figure saved to {out['plot']}")
    return "\n".join(lines)


def _limits_text(c: dict) -> str:
    """A mapped actuator's published limits as text (its band and/or its largest drive);
    "" when it publishes none."""
    parts = []
    if c.get("frequency_range_hz"):
        lo, hi = c["frequency_range_hz"]
        parts.append(f"{lo:g}-{hi:g} Hz")
    if c.get("max_drive") is not None:
        parts.append(_drive_words(c["max_drive"], c.get("drive_unit")))
    return ", ".join(parts)


def _drive_words(max_drive: float, unit: str | None) -> str:
    """``max drive 50 V``; a dimensionless drive (unit ``"1"`` or none) as a fraction of
    full scale, not ``max 1 1``."""
    if unit in (None, "", "1"):
        return f"drive up to {max_drive:g} x full scale"
    return f"drive up to {max_drive:g} {unit}"


def keep_words(e: dict[str, Any]) -> str:
    """Why a judged dimension is kept, with its interval: wholly above the threshold, or
    straddling it (the importance model cannot tell, so the dimension is kept)."""
    from ..compiler.importance import basis_words
    lo, hi = e["interval_percent"]
    thr = e["threshold_percent"]
    head = (f"predicted realism loss if left out {e['median_percent']:.1f} % "
            f"(80 % interval {lo:.1f}-{hi:.1f} % {basis_words(e.get('basis') or (), e.get('n_solutions', 0))})")
    if lo < thr <= hi:
        return (f"{head}: the interval straddles the threshold {thr:g} %, so the importance model cannot "
                f"say the loss is small; kept")
    return f"{head}: wholly at or above the threshold {thr:g} %"
