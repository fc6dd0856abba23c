"""The solution-set design cache never answers for another model object, even one that
got the id of a model freed since (a replaced or reloaded model in a long process)."""

from __future__ import annotations

import copy

import pytest

from hapticsdk.plugins import registry

pytestmark = pytest.mark.skipif("hardness" not in registry("dimension"),
                                reason="hardness dimension plugin not installed")


def test_design_cache_checks_the_model_object(monkeypatch):
    from hapticsdk.compiler import solution_set as ss
    from hapticsdk.solvers.problems import build_problem, load_model

    monkeypatch.setattr(ss, "_CACHE", {})
    model = load_model("default")
    p = build_problem({"hardness": 0.5, "roughness": 0.5}, model=model)
    U, _, _ = ss._design(p, 64)
    assert ss._design(p, 64)[0] is U          # same model object: served from the cache

    other = copy.copy(model)                  # another model object ...
    p2 = build_problem({"hardness": 0.5, "roughness": 0.5}, model=other)
    # ... that took the first one's id: the cache holds p's entry under p2's key
    (key,) = ss._CACHE
    key2 = (id(other),) + key[1:]
    ss._CACHE[key2] = ss._CACHE.pop(key)
    U2, _, _ = ss._design(p2, 64)
    assert U2 is not U                        # recomputed for the new object, not served stale
