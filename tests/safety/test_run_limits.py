"""Servo period and render duration are validated before anything is solved, opened or
allocated (issue 13, item 8: `render --seconds 500000` and `servo.period_s: 1e-9` ended in
multi-GiB allocations and tracebacks)."""

from __future__ import annotations

import pytest

from hapticsdk.devices.actuators import Actuator
from hapticsdk.errors import ValidationError
from hapticsdk.scene.limits import MAX_SECONDS, PERIOD_RANGE_S, check_period, check_seconds


@pytest.mark.parametrize("bad", [1e-9, 0, -0.001, 0.2, float("nan"), float("inf"), "abc", True, None])
def test_period_outside_the_range_is_a_named_error(bad):
    with pytest.raises(ValidationError) as ei:
        check_period(bad, "servo.period_s")
    assert ei.value.field == "servo.period_s"


@pytest.mark.parametrize("bad", [500000, MAX_SECONDS * 1.0001, 0, -1, float("nan"), float("inf"), "x", False])
def test_duration_outside_the_range_is_a_named_error(bad):
    with pytest.raises(ValidationError) as ei:
        check_seconds(bad, "seconds")
    assert ei.value.field == "seconds"


def test_range_ends_are_accepted():
    assert check_period(PERIOD_RANGE_S[0]) == PERIOD_RANGE_S[0]
    assert check_period(PERIOD_RANGE_S[1]) == PERIOD_RANGE_S[1]
    assert check_seconds(MAX_SECONDS) == MAX_SECONDS
    # hapticsdk.argcheck's rule: the text of a number is not a number (the command line
    # converts its text first)
    for check in (check_period, check_seconds):
        with pytest.raises(ValidationError, match="must be a number"):
            check("0.001")


def test_scene_with_a_nanosecond_period_is_refused():
    from hapticsdk.scene import Scene
    with pytest.raises(ValidationError) as ei:
        Scene.for_material({"roughness": 0.5}, servo={"period_s": 1e-9})
    assert ei.value.field == "scene.settings.servo.period_s"


@pytest.fixture
def opened(monkeypatch):
    """Actuator.open fails the test at once (none may happen before the range checks;
    failing at once also keeps a missing check from running a 500000 s render)."""
    calls = []

    def spy(self):
        calls.append(self.label)
        raise AssertionError(f"{self.label} opened before the range checks")
    monkeypatch.setattr(Actuator, "open", spy)
    return calls


def _plan():
    from hapticsdk.compiler import compile_scene
    from hapticsdk.scene import Scene
    return compile_scene(Scene.for_material({"roughness": 0.5}, seed=1))


@pytest.mark.parametrize("seconds", [500000, 1e12])
def test_render_plan_refuses_a_huge_duration_before_opening(opened, seconds):
    from hapticsdk.runtime.render import render_plan
    with pytest.raises(ValidationError) as ei:
        render_plan(_plan(), seconds=seconds)
    assert ei.value.field == "seconds" and opened == []


def test_render_plan_refuses_a_plan_period_of_a_nanosecond_before_opening(opened):
    from hapticsdk.runtime.render import render_plan
    d = _plan().to_dict()
    d["settings"]["servo"]["period_s"] = 1e-9
    with pytest.raises(ValidationError) as ei:
        render_plan(d, seconds=1.0)
    assert ei.value.field == "plan.settings.servo.period_s" and opened == []
    with pytest.raises(ValidationError) as ei:
        render_plan(_plan(), seconds=1.0, period_s=1e-9)
    assert ei.value.field == "period_s" and opened == []


def test_cli_render_huge_seconds_exits_2_before_solving(monkeypatch, capsys, opened):
    import hapticsdk.compiler as compiler
    from hapticsdk.cli import main

    def boom(*a, **k):
        raise AssertionError("solved before checking --seconds")
    monkeypatch.setattr(compiler, "compile_scene", boom)
    assert main(["render", "S7", "--seconds", "500000"]) == 2
    err = capsys.readouterr().err
    assert "hapticsdk: error: --seconds:" in err and "Traceback" not in err and opened == []
