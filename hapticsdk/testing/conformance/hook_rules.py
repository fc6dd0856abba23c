"""The rule of the ``hooks`` kind: every ``@hookimpl`` of a hook module names a hook of
:mod:`hapticsdk.hookspecs` and takes only that hook's arguments; the hooks that take
nothing answer what their hookspec says."""

from __future__ import annotations

import math
from typing import Any

from .runner import _Ctx, _run_rules


def _check_materials(answer: Any) -> None:
    """``hapticsdk_materials``' answer: a list of material dicts, each valid as the core's
    ``load_library(with_plugins=True)`` validates it."""
    from ...perception.materials import _material
    from ...schemas_io import validate
    assert isinstance(answer, list), \
        f"hapticsdk_materials returned {type(answer).__name__}, not a list of material dicts"
    for e in answer:
        assert isinstance(e, dict), f"hapticsdk_materials returned an entry {e!r}, not a dict"
        # the format is JSON, whose numbers are finite: a NaN passes the schema's 0..1 (every
        # comparison with it is False) and an infinity its "number", and neither is a value
        for part in ("intensities", "features"):
            vals = e.get(part)
            for k, v in (vals.items() if isinstance(vals, dict) else ()):
                assert not isinstance(v, float) or math.isfinite(v), \
                    (f"hapticsdk_materials returned material {e.get('name')!r} with {part}[{k!r}] = {v!r}: a "
                     f"material file is JSON, whose numbers are finite (an intensity lies in 0..1)")
        try:
            validate({"schema_version": 1, "generated": bool(e.get("generated", False)), "source": "kit",
                      "materials": [e]}, "materials", source="hapticsdk_materials")
            _material(e, "kit", False)
        except Exception as exc:  # noqa: BLE001 - the core skips the plugin for any of them
            raise AssertionError(f"hapticsdk_materials returned an invalid material {e.get('name')!r}: {exc} "
                                 f"(load_library(with_plugins=True) skips the plugin)") from None
    # the core adds a plugin's materials to the shipped library one by one, and a name taken
    # (case-insensitive, as MaterialLibrary looks names up) stops it there: the plugin is
    # reported as failed and its materials from that one on are missing
    from ...perception.materials import load_library
    taken = {m.name.lower(): "the shipped library" for m in load_library()}
    for e in answer:
        key = str(e["name"]).lower()
        assert key not in taken, \
            (f"hapticsdk_materials returned a material named {e['name']!r}, a name {taken[key]} already has "
             f"(names are unique, case-insensitive): load_library(with_plugins=True) refuses it and skips the "
             f"plugin's materials from there on")
        taken[key] = "an earlier material of this answer"


def _check_dimension_info(answer: Any) -> None:
    """``hapticsdk_dimension_info``' answer: a list of ``{"name", "description",
    "features": [names]}``, the features of an installed dimension of that name the ones it
    declares."""
    assert isinstance(answer, list), \
        f"hapticsdk_dimension_info returned {type(answer).__name__}, not a list of dicts"
    for e in answer:
        ok = (isinstance(e, dict) and isinstance(e.get("name"), str) and isinstance(e.get("description"), str)
              and isinstance(e.get("features"), list) and all(isinstance(f, str) for f in e["features"]))
        assert ok, (f"hapticsdk_dimension_info returned {e!r}: each entry is "
                    f'{{"name": str, "description": str, "features": [str, ...]}}')
    # the hook describes dimensions without importing them: where the dimension it names is
    # installed, its features are the ones that dimension declares (a caller builds feature
    # vectors, forms or scene entries from them); a dimension not installed is not judged
    from ...plugins import registry
    reg = registry("dimension")
    for e in answer:
        if e["name"] not in reg:
            continue
        obj = reg.load(e["name"])
        dim = obj() if isinstance(obj, type) else obj
        declared = [f.name for f in getattr(dim, "features", ())]
        assert sorted(e["features"]) == sorted(declared), \
            (f"hapticsdk_dimension_info describes dimension {e['name']!r} with features {e['features']}, but the "
             f"installed dimension declares {declared}: the hook stands for the dimension without importing it, "
             f"so its callers build features from it; list the features the dimension declares")


def _hooks_rules(ctx: _Ctx) -> None:
    """A hook module (group ``hapticsdk.hooks``): every ``@hookimpl`` names a hook of
    :mod:`hapticsdk.hookspecs` and takes only that hook's arguments (pluggy would refuse it
    at registration, after the render started)."""
    import inspect
    from ... import hookspecs

    def r_hookimpls() -> None:
        mod = ctx.obj
        marker = f"{hookspecs.PROJECT}_impl"
        impls = {n: f for n, f in vars(mod).items() if callable(f) and hasattr(f, marker)}
        specs = {n for n in dir(hookspecs) if n.startswith(f"{hookspecs.PROJECT}_")}
        unknown = [n for n in impls if n not in specs]
        assert not unknown, f"@hookimpl function(s) {unknown} name no hook of hapticsdk.hookspecs ({sorted(specs)})"
        assert impls, "the module has no @hookimpl function"
        for n, f in impls.items():
            spec = getattr(hookspecs, n)
            allowed = set(inspect.signature(spec).parameters) - {"self"}
            extra = set(inspect.signature(f).parameters) - allowed
            assert not extra, f"{n} takes {sorted(extra)}, which the hook does not pass (it passes {sorted(allowed)})"
        # and pluggy itself takes the module, as the core registers it (a hookwrapper or
        # wrapper that is not a generator function, a spec option it refuses)
        import pluggy
        pm = pluggy.PluginManager(hookspecs.PROJECT)
        pm.add_hookspecs(hookspecs)
        try:
            pm.register(mod, name="kit-hooks-under-test")
        except pluggy.PluginValidationError as exc:
            raise AssertionError(f"pluggy refuses to register the module ({exc}): the core would record it as a "
                                 f"failed hook plugin and never call it") from None
        # the hooks that take nothing are called, and their answers must be what the
        # hookspec says (the core skips a plugin whose answer is not, at run time)
        # twice: the core calls them again on every load (load_library(with_plugins=True),
        # hapticsdk plugins), so an answer that grows from call to call fails the second
        for name, judge in (("hapticsdk_materials", _check_materials),
                            ("hapticsdk_dimension_info", _check_dimension_info)):
            if name not in impls:
                continue
            judge(impls[name]())
            try:
                judge(impls[name]())
            except AssertionError as exc:
                raise AssertionError(f"{exc} (on the second call: the core calls {name} again on every load, so "
                                     f"build the answer anew each call, never by adding to a kept list)") from None

    _run_rules(ctx, [("hookimpls", r_hookimpls)])
