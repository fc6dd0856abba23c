"""Issue 23: a turn of the force on a device that renders one axis (the simulated Omni,
``force_axes = (1,)``; docs/runtime.md, Passivity, "A turn on a device that renders one
axis").

The loop's reading on such a device is the held force's work per newton,
``x_k = x_(k-1) + sum_(i in axes) n_i dp_i`` (``n`` the direction held, ``dp`` the
stylus's motion relative to the object): the book is exact at any turn. What a turn
misleads is the plan, which predicts the next interval's change from the last readings,
read along the old direction; a stylus past a box's middle turns the nearest face from the
top to the bottom and the force from +y to -y, so a motion in reads as a motion out. At a
turn (the direction's part on the rendered axes changes) the history is re-read along the
new direction, ``q_(k-j) = x_k - sum_(i in axes) n_new_i (p_k - p_(k-j))_i``, and the last
interval is booked from the last reading as it was. Where the object moved over that
interval, the frame takes its move at the mean of the force vectors held before and after
it, the book at the held direction: the difference, ``F_k (n_held - n_new) . dw / 2``, is
booked on the commit (``turned_mm``) and priced in the plan.

The positions and readings of the unit tests are multiples of 1/8 mm and the normals unit
axes or (3/5, 4/5) pairs, so the expectations are exact in binary floating point where
they are compared exactly.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from hapticsdk.passivity import ControllerSettings, PassivityController
from hapticsdk.passivity.plan import _HIST
from hapticsdk.runtime.turns import NormalTurns
from moving_slabs import moving_slab

ENERGY_J = 1e-4          # the bound on the energy to the user
UP = (0.0, 1.0, 0.0)     # a top face's normal
DOWN = (0.0, -1.0, 0.0)  # a bottom face's


class _Rec:
    """Records what a controller is asked to re-read, and from which reading it books."""

    def __init__(self) -> None:
        self.calls: list[tuple[list[float], float | None]] = []

    def rebase(self, readings_mm: list[float], booked_mm: float | None = None) -> None:
        self.calls.append((list(readings_mm), booked_mm))


def _pressing(t: NormalTurns, pc: _Rec, ticks: int) -> tuple[list[tuple[float, float, float]], float]:
    """``ticks`` ticks in contact with a top face, moving down 0.25 mm and sideways (+x,
    +z) 0.125 mm a tick, the force held and seen along +y: the one-axis reading moves by
    dp_y (-0.25) a tick, and there is no turn. Returns the positions and the last reading."""
    ps = []
    x = 0.0
    for i in range(ticks):
        p = (0.125 * i, -0.5 - 0.25 * i, 0.125 * i)
        last = x
        x = -0.5 - 0.25 * i
        assert t.reading([pc], x, last, True, True, p, None if i % 2 else UP, UP, 1.0) == x
        ps.append(p)
    assert pc.calls == []
    return ps, x


def test_a_flip_re_reads_the_history_along_the_new_direction_and_books_from_the_last_reading() -> None:
    t, pc = NormalTurns((1,)), _Rec()
    ps, last_x = _pressing(t, pc, 5)          # p_k = (0.5, -1.5, 0.5), last_x = -1.5
    p = (0.625, -1.75, 0.625)
    x = last_x + 1.0 * (p[1] - ps[-1][1])     # the loop's reading: the held +y force's work, -1.75
    assert t.reading([pc], x, last_x, True, True, p, DOWN, UP, 1.0) == x   # the reading itself unchanged
    # along -y the stylus's descent reads as a motion out: q_(k-j) = x - (-1)(p_(k+1) - p_(k-j))_y,
    # q1 = -1.75 - 0.25 = -2.0, then 0.25 lower per tick back over the 5 positions known,
    # the oldest repeated; the x and z motion (not rendered) plays no part; booked from last_x
    want = [-2.0, -2.25, -2.5, -2.75, -3.0] + [-3.0] * (_HIST - 5)
    assert pc.calls == [(want, last_x)]


def test_a_change_off_the_rendered_axes_is_no_turn() -> None:
    t, pc = NormalTurns((1,)), _Rec()
    ps, last_x = _pressing(t, pc, 3)
    # the normal turns from (0, 0.8, 0.6) to (0.6, 0.8, 0): the part along y, the force as
    # the device renders it, is the same
    p = (0.375, -1.25, 0.375)
    assert t.reading([pc], -1.25, last_x, True, True, p, (0.6, 0.8, 0.0), (0.0, 0.8, 0.6), 1.0) == -1.25
    assert pc.calls == []
    # a change of the y part is a turn: re-read along (0, 0.6, 0.8) on y alone (the descent
    # a motion in along it, so the older readings are higher by 0.6 x 0.25 mm a tick, back
    # over the 4 positions known)
    p2 = (0.5, -1.5, 0.5)
    t.reading([pc], -1.25 + 0.8 * -0.25, -1.25, True, True, p2, (0.0, 0.6, 0.8), (0.6, 0.8, 0.0), 1.0)
    (back, booked), = pc.calls
    q1 = (-1.25 + 0.8 * -0.25) - 0.6 * -0.25
    assert booked == -1.25
    assert back == pytest.approx([q1 + 0.6 * 0.25 * j for j in range(4)] + [q1 + 0.6 * 0.75] * (_HIST - 4), abs=1e-12)


def test_out_of_contact_the_one_axis_reading_is_the_loop_s() -> None:
    """Out of contact the loop holds the one-axis reading and books the held force at the
    re-entry (docs/runtime.md, "A force rendered along one axis"): no booking here (the
    three-axis path books it along the held normal)."""
    t, pc = NormalTurns((1,)), _Rec()
    _pressing(t, pc, 3)
    assert t.reading([pc], -1.0, -0.125, False, False, (0.5, 1.0, 0.5), None, DOWN, 0.5) == -1.0
    assert pc.calls == []


def _stepped(readings: list[float], f: float = 0.0) -> PassivityController:
    pc = PassivityController()
    for x in readings:
        pc.step(x, 1e-3, f)
    return pc


def test_rebase_with_the_reading_booked_from_keeps_the_book_and_re_reads_the_plan() -> None:
    """The same readings, one controller re-read with the reading booked from the last one
    (the one-axis turn) and one not re-read at all: the same book after the next step (the
    held force's work per newton is the reading's change either way); a re-read that books
    from the re-read reading (the three-axis turn) books ``f1 (q_last - q1)`` more."""
    rs = [-0.125 * i for i in range(12)]        # pressing in 0.125 mm a tick against 1 N
    a, b, c = _stepped(rs, 1.0), _stepped(rs, 1.0), _stepped(rs, 1.0)
    back = [rs[-1] - 0.125 - 0.125 * j for j in range(4)]   # re-read the other way round
    a.rebase(back, rs[-1])
    c.rebase(back)
    assert a._q1 == rs[-1] and a._q2 == back[1]
    assert [a._hist[a._hp - j] for j in range(4)] == back
    f1 = a._f1
    x = rs[-1] - 0.125
    a.step(x, 1e-3, 1.0), b.step(x, 1e-3, 1.0), c.step(x, 1e-3, 1.0)
    assert a.energy_j == b.energy_j
    assert c.energy_j - b.energy_j == pytest.approx(f1 * (rs[-1] - back[0]) * 1e-3, rel=1e-12)
    # and the re-read reaches the plan: the reading before this one is back[0], not rs[-1]
    assert a._q2 == back[0] and b._q2 == rs[-1]


def test_a_turn_s_part_of_the_move_is_booked_at_half_the_force_applied() -> None:
    """``turned_mm`` with ``own_mm``: the commit books ``F_applied turned / 2`` (J, mm ->
    m), whatever else the step booked; without ``own_mm`` (a still object) nothing."""
    pc = _stepped([0.0, -0.125, -0.25, -0.375], 1.0)
    pc.step(-0.5, 1e-3, 1.0, 0.25, 0.5)
    u = pc.energy_j
    pc.commit(0.75)
    assert pc.energy_j - u == 0.5 * 0.75 * 0.5e-3
    u = pc.energy_j
    pc.step(-0.625, 1e-3, 1.0)
    pc.commit(0.75)
    pc2 = _stepped([0.0, -0.125, -0.25, -0.375], 1.0)
    pc2.step(-0.5, 1e-3, 1.0, None, 0.5)   # type: ignore[arg-type]
    u2 = pc2.energy_j
    pc2.commit(0.75)
    assert pc2.energy_j == u2


def test_the_traced_box_rising_past_a_stylus_held_beyond_its_middle() -> None:
    """``bench/bench_servo_paths.py moving --cells 150 --seed 7``, cell 104 (1 ms, a 1 N/mm
    wall, the soft finger, the damping measured at 0 on an undamped arm, so the extra is
    the whole force; a box 20 mm tall moving 2.2 mm at 18.8 Hz): the probe ends past the
    box's middle and the force turns from +y to -y against a motion out. 0.188 mJ in the
    wall's frame before the turn's rules (the re-read, the move's part); within the bound after."""
    _, frame, turned = moving_slab(1.006775429118776, 1e-3, 0.0, "soft", 0.8080512529861584, (20.0, 10.0, 10.0),
                                   2.212224762607754, 18.811594970429883, 0.219693956273916,
                                   press_s=0.23662829777348743, hold_s=0.2200193646942372,
                                   release_s=0.37872091387615436)
    assert turned
    assert frame <= ENERGY_J, frame


@settings(max_examples=10, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(k=st.floats(0.3, 50.0), period_s=st.sampled_from([5e-4, 1e-3]),
       finger=st.sampled_from(["soft", "medium", "stiff"]), depth=st.floats(0.3, 3.0), half_mm=st.floats(0.2, 1.5),
       amp=st.floats(0.2, 3.0), hz=st.floats(1.0, 20.0), t_move=st.floats(0.05, 0.3))
@example(k=25.744434726555195, period_s=2e-3, finger="soft", depth=2.3993420238844827, half_mm=0.9840925950670305,
         amp=2.2050089628899827, hz=18.392222289319644, t_move=0.2650984122957212)
@example(k=2.4343601772080006, period_s=1e-3, finger="medium", depth=1.6323806961760032,
         half_mm=0.7887818396248507, amp=1.7624760948727012, hz=18.12908806725127, t_move=0.05447622967072553)
def test_a_plate_moving_past_a_held_stylus_stays_within_the_bound_in_its_frame(k, period_s, finger, depth, half_mm,
                                                                                amp, hz, t_move) -> None:
    """A plate of half-thickness 0.2-1.5 mm moving 0.2-3 mm at 1-20 Hz about a stylus
    pressed 0.3-3 mm (past its middle, the force turns between +y and -y, both ways, as the
    plate passes), nothing credited (the extra is the whole force, the plan alone keeps the
    book): in the wall's frame at most the issue's bound. The two examples are drawn cells
    (a script, seed 9, cells 0 and 41) that gave 0.365 and 0.240 mJ before the turn's rules.

    Periods of 0.5 and 1 ms are drawn; at 2 ms a thin plate oscillating through the stylus
    many times is open (the test below), and only the two examples run there."""
    _, frame, _ = moving_slab(k, period_s, None, finger, depth, (20.0, half_mm, 20.0), amp, hz, t_move)
    assert frame <= ENERGY_J, frame


@pytest.mark.xfail(strict=True, reason="open: a thin plate oscillating through a held stylus at 2 ms "
                   "(docs/runtime.md, Passivity, 'A turn on a device that renders one axis', left open)")
def test_open_a_thin_plate_oscillating_through_a_held_stylus_at_2_ms() -> None:
    """Found by hypothesis (the floors' version drew it): a plate 0.5 mm thick moving 2 mm
    at 20 Hz through a stylus pressed 0.5 mm, 2 ms, nothing credited. Each pass is a contact
    of one or two ticks in which the plate moves about as far as it is thick; the wall's
    frame books each move at the mean of the forces before and after it, and the
    controller's book falls behind that by about 10 uJ a pass: 0.118 mJ after nine passes
    (0.375 mJ before the turn's rules). Strict: the day it holds, this fails and is moved
    into the property above."""
    _, frame, _ = moving_slab(1.0, 2e-3, None, "stiff", 0.5, (20.0, 0.25, 20.0), 2.0, 20.0, 0.050003051757812576)
    assert frame <= ENERGY_J, frame


@settings(max_examples=8, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(k=st.floats(0.3, 50.0), period_s=st.sampled_from([5e-4, 1e-3, 2e-3]),
       finger=st.sampled_from(["soft", "medium", "stiff"]), depth=st.floats(0.3, 3.0), half_mm=st.floats(0.2, 1.5),
       press_s=st.floats(0.005, 0.2), release_s=st.floats(0.005, 0.2))
@example(k=1.828287751349705, period_s=2e-3, finger="medium", depth=2.4659472462019054, half_mm=0.5058916011678547,
         press_s=0.1225999764837453, release_s=0.008039901389635782)
def test_a_pop_through_a_still_plate_stays_within_the_bound(k, period_s, finger, depth, half_mm, press_s,
                                                            release_s) -> None:
    """A press of 0.3-3 mm into a still plate of half-thickness 0.2-1.5 mm, in and out in
    5-200 ms (up to 0.6 m/s), nothing credited: past the middle the force turns to -y, and
    back to +y on the way out. The example is a drawn cell (a script, seed 11, cell 4: 2 ms,
    a fast release) that gave 0.124 mJ with the plan's history read along the old
    direction; the re-read alone is what this test exercises (nothing moves)."""
    _, frame, _ = moving_slab(k, period_s, None, finger, depth, (20.0, half_mm, 20.0), 0.0, 1.0, math.inf,
                              press_s=press_s, hold_s=0.1, release_s=release_s)
    assert frame <= ENERGY_J, frame


def test_a_turn_s_part_of_the_move_is_priced_in_the_plan() -> None:
    """A force held on a still reading inside the wall (nothing credited, so the extra is
    the whole force; as far as the book affords the ramp up). With no turn the plan holds
    it. A turn whose part of the move is ``tw`` = 1 mm costs at least ``a tw / 2`` on the
    tick the force ``a`` is held (the plan's other terms are >= 0 here: no motion, no
    credit), so the plan sends at most ``2 (E0 - U) / tw``, ``E0`` at most ``F_max Delta / 2``
    from the Omni's declaration, or where that is below the ramp, the ramp's lower end (the
    extra falls by one ramp step ``s = F_max T / 5 ms`` a tick while the book is not
    overdrawn, docs/runtime.md, Passivity item 3)."""
    from hapticsdk_hardness.omni import OmniVirtual

    dev = OmniVirtual()
    f_max = dev.limits.max_force_n
    assert f_max is not None
    e0 = f_max * dev.encoder_resolution_mm * 1e-3 / 2.0
    st_ = ControllerSettings.for_device(dev)
    plain, turning = PassivityController(st_), PassivityController(st_)
    for pc in (plain, turning):
        for _ in range(200):
            pc.commit(pc.step(-1.0, 1e-3, 3.0))
    held = plain._sent
    assert held == turning._sent and held > 0.0
    # (held to the rounding of the plan's root: 1e-9 of it is far below any force a device resolves)
    assert plain.step(-1.0, 1e-3, 3.0, 0.0, 0.0) == pytest.approx(held, rel=1e-9)
    a = turning.step(-1.0, 1e-3, 3.0, 0.0, 1.0)
    bound = 2.0 * (e0 - turning.energy_j) / 1e-3
    ramp_end = held - f_max * 1e-3 / 5e-3
    assert bound < held
    assert a <= max(bound, ramp_end) * (1.0 + 1e-9), (a, bound, ramp_end, held)


def test_the_spring_s_share_of_a_turn_s_move_is_priced_against_the_budget() -> None:
    """Damping measured (0.5 N s/m on the simulated Omni), so the Colgate spring carries a
    wall weaker than it: the force is the spring alone, never withheld by the plan. A turn
    whose part of the move is ``tw`` = 4 mm books half the force applied times ``tw`` on
    the commit; the spring at the turn is at most what the budget left affords, ``2 (E0 -
    U) / tw`` (``U`` as booked on the step), so after the commit the book is within ``E0 =
    F_max Delta / 2`` from the Omni's declaration. Without the turn the spring is held as it
    was (nothing withheld)."""
    from hapticsdk_hardness.omni import OmniVirtual

    from omni_fits import measured

    dev = OmniVirtual(damping_ns_per_m=0.5)
    f_max = dev.limits.max_force_n
    assert f_max is not None
    e0 = f_max * dev.encoder_resolution_mm * 1e-3 / 2.0
    st_ = ControllerSettings.for_device(dev, damping=measured(0.5))
    plain, turning = PassivityController(st_), PassivityController(st_)
    wall = 0.5   # N: below the spring's K_c times the depth reached
    for pc in (plain, turning):
        for i in range(1, 201):
            pc.commit(pc.step(-3.0 * min(i, 100) / 100, 2e-3, wall))
    held = plain._sent
    assert held == turning._sent == wall == plain._spring   # the spring alone carries the wall
    assert plain.step(-3.0, 2e-3, wall, 0.0, 0.0) == held
    out = turning.step(-3.0, 2e-3, wall, 0.0, 4.0)
    bound = 2.0 * (e0 - turning.energy_j) / 4e-3
    assert bound < held
    # (to the rounding of the cap's own arithmetic)
    assert out <= bound * (1.0 + 1e-9) + 1e-12, (out, bound, held)
    turning.commit(out)
    assert turning.energy_j <= e0 * (1.0 + 1e-9), (turning.energy_j, e0)


def test_a_plate_moving_through_a_held_stylus_with_the_damping_credited() -> None:
    """A drawn cell of the family "plate moving past a held stylus, damping as in the bench"
    (a script, seed 5, cell 0: 2 ms, a 31 N/mm wall, the medium finger, 0.23 N s/m measured,
    a plate 2.9 mm thick moving 2.3 mm at 18.5 Hz): the Colgate spring carries the force and
    flips with the plate, 0.181 mJ in the wall's frame before the spring's share of a turn's
    move was priced; within the bound after."""
    _, frame, turned = moving_slab(31.258214236018187, 2e-3, 0.23281132718905267, "medium", 2.4470226270273807,
                                   (20.0, 1.4251853689101655, 20.0), 2.271716009271806, 18.524174936642922,
                                   0.05725130707090369)
    assert turned
    assert frame <= ENERGY_J, frame
