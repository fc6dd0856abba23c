"""Simulations shared by the tests under tests/sim (the tests only read them)."""

from __future__ import annotations

from types import MappingProxyType
from typing import Any, Mapping

import pytest

#: the cells of ``draw_cells(2000, seed=1)`` that single tests check on the ``sdk`` lane
#: with the controller's default settings (test_sim_stability_goals.py, test_sim_passivity.py,
#: test_stability_summary_counts.py)
SEED1_CELLS = (33, 108, 122, 259, 300, 468, 516, 580, 990, 1137, 1191, 1308, 1694, 1907, 1919, 1935)


@pytest.fixture(scope="session")
def seed1_sdk() -> Mapping[int, dict[str, Any]]:
    """``{index: cell}`` for :data:`SEED1_CELLS`, each as ``run_cells`` returns it (the
    cell, ``damping_calibration`` and ``results["sdk"]``), all run in one batch. The lanes
    of a batch are independent (element-wise; the plant's live mask is
    tests/sim/test_plant_live_lanes.py, and ``test_a_batch_gives_each_cell_what_it_gets_alone``
    compares one cell with its own run), so each cell's results are the floats a run of the
    cell alone gives; one batch costs about its longest cell's ticks instead of the sum. A
    test that runs one of these cells again with other settings may pass the entry itself
    to ``run_cells`` (which copies it): its ``damping_calibration`` is then reused, not
    measured again (the measurement is deterministic)."""
    from hapticsdk.benchmarks.stability_random import draw_cells, run_cells
    cells = draw_cells(2000, seed=1)
    runs = run_cells([cells[i] for i in SEED1_CELLS], controllers=("sdk",))
    return MappingProxyType(dict(zip(SEED1_CELLS, runs)))
