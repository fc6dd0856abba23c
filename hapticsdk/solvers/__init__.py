"""Solving: the inverse problem (which features G give the asked intensities) and the
solvers that answer it. The second stage of a request's work, called by the compiler.

* :mod:`.base`: the generic base: :class:`SolveProblem` (targets, model, feature
  space, pinned features, constraints; the fitness of formula (6)), :class:`Solver`
  (the template every solver plugin follows: public ``solve`` validates, times and
  re-evaluates, the backend implements ``_solve``) and the scipy-like result objects;
* :mod:`.problems`: problems built from perceptual targets by dimension name, and
  ``solve(method=...)`` through the solver table (``hapticsdk.solve`` at the top level).

Solver plugins (entry-point group ``hapticsdk.solvers``) subclass :class:`Solver`. This
module is the public home of the base's names (as ``hapticsdk.solvers`` was before the
package); ``hapticsdk.problems`` moved to :mod:`hapticsdk.solvers.problems`.
"""

from .base import (
    CONSTRAINT_TOL, DEFAULT_CHUNK_SIZE, MAX_CHUNK_SIZE, PER_TARGET_TRACE_MAX, BatchSolveResult, EvalBuffers,
    SolveProblem, SolveResult, Solver, SolverOutput, Trace,
)

__all__ = ["CONSTRAINT_TOL", "DEFAULT_CHUNK_SIZE", "MAX_CHUNK_SIZE", "PER_TARGET_TRACE_MAX", "BatchSolveResult",
           "EvalBuffers", "SolveProblem", "SolveResult", "Solver", "SolverOutput", "Trace"]
