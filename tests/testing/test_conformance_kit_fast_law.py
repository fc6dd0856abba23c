"""The kit's ``renderer-fast-law`` rule: a renderer that offers a law on plain floats
(``DimensionRenderer._fast_law``, which the servo loop runs instead of ``tick`` in its
steady state, mixing the two tick by tick) must give what ``tick`` gives, bit for bit,
and share its state. A correct renderer with state conforms; each broken variant below is
caught by this rule alone, and a renderer offering no law is not judged by it."""

import pytest

from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer, _steady_law_of
from hapticsdk.testing.conformance import check, format_report

from kit_variants import LAG_COIL_MAX_V, buzz_dimension, buzz_installed, rules_of


def _level(x: float, speed: float, n: int, in_contact: bool) -> float:
    """The buzz's amplitude (V): 0 out of contact, else growing with ``x`` and the sliding
    ``speed`` (mm/s), at one of three levels by the tick count ``n``."""
    if not in_contact:
        return 0.0
    a = 0.25 * LAG_COIL_MAX_V * (0.2 + 0.8 * x) * min(1.0, speed / 100.0)
    return a * (1 + n % 3) / 3


class _Counted(DimensionRenderer):
    """Correct: a buzz whose amplitude grows with x and the sliding speed, and steps through
    three levels with a tick count it keeps (state shared by ``tick`` and the law)."""
    roles = ("buzz",)

    def __init__(self, x: float) -> None:
        self.x = x
        self.n = 0

    def tick(self, inp):
        self.n += 1
        vt = inp.velocity_floats_mm_s
        s = abs(vt[0]) if vt is not None else abs(float(inp.velocity_mm_s[0]))
        return [ChannelCommand("buzz", frequency_hz=100.0, amplitude=_level(self.x, s, self.n, inp.in_contact))]

    def _fast_law(self):
        x = self.x

        def law(t, dt, pen, in_contact, v0, v1, v2, vf0, vf1, vf2, step):
            self.n += 1
            return (None, 100.0, _level(x, abs(v0), self.n, in_contact))
        return law


class _Reordered(_Counted):
    """The law divides before it multiplies: the same value in exact arithmetic, not in floats."""

    def _fast_law(self):
        x = self.x

        def law(t, dt, pen, in_contact, v0, v1, v2, vf0, vf1, vf2, step):
            self.n += 1
            if not in_contact:
                return (None, 100.0, 0.0)
            a = 0.25 * LAG_COIL_MAX_V * (0.2 + 0.8 * x) * min(1.0, abs(v0) / 100.0)
            return (None, 100.0, a / 3 * (1 + self.n % 3))
        return law


class _OwnCount(_Counted):
    """The law counts in a cell of its own: alone it agrees with tick(), mixed it does not."""

    def _fast_law(self):
        x, n = self.x, [self.n]

        def law(t, dt, pen, in_contact, v0, v1, v2, vf0, vf1, vf2, step):
            n[0] += 1
            return (None, 100.0, _level(x, abs(v0), n[0], in_contact))
        return law


class _NoForceSlot(_Counted):
    """The law leaves out the force field of its one role: two values, not three."""

    def _fast_law(self):
        law = super()._fast_law()
        return lambda *a: law(*a)[1:]


class _SilentOutside(_Counted):
    """tick() returns no command out of contact: no law can stand for it there."""

    def tick(self, inp):
        cmds = super().tick(inp)
        return cmds if inp.in_contact else []

    def _fast_law(self):
        return super()._fast_law()


class _LawRaises(_Counted):
    """The law fails out of contact (where tick() does not)."""

    def _fast_law(self):
        law = super()._fast_law()

        def raising(t, dt, pen, in_contact, *rest):
            if not in_contact:
                raise ZeroDivisionError("no contact")
            return law(t, dt, pen, in_contact, *rest)
        return raising


class _NegZero(_Counted):
    """The law gives -0.0 where tick() gives 0.0: the loop would log another bit pattern."""

    def _fast_law(self):
        law = super()._fast_law()

        def signed(*a):
            f, fr, am = law(*a)
            return (f, fr, -am if am == 0.0 else am)
        return signed


class _TickBelow(_Counted):
    """A subclass that replaces tick() below the class defining the law: no law stands for
    it (the loop and the kit call its tick), so this rule does not judge it."""

    def tick(self, inp):
        return [ChannelCommand("buzz", frequency_hz=100.0, amplitude=0.0)]


@pytest.fixture
def installed():
    yield from buzz_installed(_Counted)


def test_a_renderer_with_state_and_a_law_that_shares_it_conforms(installed):
    v = check("dimension", buzz_dimension(_Counted))
    assert v == [], format_report(v)


@pytest.mark.parametrize("renderer, why", [
    (_Reordered, "from its law alone"),
    (_OwnCount, "from tick() and its law in turn"),
    (_NoForceSlot, "returned 2 values, not 3 per role"),
    (_SilentOutside, "tick() returned 0 commands for role 'buzz'"),
    (_LawRaises, "the law raised ZeroDivisionError"),
    (_NegZero, "from its law alone"),
], ids=["reordered-arithmetic", "own-state", "short-tuple", "no-command-out-of-contact", "raises", "negative-zero"])
def test_a_law_that_is_not_its_tick_is_caught(installed, renderer, why):
    v = check("dimension", buzz_dimension(renderer))
    assert rules_of(v) == {"renderer-fast-law"}, format_report(v)
    assert why in format_report(v)


def test_a_renderer_whose_tick_is_replaced_below_its_law_is_not_judged_by_the_law(installed):
    assert _steady_law_of(_TickBelow(0.5)) is None and callable(_steady_law_of(_Counted(0.5)))
    v = check("dimension", buzz_dimension(_TickBelow), rules=["renderer-fast-law"])
    assert "renderer-fast-law" not in rules_of(v), format_report(v)


@pytest.mark.parametrize("name", ["hardness", "roughness"])
def test_the_built_in_laws_are_their_ticks(name):
    v = check("dimension", name, rules=["renderer-fast-law"])
    assert "renderer-fast-law" not in rules_of(v), format_report(v)
    from hapticsdk.plugins import registry
    d = registry("dimension").load(name)()
    r = d.renderer({f.name: 0.5 * (f.lower + f.upper) for f in d.features})
    assert callable(_steady_law_of(r)), "the rule above must have had a law to judge"
