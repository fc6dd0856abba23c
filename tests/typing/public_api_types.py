"""Checked by mypy (listed in pyproject's ``[tool.mypy] files``), not run by pytest.

Each function returns what the public API is typed to give; with ``warn_return_any``
a name that became ``Any`` again (lazy ``__getattr__`` without the ``TYPE_CHECKING``
imports) or a ``solve`` without overloads fails the check.
"""

from __future__ import annotations

import numpy as np

import hapticsdk as hs
from hapticsdk.runtime.render import RenderReport
from hapticsdk.solvers import BatchSolveResult, SolveResult


def one_target() -> SolveResult:
    res = hs.solve({"hardness": 0.8, "roughness": 0.3}, seed=1)
    print(res.x_dict)  # a SolveResult, so x_dict is not a type error
    return res


def a_batch() -> BatchSolveResult:
    batch = hs.solve([[0.8, 0.3], [0.2, 0.6]], dimensions=["hardness", "roughness"], seed=1)
    print(batch.time_s, batch.x.shape)
    return batch


def an_array() -> SolveResult | BatchSolveResult:
    return hs.solve(np.array([[0.8, 0.3]]), dimensions=["hardness", "roughness"])


def a_render() -> RenderReport:
    return hs.render("S7", seconds=0.1)


def a_model() -> hs.PerceptionModel:
    return hs.load_model("default")


def lazy_classes() -> tuple[type[hs.Solver], type[hs.HapticSDKError], type[hs.Scene]]:
    return hs.Solver, hs.HapticSDKError, hs.Scene
