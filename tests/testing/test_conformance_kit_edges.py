"""Two kit gaps found by a probe of broken third-party plugins:

* ``output-follows-command`` sampled 10..90 % of the declared ranges, so a device that
  cannot reach its declared full scale (an amplifier that saturates at 90 % of the
  declared maximum, a coil that cannot go down to its declared lowest frequency) passed
  with dishonest limits; it now also holds the edges of the declared limits;
* ``privileged-options`` gave up on any constructor with a ``**kwargs`` not named
  ``options``, so a misspelt privileged name (``"libary"``) passed and a scene file could
  set the real option (``library``: native code); and it judged only the class's own
  ``__init__``, so a subclass forwarding ``**options`` to a parent that takes the option
  was refused. It now asks the constructor itself whether it takes each name.
"""

from __future__ import annotations

from typing import Any, ClassVar

import pytest

from hapticsdk.devices.actuators import Actuator, ActuatorLimits
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.testing import check_actuator, check_device
from hapticsdk.testing.conformance import format_report
from kit_variants import API, ForceArm, rules_of


class Coil(Actuator):
    """A correct coil: outputs what it is sent, anywhere in its declared 30..300 Hz and up
    to its declared 2 V; reports what it outputs."""
    hapticsdk_api = API
    name: ClassVar[str] = "kit-edge-coil"
    channel: ClassVar[str] = "vibration"
    simulated: ClassVar[bool] = True
    readback_source: ClassVar[str] = "output"
    limits = ActuatorLimits(frequency_range_hz=(30.0, 300.0), max_amplitude=2.0, amplitude_unit="V",
                            amplitude_resolution=0.001, frequency_resolution_hz=0.5)
    #: what the hardware really does (the broken variants narrow it)
    lowest_hz = 30.0
    highest_hz = 300.0
    saturation_v = 2.0

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.out = (0.0, 0.0)

    def _open(self) -> None:
        self.out = (0.0, 0.0)

    def _command(self, cmd: ChannelCommand) -> None:
        f = min(max(float(cmd.frequency_hz or 0.0), self.lowest_hz), self.highest_hz)
        self.out = (f, min(float(cmd.amplitude or 0.0), self.saturation_v))

    def _stop(self) -> None:
        self.out = (self.out[0], 0.0)

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("vibration", frequency_hz=self.out[0], amplitude=self.out[1])


def _variant(base: type, name: str, doc: str, **attrs: Any) -> type:
    return type(name, (base,), {"__doc__": doc, "name": f"kit-edge-{name.lower()}", **attrs})


# each narrower than it declares, by a share the old 10..90 % sample never reached
EDGE_VARIANTS = [
    _variant(Coil, "TopCoil", "Declares 2 V; its amplifier saturates at 1.9 V.", saturation_v=1.9),
    _variant(Coil, "LowCoil", "Declares 30 Hz; it cannot go below 50 Hz.", lowest_hz=50.0),
    _variant(Coil, "HighCoil", "Declares 300 Hz; it cannot go above 285 Hz.", highest_hz=285.0),
    _variant(ForceArm, "Arm", "Declares 3 N; its motors saturate at 2.85 N.", saturation_n=2.85),
]


def _check(cls: type):
    return check_device(cls) if issubclass(cls, ForceArm) else check_actuator(cls)


@pytest.mark.parametrize("cls", [Coil, ForceArm])
def test_an_actuator_that_reaches_its_declared_limits_conforms(cls):
    assert _check(cls) == []


@pytest.mark.parametrize("cls", EDGE_VARIANTS, ids=[c.__name__ for c in EDGE_VARIANTS])
def test_an_actuator_short_of_its_declared_limits_is_caught(cls):
    v = _check(cls)
    assert "output-follows-command" in rules_of(v), format_report(v)
    assert all(x.plugin == cls.name for x in v)


# -- privileged options named against the constructor ---------------------------

class _LibraryCoil(Coil):
    """Loads a native library named by ``library`` (an option only code may set); its
    constructor takes other options through ``**kw``."""

    def __init__(self, *, library: str | None = None, **kw: Any) -> None:
        super().__init__(**kw)
        self.library = library


class TypoKwCoil(_LibraryCoil):
    """Declares ``libary``: the real option ``library`` stays settable from a scene file."""
    name: ClassVar[str] = "kit-edge-privtypo-kw"
    privileged_options: ClassVar = ("libary",)


class GoodKwCoil(_LibraryCoil):
    name: ClassVar[str] = "kit-edge-priv-kw"
    privileged_options: ClassVar = {"library": "native library"}


class ForwardingCoil(GoodKwCoil):
    """Correct: its own constructor forwards ``**options`` to the parent that takes
    ``library``."""
    name: ClassVar[str] = "kit-edge-priv-forward"

    def __init__(self, **options: Any) -> None:
        super().__init__(**options)


class TypoForwardingCoil(ForwardingCoil):
    """The same forwarding constructor, a misspelt declaration."""
    name: ClassVar[str] = "kit-edge-privtypo-forward"
    privileged_options: ClassVar = ("Library",)


@pytest.mark.parametrize("cls", [GoodKwCoil, ForwardingCoil])
def test_privileged_options_the_constructor_takes_conform(cls):
    assert check_actuator(cls) == []


@pytest.mark.parametrize("cls", [TypoKwCoil, TypoForwardingCoil])
def test_a_privileged_name_the_constructor_does_not_take_is_caught(cls):
    v = check_actuator(cls)
    assert rules_of(v) == {"privileged-options"}, format_report(v)
    assert "protects nothing" in format_report(v)
