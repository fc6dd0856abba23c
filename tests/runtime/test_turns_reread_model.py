"""Issue 23: :meth:`NormalTurns.reading` against a plain model of its rule (docs/runtime.md,
Passivity, "A normal that turns"), bit for bit, on random runs of contact, turns, exits,
objects and ticks without a reading.

The model keeps the positions since the contact began as a list (no ring) and re-reads the
history at a turn one entry at a time, ``q_(k-j) = q1 - n_new . (p_k - p_(k-j))`` with the
same three products summed in the same order, older ones as the oldest known; out of
contact with a force held, ``x = last_x + n_held . dp`` (its three terms added to
``last_x`` one by one, as the rule's code does). The positions are arbitrary
floats, so the two agree exactly only where each entry is the same sum of the same
positions: a ring read at the wrong place or a history one entry short or long fails it.
"""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given, settings, strategies as st

from hapticsdk.passivity.plan import _HIST
from hapticsdk.runtime.turns import NormalTurns

UP = (0.0, 1.0, 0.0)


def _dot(n: Any, a: Any, b: Any) -> float:
    return n[0] * (a[0] - b[0]) + n[1] * (a[1] - b[1]) + n[2] * (a[2] - b[2])


class _Model:
    """The rule of :class:`NormalTurns`, written plainly."""

    def __init__(self) -> None:
        self.known: list[Any] = []   # positions since the contact began, newest last

    def reading(self, x: float, last_x: float, in_contact: bool, same: bool, p: Any, d: Any, held: Any,
                f_held: float) -> tuple[float, list[float] | None]:
        known = self.known if same or not in_contact else []
        h = UP if held is None else held
        back = None
        if not in_contact:
            if known and f_held:
                lp = known[-1]   # (added term by term to the last reading, as the loop does)
                x = last_x + h[0] * (p[0] - lp[0]) + h[1] * (p[1] - lp[1]) + h[2] * (p[2] - lp[2])
        elif known:
            dn = UP if d is None else d
            if dn != h:
                lp = known[-1]
                q1 = min(last_x, x - _dot(dn, p, lp))
                back = [q1]
                for j in range(1, _HIST):
                    back.append(q1 - _dot(dn, lp, known[-1 - j]) if j < len(known) else back[-1])
        self.known = (known + [p])[-_HIST:]
        return x, back

    def forget(self) -> None:
        self.known = []


class _Rec:
    def __init__(self) -> None:
        self.calls: list[list[float]] = []

    def rebase(self, readings_mm: list[float]) -> None:
        self.calls.append(list(readings_mm))


_coord = st.floats(-60.0, 60.0, allow_nan=False)
_vec = st.tuples(_coord, _coord, _coord)
# (normals off the axes too, so that every component of a held normal counts)
_normal = st.one_of(st.none(), st.sampled_from([UP, (0.0, 0.0, 1.0), (0.6, 0.0, -0.8), (-0.48, 0.6, 0.64)]), _vec)
_tick = st.tuples(st.sampled_from(["contact", "contact", "contact", "other", "out", "out", "forget"]), _vec,
                  _normal, _coord, st.sampled_from([0.0, 1.5, 1.5]))


@settings(max_examples=200, deadline=None)
@given(st.lists(_tick, min_size=1, max_size=90))
def test_the_re_read_is_the_plain_rule_bit_for_bit(ticks: list[Any]) -> None:
    t, m, pc = NormalTurns(), _Model(), _Rec()
    held = None
    last_x = 0.0
    for kind, p, d, x, f_held in ticks:
        if kind == "forget":
            t.forget()
            m.forget()
            continue
        in_contact, same = kind != "out", kind != "other"
        before = len(pc.calls)
        got = t.reading([pc], x, last_x, in_contact, same, p, d, held, f_held)
        want, back = m.reading(x, last_x, in_contact, same, p, d, held, f_held)
        assert got == want
        if back is None:
            assert len(pc.calls) == before
        else:
            assert len(pc.calls) == before + 1 and pc.calls[-1] == back and len(back) == _HIST
        held, last_x = d, got


@pytest.mark.parametrize("steps", range(1, _HIST + 2))
@settings(max_examples=8, deadline=None)
@given(back=st.lists(_coord, min_size=1, max_size=_HIST + 4))
def test_rebase_writes_the_ring_as_the_plain_rule(steps: int, back: list[float]) -> None:
    """:meth:`PassivityController.rebase` at every place of its ring (``steps`` readings
    before it, the newest at each of its places once) against the plain rule: ``back[j]`` replaces the reading ``j`` ticks before
    the newest, the first ``_HIST`` of ``back`` used, older ones kept."""
    from hapticsdk.passivity.controller import PassivityController
    pc = PassivityController()
    for i in range(steps):
        pc.step(0.125 * i, 1e-3, 0.0)
    hist, hp = pc._hist, pc._hp
    want = list(hist)
    for j in range(min(len(back), _HIST)):
        want[(hp - j) % _HIST] = back[j]
    pc.rebase(back)
    assert pc._hist == want and pc._hp == hp
    assert (pc._q1, pc._q2) == (want[hp], want[hp - 1])
