"""Solving: the inverse problem (which features G give the asked intensities) and the
solvers that answer it; the compiler (stage 2 of a request) calls it for every material.

* :mod:`.base`: the generic base, :class:`Solver` (the template every solver plugin
  follows: public ``solve`` validates, times and re-evaluates, the backend implements
  ``_solve``, returning a :class:`SolverOutput`);
* :mod:`.objective`: :class:`SolveProblem` (targets, model, feature space, pinned
  features, constraints; the fitness of formula (6)) and its working arrays;
* :mod:`.results`: the scipy-like result objects and the convergence :class:`Trace`;
* :mod:`.problems`: problems built from perceptual targets by dimension name, and
  ``solve(method=...)`` through the solver table (``hapticsdk.solve`` at the top level).

Solver plugins (entry-point group ``hapticsdk.solvers``) subclass :class:`Solver`. This
module is the public home of the public names of ``base``, ``objective`` and
``results`` (as ``hapticsdk.solvers`` was before it became a package);
``hapticsdk.problems`` moved to :mod:`hapticsdk.solvers.problems`.
"""

from .base import CONSTRAINT_TOL, DEFAULT_CHUNK_SIZE, MAX_CHUNK_SIZE, PER_TARGET_TRACE_MAX, Solver, SolverOutput
from .objective import EvalBuffers, SolveProblem
from .results import BatchSolveResult, SolveResult, Trace

__all__ = ["CONSTRAINT_TOL", "DEFAULT_CHUNK_SIZE", "MAX_CHUNK_SIZE", "PER_TARGET_TRACE_MAX", "BatchSolveResult",
           "EvalBuffers", "SolveProblem", "SolveResult", "Solver", "SolverOutput", "Trace"]
