"""The ``plugin-api-declared`` rule every kind starts with: the plugin declares a
``hapticsdk_api`` range that this core's plugin API satisfies; the rules new since the
version it declares are named in its violations."""

from __future__ import annotations

from typing import Any

from ...errors import ValidationError
from .runner import _Ctx


def _api_rule(ctx: _Ctx, target: Any) -> None:
    """``plugin-api-declared``: the plugin (the object its entry point names, the class, or
    the factory) declares a ``hapticsdk_api`` range, on itself or its top-level package,
    that this core's plugin API satisfies. Sets the result's ``api`` and the rules new
    since the declared version."""
    from ...plugin_api import PLUGIN_API_VERSION, api_compatible, declared_api, rules_new_since
    spec, where = declared_api(ctx.obj) if ctx.obj is not None else (None, "undeclared")
    if spec is None and target is not None and not isinstance(target, str):
        spec, where = declared_api(target)
    ok: bool | None = None
    err = ""
    if spec is not None:
        try:
            ok = api_compatible(spec)
        except ValidationError as exc:
            err = str(exc)
    ctx.new_rules = rules_new_since(spec if ok else None)
    ctx.violations.api = {"declared": spec, "where": where, "provided": PLUGIN_API_VERSION,
                          "new_rules": dict(ctx.new_rules)}
    if ctx.only and "plugin-api-declared" not in ctx.only:
        return
    major = PLUGIN_API_VERSION.split(".")[0]
    if spec is None:
        ctx.fail("plugin-api-declared", f"declares no hapticsdk_api range (on the object or its top-level "
                                        f"package); this core provides plugin API {PLUGIN_API_VERSION}: declare "
                                        f"e.g. hapticsdk_api = \">={PLUGIN_API_VERSION},<{int(major) + 1}\"")
    elif err:
        ctx.fail("plugin-api-declared", f"hapticsdk_api {spec!r} ({where}) cannot be read: {err}")
    elif not ok:
        ctx.fail("plugin-api-declared", f"hapticsdk_api {spec!r} ({where}) excludes this core's plugin API "
                                        f"{PLUGIN_API_VERSION}: the registry refuses to load it")
