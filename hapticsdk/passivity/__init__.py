"""Passivity of sampled-data virtual walls: the analytic margin and a time-domain
passivity observer/controller.

One idea per module: :mod:`.margin` (the Colgate condition and the eigenvalue limit),
:mod:`.settings` (the declared parameters and derived constants), :mod:`.plan` (the
extra's plan and its cost), :mod:`.controller` (the servo tick's controller),
:mod:`.batch` (the same over many cells), :mod:`.observers` (observers of a recorded run).
Every public name is re-exported here: ``from hapticsdk.passivity import ...`` is the
place to import from.

Two tools:

* :func:`passivity_margin` is the Colgate & Schenkel condition for a wall
  ``F = -(K x + B v)`` computed every ``T`` seconds, held by a zero-order hold and
  applied ``d`` extra samples late, on a device with physical viscous damping ``b``:
  ``margin = b - (K T (1/2 + d) + |B|)`` (N*s/m). A positive margin means the device +
  wall is passive without any help from the hand; :func:`classify_wall` turns it into
  the label ``"passive"`` or ``"stable-by-assumption (not passive)"``.
  :func:`critical_stiffness_eig` finds the same boundary from the eigenvalues of the
  exactly discretised device, as an independent check. Given the device's apparent
  mass (``mass_kg=``), :func:`critical_stiffness` and :func:`passivity_margin` return that
  eigenvalue (stability) limit analytically via :func:`mass_correction` (exact for d = 0,
  second order in ``b T / m`` for d >= 1); the passivity label never uses it.
* :class:`PassivityController` renders a unilateral wall in two parts, both fixed by
  what the device declares (docs/runtime.md, "Passivity", derives every constant):

  - a **Colgate spring**: the wall's force up to the stiffness ``K_c = 2 b_s / T`` that
    its damping ``b_s`` makes passive under the zero-order hold (Colgate & Schenkel):
    the trusted device damping ``b_lo``, or half the fitted one where the damping was
    measured hands off (the other half covers the encoder's count crossings), as a
    function of the depth below the surface. It is a spring,
    continuous in depth and zero at the surface: no relay, no threshold. It rises by
    at most one ramp step a tick: where a reading jumps several counts, its anchor (the
    depth where it is 0) moves in, which keeps stored energy back;
  - the **extra** above it (the rest of the wall's force), bounded by energy: the
    controller books ``U``, an upper bound of the energy the extra has given the user,
    from the readings and the held forces alone (ZOH pairing plus the encoder's
    quantisation terms, Ryu, Kim & Hannaford 2004; Kim & Ryu's energy bounding), and
    sends the largest extra, within one ramp step of the last, whose plan "hold, then
    ramp to 0" keeps ``U`` within ``E0 = min(F_max Delta / 2, energy_allowance_j)``.

  The output is >= 0 (a unilateral wall never pulls), at most the device's declared force
  limit, and at most the wall's force except while the extra ramps down on a release.

Sign conventions: ``x`` is the probe position along the surface normal (mm, y axis,
inside the material at x < 0); ``F`` is the force on the probe along +x (N, "pushing the
probe out" is positive). ``E`` is the energy absorbed by the virtual environment (J); a
negative ``E`` means the wall has produced energy.
"""

from .batch import controller_commit_batch, controller_state_batch, controller_step_batch
from .controller import PassivityController
from .margin import (PASSIVE, STABLE_BY_ASSUMPTION, classify_wall, critical_stiffness, critical_stiffness_eig,
                     mass_correction, passivity_margin, spectral_radius)
from .observers import naive_observer_energy, zoh_observer_energy
from .plan import _HIST, _SCALES, _affordable_scalar, _ramp_sum, affordable_force, plan_cost_j  # noqa: F401
from .settings import (DAMPING_TRUST, DECLARED_DAMPING_TRUST, DEPRECATED_SETTINGS, ENERGY_ALLOWANCE_J, MASS_TRUST, RAMP_TIME_S, ControllerSettings,
                       cap_stiffness_n_per_mm, colgate_stiffness_n_per_mm)

__all__ = ["PASSIVE", "STABLE_BY_ASSUMPTION", "mass_correction", "passivity_margin", "critical_stiffness",
           "classify_wall", "spectral_radius", "critical_stiffness_eig", "RAMP_TIME_S", "DAMPING_TRUST", "DECLARED_DAMPING_TRUST", "MASS_TRUST",
           "ENERGY_ALLOWANCE_J", "ControllerSettings", "DEPRECATED_SETTINGS", "cap_stiffness_n_per_mm",
           "colgate_stiffness_n_per_mm", "plan_cost_j", "affordable_force", "PassivityController",
           "controller_state_batch", "controller_step_batch", "controller_commit_batch", "zoh_observer_energy",
           "naive_observer_energy"]
# (_HIST, _SCALES, _ramp_sum, _affordable_scalar: imported by the benchmark and the tests)
