"""Conformance kit: checks that a plugin keeps the contract of its kind.

Each ``check_<kind>(name_or_factory)`` runs every rule of that kind and returns a
:class:`KitResult`, a list of :class:`Violation` (empty: the plugin conforms). A violation names the plugin, its kind,
the rule and what was wrong, so a failure reads like
``[actuator 'piezo-virtual'] rule 'limits-enforced': backend received amplitude 250 V
above max_amplitude 100 V``.

Kinds and rules (``RULES[kind]``; every kind starts with import and
plugin-api-declared):

* ``actuator``: class, template, limits-declared, options, privileged-options, lifecycle,
  close, bad-input, limits-enforced, safe-stop, read-back, output-follows-command, reopen,
  instances, servo-loop, determinism, timing.
* ``device`` (an actuator that senses): the actuator rules plus state (for a simulated
  device also: its clock advances as it is stepped, and its position changes as its
  velocity says, within one declared encoder count; the states it gave keep what they said
  when read).
* ``dimension``: class, features, roles-declared, constraints-vectorised,
  constraints-cost, constraints-feasible, model-match, renderer, renderer-commands,
  renderer-bad-input, renderer-fast-law, determinism, timing.
* ``model``: shapes, model-dimensions, vectorised, determinism, bad-input, jacobian,
  metadata, responds.
* ``solver``: class, template, options, solves, result, constraints, determinism, batch,
  bad-input. A solver is judged by what the model says at the ``x`` it returns, never by
  what its result claims.
* ``hooks``: hookimpls.

The rules that judge what an actuator *outputs* read it back
(:meth:`hapticsdk.devices.actuators.Actuator.read_back`: the physical output where the
actuator declares ``readback_source = "output"``, else the backend's own record of its
last write, which the result's ``notes`` say) after holding each command for the safety
layer's ramp time plus the declared ``limits.settle_time_s``, and on while what the safety
layer lets through still changes (a declared force-rate limit), and compare it with the
command in force within the declared resolution (one step for an output, half a step
for a drive record) or :data:`READBACK_RTOL` of full scale. Timing rules take the fastest of
:data:`TIMING_CALLS` calls (so a preempted call does not count) against a fraction of
the servo period: :data:`COMMAND_BUDGET` for ``command()``, :data:`TICK_BUDGET` for a
renderer's ``tick()``.

Each rule runs in a daemon thread of its own: an ``AssertionError`` is its finding, any
other exception (a ``BaseException`` too, but ``KeyboardInterrupt`` and ``SystemExit``,
which propagate) a violation of that rule, and a rule still running after
:data:`RULE_TIME_BASE_S` plus :data:`RULE_TIME_FACTOR` x the device time it simulated is
a violation naming where it is stuck; the rules after it are not run (its thread is left
running).

The pytest side (classes to subclass, fixtures) is in :mod:`hapticsdk.testing.suites`
and :mod:`hapticsdk.testing.pytest_plugin`.

The kit is a package, one idea per module (until 0.2 it was one module; every public
name is still exported here, the documented home):

* :mod:`~hapticsdk.testing.conformance.entry`: :data:`RULES` per kind, :func:`check` and
  ``check_<kind>``, :func:`check_installed`, the ``plugin-api-declared`` and hook rules;
* :mod:`~hapticsdk.testing.conformance.runner`: how one plugin's rules run (each in a
  thread of its own, under a time limit that grows with the device time it simulates);
* :mod:`~hapticsdk.testing.conformance.report`: :class:`Violation`, :class:`KitResult`
  and their text;
* :mod:`~hapticsdk.testing.conformance.timing`: the kit's clocks, the servo period the
  timing rules assume and their budgets;
* :mod:`~hapticsdk.testing.conformance.values`: a finite-number test the rules share;
* the rules per contract kind: :mod:`~hapticsdk.testing.conformance.actuator_rules`
  (actuators and devices; :mod:`~hapticsdk.testing.conformance.actuator_drive` drives
  them: commands, holds, read-back, stand-ins for the servo loop),
  :mod:`~hapticsdk.testing.conformance.dimension_rules`,
  :mod:`~hapticsdk.testing.conformance.model_rules`,
  :mod:`~hapticsdk.testing.conformance.solver_rules`.
"""

from __future__ import annotations

from ...devices.actuators import READBACK_RTOL as READBACK_RTOL  # re-exported: the kit's name since 1.1
from .actuator_drive import ALTERNATE_WRITES, HOLD_LIMIT_S, STALL_RUN_S, STATE_STEPS_S, THREAD_GRACE_S
from .dimension_rules import (CLOCK_EPOCHS_S, COST_FACTOR, COST_REPEATS, COST_ROWS, FORCE_PLAUSIBILITY_FACTOR,
                              GROWTH_FACTOR, GROWTH_POINTS_S)
from .entry import (RULES, check, check_actuator, check_device, check_dimension, check_installed, check_model,
                    check_solver)
from .model_rules import INTENSITY_TOL, JACOBIAN_RTOL, JACOBIAN_STEP, RESPONSE_MIN, RESPONSE_SAMPLES
from .report import KitResult, Violation, assert_conforms, format_report, format_violations
from .runner import RULE_TIME_BASE_S, RULE_TIME_FACTOR
from .solver_rules import (ACTIVE_OPTIMUM, ACTIVE_TARGETS, REPORT_ATOL, RESULT_FIELDS, ReferenceModel,
                           reference_problem)
from .timing import COMMAND_BUDGET, KIT_PERIOD_S, TICK_BUDGET, TIMING_CALLS, TIMING_WINDOW_S

#: the kit's public names, the same as when it was one module (0.1)
__all__ = [
    "RULES", "check", "check_actuator", "check_device", "check_dimension", "check_model", "check_solver",
    "check_installed", "reference_problem", "ReferenceModel",
    "Violation", "KitResult", "format_report", "format_violations", "assert_conforms",
    "READBACK_RTOL", "RULE_TIME_BASE_S", "RULE_TIME_FACTOR", "KIT_PERIOD_S", "COMMAND_BUDGET", "TICK_BUDGET",
    "TIMING_CALLS", "TIMING_WINDOW_S", "HOLD_LIMIT_S", "STATE_STEPS_S", "ALTERNATE_WRITES", "THREAD_GRACE_S",
    "STALL_RUN_S", "FORCE_PLAUSIBILITY_FACTOR", "COST_ROWS", "COST_FACTOR", "COST_REPEATS", "CLOCK_EPOCHS_S",
    "GROWTH_POINTS_S", "GROWTH_FACTOR", "INTENSITY_TOL", "JACOBIAN_STEP", "JACOBIAN_RTOL", "RESPONSE_MIN",
    "RESPONSE_SAMPLES", "RESULT_FIELDS", "REPORT_ATOL", "ACTIVE_TARGETS", "ACTIVE_OPTIMUM",
]
