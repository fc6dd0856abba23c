"""Benchmarks of hapticsdk (run by ``hapticsdk bench ...``; not imported by the SDK itself).

:mod:`hapticsdk.benchmarks.solvers` -- work-precision and runtime-to-target of the inverse
solvers, peers (pygad, DEAP, pymoo; the ``bench`` extra) at the same evaluation budget.
"""
