"""Edges of the stability benchmark's per-cell verdicts, on hand-made cells. The goals are
stated as inclusive bounds (energy "within" the bound, force "never" below 0, a step
"within" the ramp step), so a figure exactly on a bound keeps the goal; the rise goal
reads the largest rise, not the largest step (a fall may exceed the ramp); a peer with no
delivered ratio (NaN: it never touched) is no peer; "over half" is strict."""

import math

from hapticsdk.benchmarks.stability_random import ENERGY_BOUND_J, PASSIVE_PEERS, cell_verdicts, summarise

RAMP = 0.5  # the SDK lane's ramp step in these made-up cells (N)


def _res(energy=1e-6, ratio=0.5, neg=0.0, step=0.1, **extra):
    return dict({"energy_to_user_j": energy, "delivered_ratio": ratio, "max_force_step_n": step,
                 "min_contact_force_n": neg, "contact_ticks": 10}, **extra)


def _cell(sdk, peers=None):
    r = {"sdk": dict(sdk, ramp_step_n=RAMP)}
    for p in PASSIVE_PEERS:
        r[p] = (peers or {}).get(p, _res(energy=1.0))  # default: over the energy bound, no peer
    return {"trajectory": "press_hold", "results": r}


def test_figures_exactly_on_a_bound_keep_the_goal():
    v = cell_verdicts(_cell(_res(energy=ENERGY_BOUND_J, neg=0.0, step=RAMP, max_force_rise_n=RAMP,
                                 max_step_beyond_spring_n=RAMP)))
    assert v["energy_ok"] and v["no_pull"] and v["step_ok"] and v["rise_ok"] and v["step_ok_plus_spring"]


def test_a_peer_exactly_on_the_energy_bound_is_a_peer():
    v = cell_verdicts(_cell(_res(ratio=0.5), {"eb": _res(energy=ENERGY_BOUND_J, ratio=0.9)}))
    assert v["best_passive_peer_ratio"] == 0.9 and v["delivered_ok"] is False  # 0.5 < 0.95 * 0.9


def test_the_rise_goal_reads_the_rise_and_a_large_fall_only_fails_the_step_goal():
    v = cell_verdicts(_cell(_res(step=3 * RAMP, max_force_rise_n=0.5 * RAMP)))
    assert v["rise_ok"] and not v["step_ok"]


def test_a_peer_that_never_touched_is_no_peer():
    # popc (first peer) has no ratio; eb delivered 0.5, which the SDK's 0.6 beats
    v = cell_verdicts(_cell(_res(ratio=0.6), {"popc": _res(ratio=math.nan), "eb": _res(ratio=0.5)}))
    assert v["delivered_ok"] is True and v["best_passive_peer_ratio"] == 0.5
    alone = cell_verdicts(_cell(_res(ratio=0.6), {"popc": _res(ratio=math.nan)}))
    assert alone["delivered_ok"] is None  # nothing to compare with


def test_spring_only_over_half_is_strict():
    cells = [_cell(_res(spring_only_share=s)) for s in (0.5, 0.51, 0.0)]
    assert summarise(cells)["sdk_spring_only_over_half"] == 1
