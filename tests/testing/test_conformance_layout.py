"""The conformance kit is a package split along its seams (issue 29 item 7); its public
names, its entry point and its report of where a plugin is stuck are unchanged."""

from __future__ import annotations

import functools
import sys
import threading
import time
import traceback
from importlib import import_module, metadata

import hapticsdk.testing as testing
import hapticsdk.testing.conformance as kit

#: the public names of ``hapticsdk.testing.conformance`` when it was one module (0.1 and
#: main up to 3fddcc6): a plugin's tests may import any of them from there
NAMES_0_1 = {
    "ACTIVE_OPTIMUM", "ACTIVE_TARGETS", "ALTERNATE_WRITES", "CLOCK_EPOCHS_S", "COMMAND_BUDGET", "COST_FACTOR",
    "COST_REPEATS", "COST_ROWS", "FORCE_PLAUSIBILITY_FACTOR", "GROWTH_FACTOR", "GROWTH_POINTS_S", "HOLD_LIMIT_S",
    "INTENSITY_TOL", "JACOBIAN_RTOL", "JACOBIAN_STEP", "KIT_PERIOD_S", "KitResult", "READBACK_RTOL",
    "REPORT_ATOL", "RESPONSE_MIN", "RESPONSE_SAMPLES", "RESULT_FIELDS", "RULES", "RULE_TIME_BASE_S",
    "RULE_TIME_FACTOR", "ReferenceModel", "STALL_RUN_S", "STATE_STEPS_S", "THREAD_GRACE_S", "TICK_BUDGET",
    "TIMING_CALLS", "TIMING_WINDOW_S", "Violation", "assert_conforms", "check", "check_actuator",
    "check_device", "check_dimension", "check_installed", "check_model", "check_solver", "format_report",
    "format_violations", "reference_problem",
}


def test_the_kit_keeps_its_public_names():
    assert set(kit.__all__) == NAMES_0_1
    for name in NAMES_0_1:
        value = getattr(kit, name)
        home = getattr(value, "__module__", None)
        if home and home.startswith("hapticsdk.testing.conformance."):   # a function or class: its module's
            assert getattr(import_module(home), name) is value
    for name in testing.__all__:
        if hasattr(kit, name):
            assert getattr(testing, name) is getattr(kit, name)


def test_the_pytest11_entry_point_loads_the_kit():
    eps = [e for e in metadata.entry_points(group="pytest11") if e.name == "hapticsdk"]
    assert [e.value for e in eps] == ["hapticsdk.testing.pytest_plugin"]
    plugin = eps[0].load()
    assert callable(plugin.hapticsdk_conformance)


def test_where_a_rule_is_stuck_names_code_outside_every_kit_module():
    """A thread blocked in the standard library, under a helper of one kit module
    (``timing._fastest``), called from code outside the kit: the report names that code,
    never a module of the kit (any of them, not only the runner's own file)."""
    from hapticsdk.testing.conformance.runner import _where
    from hapticsdk.testing.conformance.timing import _fastest

    release = threading.Event()

    def outside_the_kit() -> None:
        _fastest(functools.partial(release.wait, 30), n=1)   # the kit's frame calls the stdlib

    th = threading.Thread(target=outside_the_kit, daemon=True)
    th.start()
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:   # until the thread waits inside the stdlib
            frame = sys._current_frames().get(th.ident or -1)
            names = [fs.name for fs in traceback.extract_stack(frame)] if frame else []
            if "_fastest" in names and names[-1] == "wait":
                break
            time.sleep(0.001)
        where = _where(th)
    finally:
        release.set()
        th.join(30)
    assert where.startswith("outside_the_kit (") and __file__ in where, where
