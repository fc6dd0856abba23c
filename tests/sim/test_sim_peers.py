"""The stability benchmark's textbook peers (``hapticsdk.sim.peers``) follow their laws
lane by lane: the plain wall, PO/PC's observer and damper, energy bounding's per-sample
limit and the virtual coupling's series spring. Each law is checked on drawn lanes
against its formula written out here, so a sign or a factor changed in the peers fails.
"""

from __future__ import annotations

import numpy as np
import pytest

from hapticsdk.sim import peers

N = 400


def _draw(rng):
    T = np.exp(rng.uniform(np.log(0.25e-3), np.log(10e-3), N))
    K = np.exp(rng.uniform(np.log(0.01), np.log(100.0), N))          # N/mm
    b = np.where(rng.random(N) < 0.2, 0.0, rng.uniform(0.0, 2.0, N))  # N s/m
    return T, K, b


def _two_ticks(rng, kind):
    """Start every lane, commit a force, step once more: (state before, inputs, output)."""
    T, K, b = _draw(rng)
    k = np.full(N, peers.PEERS.index(kind))
    st = peers.state(N)
    x0 = rng.uniform(-3.0, 1.0, N)
    pen0 = np.maximum(-x0, 0.0)
    peers.step(k, st, x0, T, K * pen0, K, pen0, b)
    f1 = rng.uniform(0.0, 3.3, N)
    peers.commit(st, f1)
    E0 = st["E"].copy()
    x1 = x0 + rng.normal(0.0, 0.2, N) * np.where(rng.random(N) < 0.1, 0.0, 1.0)   # some lanes at rest
    pen1 = np.maximum(-x1, 0.0)
    fw = K * pen1
    out = peers.step(k, st, x1, T, fw, K, pen1, b)
    return dict(T=T, K=K, b=b, f1=f1, E0=E0, dq=(x1 - x0) * 1e-3, fw=fw, pen=pen1, out=out, st=st)


def test_the_first_tick_books_no_motion():
    rng = np.random.default_rng(0)
    T, K, b = _draw(rng)
    st = peers.state(N)
    x = rng.uniform(-3.0, 1.0, N)
    pen = np.maximum(-x, 0.0)
    out = peers.step(np.full(N, peers.PEERS.index("popc")), st, x, T, K * pen, K, pen, b)
    assert np.array_equal(st["E"], np.zeros(N)) and np.array_equal(out, K * pen)


@pytest.mark.parametrize("seed", range(3))
def test_the_plain_wall_is_the_wall(seed):
    r = _two_ticks(np.random.default_rng(seed), "plain")
    assert np.array_equal(r["out"], r["fw"])


@pytest.mark.parametrize("seed", range(3))
def test_popc_observes_the_held_force_and_damps_exactly_its_deficit(seed):
    """Observer paired with the hold: ``E <- E - F_applied(n-1) dx(n)``. Where it is
    negative and the stylus moved, the damper ``alpha = -E / (T v^2)`` takes back exactly
    the deficit over the next sample: ``(F_wall - F) dx = -E``; elsewhere ``F = F_wall``."""
    r = _two_ticks(np.random.default_rng(seed), "popc")
    E = r["E0"] - r["f1"] * r["dq"]
    assert r["st"]["E"] == pytest.approx(E, rel=1e-12, abs=0.0)
    damped = (E < 0) & (r["dq"] != 0)
    assert damped.any() and (~damped).any()
    assert np.array_equal(r["out"][~damped], r["fw"][~damped])
    assert (r["fw"] - r["out"])[damped] * r["dq"][damped] == pytest.approx(-E[damped], rel=1e-9, abs=0.0)


@pytest.mark.parametrize("seed", range(3))
def test_energy_bounding_moves_toward_the_wall_within_what_the_damping_takes(seed):
    """``|F_n - F_(n-1)| <= 2 b |dx| / T`` (the hold's energy within the declared damping's
    dissipation), as far toward the wall's force as that allows."""
    r = _two_ticks(np.random.default_rng(seed), "eb")
    lim = 2.0 * r["b"] * np.abs(r["dq"]) / r["T"]
    step = r["out"] - r["f1"]
    assert np.all(np.abs(step) <= lim * (1 + 1e-12))
    want = r["fw"] - r["f1"]
    reached = np.abs(want) <= lim
    assert reached.any() and (~reached).any()
    assert r["out"][reached] == pytest.approx(r["fw"][reached], rel=1e-12, abs=1e-15)
    assert step[~reached] == pytest.approx((np.sign(want) * lim)[~reached], rel=1e-12, abs=0.0)


@pytest.mark.parametrize("seed", range(3))
def test_the_virtual_coupling_is_the_wall_in_series_with_colgate_s_spring(seed):
    """``K_c = 2 b / T`` (N/m, the declared damping at face value) in series with the wall:
    ``F = K K_c / (K + K_c) x penetration``, 0 without damping."""
    r = _two_ticks(np.random.default_rng(seed), "vc")
    kc = 2.0 * r["b"] / r["T"] * 1e-3   # N/mm
    with np.errstate(invalid="ignore", divide="ignore"):
        want = np.where(kc > 0, r["K"] * kc / (r["K"] + kc), 0.0) * r["pen"]
    assert r["out"] == pytest.approx(want, rel=1e-12, abs=0.0)
    assert np.all(r["out"][r["b"] == 0] == 0.0)


def test_commit_is_what_the_next_sample_holds():
    st = peers.state(3)
    peers.commit(st, np.array([1.0, 2.0, 0.5]))
    assert np.array_equal(st["f1"], [1.0, 2.0, 0.5]) and np.array_equal(st["out"], [1.0, 2.0, 0.5])
    assert st["out"] is not st["f1"]


def test_energy_bounding_starts_from_zero_on_the_first_tick():
    """The first tick books no motion (``dx = 0``), so energy bounding's per-sample limit
    ``2 b |dx| / T`` is 0 there and its force stays at its start, 0 N, whatever the wall
    asks; the next tick moves toward the wall within the limit of that tick's motion."""
    rng = np.random.default_rng(5)
    T, K, b = _draw(rng)
    st = peers.state(N)
    x = rng.uniform(-3.0, -0.5, N)                     # every lane inside the wall
    pen = -x
    kind = np.full(N, peers.PEERS.index("eb"))
    assert np.array_equal(peers.step(kind, st, x, T, K * pen, K, pen, b), np.zeros(N))
    peers.commit(st, np.zeros(N))
    out = peers.step(kind, st, x - 0.1, T, K * (pen + 0.1), K, pen + 0.1, b)
    assert np.all(np.abs(out) <= 2.0 * b * 0.1e-3 / T * (1 + 1e-12))


def test_the_virtual_coupling_of_a_wall_without_stiffness_or_damping_gives_nothing():
    """``F = K K_c / (K + K_c) x penetration`` is 0 where either spring is 0, also where
    both are (a wall of 0 N/mm on a device declaring no damping): 0 N, not NaN."""
    st = peers.state(4)
    K = np.array([0.0, 0.0, 2.0, 0.0])
    b = np.array([0.0, 0.5, 0.0, 0.0])
    pen = np.array([1.0, 1.0, 1.0, 0.0])
    out = peers.step(np.full(4, peers.PEERS.index("vc")), st, -pen, np.full(4, 1e-3), K * pen, K, pen, b)
    assert np.array_equal(out, np.zeros(4))


def test_popc_damps_at_every_speed_including_one_metre_per_second():
    """The damper acts wherever the observed energy is negative and the stylus moved,
    at any speed: lanes moving 0.25, 0.5, 1, 2 and 4 mm in a 1 ms sample (1 m/s exactly
    among them, all exact in binary) with a held force that gave energy are damped by
    exactly their deficit, ``(F_wall - F) dx = -E``."""
    dx_mm = np.array([0.25, 0.5, 1.0, 2.0, 4.0])
    n = dx_mm.size
    st = peers.state(n)
    T = np.full(n, 1e-3)
    K, b = np.full(n, 1.0), np.full(n, 0.5)
    kind = np.full(n, peers.PEERS.index("popc"))
    x0 = np.full(n, -5.0)
    peers.step(kind, st, x0, T, -x0 * K, K, -x0, b)
    peers.commit(st, np.full(n, 2.0))                   # pushing out while the stylus moves out
    x1 = x0 + dx_mm
    out = peers.step(kind, st, x1, T, -x1 * K, K, -x1, b)
    E = -2.0 * dx_mm * 1e-3
    assert st["E"] == pytest.approx(E, rel=1e-12, abs=0.0)
    assert (-x1 * K - out) * dx_mm * 1e-3 == pytest.approx(-E, rel=1e-9, abs=0.0)
