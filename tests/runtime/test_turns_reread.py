"""Issue 23: the re-read of the stiff-wall controller's history at a turn of the contact
normal (:class:`hapticsdk.runtime.turns.NormalTurns`, :meth:`PassivityController.rebase`;
docs/runtime.md, Passivity, "A normal that turns"), against expectations worked by hand
from the derivation.

At a turn on tick ``k+1`` (the normal seen, ``n_new``, not the one held over the last
interval), with the measured positions ``p_(k-j)`` of the ticks since the contact began
(``p_k`` the last one) and the readings ``last_x`` (tick ``k``) and ``x`` (this tick):

* ``q1 = min(last_x, x - n_new . (p_(k+1) - p_k))``, the last reading re-read;
* ``q_(k-j) = q1 - n_new . (p_k - p_(k-j))`` for the positions known, older ones as the
  oldest known (the ring is ``_HIST`` long);
* no position known (a new object, or the tick after one without a reading): nothing to
  re-read, the ring starts afresh.

Out of contact with a force held, the reading moves by the held normal's part of the
displacement, ``x = last_x + n_held . dp``.

The positions and readings are multiples of 1/8 mm and the normals unit axes, so every
sum is exact in binary floating point: the expectations are compared exactly.
"""

from __future__ import annotations

from hapticsdk.passivity.controller import PassivityController
from hapticsdk.passivity.plan import _HIST
from hapticsdk.runtime.turns import NormalTurns

UP = (0.0, 1.0, 0.0)       # the top face's normal
FRONT = (0.0, 0.0, 1.0)    # the front face's
SIDE = (1.0, 0.0, 0.0)     # the side face's


class _Rec:
    """Records what a controller is asked to re-read."""

    def __init__(self) -> None:
        self.calls: list[list[float]] = []

    def rebase(self, readings_mm: list[float]) -> None:
        self.calls.append(list(readings_mm))


def _pressing(t: NormalTurns, pc: _Rec, ticks: int) -> tuple[list[tuple[float, float, float]], float]:
    """``ticks`` ticks in contact with the top face, moving in (down) and forward (+z), the
    normal held and seen +y: no turn. Returns the positions and the last reading."""
    ps = []
    x = 0.0
    for i in range(ticks):
        p = (1.0, -0.5 - 0.25 * i, 9.0 + 0.125 * i)
        last = x
        x = p[1]     # -pen under the top face y = 0
        assert t.reading([pc], x, last, True, True, p, UP, UP, 1.0) == x
        ps.append(p)
    assert pc.calls == []
    return ps, x


def test_a_turn_re_reads_the_history_along_the_new_normal_from_the_last_reading() -> None:
    t, pc = NormalTurns(), _Rec()
    ps, last_x = _pressing(t, pc, 5)            # p_k = ps[4] = (1, -1.5, 9.5), last_x = -1.5
    p = (1.0, -1.75, 9.625)
    x = -0.375                                  # 10 - 9.625 from the front face z = 10
    assert t.reading([pc], x, last_x, True, True, p, FRONT, UP, 1.0) == x   # the reading itself unchanged
    # q1 = min(-1.5, -0.375 - 0.125) = -1.5 (the last reading); q_(k-j) = -1.5 - 0.125 j
    # for the 4 earlier positions known, then the oldest (-2.0) repeated
    want = [-1.5, -1.625, -1.75, -1.875, -2.0] + [-2.0] * (_HIST - 5)
    assert pc.calls == [want]


def test_a_turn_books_the_last_interval_from_the_reading_where_that_is_lower() -> None:
    t, pc = NormalTurns(), _Rec()
    ps, _ = _pressing(t, pc, 3)                 # p_k = (1, -1.0, 9.25)
    p = (1.0, -1.25, 9.5)
    # last_x above x - n_new . dp = -0.5 - 0.25 = -0.75: q1 = -0.75
    t.reading([pc], -0.5, -0.25, True, True, p, FRONT, UP, 1.0)
    want = [-0.75, -0.875, -1.0] + [-1.0] * (_HIST - 3)
    assert pc.calls == [want]


def test_the_re_read_runs_back_over_the_whole_ring_and_no_further() -> None:
    t, pc = NormalTurns(), _Rec()
    ps, last_x = _pressing(t, pc, _HIST + 4)    # more positions than the ring holds
    k = len(ps) - 1
    p = (1.0, ps[k][1], ps[k][2] + 0.125)
    t.reading([pc], 0.0, last_x, True, True, p, FRONT, UP, 1.0)
    q1 = min(last_x, 0.0 - 0.125)
    # the ring holds _HIST positions: p_k back to p_(k-_HIST+1), each re-read by its own
    # distance along the front normal (0.125 mm a tick)
    want = [q1 - 0.125 * j for j in range(_HIST)]
    assert pc.calls == [want]


def test_a_new_object_forgets_the_positions() -> None:
    t, pc = NormalTurns(), _Rec()
    _pressing(t, pc, 5)
    # another object, its nearest face another: no position of it known, nothing re-read
    p1 = (2.0, -2.0, 9.75)
    t.reading([pc], -0.25, -1.0, True, False, p1, FRONT, UP, 1.0)
    assert pc.calls == []
    # the next tick turns on it: one position known (p1), the history flat at q1
    p2 = (2.125, -2.0, 9.875)
    t.reading([pc], -0.5, -0.25, True, True, p2, SIDE, FRONT, 1.0)
    q1 = min(-0.25, -0.5 - 0.125)
    assert pc.calls == [[q1] * _HIST]


def test_a_tick_without_a_reading_forgets_the_positions() -> None:
    t, pc = NormalTurns(), _Rec()
    _pressing(t, pc, 5)
    t.forget()
    p1 = (1.0, -1.75, 9.625)
    t.reading([pc], -0.375, -1.5, True, True, p1, FRONT, UP, 1.0)
    assert pc.calls == []        # nothing known to re-read from
    p2 = (1.125, -1.75, 9.75)
    t.reading([pc], -0.25, -0.375, True, True, p2, SIDE, FRONT, 1.0)
    assert pc.calls == [[min(-0.375, -0.25 - 0.125)] * _HIST]


def test_the_same_normal_is_no_turn() -> None:
    t, pc = NormalTurns(), _Rec()
    _pressing(t, pc, 5)
    t.reading([pc], -1.75, -1.5, True, True, (1.0, -1.75, 9.625), UP, None, 1.0)   # None held: +y
    assert pc.calls == []


def test_a_force_held_out_of_contact_is_booked_along_its_normal() -> None:
    t, pc = NormalTurns(), _Rec()
    _pressing(t, pc, 3)                         # p_k = (1, -1.0, 9.25)
    # out through the front face with the front normal's force held: the reading moves by
    # its part of the displacement, n . dp = 0.5
    assert t.reading([pc], -1.0, -0.125, False, False, (1.0, -1.0, 9.75), None, FRONT, 0.5) == -0.125 + 0.5
    # no force held: the reading as the loop holds it
    assert t.reading([pc], -1.0, 0.375, False, False, (1.0, -1.0, 10.25), None, FRONT, 0.0) == -1.0
    assert pc.calls == []


def _stepped(readings: list[float]) -> PassivityController:
    pc = PassivityController()
    for x in readings:
        pc.step(x, 1e-3, 0.0)
    return pc


def test_rebase_replaces_the_newest_readings_and_keeps_the_older() -> None:
    rs = [0.125 * i for i in range(10)]
    pc = _stepped(rs)
    back = [-1.0, -1.5, -2.0, -2.5]
    pc.rebase(back)
    hist, hp = pc._hist, pc._hp
    got = [hist[hp - j] for j in range(_HIST)]
    # the first step fills the ring with its reading; the 9 after it are newer
    old = [rs[9 - j] if j <= 9 else rs[0] for j in range(_HIST)]
    assert got == back + old[len(back):]
    # the next step books from the last reading re-read, and reads ahead from the one before
    assert (pc._q1, pc._q2) == (back[0], back[1])


def test_rebase_of_the_whole_ring() -> None:
    pc = _stepped([0.25 * i for i in range(40)])
    back = [-0.125 * j for j in range(_HIST + 3)]   # longer than the ring: the first _HIST used
    pc.rebase(back)
    assert [pc._hist[pc._hp - j] for j in range(_HIST)] == back[:_HIST]
    assert (pc._q1, pc._q2) == (0.0, -0.125)


def test_rebase_before_a_reading_keeps_none() -> None:
    pc = PassivityController()
    pc.rebase([5.0, 4.0])
    pc.step(1.0, 1e-3, 0.0)      # the first reading starts the history
    assert pc._hist == [1.0] * _HIST and (pc._q1, pc._q2) == (1.0, 1.0)
