"""The stiff-wall controller's reading at a turn of the force's direction, in a spatial
scene: on a device that renders the force on all three axes (docs/runtime.md, Passivity,
"A normal that turns"), and on one that renders fewer ("A turn on a device that renders
one axis": there the loop's reading is the held force's work per newton already, the book
is exact, and only the history the plan predicts from is re-read, on the rendered axes).

In contact the reading is the distance to the surface, ``x = -pen`` (the loop's own). The
force held over an interval is ``F n``, ``n`` the normal sent with it; its work per newton
on the measured motion is ``n . dp``. Two places where that reading alone misleads the
controller:

* **A normal that turns** (a box's edge or corner, met from inside: the nearest face
  changes while the distance is continuous). The reading's rate jumps from ``n_old . v``
  to ``n_new . v``, by up to ``|n_new - n_old| |v|`` in one tick, a change of motion no
  earlier reading foretold: the plan, sized on the motion along the old normal, sends
  the new force against a motion it did not predict (traced: a hand moving in along the
  bottom face of a box, earning credit, then out along the side face as the nearest face
  changed: 0.9 mJ given in one 4 ms tick). At a turn the controller's history is re-read
  along the new normal, ``q_(k-j) = q_k - n_new . (p_k - p_(k-j))`` from the measured
  positions of the ticks since the contact began (older ones as the oldest of them), so
  its prediction is of the motion the new force meets.
* **A force held out of contact** (the release's ramp after the stylus left, or the
  interval in which it left). The loop holds the reading out of contact (the distance
  jumps where another object becomes the nearest), so the held force's work went
  unbooked; it is now booked along its normal, ``x += n_held . dp``.

The booking stays an upper bound. At a turn the interval last booked (its force along
the old normal) is booked from ``q' = min(q_(k-1), x_k - n_new . dp)``. Inside a convex
shape (every shape of :mod:`hapticsdk.scene.geometry`) the signed distance is convex, so
``n_old . dp <= x_k - x_(k-1) <= n_new . dp`` (each normal its gradient at its end of the
interval): the change booked, ``n_new . dp``, is at least the distance's change, which
already bounded the held force's work per newton (the extra over the spring is >= 0); a
larger change booked only lowers the force the plan affords and the spring's rise (it
rises only as the reading moves in). The plan's damping credit then uses the
displacement's projection on a unit normal, within what the arm's damper dissipates
(``b |v|^2 >= b (n . v)^2``), as the distance's change did.
"""

from __future__ import annotations

from typing import Any, Callable, Sequence

from ..passivity.plan import _HIST

_UP = (0.0, 1.0, 0.0)


def carrier(old: Any, new: Any) -> "Callable[[tuple[float, float, float]], tuple[float, float, float]]":
    """The map a rigid move of an object from pose ``old`` to ``new`` (each with
    ``position_mm`` and the rotation ``matrix``, rows) applies to the points fixed in it:
    ``q -> R_new R_old^T (q - t_old) + t_new``. A position the loop remembers, carried so,
    is the same point of the object: the displacement to it from a later position is the
    stylus's motion relative to the object, in the object's frame (docs/runtime.md,
    Passivity, "A moving wall")."""
    a, b = old.matrix, new.matrix
    m = [[b[i][0] * a[j][0] + b[i][1] * a[j][1] + b[i][2] * a[j][2] for j in range(3)] for i in range(3)]
    t0, t1 = old.position_mm, new.position_mm

    def carry(q: tuple[float, float, float]) -> tuple[float, float, float]:
        d0, d1, d2 = q[0] - t0[0], q[1] - t0[1], q[2] - t0[2]
        return (m[0][0] * d0 + m[0][1] * d1 + m[0][2] * d2 + t1[0],
                m[1][0] * d0 + m[1][1] * d1 + m[1][2] * d2 + t1[1],
                m[2][0] * d0 + m[2][1] * d1 + m[2][2] * d2 + t1[2])
    return carry


def _re_read(q1: float, dn: Any, lp: Any, older: Any) -> list[float]:
    """``q1 - dn . (lp - r)`` for each position ``r`` of ``older``, the three products summed
    in that order. A turn comes on every tick that a curved surface's reading moves, so this
    is one comprehension (docs/runtime.md, "A normal that turns", its cost); it is a function
    of its own so that the names it closes over are cells of this call only, not of every
    :meth:`NormalTurns.reading`."""
    d0, d1, d2 = dn
    l0, l1, l2 = lp
    return [q1 - (d0 * (l0 - r0) + d1 * (l1 - r1) + d2 * (l2 - r2)) for r0, r1, r2 in older]


class NormalTurns:
    """Measured positions since the contact began, and the readings of each tick.

    ``axes``: the SDK axes the device renders the force along (``Actuator.force_axes``).
    On all three the reading is the distance: a turn also books the last interval from the
    re-read reading where that is lower, and a force held out of contact is booked along
    its normal. On fewer (the simulated Omni: ``(1,)``) the loop's reading already is the
    held force's work per newton, ``sum_(i in axes) n_i dp_i`` a tick (docs/runtime.md,
    Passivity, "A force rendered along one axis"; out of contact the loop books the held
    force at the re-entry): a turn is a change of the direction's part on those axes, and
    only the history the plan predicts from is re-read, on them, while the last interval is
    booked from the last reading as it was (docs/runtime.md, Passivity, "A normal that
    turns", "A turn on a device that renders one axis").
    """

    __slots__ = ("_ring", "_at", "_n", "_axes")

    def __init__(self, axes: Sequence[int] = (0, 1, 2)) -> None:
        self._ring: list[tuple[float, float, float]] = [(0.0, 0.0, 0.0)] * _HIST
        self._at = 0
        self._n = 0     # positions known, newest at _at (0: none)
        self._axes: tuple[int, ...] | None = None if tuple(axes) == (0, 1, 2) else tuple(axes)

    def reading(self, pcs: Sequence[Any], x: float, last_x: float, in_contact: bool, same: bool,
                p: tuple[float, float, float], d: "tuple[float, float, float] | None",
                held: "tuple[float, float, float] | None", f_held: float) -> float:
        """This tick's reading (mm) for the controllers ``pcs`` (rebased where due, before
        their step): ``x`` the loop's (``-pen`` in contact, the last reading out of it; on a
        device that renders fewer axes, the last reading plus the held force's work per
        newton), ``last_x`` the reading of the last tick, ``same`` the object the
        controllers observe, ``p`` the measured position, ``d`` this tick's normal, ``held``
        and ``f_held`` the normal and force held over the last interval (None: +y)."""
        ring = self._ring
        at = self._at
        n = self._n if same or not in_contact else 0
        h = _UP if held is None else held
        lp = ring[at]
        axes = self._axes
        if axes is not None:
            if in_contact and n:
                dn = _UP if d is None else d
                if any(dn[i] != h[i] for i in axes):
                    # a turn of the force as rendered: the history the plan predicts from,
                    # re-read along the new direction on the rendered axes (its part off
                    # them taken as 0) back from this reading; the last interval booked
                    # from the last reading (exact)
                    dr = (dn[0] if 0 in axes else 0.0, dn[1] if 1 in axes else 0.0, dn[2] if 2 in axes else 0.0)
                    back = self._history(x - (dr[0] * (p[0] - lp[0]) + dr[1] * (p[1] - lp[1])
                                              + dr[2] * (p[2] - lp[2])), dr, lp, at, n)
                    for pc in pcs:
                        pc.rebase(back, last_x)
        elif not in_contact:
            if n and f_held:
                # the held force's work per newton, along its normal
                x = last_x + h[0] * (p[0] - lp[0]) + h[1] * (p[1] - lp[1]) + h[2] * (p[2] - lp[2])
        elif n:
            dn = _UP if d is None else d
            if dn != h:
                # a turn (also at an entry where the nearest face outside was another):
                # the history along the new normal, booked from at most the last reading
                # (the same on a convex shape)
                q1 = min(last_x, x - (dn[0] * (p[0] - lp[0]) + dn[1] * (p[1] - lp[1]) + dn[2] * (p[2] - lp[2])))
                back = self._history(q1, dn, lp, at, n)
                for pc in pcs:
                    pc.rebase(back)
        at = at + 1 if at + 1 < _HIST else 0
        ring[at] = p
        self._at = at
        self._n = n + 1 if n < _HIST else _HIST
        return x

    def _history(self, q1: float, dn: Any, lp: Any, at: int, n: int) -> list[float]:
        """The readings re-read along ``dn`` back from ``q1``, newest first, ``_HIST`` of them:
        each of the positions 1 .. n-1 ticks before ``lp`` (``ring[at - j]``) by
        :func:`_re_read`, older ones as the oldest known."""
        ring = self._ring
        older = ring[at - 1::-1] + ring[:at:-1] if at else ring[:0:-1]
        back = [q1]
        back += _re_read(q1, dn, lp, older[:n - 1])
        if n < _HIST:
            back += [back[-1]] * (_HIST - n)
        return back

    def carry(self, move: "Callable[[tuple[float, float, float]], tuple[float, float, float]]") -> None:
        """The object the controllers observe moved (:func:`carrier`): the positions known
        are carried with it, so the re-read and the held force's booking are of the
        stylus's motion relative to the object."""
        ring = self._ring
        for j in range(self._n):
            i = self._at - j
            ring[i] = move(ring[i])

    def forget(self) -> None:
        """No position this tick: the next one starts afresh."""
        self._n = 0
