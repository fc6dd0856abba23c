"""The rule of the ``hooks`` kind: every ``@hookimpl`` of a hook module names a hook of
:mod:`hapticsdk.hookspecs` and takes only that hook's arguments."""

from __future__ import annotations

from .runner import _Ctx, _run_rules


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

    _run_rules(ctx, [("hookimpls", r_hookimpls)])
