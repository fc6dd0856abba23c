"""Kit rules widened after an external round of broken plugins (round 4), each broken
variant passed by the kit before:

* ``renderer``: a command that turns non-finite or negative only beyond the kit's own
  ticks (deeper than 3 mm, faster than 400 mm/s: the sweep of penetrations and speeds),
  or only after many ticks of one renderer (the long run);
* ``renderer``: a renderer that keeps something of every tick (its memory grows with
  the run);
* ``timing`` (dimension): a tick that now and then blocks longer than the safety layer's
  restart gap (the fastest of 25 ticks hid it);
* ``vectorised`` (model): predictions that change with the batch's size above the 33 rows
  the rule compared, a ``predict`` that writes into the caller's array, and one that keeps
  something of every batch (its memory grows with the calls);
* ``reopen`` (actuator): an instance whose ``stop()`` or ``close()`` works in its first
  open only (a latch or a handle that ``_open`` does not reset);
* ``hookimpls``: a hook that takes nothing answering what its hookspec does not say (a
  dict for a list, a material the schema refuses, features as one string, a material
  name given twice or taken by the shipped library, a NaN intensity or an infinite feature).

The correct variants conform."""

from __future__ import annotations

import collections
import time
import types
from typing import Any, Callable, ClassVar

import numpy as np
import pytest

from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer
from hapticsdk.perception.materials import load_library
from hapticsdk.plugins import registry
from hapticsdk.testing import check, check_dimension, check_model
from hapticsdk.testing.conformance import format_report
from kit_variants import API, LAG_COIL_MAX_V, BuzzModel, LagCoil, coil_dimension, registered, rules_of

Amp = Callable[[Any, float, int], float]


class _Coil(DimensionRenderer):
    """Vibration at 100 Hz in contact, amplitude ``amp(inp, x, k)`` (tick ``k`` of this
    renderer), 0 out of contact; a broken variant swaps ``amp``."""
    roles = ("buzz",)
    amp: ClassVar[Amp]

    def __init__(self, x: float) -> None:
        self.x, self.k = x, 0

    def tick(self, inp):
        self.k += 1
        a = type(self).amp(inp, self.x, self.k) if inp.in_contact else 0.0
        return [ChannelCommand("buzz", frequency_hz=100.0, amplitude=a)]


def _good(inp: Any, x: float, k: int) -> float:
    return 0.5 * LAG_COIL_MAX_V * (0.2 + 0.8 * x) * min(1.0, abs(inp.penetration_mm))


_Coil.amp = staticmethod(_good)
#: a correct dimension: vibration on the lagging coil, its amplitude saturating with depth
BuzzDim = coil_dimension("kit-buzz", "kit.b", _Coil, "kit-buzz-model")


@pytest.fixture
def installed():
    yield from registered([(registry("actuator"), "kit-lag-coil", LagCoil), (registry("dimension"), "kit-buzz", BuzzDim),
                           (registry("model"), "kit-buzz-model", BuzzModel)])


def _buzz(amp: Amp) -> type:
    coil = type("BrokenCoil", (_Coil,), {"amp": staticmethod(amp)})
    return type("BrokenBuzz", (BuzzDim,), {"renderer_cls": coil})


def _stall_every_300(inp: Any, x: float, k: int) -> float:
    if k % 300 == 0:
        time.sleep(0.06)     # > restart_after_s (50 ms)
    return _good(inp, x, k)


DIMENSION_VARIANTS = [
    # NaN only deeper than the kit's ticks (3 mm): a 1/(depth - 4 mm) in the formula
    (lambda inp, x, k: _good(inp, x, k) / (4.0 - inp.penetration_mm) if inp.penetration_mm < 4 else float("nan"),
     "renderer", "amplitude=nan"),
    # negative amplitude only deeper than 3 mm
    (lambda inp, x, k: -1.0 if inp.penetration_mm > 5 else _good(inp, x, k), "renderer", "negative amplitude"),
    # non-finite only faster than the kit's ticks (400 mm/s)
    (lambda inp, x, k: _good(inp, x, k) * (1.0 if np.abs(inp.velocity_mm_s).max() < 500 else float("inf")),
     "renderer", "amplitude=inf"),
    # NaN only after 5000 ticks of one renderer (a diverging state)
    (lambda inp, x, k: float("nan") if k > 5000 else _good(inp, x, k), "renderer", "of a run"),
    (_stall_every_300, "timing", "blocked"),
]


def test_the_correct_dimension_and_model_conform(installed):
    assert check_dimension(BuzzDim) == []
    assert check_model(BuzzModel) == []


@pytest.mark.parametrize("amp, rule, why", DIMENSION_VARIANTS,
                         ids=["nan-deep", "negative-deep", "inf-fast", "nan-after-5000", "tick-stall"])
def test_each_broken_dimension_is_caught_by_its_rule(installed, amp, rule, why):
    # the stalling renderer runs its own rule only: its sleeps would cost seconds elsewhere
    v = check("dimension", _buzz(amp), rules=[rule]) if rule == "timing" else check_dimension(_buzz(amp))
    assert rule in rules_of(v), format_report(v)
    assert why in format_report(v)


class _History(_Coil):
    """A correct :class:`_Coil` that also keeps the depth of its last ``keep`` ticks (a
    smoothing window); ``keep=None`` keeps every tick's (a history that grows per tick)."""
    keep: ClassVar[int | None] = None

    def __init__(self, x: float) -> None:
        super().__init__(x)
        self.depths: Any = [] if self.keep is None else collections.deque(maxlen=self.keep)

    def tick(self, inp):
        self.depths.append(float(inp.penetration_mm))
        return super().tick(inp)


def _history(keep: int | None) -> type:
    coil = type("HistoryCoil", (_History,), {"keep": keep})
    return type("HistoryBuzz", (BuzzDim,), {"renderer_cls": coil})


@pytest.mark.parametrize("keep, caught", [(None, True), (500, False), (6000, False)],
                         ids=["every-tick", "bounded-0.5s", "bounded-6s"])
def test_a_renderer_whose_memory_grows_every_tick_is_caught_by_renderer_rule(installed, keep, caught):
    """A history of every tick fails; the same window bounded (half a second, or six
    seconds, which has stopped growing by the last two points) conforms."""
    v = check("dimension", _history(keep), rules=["renderer"])
    assert (rules_of(v) == {"renderer"}) is caught, format_report(v)
    assert ("holds more memory the longer it runs" in format_report(v)) is caught


class _SizeModel(BuzzModel):
    def _out(self, X, y):
        return np.clip(y + 0.3, 0, 1) if X.shape[0] > 1000 else y      # a large batch reads another path


class _OutOfRangeInLargeBatches(BuzzModel):
    def _out(self, X, y):
        if X.shape[0] > 1000:
            y = y.copy()
            y[-1] = 1.5          # the batch's rows beyond the compared ones
        return y


class _WritesInput(BuzzModel):
    def _out(self, X, y):
        X -= 0.0 * X + 1e-3       # normalises in place: the caller's array
        return y


class _KeepsBatches(BuzzModel):
    """Keeps every batch's intensities (an unbounded cache, or a debug history)."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: list[np.ndarray] = []

    def _out(self, X, y):
        self.seen.append(y.copy())
        return y


class _CachesLast100(_KeepsBatches):
    """Correct: keeps the intensities of its last 100 batches only (a bounded cache)."""

    def _out(self, X, y):
        y = super()._out(X, y)
        del self.seen[:-100]
        return y


@pytest.mark.parametrize("factory, rule, why", [
    (_SizeModel, "vectorised", "batch of 10000 rows"),
    (_OutOfRangeInLargeBatches, "vectorised", "outside 0..1"),
    (_WritesInput, "vectorised", "changed its input array"),
    (_KeepsBatches, "vectorised", "holds more memory the more it is called"),
], ids=["batch-size", "range-in-large-batch", "writes-input", "keeps-every-batch"])
def test_each_broken_model_is_caught_by_its_rule(installed, factory, rule, why):
    v = check_model(factory)
    assert rule in rules_of(v), format_report(v)
    assert why in format_report(v)


def test_a_model_with_a_bounded_cache_conforms(installed):
    v = check_model(_CachesLast100)
    assert v == [], format_report(v)


# ---------------------------------------------------------------------------
# actuators: one instance's second life (reopen)
# ---------------------------------------------------------------------------

class StopLatchCoil(LagCoil):
    """Stops once per instance: a "stopped" latch that ``_open`` does not reset."""
    name: ClassVar[str] = "kit-lag-coil-latch"
    latched = False          # set on the instance by the first stop, never reset

    def _stop(self) -> None:
        if not self.latched:
            self.latched = True
            self.drive_a = 0.0


class CloseOnceCoil(LagCoil):
    """Releases its handle once per instance: a second ``_close`` (after a reopen) fails."""
    name: ClassVar[str] = "kit-lag-coil-close-once"
    released = False         # set on the instance by the first close, never reset

    def _close(self) -> None:
        if self.released:
            raise OSError("handle already released")
        self.released = True


@pytest.mark.parametrize("cls, why", [(StopLatchCoil, "after stop() in the second open"),
                                      (CloseOnceCoil, "failed while closing after the second open")],
                         ids=["stop-latch", "close-once"])
def test_an_instance_broken_in_its_second_life_is_caught_by_reopen(cls, why):
    assert check("actuator", LagCoil, rules=["reopen"]) == []
    v = check("actuator", cls, rules=["reopen"])
    assert "reopen" in rules_of(v), format_report(v)
    assert why in format_report(v)


class ReadBackGoesBadCoil(LagCoil):
    """Its read-back turns NaN after 200 reads (a counter that overflows a table): the
    servo loop's read-back then raises. The kit read back a handful of times."""
    name: ClassVar[str] = "kit-lag-coil-readback-200"
    reads = 0

    def _read_back(self) -> ChannelCommand:
        self.reads += 1
        rb = super()._read_back()
        if self.reads > 200:
            rb = ChannelCommand(rb.role, force_n=rb.force_n, frequency_hz=rb.frequency_hz, amplitude=float("nan"))
        return rb


def test_a_read_back_that_goes_bad_after_many_reads_is_caught_by_read_back_rule():
    assert check("actuator", LagCoil, rules=["read-back"]) == []
    v = check("actuator", ReadBackGoesBadCoil, rules=["read-back"])
    assert rules_of(v) == {"read-back"}, format_report(v)
    assert "read_back() failed after" in format_report(v) and "nan" in format_report(v)


# ---------------------------------------------------------------------------
# hook modules: answers of the wrong type
# ---------------------------------------------------------------------------

_MATERIAL = {"name": "kit-m", "intensities": {"hardness": 0.3, "roughness": 0.6}}
#: the name of a shipped material, in lower case (names are unique case-insensitive)
_SHIPPED = next(iter(load_library())).name.lower()


def _hooks(hook: str, answer: Any) -> types.ModuleType:
    from hapticsdk.hookspecs import hookimpl
    mod = types.ModuleType("kit_hooks_answers")
    mod.hapticsdk_api = API   # type: ignore[attr-defined]
    impl = hookimpl(lambda: answer)
    impl.__name__ = hook
    setattr(mod, hook, impl)
    return mod


def test_hooks_answering_what_their_hookspec_says_conform():
    assert check("hooks", _hooks("hapticsdk_materials", [_MATERIAL])) == []
    assert check("hooks", _hooks("hapticsdk_dimension_info",
                                 [{"name": "kit", "description": "d", "features": ["a"]}])) == []


@pytest.mark.parametrize("hook, answer, why", [
    ("hapticsdk_materials", _MATERIAL, "not a list"),                                   # one dict, not a list
    ("hapticsdk_materials", [{"name": "kit-m"}], "invalid material"),                   # no intensities
    ("hapticsdk_dimension_info", [{"name": "kit", "description": "d", "features": "a,b"}], "each entry is"),
    # names the core refuses when it adds them to the library: its other materials go too
    ("hapticsdk_materials", [_MATERIAL, {**_MATERIAL, "name": "KIT-M"}], "an earlier material of this answer"),
    ("hapticsdk_materials", [{**_MATERIAL, "name": _SHIPPED}], "the shipped library already has"),
    # numbers JSON cannot hold: a NaN passes the schema's 0..1, an infinity its "number"
    ("hapticsdk_materials", [{**_MATERIAL, "intensities": {"hardness": float("nan")}}], "intensities['hardness'] = nan"),
    ("hapticsdk_materials", [{**_MATERIAL, "features": {"GS": float("inf")}}], "features['GS'] = inf"),
], ids=["materials-dict", "materials-invalid", "dimension-info-features-str", "materials-name-twice",
        "materials-name-shipped", "materials-intensity-nan", "materials-feature-inf"])
def test_a_hook_answering_the_wrong_type_is_caught(hook, answer, why):
    v = check("hooks", _hooks(hook, answer))
    assert rules_of(v) == {"hookimpls"}, format_report(v)
    assert why in format_report(v)
