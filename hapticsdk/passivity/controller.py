"""The stiff-wall controller of the servo tick: a Colgate spring plus an energy-bounded
extra (:class:`PassivityController`)."""

from __future__ import annotations

import logging
import math
from typing import Any

from .plan import _BRANCH_TOL, _HIST, _ROUNDING_SLACK, _affordable_scalar, _below_ramp_scalar, _cost_scalar
from .settings import ControllerSettings, _spring_stiffness_and_step

_log = logging.getLogger(__name__)

_INF = math.inf


def _moving_wall_credit(b_lo: float, b_x: float, ks: float, span: float, a: float, c: float, q: float) -> float:
    """The damping credit (J) of an interval over which the object moved: the arm's damper
    dissipates at least ``b_lo a_t^2 / span`` (``a_t`` the stylus's true displacement along
    the force), and the spring held over it needs ``K_s a_t c_t / 2`` (``c_t`` the true
    change of the depth's reading; the wall's move taken at the mean of the forces held
    before and after it), at the least over the readings' error ``d`` in ``[-q, q]``, which
    is the same in both (the same stylus reading): ``min_d b_lo (a + d)^2 / span - K_s (a + d)
    (c + d) / 2``, ``a``, ``c`` the readings' values (m). With ``a == c`` (an object at rest)
    it is the still wall's ``b_x max(|c| - q, 0)^2 / span``, or with ``b_x < 0`` the deficit
    ``b_x (|c| + q)^2 / span`` (docs/runtime.md, Passivity, "A moving wall"). A reading
    that is not a number earns no credit: the deficit alone, on the reading's change."""
    if not -_INF < a < _INF:
        ex = abs(c) + q
        return b_x * ex * ex / span if b_x < 0.0 else 0.0
    qa = b_x / span                                   # the quadratic in d: qa d^2 + qb d + qc
    qb = 2.0 * b_lo * a / span - 0.5 * ks * (a + c)
    qc = b_lo * a * a / span - 0.5 * ks * a * c
    best = qc - qb * q + qa * q * q
    hi = qc + qb * q + qa * q * q
    if hi < best:
        best = hi
    if qa > 0.0:
        d = -qb / (2.0 * qa)
        if -q < d < q:
            mid = qc + d * (qb + qa * d)
            if mid < best:
                best = mid
    return best


class PassivityController:
    """Passive wall from the device's declared parameters: a Colgate spring plus an
    energy-bounded extra.

    Per tick call :meth:`step` with the measured position (mm, along the normal, the
    surface at 0, inside at x < 0), the measured period ``dt`` (s) and the wall's force
    (N); send the returned force; then call :meth:`commit` with the force the device
    actually applied (after its safety clamp). A step with no commit since the last one
    takes the force the last step returned as applied: a caller that never calls
    :meth:`commit` gets the book of a device that applies what it is sent.

    **The Colgate spring** ``P = min(F_wall, K_c depth)``, ``K_c = min(2 b_s / T, s /
    Delta)`` (``T`` the servo's period, ``settings.period_s``, else each measured
    ``dt``; with the period declared, ``K_c`` never rises while the spring is
    compressed), ``b_s = min(b_lo, damping_trust x device damping)``: ``b_lo`` the trusted
    damping (the measured lower bound where the settings carry one, else
    ``declared_damping_trust x declared damping``, none by default), the device damping the declared one or, after
    a hands-off measurement, the fitted one. So the spring is passive under the
    zero-order hold for the trusted damping (Colgate & Schenkel's ``b > K T / 2``), and
    with a measured damping it sits at half Colgate's limit of the fit, which leaves the
    encoder's count crossings damping of their own; one count of it is at most one ramp
    step ``s``. It follows the reading at once (a spring, not a ramp: a ramp on a spring
    lags it, and a lagging spring gives energy), from its anchor ``o``: ``K_c (depth -
    o)``, ``o`` 0 at first; where a reading jumps several counts the spring rises by one
    ramp step and ``o`` moves in to match (stored energy kept back, never handed over),
    where the reading is above ``o`` it follows the reading out, and out of the wall it is
    0. It rises only as the reading moves in (by at most ``K_c`` times the inward change
    of a tick; ``o`` moves in where that binds): a wall that appears around a resting
    stylus stores nothing. It is at most the force the device applied: a commit below it (a
    safety layer's start ramp or clamp) lowers it to that force and moves ``o`` in, and the
    energy that took out is credited to ``U`` where the spring is on its ``K_c`` branch. The extra gives way to the spring's rise, so the force rises by at most ``s`` per
    tick; on a release it takes up the spring's fall (never above what it held) where the
    plan affords it (on a move out by one count after a rest, where not even the ramp down fits: priced
    at what the take-up adds to that ramp, within what is left of the allowance), so the
    force falls by at most ``s``, else by at most ``s`` plus the spring's fall ``K_c |dq|``.

    **The extra** ``X = F - P`` carries the rest of the wall. The controller keeps ``U``,
    an *upper bound* of the energy the extra has given the user, from the readings ``q``
    and the held extras alone:

        ``U += X_{k-1} dq_k + (Delta/2) |X_{k-1} - X_{k-2}| - b_x max(|dq_k| - Delta, 0)^2 / dt``

    (ZOH pairing: the extra held over an interval times that interval's reading change;
    summation by parts bounds its true work by this plus ``Delta/2`` per unit of change,
    plus ``Delta/2 |X|`` at the end; ``b_x = b_lo - K_s dt / 2`` is the damping the spring
    leaves, ``K_s`` its secant stiffness at the interval's start, or ``K_c`` on an
    interval entering the wall from outside; it dissipates at least ``b_x dy^2 / dt`` per
    interval with ``|dy| >= |dq| - Delta``; where the object moved, on the stylus's own
    motion, :meth:`step`'s ``own_mm``). It sends the largest extra, between 0 and
    ``F_wall - P``, within one ramp step ``s`` of the last, whose plan "hold it one tick,
    then ramp to 0 at ``s`` per tick" keeps ``U`` below ``E0 = min(F_max Delta / 2,
    energy_allowance_j)`` if the reading keeps moving at the rate of the last two ticks,
    changing by up to the largest change of motion seen over the last ``_HIST`` ticks
    (counting, as far as the readings allow, what a change of the held force gives the
    free arm) plus the largest third difference (:func:`affordable_force`).
    If the motion outruns that prediction the excess is booked (``overdrawn_j``), and the
    extra ramps down at ``s``; where the book is overdrawn (``U > E0``) and even that ramp
    does not fit, it falls below it to the largest force the plan affords
    (``below_ramp_ticks``).

    **Release.** The spring follows the reading out; the extra ramps to 0 at ``s`` per
    tick, charged to the same bound, and once the bound is spent only the spring is
    left (the force never drops below it while the stylus is inside). With no wall force
    and no output, credit is dropped (``U <- max(U, 0)``); a debt is kept.

    **A tick without a period or a reading** (``dt`` 0, negative or NaN: a clock that
    stalled; a position that is NaN or infinite) books nothing and returns 0 N, the safe
    output: the ramp step and the damping credit need a period, the book a position. The
    next tick with both books the whole span since the last reading.
    """

    __slots__ = ("settings", "energy_j", "active_ticks", "withheld_n_ticks", "overdrawn_j", "spent_ticks", "below_ramp_ticks", "_said", "_q1", "_q2", "_hist", "_hp",
                 "_f1", "_f2", "_started", "_still", "_spring", "_kf", "_kc", "_full",
                 "_jw", "_jw_top", "_jw_at", "_j3w", "_j3w_top", "_j3w_at",
                 "_a1", "_a2", "_a3", "_sent", "_pending", "_o", "_gap", "_dw", "_tw")

    def __init__(self, settings: ControllerSettings | None = None, **kw: Any) -> None:
        self.settings = settings or ControllerSettings(**kw)
        self._said = False          # the spent bound was logged (once per controller)
        self.energy_j: float = 0.0
        self.reset()

    def reset(self, *, keep_debt: bool = False) -> None:
        """Forget the energy observed so far (a new run). With ``keep_debt`` (another object
        of the same run, the servo loop's restart) the controller starts afresh on the new
        object's readings but keeps a debt, ``U = max(U, 0)``: the bound covers the run, and
        a restart that forgave it would hand a hand that moves from object to object one
        allowance per object (docs/runtime.md, Passivity, "A bound per run, not per
        object")."""
        debt = self.energy_j if keep_debt and self.energy_j > 0.0 else 0.0
        self.energy_j = debt        # U: upper bound of the energy given to the user (J)
        self.active_ticks = 0       # ticks where the output was below the wall's force
        self.withheld_n_ticks = 0.0 # sum over ticks of the force withheld (N)
        self.overdrawn_j = 0.0      # largest U - E0 seen (J): motion beyond the prediction
        self.spent_ticks = 0        # ticks held below the wall's force with the bound spent (U >= E0)
        self.below_ramp_ticks = 0   # ticks the extra fell below its ramp: the book overdrawn (U > E0)
        self._q1 = self._q2 = 0.0
        self._hist = [0.0] * _HIST    # the last readings (mm), a ring; _hp the newest
        self._hp = 0
        # two windows over the same ticks as the ring: the values of its last _HIST ticks
        # (a ring of their own, written at the same index), their largest and its index,
        # kept as the ring turns (a full search only when the largest leaves the window;
        # written out in step, the servo tick)
        self._jw = [0.0] * _HIST      # the change-of-motion estimates of the same ticks
        self._jw_top = 0.0
        self._jw_at = 0
        self._j3w = [0.0] * _HIST     # the third differences of the same ticks
        self._j3w_top = 0.0
        self._j3w_at = 0
        # the forces applied over the last three ticks (N): _a1 the one the last commit
        # recorded, held over the coming interval (a step commits its own where none came)
        self._a1 = self._a2 = self._a3 = 0.0
        self._f1 = self._f2 = 0.0   # the extra (applied force minus the spring) over the last two ticks
        self._started = False
        self._still = 0             # ticks since the reading last changed
        self._spring = 0.0          # the Colgate spring sent this tick (N)
        self._kf = 0.0              # its secant stiffness (N/m)
        self._kc = 0.0              # its stiffness K_c while compressed (N/m), else 0
        self._o = 0.0               # its anchor: the depth (m) at which it is 0
        self._full = 0.0            # full scale without a declared force limit: the largest force so far
        self._sent = 0.0            # the force the last step returned
        self._pending = False       # a step returned a force that no commit has recorded yet
        self._gap = 0.0             # time (s) of the ticks since the last booked one that had no reading
        self._dw = 0.0              # the wall's move into the depth over the last booking (m; 0: at rest)
        self._tw = 0.0              # a turn's part of that move the commit books (m; 0: none)

    def rebase(self, readings_mm: "list[float]", booked_mm: float | None = None) -> None:
        """Replace the newest readings the controller holds (mm): ``readings_mm[0]`` the
        last one, ``readings_mm[j]`` the one ``j`` ticks before it; older ones are kept. The
        next :meth:`step` books the last interval from ``booked_mm`` (None: from
        ``readings_mm[0]``) and predicts the motion from the readings. The servo loop's turn
        of a contact normal (docs/runtime.md, Passivity, "A normal that turns"): the history
        re-read along the new normal, so the plan's prediction is of the motion the new
        force meets; on a device that renders all three axes the last interval is booked
        from the re-read reading where that is lower, on one that renders fewer (whose
        reading is the held force's work per newton, exactly) from the reading as it was.
        A controller that has no reading yet keeps none."""
        if not self._started or not readings_mm:
            return
        hist = self._hist
        hp = self._hp
        if len(readings_mm) >= _HIST:
            # the whole ring (the servo loop's re-read): the newest from hp back to 0, then
            # the rest from the ring's end
            hist[hp::-1] = readings_mm[:hp + 1]
            hist[:hp:-1] = readings_mm[hp + 1:_HIST]
        else:
            for j in range(len(readings_mm)):
                hist[hp - j] = readings_mm[j]
        self._q1 = hist[hp] if booked_mm is None else booked_mm
        self._q2 = hist[hp - 1]

    def step(self, x_mm: float, dt: float, f_wall: float, own_mm: float | None = None,
             turned_mm: float = 0.0) -> float:
        """Book the last interval, then return the force (N) to command this tick.

        ``own_mm``: where the object moved since the last reading, the stylus's own
        displacement along the force's direction over the same span (mm, outward +; the
        device reading's change, not the distance's): the arm's damper dissipates the
        stylus's motion, not the wall's, so the damping credit is taken on it, and the
        spring's need on the product of it and the reading's change (docs/runtime.md,
        Passivity, "A moving wall"). None (the default): an object at rest, the reading's
        change is the stylus's. A value that is not a finite number earns no credit.

        ``turned_mm`` (with ``own_mm``): where the force's direction turned over that span on
        a device that renders it along fewer than three axes, ``(n_held - n_new) . dw`` on
        those axes (mm, ``dw`` the object's move at the stylus). The frame's move is taken
        at the mean of the force vectors held before and after it, and the book pairs it
        with the held direction: the difference, half the force applied this tick times
        ``turned_mm``, is booked on :meth:`commit` and priced in this tick's plan, the
        Colgate spring's share too: on a turn with ``turned_mm > 0`` the spring is at most
        ``2 (E0 - U) / turned`` (docs/runtime.md, Passivity, "A turn on a device that
        renders one axis", "The spring at a turn")."""
        if self._pending:
            # no commit since the last step: the force it returned is taken as applied
            self.commit(self._sent)
        self._pending = True
        # the constants derived from the settings: once per configuration (a field set on
        # the settings drops them; ControllerSettings._derive_tick_constants)
        c = self.settings._tick_consts
        if c is None:
            c = self.settings._derive_tick_constants()
        q, h, c2, b_lo, b_s, m, fm, ramp_time, period, allowance, energy_bound, kc_p, sp_p, e0_p = c
        if not -_INF < f_wall < _INF:   # NaN or infinite: no wall
            f_wall = 0.0
        if not self._started or not dt > 0 or not -_INF < x_mm < _INF:
            if not -_INF < x_mm < _INF:
                if self._started and 0.0 < dt < _INF:
                    # the next booking spans this tick too: its damping credit is for the
                    # whole span (docs/runtime.md, Passivity, "A tick without a period or a
                    # reading")
                    self._gap += dt
                # the device gets 0: no spring (its next rise is from the next reading)
                self._spring = self._kf = self._kc = self._o = 0.0
                self._sent = 0.0
                return 0.0           # a reading that is not a number: nothing to book, no force
            if not self._started:
                self._q1 = self._q2 = x_mm
                self._hist = [x_mm] * _HIST
                self._started = True
            r = 0.0 if not dt > 0 else self._a1
            self._sent = r
            return r
        dq = (x_mm - self._q1) * 1e-3
        f1 = self._f1
        # the extra above the spring: ZOH-paired work plus half a count of reading error
        # per newton of change (summation by parts); the damping the Colgate spring does
        # not need is credited below, once this tick's spring is known
        u = self.energy_j + f1 * dq + h * abs(f1 - self._f2)
        if self._dw:
            # the last booking's wall move dw, paired with the extra held before it: its work
            # in the wall's frame is at the mean of the extras held before and after it, the
            # difference known now ("A moving wall")
            u += 0.5 * (self._f2 - f1) * self._dw
        ex = abs(dq) - q
        ahead = 0.5 * (x_mm - self._q2) * 1e-3
        # the change of the per-tick motion beyond what quantisation alone makes (2 counts),
        # read over spans of 1-16 ticks (_SCALES, unrolled: this is the servo tick)
        hist = self._hist
        hp = self._hp + 1
        if hp == _HIST:
            hp = 0
        self._hp = hp
        hist[hp] = x_mm
        x1 = hist[hp - 1]
        x2 = hist[hp - 2]
        d1 = abs(x_mm - 2.0 * x1 + x2)   # this tick's second difference (mm)
        jerk = d1 - c2
        x4 = hist[hp - 4]
        d = (abs(x_mm - 2.0 * x2 + x4) - c2) * 0.25
        if d > jerk:
            jerk = d
        x8 = hist[hp - 8]
        d = (abs(x_mm - 2.0 * x4 + x8) - c2) * 0.0625
        if d > jerk:
            jerk = d
        x16 = hist[hp - 16]
        d = (abs(x_mm - 2.0 * x8 + x16) - c2) * 0.015625
        if d > jerk:
            jerk = d
        d = (abs(x_mm - 2.0 * x16 + hist[hp - 32]) - c2) * 0.00390625
        if d > jerk:
            jerk = d
        jerk = jerk * 1e-3 if jerk > 0.0 else 0.0
        a1 = self._a1   # the force applied over the last interval (N)
        if m:   # the trusted mass (ControllerSettings.trusted_mass_kg)
            # the largest change of motion the readings allow (2 counts above the second
            # difference), up to what the held force's change over the last two ticks
            # gives the free arm (docs/runtime.md, Passivity item 5)
            d = abs(a1 - self._a2)
            d3 = abs(a1 - self._a3)
            if d3 > d:
                d = d3
            if d > 0.0:   # a force held steady adds nothing
                d = d * dt * dt / m
                seen = (d1 + c2) * 1e-3
                if seen < d:
                    d = seen
                if d > jerk:
                    jerk = d
        # the largest change of motion over the ring's window (_HIST ticks): a hand that
        # reversed within it can reverse again; the estimate of this tick alone is blind
        # between reversals (taps, the finger-and-arm resonance at long periods)
        # (stored at the ring's index, the oldest value's; the window's largest kept)
        w = self._jw
        w[hp] = jerk
        if jerk >= self._jw_top:
            self._jw_top = jerk
            self._jw_at = hp
        elif self._jw_at == hp:   # the largest left the window: find the next one
            jerk = self._jw_top = max(w)
            self._jw_at = w.index(jerk)
        else:
            jerk = self._jw_top
        # the third difference beyond what quantisation alone makes (1 + 3 + 3 + 1 half
        # counts = 4 counts): the term after the acceleration in the extrapolation to the
        # next tick, exact for a cubic motion (docs/runtime.md, Passivity item 5); its
        # largest over the same window
        j3 = abs(x_mm - 3.0 * (x1 - x2) - hist[hp - 3]) - 2.0 * c2
        j3 = j3 * 1e-3 if j3 > 0.0 else 0.0
        w = self._j3w
        w[hp] = j3
        if j3 >= self._j3w_top:
            self._j3w_top = j3
            self._j3w_at = hp
        elif self._j3w_at == hp:   # as above: the largest left the window
            j3 = self._j3w_top = max(w)
            self._j3w_at = w.index(j3)
        else:
            j3 = self._j3w_top
        rest = self._still          # ticks the reading had rested before this one
        still = rest + 1 if dq == 0.0 else 0
        self._still = still
        self._q2 = x1   # (the last reading, as re-read at a turn: the one booked from otherwise)
        self._q1 = x_mm
        # the Colgate spring: the wall up to the stiffness its damping makes passive
        # (K_c = 2 b_s / T, at most one ramp step per count), as a function of the depth
        # below the surface x = 0
        if fm is None:
            # no declared limit: the largest force seen so far is the full scale (a fixed
            # step, so a ramp to 0 ends; a scale that followed the output would shrink
            # with it and never reach 0)
            full = max(self._full, abs(f_wall), abs(a1))
            self._full = full
        else:
            full = fm
        step = full * (dt / ramp_time if dt < ramp_time else 1.0)
        depth = -x_mm * 1e-3
        s0 = self._spring   # the spring sent last tick (N)
        spring = 0.0
        kf = 0.0
        kc = 0.0
        o = 0.0
        if f_wall > 0.0 and depth > 0.0:
            # its damping b_s: half the device's damping (the measured fit, else the
            # declaration), at most the trusted lower bound (item 0;
            # ControllerSettings.spring_damping_ns_per_m, inline: only in contact)
            if kc_p is not None:
                # period and force limit declared: K_c and s derived with the settings
                kc, sp = kc_p, sp_p
            else:
                # sized on the servo's period where declared; the ramp step at that period
                kc, sp = _spring_stiffness_and_step(b_s, period or dt, full, ramp_time, q)
            kc0 = self._kc
            if period is not None and kc0 > 0.0 and kc > kc0:
                # and never stiffer while compressed: a rise of K_c stores (dK/2) d^2 that
                # no motion paid for (a full scale that grows without a declared limit, a
                # setting assigned mid-contact); without a declared period the spring
                # follows each measured one, as documented on ControllerSettings.period_s
                kc = kc0
            # the spring is K_c (depth - o), o its anchor: 0 at first, moved in where the
            # spring's rise is held to one ramp step (below), and following the reading
            # out where the reading is above it (the spring then stays at 0)
            o = self._o
            if o > depth:
                o = depth
            spring = kc * (depth - o)
            if spring > f_wall:
                spring = f_wall
            if fm is not None and spring > fm:
                spring = fm
            if spring > s0 + sp and kc > 0.0:
                # a reading that jumped several counts in one tick: the spring rises by one
                # ramp step (at its own period, like its cap) and its anchor moves in to
                # match. Moving the anchor in while compressed takes stored energy out
                # (K_c (depth - o)^2 / 2 falls), so the spring stays passive (item 0)
                spring = s0 + sp
                o = depth - spring / kc
            # (not after ticks without a reading: the motion over them met no force, so it
            # paid for no spring; the spring starts from where the reading is found)
            inward = s0 - kc * dq if dq < 0.0 and not self._gap else s0
            if spring > inward * _ROUNDING_SLACK and kc > 0.0:
                # and only as the reading moves in: a spring that rises where the stylus
                # stays (a wall that appears around it, a first reading inside, a wall law
                # that stiffens) stores energy no motion paid for; it rises by at most K_c
                # times the reading's inward change, and its anchor moves in to match
                # (item 0, "a spring born compressed")
                spring = inward
                o = depth - spring / kc
        self._o = o
        if spring > 0.0:
            # its secant stiffness, or K_c where the anchor has moved in (a spring that is 0
            # above the surface has a secant below its slope)
            kf = spring / depth if o == 0.0 else kc
        # the damping credited to the extra, b_x = b_lo - K_s T / 2: the spring held over
        # the interval needs K_s T / 2 of it, K_s its secant stiffness at the interval's
        # start; an interval that enters the wall from outside (no spring at its start)
        # needs the spring's full slope K_c. An interval longer than the one the spring was
        # sized for (a late tick) can need more than b_lo: the deficit is charged, with the
        # largest displacement the readings allow (docs/runtime.md, Passivity item 1)
        ks = self._kf
        if ks == 0.0 and spring > 0.0:
            ks = kc
        span = dt
        if self._gap:
            # the reading's change spans the ticks without a reading since the last one: the
            # damper took at least b dy^2 over the whole span, not over this tick
            span += self._gap
            self._gap = 0.0
        b_x = b_lo - 0.5 * ks * span
        tw = 0.0
        if own_mm is not None:
            # a moving object: the credit on the stylus's own motion (item 1, "A moving wall")
            u -= _moving_wall_credit(b_lo, b_x, ks, span, own_mm * 1e-3, dq, q)
            dw = own_mm * 1e-3 - dq
            self._dw = dw if -_INF < dw < _INF else 0.0
            if turned_mm:
                tw = turned_mm * 1e-3
                if not -_INF < tw < _INF:
                    tw = 0.0
        else:
            self._dw = 0.0
            if b_x < 0.0:
                ex = abs(dq) + q         # the deficit: the largest displacement the readings allow
            if ex > 0.0:
                u -= b_x * ex * ex / span
        self._tw = tw
        if e0_p is not None:
            e0 = e0_p
        else:
            e0 = full * h
            if e0 > allowance:
                e0 = allowance
        if tw > 0.0 and spring > 0.0 and energy_bound:
            # a turn's part of the move, half the force applied times tw, is no change of the
            # spring's stored energy (its passivity is along one direction): the spring's
            # share is priced like the extra's, the spring at most what the budget left
            # affords, 2 (E0 - U) / tw, its anchor moved in to match (stored energy kept
            # back, as at a new contact; docs/runtime.md, Passivity, "A turn on a device
            # that renders one axis", the spring at a turn)
            cap = 2.0 * (e0 - u) / tw
            if spring > cap:
                spring = cap if cap > 0.0 else 0.0
                o = depth - spring / kc
                self._o = o
                kf = kc if spring > 0.0 else 0.0
        rise = spring - s0   # the spring's change since the last tick
        self._spring = spring
        self._kf = kf
        self._kc = kc if spring > 0.0 else 0.0   # 0 where the spring is 0 (out of the wall, no damping, at its anchor)
        if f_wall == 0.0 and a1 == 0.0 and f1 == 0.0:
            self.energy_j = u if u > 0.0 else 0.0
            self._sent = 0.0
            return 0.0
        self.energy_j = u
        if u - e0 > self.overdrawn_j:
            self.overdrawn_j = u - e0
        # work in the direction of the wall's force (the last output's when the wall is 0)
        sg = 1.0 if (f_wall > 0.0 or (f_wall == 0.0 and a1 >= 0.0)) else -1.0
        target = sg * f_wall
        if fm is not None and target > fm:
            target = fm
        target -= spring
        p = sg * f1
        # the extra's ramp: within one step of the last one, and not past 0 while it can reach it
        lo = p - step
        if lo < 0.0:
            lo = 0.0 if p + step >= 0.0 else p + step
        if fm is not None and lo > fm - spring:
            # but not past the device's limit: where the spring rose by more than the ramp
            # gives way (a reading that jumped several counts), the extra yields at once
            # (holding less is never active; the total stays at the limit, no step down)
            lo = fm - spring
        # and the whole force rises by at most that step: the extra gives way to the spring's
        # rise (item 3)
        hi = p + step
        if rise > 0.0:
            hi -= rise
        if hi > target:
            hi = target
        if hi < lo:
            hi = lo
        if rise < 0.0 < p:
            # and falls by at most that step where the book affords it: the extra takes up
            # what the spring gave up this tick, never above what it held (item 7)
            hold = p - step - rise
            if hold > p:
                hold = p
            if hold > hi:
                hi = hold
        a = hi
        if energy_bound and hi > lo:
            # the arm's motion over the next tick: the last two ticks' mean, its reading
            # error (half a count; Delta/n after n > 2 ticks at one reading), 1.5 x the
            # largest change of motion of the window carried through the ramp (with what a
            # change of the held force gives the free arm), and the third difference
            lead = (sg * ahead + (1.5 + 0.5 * hi / step) * jerk + j3
                    + q / (still if still > 2 else 2))
            c_m = dt * dt / (2.0 * m) if m else 0.0
            A = e0 - u
            if tw > 0.0:
                # a turn's part of the move, half the force held this tick times tw, booked
                # on the commit: the spring's share off the budget, the extra's per newton
                # on the tick it is held (the plan's sum of the ramp is at least it)
                A -= 0.5 * spring * tw
                lead += 0.5 * tw
            if p == 0.0 and lo == 0.0 and A < 0.0 and 0.0 < lead + 2.0 * h < _INF and c_m < _INF:
                # the bound spent and no extra held, the common tick of a spent book: the
                # plan's answer is lo (the second exit of _affordable_scalar), decided here
                # without the call. Its cost is 0 at lo = p = 0 and rises from there (lead + 2 h
                # > 0 per unit of the ramp's sum, plus c_m >= 0 times its square), so no force
                # fits under A < 0. A slope or c_m that overflowed takes the plan's other paths
                # (a reading that overflows the slope overflows the book first, so A is not
                # finite then)
                a = lo
            else:
                a = _affordable_scalar(A, lo, hi, p, lead, c_m, step, h)
                if a == lo and lo > 0.0 and A < 0.0 and _cost_scalar(lo, p, lead, c_m, step, h) > A:
                    # the book is overdrawn (the hand outran the plan) and even the ramp down
                    # does not fit: the energy goal before the ramp, the extra falls to the
                    # largest force that fits, else to the one of least cost (item 3, "when
                    # the book is overdrawn")
                    a = _below_ramp_scalar(A, lo, p, lead, c_m, step, h)
                    self.below_ramp_ticks += 1
                elif (a == lo and rise < 0.0 < p and A > 0.0 and rest > 2
                      and abs(dq) <= q + _BRANCH_TOL * (abs(x_mm) + abs(x1)) * 1e-3):
                    # the reading moved out by one count after a rest long enough for the
                    # plan's speed estimate to shrink below half a count (more than 2
                    # ticks), and nothing fits, not even the ramp down, which is taken
                    # anyway: the extra's take-up of the spring's fall is priced at what it
                    # adds to that ramp (the same encoder term; the work of holding more),
                    # within what is left of the allowance, so that the whole force falls
                    # by at most s (item 3, "the count crossing")
                    base = _cost_scalar(lo, p, lead, c_m, step, h)
                    hold = p - step - rise
                    if hold > p:
                        hold = p
                    if base > A and hold > lo:
                        a = _affordable_scalar(A + base, lo, hold, p, lead, c_m, step, h)
        if a < target:
            self.active_ticks += 1
            self.withheld_n_ticks += target - a
            if u >= e0:
                self.spent_ticks += 1
                if not self._said:
                    self._say_spent(u, e0)
        out = spring + sg * a
        self._sent = out
        return out

    def _say_spent(self, u: float, e0: float) -> None:
        """Log, once per controller, that its bound is spent: from here on the force above
        the spring waits for credit (docs/runtime.md, Passivity item 7)."""
        self._said = True
        b = self.settings.trusted_damping_ns_per_m()
        _log.warning(
            "stiff-wall controller: its energy bound is spent (%.3g uJ booked of the %.3g uJ allowed), so the force "
            "above the Colgate spring is held back until the hand's motion earns credit; %s (docs/runtime.md, "
            "Passivity item 7)", u * 1e6, e0 * 1e6,
            "no damping is credited, so the spring is 0 and the arm renders no wall: measure the arm's damping hands "
            "off (hapticsdk calibrate damping --device NAME --save)" if not b else f"the spring takes {b:.3g} N s/m of credited damping")

    def commit(self, f_applied: float) -> None:
        """Record the force the device actually held over the coming interval (N). Without
        a commit before the next :meth:`step`, that step takes the force the last one
        returned as applied."""
        self._pending = False
        if not -_INF < f_applied < _INF:   # NaN or infinite: none applied
            f_applied = 0.0
        if self._tw:
            # the turn's part of the move, at half the force applied (step's turned_mm)
            self.energy_j += 0.5 * f_applied * self._tw
            self._tw = 0.0
        sp = self._spring
        if 0.0 < sp and f_applied < sp:
            # the device applied less than the spring (a safety layer's start ramp or clamp):
            # the spring held over the coming interval is the force applied, its anchor moved
            # in to match. Its stored energy only falls, and where it is on its K_c branch
            # what the move took out is credit: the spring's true work is at most minus it
            # (docs/runtime.md, Passivity item 0, "A spring the device did not apply")
            kc = self._kc
            depth = -self._q1 * 1e-3
            fa = f_applied if f_applied > 0.0 else 0.0
            dw = self._dw
            if abs(sp - kc * (depth - self._o)) <= _BRANCH_TOL * sp:
                self.energy_j -= (sp * sp - fa * fa) / (2.0 * kc)
                if dw:
                    # where the wall moved the depth by dw, the scene's move paid the spring's
                    # rise at the mean of the forces applied, not of the spring: the part of
                    # the stored energy above is unpaid ("A moving wall")
                    self.energy_j += 0.5 * (sp - fa) * dw
            elif dw > 0.0:
                self.energy_j += 0.5 * (sp - fa) * dw
            self._spring = fa
            if fa > 0.0:
                self._o = depth - fa / kc
                self._kf = kc
            else:
                self._kf = self._kc = 0.0
                self._o = depth if depth > 0.0 else 0.0
        self._f2 = self._f1
        self._f1 = f_applied - self._spring   # the extra actually held (the ramp starts from it)
        self._a3 = self._a2
        self._a2 = self._a1
        self._a1 = f_applied

    def report(self) -> dict[str, float]:
        """``energy_bound_j`` (U, J: upper bound of the energy given to the user over the
        current contact; the credit is dropped between contacts), ``overdrawn_j`` (largest
        ``U - E0``, J: > 0 only when the motion outran the one-tick prediction),
        ``withheld_n_ticks`` (N), ``active_ticks``, ``spent_ticks`` (the ticks of
        ``active_ticks`` on which the bound was spent, ``U >= E0``: the force above the
        spring waits for credit; with no damping credited the spring is 0 and the wall is
        gone until then), ``below_ramp_ticks`` (ticks on which the book was overdrawn, ``U >
        E0``, and the extra fell below its ramp to a force the plan affords: a step beyond
        the ramp, taken for the energy bound). The first spent tick is logged as a warning
        (once per controller)."""
        return {"energy_bound_j": self.energy_j, "overdrawn_j": self.overdrawn_j,
                "withheld_n_ticks": self.withheld_n_ticks, "active_ticks": self.active_ticks,
                "spent_ticks": self.spent_ticks, "below_ramp_ticks": self.below_ramp_ticks}
