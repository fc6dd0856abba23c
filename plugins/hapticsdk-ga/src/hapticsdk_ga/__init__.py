"""Solver plugins of hapticsdk (entry-point group ``hapticsdk.solvers``).

* ``ga`` -- the reference paper's real-coded genetic algorithm (:mod:`hapticsdk_ga.ga`).
* ``de`` -- differential evolution batched over targets x population; ``de-scipy`` runs
  :func:`scipy.optimize.differential_evolution` per target (:mod:`hapticsdk_ga.de`).
* ``polish`` -- bounded Levenberg-Marquardt (damped Gauss-Newton) on the intensity residuals
  with constraints as extra residuals, using the model's Jacobian, started from the nearest
  points of a cached sample cloud (:func:`hapticsdk_ga._common.sample_cloud`) and random
  points, with a rescue round for missed targets; ``ga-polish`` chains a short GA and the
  polish (:mod:`hapticsdk_ga.polish`).
* ``amortised`` -- a precomputed target-grid table answered by interpolation
  (:mod:`hapticsdk_ga.amortised`).

Modules are imported lazily by the registry; importing this package imports nothing heavy.
"""

__all__ = ["__version__", "hapticsdk_api"]
__version__ = "0.2.0"
#: plugin API range this distribution was built for (checked when a plugin is loaded)
hapticsdk_api = ">=1.0,<2"
