"""Kit rules on what a plugin does in use rather than in the kit's own short holds.

* ``output-follows-command``: a simulated actuator declaring ``readback_source =
  "output"`` and a settle time whose read-back shows every new command the instant it is
  written (no simulated time passed) reports its drive record, not the output.
* ``close``: a thread started while the actuator was open still running after
  ``close()`` (one more per reopen).
* ``timing`` (actuator): a ``command()`` that now and then blocks longer than the safety
  layer's restart gap.
* ``servo-loop``: an actuator that follows its commands under the kit but not when the
  core's ServoLoop drives it from a thread of its own.
* ``determinism`` (dimension): commands that depend on the absolute wall clock.
* ``timing`` (dimension): a tick whose cost grows with the length of the run.
* ``renderer``: non-finite commands at a feature value inside the declared range (the
  tenths of each range are rendered, not only the middle and the ends).

Each broken variant is caught by its rule, and was passed by the kit before the rule
was added or widened; the correct variants conform."""

from __future__ import annotations

import queue
import threading
import time
from collections import deque
from typing import Any, ClassVar

import numpy as np
import pytest

from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer
from hapticsdk.perception.features import Feature, FeatureSpace
from hapticsdk.perception.models import PerceptionModel
from hapticsdk.plugins import registry
from hapticsdk.testing import check, check_dimension
from hapticsdk.testing.conformance import format_report
from kit_variants import LagCoil, coil_dimension, registered, rules_of

# ---------------------------------------------------------------------------
# actuators
# ---------------------------------------------------------------------------


class EchoCoil(LagCoil):
    """Declares its read-back the output, but reports the drive it was last sent (its
    amplifier's output, twice the drive, is never read)."""
    name: ClassVar[str] = "kit-echo-coil"

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("vibration", frequency_hz=self.drive_f, amplitude=self.drive_a)


class WriterCoil(LagCoil):
    """Writes through a worker thread fed by a queue, which close() leaves running."""
    name: ClassVar[str] = "kit-writer-coil"
    joins = False

    def _open(self) -> None:
        super()._open()
        self.q: queue.Queue = queue.Queue()
        self.worker = threading.Thread(target=self._drain, name="kit-writer", daemon=True)
        self.worker.start()

    def _drain(self) -> None:
        while self.q.get() is not None:
            pass

    def _command(self, cmd: ChannelCommand) -> None:
        super()._command(cmd)
        self.q.put(cmd)

    def _close(self) -> None:
        if self.joins:
            self.q.put(None)
            self.worker.join()


class JoiningWriterCoil(WriterCoil):
    """Correct: close() ends its worker and joins it."""
    name: ClassVar[str] = "kit-joining-writer-coil"
    joins = True


class FlushStallCoil(LagCoil):
    """Every 64th write flushes a buffer and blocks 80 ms (a USB write that waits)."""
    name: ClassVar[str] = "kit-flush-stall-coil"

    def _open(self) -> None:
        super()._open()
        self.writes = 0

    def _command(self, cmd: ChannelCommand) -> None:
        super()._command(cmd)
        self.writes += 1
        if self.writes % 64 == 0:
            time.sleep(0.08)


class ThreadNameCoil(LagCoil):
    """Hostile: doubles its drive unless it is called from a thread the kit named."""
    name: ClassVar[str] = "kit-thread-name-coil"

    def _command(self, cmd: ChannelCommand) -> None:
        super()._command(cmd)
        if not threading.current_thread().name.startswith("hapticsdk-kit"):
            self.drive_a *= 2.0


ACTUATOR_VARIANTS = [(EchoCoil, "output-follows-command"), (WriterCoil, "close"), (FlushStallCoil, "timing"),
                     (ThreadNameCoil, "servo-loop")]


@pytest.mark.parametrize("cls, rule", ACTUATOR_VARIANTS, ids=[c.__name__ for c, _ in ACTUATOR_VARIANTS])
def test_broken_actuators_are_caught_by_their_rule(cls, rule):
    v = check("actuator", cls)
    assert rules_of(v) == {rule}, format_report(v)
    if cls is FlushStallCoil:   # the stall's report names the restart gap and the call
        assert "restart_after_s 50 ms" in format_report(v) and "call 64 " in format_report(v), format_report(v)


@pytest.mark.parametrize("cls", [LagCoil, JoiningWriterCoil])
def test_correct_actuators_conform(cls):
    v = check("actuator", cls)
    assert v == [], format_report(v)


def test_the_leak_report_names_the_thread():
    v = check("actuator", WriterCoil, rules=["close"])
    assert "'kit-writer'" in format_report(v), format_report(v)


# ---------------------------------------------------------------------------
# dimensions
# ---------------------------------------------------------------------------


def _buzz(inp: Any, x: float, gain: float = 1.0) -> list[ChannelCommand]:
    if not inp.in_contact:
        return [ChannelCommand("buzz", frequency_hz=100.0, amplitude=0.0)]
    speed = abs(float(inp.velocity_mm_s[0]))
    return [ChannelCommand("buzz", frequency_hz=min(300.0, 30.0 + speed), amplitude=(0.2 + 1.5 * x) * gain)]


class Buzz(DimensionRenderer):
    """Correct: amplitude from x, frequency from the sliding speed."""
    roles = ("buzz",)

    def __init__(self, x: float) -> None:
        self.x = x

    def tick(self, inp: Any) -> list[ChannelCommand]:
        return _buzz(inp, self.x)


class HourlyDrift(Buzz):
    """Lowers its gain every second hour of the wall clock (a duty cycle read from
    time.time(); the same within one hour, so two renderers made a moment apart agree)."""

    def tick(self, inp: Any) -> list[ChannelCommand]:
        return _buzz(inp, self.x, 0.8 if int(time.time() // 3600) % 2 else 1.0)


class DayOfYear(Buzz):
    """Its gain follows the season (time.localtime().tm_yday)."""

    def tick(self, inp: Any) -> list[ChannelCommand]:
        return _buzz(inp, self.x, 1.0 - 0.1 * (time.localtime().tm_yday > 180))


class MedianOfAll(Buzz):
    """Scales by the median of every penetration it was ever given (the history grows)."""

    def __init__(self, x: float) -> None:
        super().__init__(x)
        self.seen: list[float] = []

    def tick(self, inp: Any) -> list[ChannelCommand]:
        self.seen.append(float(inp.penetration_mm))
        return _buzz(inp, self.x, 1.0 + 1e-3 * float(np.median(self.seen)))


class MedianOfLast(MedianOfAll):
    """Correct: the median of the last 100 penetrations (bounded state)."""

    def __init__(self, x: float) -> None:
        super().__init__(x)
        self.seen = deque(maxlen=100)   # type: ignore[assignment]


#: a gain table of ten bands of x with one entry mistyped
_GAINS = [1.0] * 10
_GAINS[4] = float("nan")


class BandTable(Buzz):
    """Looks its gain up in a table of ten bands of x; the band 0.4..0.5 is NaN."""

    def tick(self, inp: Any) -> list[ChannelCommand]:
        return _buzz(inp, self.x, _GAINS[min(int(self.x * 10), 9)])


class InUseModel(PerceptionModel):
    def __init__(self) -> None:
        space = FeatureSpace((Feature("kit-use.x", "1", 0.0, 1.0),))
        super().__init__(space.names, ("kit-use",), feature_space=space, name="kit-use-model")

    def _predict(self, X: np.ndarray) -> np.ndarray:
        return 0.5 * (1 + np.tanh(2 * X[:, :1] - 1))


UseDim = coil_dimension("kit-use", "kit-use.x", Buzz, "kit-use-model")


def _dim(renderer: type) -> type:
    return type(f"UseDim{renderer.__name__}", (UseDim,), {"renderer_cls": renderer})


@pytest.fixture
def installed():
    yield from registered([(registry("actuator"), "kit-lag-coil", LagCoil),
                           (registry("model"), "kit-use-model", InUseModel)])


#: the rules each variant breaks: a history of every tick costs more per tick (timing) and
#: holds more memory (renderer) the longer the run
DIMENSION_VARIANTS = [(HourlyDrift, {"determinism"}), (DayOfYear, {"determinism"}),
                      (MedianOfAll, {"timing", "renderer"}), (BandTable, {"renderer"})]


@pytest.mark.parametrize("renderer, rules", DIMENSION_VARIANTS, ids=[r.__name__ for r, _ in DIMENSION_VARIANTS])
def test_broken_dimensions_are_caught_by_their_rule(installed, renderer, rules):
    v = check_dimension(_dim(renderer))
    assert rules_of(v) == rules, format_report(v)


@pytest.mark.parametrize("renderer", [Buzz, MedianOfLast])
def test_correct_dimensions_conform(installed, renderer):
    v = check_dimension(_dim(renderer))
    assert v == [], format_report(v)


def test_the_clock_rule_restores_the_clocks(installed):
    names = ("time", "monotonic", "perf_counter", "time_ns", "monotonic_ns", "perf_counter_ns", "localtime", "gmtime")
    clocks = [getattr(time, n) for n in names]
    check_dimension(_dim(HourlyDrift))
    assert [getattr(time, n) for n in names] == clocks
