"""Kit rules widened after round 7 of broken plugins, each broken variant passed by the
kit before:

* ``result`` (solver): a solver that changes the problem it was handed (raises its
  penalty weight, widens its tolerance, leaves its answer on it as ``x0``), and one whose
  ``nfev`` counts more evaluations than the model computed;
* ``determinism`` (solver): one instance that carries something from one solve to the next
  (a warm start from its last answer), so the same seed gives another answer the second
  time;
* ``determinism`` (dimension): renderers that share state (a contact timer in a class
  attribute), so two renderers alive at once (a scene with two materials of the
  dimension) give other commands than each alone;
* ``renderer-commands`` (dimension): an amplitude a unit slip makes 1000 x its default
  actuator's ``max_amplitude`` (mV sent as V), which the safety layer clamps;
* ``hookimpls``: ``hapticsdk_dimension_info`` describing an installed dimension with
  features other than those it declares (a feature renamed in the dimension and not in
  the hook);
* ``state`` (device): a simulated device whose ``read_state()`` hands out the arrays it
  goes on writing, so a state read earlier changes as the device moves (and the kit's own
  kinematics check, which kept the arrays, saw every reading as the last one), and
  simulated devices whose physics is shared between instances (a second instance moves
  when the first is driven).

The correct variants conform."""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import pytest

from hapticsdk.devices.actuators import DeviceState
from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer
from hapticsdk.plugins import registry
from hapticsdk.solvers import SolverOutput
from hapticsdk.testing import check_device, check_dimension, check_solver
from hapticsdk.testing.conformance import format_report
from kit_variants import LAG_COIL_MAX_V, GoodSolver, OutputArm, buzz_dimension, buzz_installed, rules_of


# ---------------------------------------------------------------------------
# solvers
# ---------------------------------------------------------------------------

class _PenaltyRaised(GoodSolver):
    """Weighs the constraints ten times harder by setting ``penalty_weight`` on the
    caller's problem (the answer is feasible, so its ``fun`` is as the kit computes it)."""

    def _solve(self, problem, rng, trace):
        problem.penalty_weight = 10.0
        return super()._solve(problem, rng, trace)


class _ToleranceWidened(GoodSolver):
    """Widens the caller's tolerance to 0.05 'so that success means something'."""

    def _solve(self, problem, rng, trace):
        problem.tolerance = max(problem.tolerance, 0.05)
        return super()._solve(problem, rng, trace)


class _LeavesWarmStart(GoodSolver):
    """Leaves its answer on the caller's problem as ``x0``, for the next solve to start from."""

    def _solve(self, problem, rng, trace):
        out = super()._solve(problem, rng, trace)
        problem.x0 = np.array(out.x)
        return out


class _NfevInflated(GoodSolver):
    """Reports nfev as evaluations times 1000 (a counter incremented per row of a
    population that is already counted in rows)."""

    def _solve(self, problem, rng, trace):
        out = super()._solve(problem, rng, trace)
        return SolverOutput(out.x, nfev=out.nfev * 1000, nit=out.nit)


class _InstanceWarmStart(GoodSolver):
    """Keeps its last answer on the instance and averages the next answer of the same
    shape with it (a warm start): a second solve of one problem with one seed differs."""

    def _solve(self, problem, rng, trace):
        out = super()._solve(problem, rng, trace)
        prev, self._prev = getattr(self, "_prev", None), out
        if prev is not None and prev.x.shape == out.x.shape:
            return SolverOutput(0.5 * (prev.x + out.x), nfev=out.nfev, nit=out.nit)
        return out


SOLVER_VARIANTS = {
    "penalty-weight-raised": (_PenaltyRaised, "result", "penalty_weight: 1.0 -> 10.0"),
    "tolerance-widened": (_ToleranceWidened, "result", "tolerance: 0.02 -> 0.05"),
    "warm-start-left-on-problem": (_LeavesWarmStart, "result", "x0: None -> "),
    "nfev-inflated": (_NfevInflated, "result", "but the model computed only"),
    "instance-warm-start": (_InstanceWarmStart, "determinism", "one solver instance gave a different answer"),
}


@pytest.mark.parametrize("name", list(SOLVER_VARIANTS))
def test_each_broken_solver_is_caught_by_its_rule(name):
    cls, rule, why = SOLVER_VARIANTS[name]
    v = check_solver(cls)
    assert rules_of(v) == {rule}, format_report(v)
    assert why in format_report(v)


def test_a_solver_that_works_on_a_copy_of_the_problem_conforms():
    """Changing a copy (``with_targets``: a shallow one, its own attributes) is fine."""
    class OwnCopy(GoodSolver):
        def _solve(self, problem, rng, trace):
            mine = problem.with_targets(problem.targets)
            mine.penalty_weight = 1.0
            return super()._solve(mine, rng, trace)
    v = check_solver(OwnCopy)
    assert v == [], format_report(v)


@pytest.mark.parametrize("name", ["amortised", "de", "de-scipy", "ga", "ga-polish", "polish"])
def test_first_party_solvers_keep_the_problem_nfev_and_seed(name):
    if name not in registry("solver"):
        pytest.skip(f"solver {name!r} not installed (hapticsdk-ga)")
    v = check_solver(name)
    assert v == [], format_report(v)


# ---------------------------------------------------------------------------
# devices
# ---------------------------------------------------------------------------

class _MovingArm(OutputArm):
    """A correct simulated arm that moves: velocity 10 mm/s per N of its force along y,
    position integrating it; each state is a copy of its arrays."""
    name: ClassVar[str] = "kit-arm-moving"

    def _open(self) -> None:
        super()._open()
        self.pos, self.vel = np.zeros(3), np.zeros(3)

    def _step(self, dt: float) -> None:
        super()._step(dt)
        self.vel[1] = 10.0 * self.f
        self.pos += self.vel * dt

    def _read_state(self) -> DeviceState:
        return DeviceState(t=self.t, position_mm=self.pos.copy(), velocity_mm_s=self.vel.copy(),
                           force_n=np.array([0.0, self.f, 0.0]))


class _AliasedState(_MovingArm):
    """Hands out its working arrays: a state read earlier changes as the arm moves."""
    name: ClassVar[str] = "kit-arm-aliased-state"

    def _read_state(self) -> DeviceState:
        return DeviceState(t=self.t, position_mm=self.pos, velocity_mm_s=self.vel,
                           force_n=np.array([0.0, self.f, 0.0]))


class _SharedPhysics(_MovingArm):
    """Keeps its simulated motion in class-level arrays (reset by ``open()``): a second
    instance open beside it moves when the first is driven."""
    name: ClassVar[str] = "kit-arm-shared-physics"
    _pos: ClassVar[np.ndarray] = np.zeros(3)
    _vel: ClassVar[np.ndarray] = np.zeros(3)

    def _open(self) -> None:
        super()._open()
        self._pos[:] = 0.0
        self._vel[:] = 0.0
        self.pos, self.vel = self._pos, self._vel


def test_devices_sharing_their_physics_are_caught():
    v = check_device(_SharedPhysics)
    assert rules_of(v) == {"state"}, format_report(v)
    assert "a second instance senses the first's motion" in format_report(v)


@pytest.mark.parametrize("name", ["omni-virtual", "playback-virtual", "probe-virtual"])
def test_first_party_simulated_devices_keep_their_states_and_physics_apart(name):
    if name not in registry("actuator"):
        pytest.skip(f"device {name!r} not installed")
    from hapticsdk.testing import check
    v = check("device", name, rules=["state"])
    assert v == [] and "state" not in v.notes, format_report(v)


def test_a_moving_device_with_its_own_state_arrays_conforms():
    v = check_device(_MovingArm)
    assert v == [], format_report(v)


def test_a_state_that_changes_after_it_was_read_is_caught():
    v = check_device(_AliasedState)
    assert rules_of(v) == {"state"}, format_report(v)
    assert "read_state() hands out arrays the device goes on writing" in format_report(v)


# ---------------------------------------------------------------------------
# dimensions
# ---------------------------------------------------------------------------

class _Onset(DimensionRenderer):
    """A correct renderer: 100 Hz on the lagging coil, its amplitude rising with depth and
    doubled at the onset of a contact, the extra decaying over 30 ms of contact (timed by
    ``dt``); 0 out of contact."""
    roles = ("buzz",)

    def __init__(self, x: float) -> None:
        self.x, self.clock = x, [0.0]

    def tick(self, inp):
        if not inp.in_contact:
            self.clock[0] = 0.0
            return [ChannelCommand("buzz", frequency_hz=100.0, amplitude=0.0)]
        self.clock[0] += inp.dt
        a = 0.25 * LAG_COIL_MAX_V * (0.2 + 0.8 * self.x) * min(1.0, abs(inp.penetration_mm))
        return [ChannelCommand("buzz", frequency_hz=100.0,
                               amplitude=a * self.scale * (1.0 + float(np.exp(-self.clock[0] / 0.03))))]

    scale: ClassVar[float] = 1.0


class _SharedOnset(_Onset):
    """Keeps its contact timer in a class attribute (a list meant as a default, changed in
    place): two renderers alive at once advance and reset one timer."""
    clock_shared: ClassVar[list[float]] = [0.0]

    def __init__(self, x: float) -> None:
        super().__init__(x)
        self.clock = self.clock_shared


class _MilliVolt(_Onset):
    """Computes its amplitude in mV and sends it as the V its role declares."""
    scale: ClassVar[float] = 1000.0


_dim = buzz_dimension


@pytest.fixture
def installed():
    yield from buzz_installed(_Onset)


def test_the_correct_onset_renderer_conforms(installed):
    v = check_dimension(_dim(_Onset))
    assert v == [], format_report(v)


@pytest.mark.parametrize("renderer, rule, why", [
    (_SharedOnset, "determinism", "two renderers ticked in turn"),
    (_MilliVolt, "renderer-commands", "more than 10 x the 2 V its actuator declares"),
], ids=["shared-contact-timer", "amplitude-in-mV"])
def test_each_broken_dimension_is_caught_by_its_rule(installed, renderer, rule, why):
    v = check_dimension(_dim(renderer))
    assert rules_of(v) == {rule}, format_report(v)
    assert why in format_report(v)


@pytest.mark.parametrize("name", ["hardness", "roughness", "warmth"])
def test_first_party_dimensions_keep_renderers_apart_and_amplitudes_plausible(name):
    if name not in registry("dimension"):
        pytest.skip(f"dimension {name!r} not installed")
    from hapticsdk.testing import check
    v = check("dimension", name, rules=["determinism", "renderer-commands"])
    assert v == [], format_report(v)


# ---------------------------------------------------------------------------
# hook modules
# ---------------------------------------------------------------------------

def _info_hooks(answer):
    import types
    from hapticsdk.hookspecs import hookimpl
    from kit_variants import API
    mod = types.ModuleType("kit_hooks_info")
    mod.hapticsdk_api = API   # type: ignore[attr-defined]
    impl = hookimpl(lambda: answer)
    impl.__name__ = "hapticsdk_dimension_info"
    mod.hapticsdk_dimension_info = impl   # type: ignore[attr-defined]
    return mod


def _hardness_features():
    if "hardness" not in registry("dimension"):
        pytest.skip("the hardness dimension is not installed")
    return [f.name for f in registry("dimension").load("hardness")().features]


def test_dimension_info_with_the_installed_features_conforms():
    feats = _hardness_features()
    from hapticsdk.testing import check
    entry = {"name": "hardness", "description": "d", "features": list(reversed(feats))}   # order is free
    assert check("hooks", _info_hooks([entry])) == []
    # a dimension that is not installed is not judged
    assert check("hooks", _info_hooks([{"name": "kit-absent", "description": "d", "features": ["a"]}])) == []


def test_dimension_info_that_lies_about_an_installed_dimension_is_caught():
    feats = _hardness_features()
    from hapticsdk.testing import check
    entry = {"name": "hardness", "description": "d", "features": feats[:-1] + ["stiffness"]}
    v = check("hooks", _info_hooks([entry]))
    assert rules_of(v) == {"hookimpls"}, format_report(v)
    assert "but the installed dimension declares" in format_report(v)


@pytest.mark.parametrize("name", ["hardness", "warmth"])
def test_the_shipped_hook_modules_conform(name):
    if name not in registry("hooks"):
        pytest.skip(f"hook module {name!r} not installed")
    from hapticsdk.testing import check
    v = check("hooks", name)
    assert v == [], format_report(v)
