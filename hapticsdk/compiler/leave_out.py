"""The feature points a leave-out decision judges, for one material.

:func:`material_points` gives, for a material of a compile, the points of
:func:`hapticsdk.compiler.importance.judge_material`:

* ``recorded``: the library's recorded features of the material (mean over its trials),
  when the library has them and the scene kept the library's intensities;
* ``recorded, solved onto the target``: the recorded features moved onto the target by
  damped minimum-norm Gauss-Newton steps on the perception model, in unit-box
  coordinates and clipped to the searched box (the member of the model's inverse nearest
  to the material's own features; no random number is drawn, so it is the same on every
  run);
* ``solved``: for a material without recorded features, the compile's solved features
  (what is rendered).

None of them depends on a solver seed, a search design's size or a number of starts:
those settings do not enter.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from .importance import RECORDED, RECORDED_SOLVED, SOLVED

__all__ = ["material_points", "solve_onto_target"]

#: Gauss-Newton steps moving the recorded features onto the target (each step solves the
#: linearised model exactly in the minimum-norm sense; the model is smooth (tanh), so a few
#: steps reach the solve tolerance from a point the model was fitted on)
PROJECTION_STEPS = 8


def solve_onto_target(problem: Any, row: int, x: Mapping[str, float]) -> dict[str, float] | None:
    """``x`` (physical units) moved onto target ``row`` of ``problem`` by
    :data:`PROJECTION_STEPS` minimum-norm Gauss-Newton steps; ``None`` when ``x`` lacks a
    searched feature. The model's error there is in the result under ``"_error"``."""
    from .solution_set import _project
    names = problem.space.names
    if any(n not in x for n in names):
        return None
    X0 = problem.space.clip(np.array([[float(x[n]) for n in names]]))
    U = _project(problem, problem.space.to_unit(X0), problem.targets[row], PROJECTION_STEPS)
    X = problem.space.from_unit(U)
    det = problem.evaluate(X, rows=np.array([row]), details=True)
    out = {n: float(v) for n, v in zip(names, X[0])}
    out.update({k: float(v) for k, v in problem.fixed.items()})
    out["_error"] = float(np.asarray(det["error"])[0])
    return out


def material_points(problem: Any, row: int, recorded: Mapping[str, float] | None,
                    solved: Mapping[str, float] | None) -> list[tuple[str, dict[str, float]]]:
    """The feature points judged for target ``row`` of ``problem`` (see the module
    docstring): recorded and recorded-solved-onto-the-target when ``recorded`` is given,
    else ``solved``."""
    pts: list[tuple[str, dict[str, float]]] = []
    if recorded:
        pts.append((RECORDED, {k: float(v) for k, v in recorded.items()}))
        moved = solve_onto_target(problem, row, recorded)
        if moved is not None:
            moved.pop("_error", None)
            pts.append((RECORDED_SOLVED, moved))
    elif solved:
        pts.append((SOLVED, {k: float(v) for k, v in solved.items()}))
    return pts

