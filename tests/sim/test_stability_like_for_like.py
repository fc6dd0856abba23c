"""Issue 23: the stability benchmark's like-for-like peers, and the peers held to the SDK's
force-shape goals.

The goal's comparison is the SDK's ``sdk`` lane against the best passive peer sized on the
declared damping. As context, the peers also run on the damping the ``sdk`` lane trusts
(the hands-off calibration's lower bound): ``eb_measured`` and ``vc_measured``, with PO/PC
(which takes no damping) the like-for-like set. Both sets are also read with the peers held
to the rules the SDK is held to (never pulls, every step within the SDK's ramp step, the
step measured as ``sdk_step_within_ramp`` measures the SDK's).

The reasoning here is the definitions' own: a peer run on a damping equal to the declared
one is the declared-damping peer, tick for tick; a peer on no damping renders no force;
a peer that pulls, or steps beyond the ramp, is compared in the passive counts and not in
the shaped ones, in either set; a lane the goal's comparison does not name never changes it.
"""

import math

from hypothesis import given, settings, strategies as st

from hapticsdk.benchmarks.stability_random import (
    ENERGY_BOUND_J, LIKE_FOR_LIKE_PEERS, MEASURED_DAMPING_PEERS, PASSIVE_PEERS, _Ref, draw_cells, run_cells, summarise)

RAMP = 0.5   # the SDK's ramp step in these made-up cells (N)


def _res(energy=1e-6, ratio=0.5, neg=0.0, step=0.1):
    return {"energy_to_user_j": energy, "delivered_ratio": ratio, "max_force_step_n": step,
            "min_contact_force_n": neg, "contact_ticks": 10}


def _cell(sdk_ratio, peers):
    """A made-up cell: every peer of both sets over the energy bound (no peer) unless given."""
    r = {"plain": _res(1.0, 1.0), "sdk": dict(_res(1e-6, sdk_ratio), ramp_step_n=RAMP)}
    for p in (*PASSIVE_PEERS, *MEASURED_DAMPING_PEERS):
        r[p] = peers.get(p, _res(energy=1.0, ratio=1.0))
    return {"trajectory": "press_hold", "results": r}


def _lfl(s):
    d = s["peers_on_trusted_damping"]
    return (d["sdk_delivered_vs_best_passive_peer"], d["cells_with_a_passive_peer"],
            d["sdk_delivered_vs_best_shaped_peer"], d["cells_with_a_shaped_peer"])


def test_a_pulling_or_stepping_peer_counts_in_the_passive_column_only():
    # like for like: PO/PC pulls, eb_measured steps twice the ramp; vc_measured keeps the rules
    pulls = _cell(0.3, {"popc": _res(ratio=1.0, neg=-0.5), "vc_measured": _res(ratio=0.3)})
    steps = _cell(0.3, {"eb_measured": _res(ratio=0.9, step=2 * RAMP), "vc_measured": _res(ratio=0.2)})
    s = summarise([pulls, steps])
    assert _lfl(s) == (0, 2, 2, 2)
    # the goal's comparison (declared-damping peers) sees PO/PC, which pulls, and no other peer
    assert (s["sdk_delivered_vs_best_passive_peer"], s["cells_with_a_passive_peer"]) == (0, 1)
    assert (s["sdk_delivered_vs_best_shaped_peer"], s["cells_with_a_shaped_peer"]) == (0, 0)


def test_the_step_rule_is_the_sdks_own_inclusive_and_reads_the_largest_step():
    on = _cell(0.3, {"vc_measured": _res(ratio=1.0, step=RAMP)})     # exactly the ramp: kept
    beyond = _cell(0.3, {"vc_measured": _res(ratio=1.0, step=RAMP * (1 + 1e-6))})
    assert _lfl(summarise([on])) == (0, 1, 0, 1)
    assert _lfl(summarise([beyond])) == (0, 1, 0, 0)


def test_a_peer_sized_on_the_declaration_never_enters_the_like_for_like_set():
    # vc on the declaration delivers all and stays within the bound (luck); on the trusted damping it gives 0.3
    c = _cell(0.3, {"vc": _res(ratio=1.0), "vc_measured": _res(ratio=0.3)})
    s = summarise([c])
    assert (s["sdk_delivered_vs_best_passive_peer"], s["cells_with_a_passive_peer"]) == (0, 1)
    assert _lfl(s) == (1, 1, 1, 1)


def test_without_the_measured_lanes_the_summary_has_no_like_for_like_counts():
    c = _cell(0.3, {"vc": _res(ratio=0.3)})
    for p in MEASURED_DAMPING_PEERS:
        del c["results"][p]
    assert "peers_on_trusted_damping" not in summarise([c])


_peer = st.builds(_res, st.sampled_from([1e-6, ENERGY_BOUND_J, 2 * ENERGY_BOUND_J]),
                  st.one_of(st.floats(0.0, 1.0), st.just(math.nan)),
                  st.sampled_from([0.0, -1e-9, -1.0]), st.sampled_from([0.1, RAMP, 2 * RAMP]))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.floats(0.0, 1.0),
                          st.fixed_dictionaries({p: _peer for p in (*PASSIVE_PEERS, *MEASURED_DAMPING_PEERS)})),
                min_size=1, max_size=8))
def test_the_like_for_like_counts_follow_the_goal_cell_by_cell(cells):
    def kept(q, shaped):   # passive, and under the SDK's rules when shaped
        return (q["energy_to_user_j"] <= ENERGY_BOUND_J and not math.isnan(q["delivered_ratio"])
                and (not shaped or (q["min_contact_force_n"] >= 0 and q["max_force_step_n"] <= RAMP)))

    def expected(shaped):
        best = [max((q["delivered_ratio"] for p, q in peers.items() if p in LIKE_FOR_LIKE_PEERS and kept(q, shaped)),
                    default=None) for _, peers in cells]
        return (sum(b is not None and m >= 0.95 * b for (m, _), b in zip(cells, best)),
                sum(b is not None for b in best))
    got = _lfl(summarise([_cell(m, peers) for m, peers in cells]))
    assert got == (*expected(False), *expected(True))
    assert set(LIKE_FOR_LIKE_PEERS) == {"popc", *MEASURED_DAMPING_PEERS}


def _with_trusted(cell, b):
    return dict(cell, damping_calibration={"trusted_damping_ns_per_m": b})


def test_a_measured_peer_is_the_declared_peer_run_on_the_trusted_damping():
    """Run through the simulator: with the trusted damping set to the declared one, each
    measured lane is its base peer tick for tick (every figure the same number); with none
    trusted, energy bounding and the virtual coupling render no force."""
    drawn = [c for c in draw_cells(40, seed=23) if c["damping_declared_ns_per_m"] > 0]
    cells = sorted(drawn, key=lambda c: float(_Ref([c]).duration_s[0] / c["period_s"]))[:3]   # the shortest runs
    lanes = ("eb", "vc", *MEASURED_DAMPING_PEERS)
    same = run_cells([_with_trusted(c, c["damping_declared_ns_per_m"]) for c in cells], controllers=lanes)
    none = run_cells([_with_trusted(c, 0.0) for c in cells], controllers=lanes)
    for a, z in zip(same, none):
        for lane, base in MEASURED_DAMPING_PEERS.items():
            assert a["results"][lane] == a["results"][base]
            assert z["results"][lane]["energy_to_user_j"] == 0.0
            assert z["results"][lane]["max_force_step_n"] == 0.0
            assert not z["results"][lane]["delivered_ratio"] > 0.0
        assert any(a["results"][b]["max_force_step_n"] > 0 for b in MEASURED_DAMPING_PEERS.values())


def test_the_text_output_prints_the_like_for_like_counts_as_context():
    from hapticsdk.cli.bench_runtime import _like_for_like_text
    c = _cell(0.3, {"vc": _res(ratio=1.0), "vc_measured": _res(ratio=0.3), "eb_measured": _res(ratio=0.9, step=2 * RAMP)})
    s = summarise([c])
    text = _like_for_like_text(s)
    assert "the goal's comparison is the one above, the peers on the declared damping" in text
    assert "at the best passive peer in 0/1, at the best shaped peer in 1/1" in text
    assert "vc_measured 0.300" in text and "sdk 0.300" in text
    assert _like_for_like_text({k: v for k, v in s.items() if k != "peers_on_trusted_damping"}) == ""
