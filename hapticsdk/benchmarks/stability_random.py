"""Stiff walls off the grid: randomised stability cells, each run with the SDK's
passivity controller and four textbook peers on the same plant and trajectory
(``hapticsdk bench stability --random N --seed S``; the fixed grid runs through the same
code as a regression set).

A cell is a wall ``F = K x penetration`` (of the encoder reading; the surface at 0) on one
normal axis of an arm (mass, true damping, encoder, 3.3 N force limit) held by a finger
(mass, spring, damper) that follows a scripted reference. Drawn, per cell, independently:

* trajectory: press-and-hold, taps (up to 1.5 m/s), bumpy sliding (depth modulated by
  0.3-1 mm at 5-40 Hz), plain sliding (depth drifting), slow creep (1-5 mm/s);
* finger: mass 3-50 g, stiffness 50-2000 N/m, damping 0.1-5 N*s/m (log-uniform; a band
  around the presets of :data:`hapticsdk.sim.finger.FINGERS`, generated, not measured);
* period 0.25-10 ms, encoder 0.001-0.2 mm, arm mass 0.02-0.1 kg (log-uniform), declared
  at 0.5x-2x the true mass (log-uniform factor; the controller is told the declared mass);
* true damping 0 (a quarter of the cells) or 0.05-1 N*s/m, declared at 0.5x-2x the true
  value (log-uniform factor);
* stiffness 0.01-10^4 N/mm (log-uniform).

Plant: :class:`hapticsdk.sim.plant.PlantBatch` (exact ZOH, energy from the raw state).
Controllers per cell: ``plain``, ``popc``, ``eb``, ``vc`` (:mod:`hapticsdk.sim.peers`,
the declared damping at face value), ``sdk`` (:class:`~hapticsdk.passivity.PassivityController`
with the damping measured hands off on the cell's own arm, :func:`measure_cell_damping`:
the fit's lower bound trusted and the fit as the device's damping; the declared
resolution and force limit) and ``sdk_declared`` (the same controller on a device never
calibrated: ``declared_damping_trust`` of the declared damping, none by default), and
``eb_measured`` and ``vc_measured`` (:data:`MEASURED_DAMPING_PEERS`: energy bounding and
the virtual coupling once more, on the damping the ``sdk`` lane trusts, the calibration's
lower bound ``trusted_damping_ns_per_m``, instead of the declaration; PO/PC takes no
damping, so its one run serves both sets).

Per cell and controller: ``energy_to_user_j`` (max over time of the energy given to the
finger), ``delivered_ratio`` (over the contact ticks, i.e. reading inside the wall:
``sum min(F+, F_target) / sum F_target`` with ``F_target = min(K pen, 3.3 N)``; force
beyond the wall's law, e.g. a damper's, is not counted as delivered), ``max_force_step_n``
(largest change of the applied force between two ticks, all ticks; ``max_force_rise_n`` and
``max_force_fall_n`` the largest rise and the largest fall alone), ``min_contact_force_n``
(most negative applied force on a contact tick; 0 if none); for ``sdk`` and ``sdk_declared`` also
``ramp_step_n`` (the controller's own step at that period) and ``bound_shortfall_j``
(largest ``true energy - U - (Delta/2) |F|`` over the ticks: <= 0 when the controller's
bound ``U`` held as an upper bound of the truth), ``max_step_beyond_spring_n`` (largest
change of the force beyond the Colgate spring's, ``K_c |dq|``),
``max_step_beyond_spring_where_ramp_kept_n`` (the same over the ticks on which the
controller did not fall below its ramp), ``below_ramp_ticks`` (ticks on which its book
was overdrawn and the extra fell below its ramp, the energy goal put first:
docs/runtime.md, Passivity item 3) and ``spring_only_share`` (share of the contact ticks on which the controller sent the Colgate spring alone, the extra held at 0,
while the wall asked for more: where its energy bound had nothing left for the extra).
Not modelled: Coulomb friction, computation
delay, jitter, multi-axis coupling, a reacting hand.

The summary's delivered goal (:func:`summarise`; the ``sdk`` lane at the top level, the
``sdk_declared`` lane under ``declared_damping``): the SDK controller delivers at least 95 %
of the best passive peer's ratio (``popc``, ``eb`` or ``vc``, among those within the energy
bound in that cell), counted over the cells that have such a peer
(``sdk_delivered_vs_best_passive_peer`` of ``cells_with_a_passive_peer``); and the same
against the best such peer that also kept the force-shape goals the SDK is held to, never
pulling and no step beyond the SDK's ramp step (``sdk_delivered_vs_best_shaped_peer`` of
``cells_with_a_shaped_peer``). A cell with no such peer counts in neither. The step measure
is the SDK's own (``sdk_step_within_ramp``): the peer's ``max_force_step_n`` (largest
change of the applied force between two ticks) within the ramp step of the SDK lane in
that cell; never pulling is ``min_contact_force_n >= 0`` (``sdk_no_pull``).

The goal's comparison is the one above, against the peers on the declared damping (the
benchmark draws it at 0.5x-2x the truth, so a peer sized on it may sit beyond the true
Colgate limit and still stay within the bound by the motion's luck). As context, like for
like with the ``sdk`` lane, ``peers_on_trusted_damping`` gives the same two counts against
:data:`LIKE_FOR_LIKE_PEERS` (``popc``, ``eb_measured``, ``vc_measured``: the peers on the
damping the ``sdk`` lane trusts): ``sdk_delivered_vs_best_passive_peer`` of
``cells_with_a_passive_peer`` and ``sdk_delivered_vs_best_shaped_peer`` of
``cells_with_a_shaped_peer``, with ``peers`` naming the set (the ``sdk`` lane only; the
``sdk_declared`` lane credits none of a declaration by default, which would leave these
peers no force). Every controller's median delivered ratio is under ``controllers``.
``sdk_spring_only_over_half`` counts the cells whose ``spring_only_share`` exceeds 1/2;
``sdk_rise_within_ramp`` the cells whose largest rise is within the ramp step (the force
rises by at most one ramp step a tick; it falls by up to that plus the Colgate spring's
fall as the reading moves out: docs/runtime.md, Passivity item 3, says why).
"""

from __future__ import annotations

import time
from typing import Any, Sequence

import numpy as np

from ..passivity import ControllerSettings, controller_commit_batch, controller_state_batch, controller_step_batch
from ..passivity.batch import _colgate_n_per_m
from ..passivity.settings import DECLARED_DAMPING_TRUST
from ..sim import peers as P
from ..sim.arm import ArmParams
from ..sim.finger import FINGERS, FingerParams
from ..sim.plant import PlantBatch

#: The peers run a second time on the damping the ``sdk`` lane trusts (the hands-off
#: calibration's lower bound, ``trusted_damping_ns_per_m`` of :func:`measure_cell_damping`)
#: instead of the declared damping: lane -> the peer of :data:`hapticsdk.sim.peers.PEERS`
#: it runs. PO/PC takes no damping, so its one run belongs to both sets.
MEASURED_DAMPING_PEERS = {"eb_measured": "eb", "vc_measured": "vc"}
CONTROLLERS = (*P.PEERS, "sdk", "sdk_declared", *MEASURED_DAMPING_PEERS)
#: The SDK controller's lanes: ``sdk`` credits the damping measured hands off on the
#: cell's own arm (:mod:`hapticsdk.calibration.damping`), ``sdk_declared`` only the share
#: ``declared_damping_trust`` of the declared damping (a device never calibrated; none by
#: default).
SDK_LANES = ("sdk", "sdk_declared")
PASSIVE_PEERS = ("popc", "eb", "vc")
#: The passive peers like for like with the ``sdk`` lane: on the damping it trusts
#: (:data:`MEASURED_DAMPING_PEERS`; context next to the goal's comparison, which is against
#: :data:`PASSIVE_PEERS` on the declared damping).
LIKE_FOR_LIKE_PEERS = ("popc", *MEASURED_DAMPING_PEERS)
KINDS = ("press_hold", "tap", "bumpy_slide", "plain_slide", "creep", "knots")
#: Energy to the user a cell may show (J), the issue's bound (0.1 mJ over a run).
ENERGY_BOUND_J = 1.0e-4
#: Relative shortfall of the delivered ratio allowed against the best passive peer.
DELIVERED_SHORTFALL = 0.05
FORCE_LIMIT_N = 3.3
REST_S = 0.3


def _lu(rng: np.random.Generator, lo: float, hi: float, n: int) -> np.ndarray:
    return np.exp(rng.uniform(np.log(lo), np.log(hi), n))


#: Most cells one ``--random`` run draws: a cell's results take 6.1 KiB in memory (the
#: summed ``sys.getsizeof`` of a cell's dicts, keys and values, 30 cells of seed 1; 5.3 KiB
#: before the two lanes on the trusted damping) and 3.4 kB of compact JSON (2000 cells), so
#: 50 000 cells stay within 500 MB (the memory a batch job of the SDK may take, issue 30; the
#: ``--json`` text, about 4.6 kB a cell indented, is written as it is encoded, ``cli.emit``,
#: not held beside the results); at about 75 ms of CPU per cell that is an hour.
MAX_RANDOM_CELLS = 50_000


def draw_cells(n: int, seed: int) -> list[dict[str, Any]]:
    """``n`` cells drawn from the whole space (see the module docstring); ``n`` from 1 to
    :data:`MAX_RANDOM_CELLS`."""
    from ..argcheck import number
    number(n, "random", lo=1, hi=MAX_RANDOM_CELLS, integer=True)
    rng = np.random.default_rng(seed)
    kind = rng.integers(0, 5, n)
    b_true = np.where(rng.random(n) < 0.25, 0.0, _lu(rng, 0.05, 1.0, n))
    cells = []
    cols = {
        "stiffness_n_per_mm": _lu(rng, 0.01, 1e4, n), "period_s": _lu(rng, 0.25e-3, 10e-3, n),
        "resolution_mm": _lu(rng, 0.001, 0.2, n), "arm_mass_kg": _lu(rng, 0.02, 0.1, n),
        "damping_true_ns_per_m": b_true, "damping_declared_ns_per_m": b_true * _lu(rng, 0.5, 2.0, n),
        "finger_mass_kg": _lu(rng, 0.003, 0.05, n), "finger_stiffness_n_per_m": _lu(rng, 50.0, 2000.0, n),
        "finger_damping_ns_per_m": _lu(rng, 0.1, 5.0, n),
        "depth_mm": rng.uniform(0.5, 6.0, n), "speed_in_mm_s": _lu(rng, 5.0, 200.0, n),
        "speed_out_mm_s": _lu(rng, 5.0, 200.0, n), "hold_s": rng.uniform(0.3, 1.2, n),
        "tap_speed_mm_s": _lu(rng, 100.0, 1500.0, n), "taps": rng.integers(2, 7, n).astype(float),
        "tap_dwell_s": rng.uniform(0.0, 0.02, n), "tap_pause_s": rng.uniform(0.05, 0.2, n),
        "bump_mm": rng.uniform(0.3, 1.0, n), "bump_hz": rng.uniform(5.0, 40.0, n),
        "drift_mm": rng.uniform(-1.0, 1.0, n), "creep_mm_s": rng.uniform(1.0, 5.0, n),
    }
    # drawn after the rest, so that a seed's other parameters are those it drew before the
    # mass was declared apart from the truth (0.2.x)
    cols["arm_mass_declared_kg"] = cols["arm_mass_kg"] * _lu(rng, 0.5, 2.0, n)
    for i in range(n):
        c: dict[str, Any] = {k: float(v[i]) for k, v in cols.items()}
        c["trajectory"] = KINDS[int(kind[i])]
        if c["trajectory"] == "creep":
            c["depth_mm"] = min(c["depth_mm"], 1.5)
        cells.append(c)
    return cells


def declared_mass_kg(cell: dict[str, Any]) -> float:
    """The arm's mass a cell declares to the controller (kg): ``arm_mass_declared_kg``, or
    the true ``arm_mass_kg`` in a cell that declares none (the fixed grid, cells drawn
    before 0.2.x)."""
    return float(cell.get("arm_mass_declared_kg", cell["arm_mass_kg"]))


class _Ref:
    """Vectorised finger references of many cells (mm)."""

    def __init__(self, cells: Sequence[dict[str, Any]], knots: Any = None) -> None:
        def g(k: str, d: float = 0.0) -> np.ndarray:
            return np.array([float(c.get(k, d)) for c in cells])
        self.kind = np.array([KINDS.index(c["trajectory"]) for c in cells])
        creep = self.kind == 4
        self.a = np.where(creep, 0.2, 2.0)
        self.d = g("depth_mm", 1.0)
        vin = np.where(creep, g("creep_mm_s", 1.0), g("speed_in_mm_s", 50.0))
        vout = np.where(creep, g("creep_mm_s", 1.0), g("speed_out_mm_s", 50.0))
        self.d2 = self.d + np.where(self.kind == 3, g("drift_mm"), 0.0)
        self.d2 = np.maximum(self.d2, 0.2)
        self.t_in = (self.a + self.d) / vin
        self.f = g("bump_hz", 10.0)
        hold = g("hold_s", 0.5)
        hold = np.where(self.kind == 2, np.maximum(np.round(hold * self.f), 1.0) / self.f, hold)
        self.hold = hold
        self.A = np.where(self.kind == 2, g("bump_mm"), 0.0)
        self.t_out = (self.a + self.d2) / vout
        self.t_h = self.t_in + hold
        # taps
        self.td = (self.a + self.d) / g("tap_speed_mm_s", 500.0)
        self.dw = g("tap_dwell_s")
        self.per = 2 * self.td + self.dw + g("tap_pause_s", 0.1)
        self.n_taps = g("taps", 3.0)
        self.knots = knots
        dur = np.where(self.kind == 1, self.n_taps * self.per, self.t_h + self.t_out) + REST_S
        if knots is not None:
            dur = np.where(self.kind == 5, float(knots.t[-1]), dur)
        self.duration_s = dur

    def __call__(self, t: np.ndarray) -> np.ndarray:
        c = lambda z: np.clip(z, 0.0, 1.0)  # noqa: E731
        a, d = self.a, self.d
        hold_part = np.where((t > self.t_in) & (t < self.t_h), 1.0, 0.0)
        r = (a - (a + d) * c(t / self.t_in) - (self.d2 - d) * c((t - self.t_in) / self.hold)
             + (a + self.d2) * c((t - self.t_h) / self.t_out)
             - self.A * np.sin(2 * np.pi * self.f * (t - self.t_in)) * hold_part)
        u = np.mod(t, self.per)
        k = np.floor(t / self.per)
        with np.errstate(divide="ignore", invalid="ignore"):
            tri = c(np.minimum(u / self.td, (2 * self.td + self.dw - u) / self.td))
        rt = a - (a + d) * tri * (k < self.n_taps)
        r = np.where(self.kind == 1, rt, r)
        if self.knots is not None:
            r = np.where(self.kind == 5, np.interp(t, self.knots.t, self.knots.y), r)
        return r


def measure_cell_damping(cell: dict[str, Any]) -> dict[str, Any]:
    """The hands-off damping calibration on a cell's own arm (its true mass and damping,
    its encoder and period; the excitation sized by the arm's mass as declared,
    :func:`declared_mass_kg`): :func:`hapticsdk.calibration.damping.fit_damping` of the
    simulated readings. Returns the fit as a dict."""
    from ..calibration.damping import fit_damping, simulated_run
    T = float(cell["period_s"])
    f, y = simulated_run(T, cell["arm_mass_kg"], cell["damping_true_ns_per_m"], cell["resolution_mm"], FORCE_LIMIT_N,
                         declared_mass_kg=declared_mass_kg(cell))
    fit = fit_damping(f, y, T, cell["resolution_mm"])
    return {"damping_ns_per_m": fit.damping_ns_per_m, "trusted_damping_ns_per_m": fit.trusted_damping_ns_per_m,
            "worst_error_ns_per_m": fit.worst_error_ns_per_m, "success": fit.success, "message": fit.message,
            "readings": fit.readings}


def run_cells(cells: Sequence[dict[str, Any]], *, knots: Any = None, chunk_lanes: int = 6000,
              settings: ControllerSettings | None = None, controllers: Sequence[str] = CONTROLLERS,
              progress: Any = None) -> list[dict[str, Any]]:
    """Run every cell with every controller; returns one dict per cell (the cell's
    parameters plus ``results[controller]`` with the metrics of the module docstring, and
    ``damping_calibration``, :func:`measure_cell_damping`, where the ``sdk`` lane or a peer
    of :data:`MEASURED_DAMPING_PEERS` runs)."""
    cells = [dict(c) for c in cells]
    if any(k == "sdk" or k in MEASURED_DAMPING_PEERS for k in controllers):
        for c in cells:
            if "damping_calibration" not in c:
                c["damping_calibration"] = measure_cell_damping(c)
    order = np.argsort([c["period_s"] for c in cells], kind="stable")
    nc = len(controllers)
    per_chunk = max(1, chunk_lanes // nc)
    total_ticks = sum(int(np.ceil(_Ref([c], knots).duration_s[0] / c["period_s"])) for c in cells)
    done = 0
    from ..progress import report
    for s0 in range(0, len(cells), per_chunk):
        idx = order[s0:s0 + per_chunk]
        sub = [cells[i] for i in idx]
        res = _run_chunk(sub, knots, settings, controllers)
        for c, r in zip(sub, res):
            c["results"] = r
        done += sum(int(np.ceil(_Ref([c], knots).duration_s[0] / c["period_s"])) for c in sub)
        report(progress, "simulated cell ticks", done, total_ticks)
    return cells


def _run_chunk(cells: Sequence[dict[str, Any]], knots: Any, settings: ControllerSettings | None,
               controllers: Sequence[str]) -> list[dict[str, dict[str, float]]]:
    n = len(cells)
    nc = len(controllers)
    arms = [ArmParams(mass_kg=c["arm_mass_kg"], damping_ns_per_m=c["damping_true_ns_per_m"],
                      max_force_n=FORCE_LIMIT_N, encoder_resolution_mm=c["resolution_mm"]) for c in cells]
    fings = [FingerParams(mass_kg=c["finger_mass_kg"], stiffness_n_per_m=c["finger_stiffness_n_per_m"],
                          damping_ns_per_m=c["finger_damping_ns_per_m"]) for c in cells]
    ref = _Ref(cells, knots)
    rows = np.repeat(np.arange(n), nc)
    kind = np.tile(np.array([CONTROLLERS.index(k) for k in controllers]), n)
    # the peer each lane runs (a measured-damping lane its base peer); the sdk lanes' values are unused
    peer_kind = np.tile(np.array([P.PEERS.index(MEASURED_DAMPING_PEERS[k]) if k in MEASURED_DAMPING_PEERS
                                  else CONTROLLERS.index(k) for k in controllers]), n)
    T = np.array([c["period_s"] for c in cells])[rows]
    K = np.array([c["stiffness_n_per_mm"] for c in cells])[rows]
    bd = np.array([c["damping_declared_ns_per_m"] for c in cells])[rows]
    dur = ref.duration_s[rows]
    y0 = ref(np.zeros(n))
    plant = PlantBatch([c["period_s"] for c in cells], arms, fings, y0, rows=rows)
    L = rows.size
    pst = P.state(L)
    cst = controller_state_batch(L)
    sdk = np.isin(kind, [CONTROLLERS.index(k) for k in SDK_LANES])
    s = settings or ControllerSettings()
    # the damping each sdk lane credits, and the device damping its spring takes half of:
    # sdk, the fit's lower bound and the fit; sdk_declared, the declared share (none by default) and the declaration
    b_tr = np.asarray(s.trusted_damping_ns_per_m(bd), float) * np.ones(rows.size)
    bd_ctrl = bd
    bd_peer = bd   # the damping each peer is sized on: declared, or the sdk lane's trusted bound
    if any(k == "sdk" or k in MEASURED_DAMPING_PEERS for k in controllers):   # run_cells measured it
        meas = np.array([c["damping_calibration"]["trusted_damping_ns_per_m"] for c in cells])[rows]
    if "sdk" in controllers:
        on_sdk = kind == CONTROLLERS.index("sdk")
        fit = np.array([c["damping_calibration"]["damping_ns_per_m"] for c in cells])[rows]
        b_tr = np.where(on_sdk, meas, b_tr)
        bd_ctrl = np.where(on_sdk, np.nan_to_num(fit), bd)
    if any(k in MEASURED_DAMPING_PEERS for k in controllers):
        on_meas = np.isin(kind, [CONTROLLERS.index(k) for k in MEASURED_DAMPING_PEERS])
        bd_peer = np.where(on_meas, meas, bd)
    m_decl = np.array([declared_mass_kg(c) for c in cells])[rows]   # what the controller is told
    lane_ref = _Ref([cells[int(i)] for i in rows], knots)
    n_ticks = np.ceil(dur / T).astype(int)
    e_max = np.zeros(L)
    given = np.zeros(L)
    asked = np.zeros(L)
    rmax = np.zeros(L)      # largest rise of the applied force between two ticks
    fmax_fall = np.zeros(L)   # largest fall
    dspring = np.zeros(L)   # sdk: largest step beyond the Colgate spring (K_c |dq|)
    dspring_held = np.zeros(L)   # the same over the ticks the controller did not fall below its ramp
    below = np.zeros(L, int)     # sdk: ticks the extra fell below its ramp (the book overdrawn)
    x_last = None
    fneg = np.zeros(L)
    contact = np.zeros(L, int)
    f_last = np.zeros(L)
    unsound = np.full(L, -np.inf)
    spring_only = np.zeros(L, int)   # sdk: contact ticks with the spring alone sent, below the wall's force
    r_now = lane_ref(np.zeros(L))
    step_n = np.minimum(T / s.ramp_time_s, 1.0) * plant.fmax   # the controller's ramp step (N per tick)
    kc = _colgate_n_per_m(s.spring_damping_ns_per_m(bd_ctrl, b_tr), T, step_n, plant.res_mm * 1e-3)  # its spring
    for k in range(int(n_ticks.max())):
        live = k < n_ticks
        t1 = (k + 1) * T
        r_next = lane_ref(t1)
        x = plant.measured_mm()
        pen = -x
        touching = pen > 0
        fw = np.where(touching, K * pen, 0.0)
        f_peer = P.step(peer_kind, pst, x, T, fw, K, pen, bd_peer)
        f_sdk = controller_step_batch(cst, x, T, fw, True, s, damping_ns_per_m=bd_ctrl, resolution_mm=plant.res_mm,
                                      max_force_n=plant.fmax, mass_kg=m_decl, trusted_damping_ns_per_m=b_tr)
        f_cmd = np.where(sdk, f_sdk, f_peer)
        dropped = cst["below_ramp"] & sdk & live
        below += dropped
        tgt = np.minimum(fw, plant.fmax)   # the wall's force the device can give
        # the extra held at 0 (the output is the Colgate spring) while the wall asks for more
        spr = cst["spring"]
        held_back = (f_sdk <= spr) & (tgt > spr)
        # soundness of the controller's bound: the true energy so far (plant) never exceeds
        # U plus the reading's error times the held force (the bound's open tail)
        gap = plant.energy_to_user_j() - cst["energy"] - 0.5 * plant.res_mm * 1e-3 * np.abs(cst["f1"])
        unsound = np.maximum(unsound, np.where(sdk & live, gap, -np.inf))
        f = plant.step(f_cmd, r_now, (r_next - r_now) / T, live)
        f = np.where(live, f, f_last)
        P.commit(pst, f)
        controller_commit_batch(cst, f)
        tl = touching & live
        given += np.where(tl, np.minimum(np.maximum(f, 0.0), tgt), 0.0)
        asked += np.where(tl, tgt, 0.0)
        contact += tl
        spring_only += tl & sdk & held_back
        fneg = np.minimum(fneg, np.where(tl, f, 0.0))
        rmax = np.maximum(rmax, np.where(live, f - f_last, 0.0))
        fmax_fall = np.maximum(fmax_fall, np.where(live, f_last - f, 0.0))
        if x_last is not None:
            beyond = np.abs(f - f_last) - kc * np.abs(x - x_last) * 1e-3
            dspring = np.maximum(dspring, np.where(live & sdk, beyond, 0.0))
            dspring_held = np.maximum(dspring_held, np.where(live & sdk & ~dropped, beyond, 0.0))
        x_last = x
        f_last = f
        e_max = np.maximum(e_max, plant.energy_to_user_j())
        r_now = r_next
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(asked > 0, given / np.where(asked > 0, asked, 1.0), np.nan)
    step = step_n
    out: list[dict[str, dict[str, float]]] = []
    for i in range(n):
        d = {}
        for j, name in enumerate(controllers):
            ln = i * nc + j
            d[name] = {"energy_to_user_j": float(e_max[ln]), "delivered_ratio": float(ratio[ln]),
                       "max_force_step_n": float(max(rmax[ln], fmax_fall[ln])), "max_force_rise_n": float(rmax[ln]),
                       "max_force_fall_n": float(fmax_fall[ln]), "min_contact_force_n": float(fneg[ln]),
                       "contact_ticks": int(contact[ln])}
            if name in SDK_LANES:
                d[name]["ramp_step_n"] = float(step[ln])
                d[name]["max_step_beyond_spring_n"] = float(dspring[ln])
                d[name]["max_step_beyond_spring_where_ramp_kept_n"] = float(dspring_held[ln])
                d[name]["below_ramp_ticks"] = int(below[ln])
                d[name]["bound_shortfall_j"] = float(unsound[ln])
                d[name]["spring_only_share"] = float(spring_only[ln] / contact[ln]) if contact[ln] else 0.0
        out.append(d)
    return out


def _within_ramp(step_n: float, ramp_step_n: float) -> bool:
    """A force step (N) within a ramp step, up to float rounding of the two."""
    return step_n <= ramp_step_n * (1 + 1e-9) + 1e-12


def _peer_ratios(r: dict[str, Any], ramp_step_n: float,
                 peers: Sequence[str] = PASSIVE_PEERS) -> tuple[list[float], list[float]]:
    """Delivered ratios of the passive peers ``peers`` (:data:`PASSIVE_PEERS` by default)
    that stayed within the energy bound in one cell, and of those of them that also kept the
    force-shape goals the SDK controller is held to: never pulled (``min_contact_force_n >=
    0``, the SDK's ``no_pull``) and no step beyond the SDK controller's ramp step
    ``ramp_step_n`` in that cell (``max_force_step_n`` within it, the SDK's ``step_ok``)."""
    passive: list[float] = []
    shaped: list[float] = []
    for p in peers:
        q = r.get(p)
        if q is None or not q["energy_to_user_j"] <= ENERGY_BOUND_J or q["delivered_ratio"] != q["delivered_ratio"]:
            continue
        passive.append(q["delivered_ratio"])
        if q["min_contact_force_n"] >= 0.0 and _within_ramp(q["max_force_step_n"], ramp_step_n):
            shaped.append(q["delivered_ratio"])
    return passive, shaped


def _at_least(mine: float, best: list[float]) -> bool | None:
    """The delivered goal against the best of ``best``: None when there is no peer to compare
    with (a cell with no such peer counts neither way)."""
    if not best:
        return None
    return mine == mine and mine >= (1.0 - DELIVERED_SHORTFALL) * max(best)


def cell_verdicts(cell: dict[str, Any], lane: str = "sdk") -> dict[str, Any]:
    """The SDK controller's goals in one cell (its lane ``lane``, :data:`SDK_LANES`):
    energy, no pull, step within its ramp, delivered ratio against the best peer that stayed
    within the energy bound (``delivered_ok``; None when no peer did) and against the best
    such peer that also kept the force-shape goals (``delivered_ok_shaped``; None when none
    did). For the ``sdk`` lane in a cell with a peer of :data:`MEASURED_DAMPING_PEERS`, the
    same two against :data:`LIKE_FOR_LIKE_PEERS` (``delivered_ok_like_for_like``,
    ``delivered_ok_like_for_like_shaped``)."""
    r = cell["results"]
    me = r[lane]
    best, shaped = _peer_ratios(r, me["ramp_step_n"])
    mine = me["delivered_ratio"]
    out = {"energy_ok": me["energy_to_user_j"] <= ENERGY_BOUND_J, "no_pull": me["min_contact_force_n"] >= 0.0,
            "step_ok": _within_ramp(me["max_force_step_n"], me["ramp_step_n"]),
            "rise_ok": _within_ramp(me.get("max_force_rise_n", me["max_force_step_n"]), me["ramp_step_n"]),
            "step_ok_plus_spring": _within_ramp(me.get("max_step_beyond_spring_n", me["max_force_step_n"]),
                                                me["ramp_step_n"]),
            "step_ok_plus_spring_where_ramp_kept": _within_ramp(
                me.get("max_step_beyond_spring_where_ramp_kept_n", me.get("max_step_beyond_spring_n", me["max_force_step_n"])),
                me["ramp_step_n"]),
            "fell_below_ramp": me.get("below_ramp_ticks", 0) > 0,
            "delivered_ok": _at_least(mine, best), "best_passive_peer_ratio": max(best) if best else float("nan"),
            "delivered_ok_shaped": _at_least(mine, shaped),
            "best_shaped_peer_ratio": max(shaped) if shaped else float("nan")}
    if lane == "sdk" and any(p in r for p in MEASURED_DAMPING_PEERS):
        # context: the same two comparisons against the peers on the damping this lane trusts
        best_m, shaped_m = _peer_ratios(r, me["ramp_step_n"], LIKE_FOR_LIKE_PEERS)
        out.update({"delivered_ok_like_for_like": _at_least(mine, best_m),
                    "best_like_for_like_peer_ratio": max(best_m) if best_m else float("nan"),
                    "delivered_ok_like_for_like_shaped": _at_least(mine, shaped_m),
                    "best_like_for_like_shaped_peer_ratio": max(shaped_m) if shaped_m else float("nan")})
    return out


def _delivered_counts(v: Sequence[dict[str, Any]], key: str) -> dict[str, int]:
    """Cells at the best passive peer's force and at the best shaped peer's, each of the cells
    that have such a peer, from the verdicts ``key`` and ``key + "_shaped"`` of
    :func:`cell_verdicts` (None: no such peer in that cell)."""
    return {"sdk_delivered_vs_best_passive_peer": sum(x.get(key) is True for x in v),
            "cells_with_a_passive_peer": sum(x.get(key) is not None for x in v),
            "sdk_delivered_vs_best_shaped_peer": sum(x.get(key + "_shaped") is True for x in v),
            "cells_with_a_shaped_peer": sum(x.get(key + "_shaped") is not None for x in v)}


def _goal_counts(cells: Sequence[dict[str, Any]], lane: str) -> dict[str, Any]:
    v = [cell_verdicts(c, lane) for c in cells]
    return {"sdk_energy_within_bound": sum(x["energy_ok"] for x in v),
            "sdk_no_pull": sum(x["no_pull"] for x in v),
            "sdk_step_within_ramp": sum(x["step_ok"] for x in v),
            "sdk_step_within_ramp_plus_spring": sum(x["step_ok_plus_spring"] for x in v),
            "sdk_step_within_ramp_plus_spring_where_ramp_kept": sum(x["step_ok_plus_spring_where_ramp_kept"] for x in v),
            "sdk_cells_below_ramp": sum(x["fell_below_ramp"] for x in v),
            "sdk_rise_within_ramp": sum(x["rise_ok"] for x in v),
            **_delivered_counts(v, "delivered_ok"),
            "sdk_spring_only_over_half": sum(c["results"][lane].get("spring_only_share", 0.0) > 0.5 for c in cells),
            **({"peers_on_trusted_damping": {"peers": list(LIKE_FOR_LIKE_PEERS),
                                             **_delivered_counts(v, "delivered_ok_like_for_like")}}
               if any("delivered_ok_like_for_like" in x for x in v) else {})}


def _damping_summary(cells: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """How the hands-off calibration's bound compares with the cells' true damping."""
    cal = [(c["damping_calibration"], c["damping_true_ns_per_m"], c["damping_declared_ns_per_m"])
           for c in cells if "damping_calibration" in c]
    pos = [(d["trusted_damping_ns_per_m"] / b, t / b) for d, b, t in cal if b > 0]
    declared_over_true = float(np.median([p[1] for p in pos])) if pos else float("nan")
    return {"cells_calibrated": len(cal),
            "cells_trusted_above_true": sum(d["trusted_damping_ns_per_m"] > b for d, b, _ in cal),
            "calibrations_failed": sum(not d["success"] for d, _, _ in cal),
            "median_trusted_over_true": float(np.median([p[0] for p in pos])) if pos else float("nan"),
            "median_declared_over_true": declared_over_true,
            "median_declared_share_over_true": declared_over_true * DECLARED_DAMPING_TRUST}


def summarise(cells: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Goal counts for the SDK controller (the ``sdk`` lane at the top level, the
    ``sdk_declared`` lane under ``declared_damping``), the calibration's bound against the
    true damping (``damping_calibration``) and per-controller medians and worst figures."""
    n = len(cells)
    per: dict[str, Any] = {}
    names = list(cells[0]["results"]) if cells else []
    for name in names:
        e = np.array([c["results"][name]["energy_to_user_j"] for c in cells])
        d = np.array([c["results"][name]["delivered_ratio"] for c in cells])
        st = np.array([c["results"][name]["max_force_step_n"] for c in cells])
        mn = np.array([c["results"][name]["min_contact_force_n"] for c in cells])
        per[name] = {"cells_energy_within_bound": int((e <= ENERGY_BOUND_J).sum()),
                     "max_energy_to_user_j": float(e.max()), "median_energy_to_user_j": float(np.median(e)),
                     "median_delivered_ratio": float(np.nanmedian(d)) if np.isfinite(d).any() else float("nan"),
                     "max_force_step_n": float(st.max()), "most_negative_contact_force_n": float(mn.min())}
    out: dict[str, Any] = {"cells": n, "energy_bound_j": ENERGY_BOUND_J,
                           "delivered_shortfall_allowed": DELIVERED_SHORTFALL}
    lane = "sdk" if "sdk" in names else ("sdk_declared" if "sdk_declared" in names else None)
    if lane:
        out.update(_goal_counts(cells, lane))
        out["sdk_lane"] = lane
    if lane == "sdk" and "sdk_declared" in names:
        out["declared_damping"] = _goal_counts(cells, "sdk_declared")
    if any("damping_calibration" in c for c in cells):
        out["damping_calibration"] = _damping_summary(cells)
    out["controllers"] = per
    return out


def run_random(n: int, seed: int, *, progress: Any = None, settings: ControllerSettings | None = None
               ) -> dict[str, Any]:
    """Draw ``n`` cells with ``seed`` and run them (see the module docstring)."""
    t0 = time.perf_counter()
    cells = run_cells(draw_cells(n, seed), settings=settings, progress=progress)
    return {"mode": "random", "seed": int(seed), "cells": cells, "summary": summarise(cells),
            "runtime_s": time.perf_counter() - t0}


def grid_cells(grid: dict[str, Any]) -> list[dict[str, Any]]:
    """The fixed grid (keys as :data:`hapticsdk.benchmarks.stability.DEFAULT_GRID`) as cells on
    the simulated Omni (45 g, 0.055 mm, declared damping = true damping) with the grid's
    press/slide/tap trajectory."""
    out = []
    for K in grid["stiffness_n_per_mm"]:
        for T in grid["period_s"]:
            for b in grid["damping_ns_per_m"]:
                for fn in grid["finger"]:
                    f: FingerParams = FINGERS[fn]
                    out.append({"trajectory": "knots", "stiffness_n_per_mm": float(K), "period_s": float(T),
                                "resolution_mm": 0.055, "arm_mass_kg": 0.045, "damping_true_ns_per_m": float(b),
                                "damping_declared_ns_per_m": float(b), "finger": fn, "finger_mass_kg": f.mass_kg,
                                "finger_stiffness_n_per_m": f.stiffness_n_per_m,
                                "finger_damping_ns_per_m": f.damping_ns_per_m})
    return out


def run_grid(grid: dict[str, Any], *, progress: Any = None, settings: ControllerSettings | None = None
             ) -> dict[str, Any]:
    """The fixed grid through the same simulation and peers (regression set)."""
    from .stability import matrix_trajectory
    t0 = time.perf_counter()
    tr = matrix_trajectory(float(grid["duration_s"]))

    cells = run_cells(grid_cells(grid), knots=tr, settings=settings, progress=progress)
    return {"mode": "grid", "cells": cells, "summary": summarise(cells), "runtime_s": time.perf_counter() - t0}
