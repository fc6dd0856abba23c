"""Kit rule ``close``: a simulated actuator's own model must be at rest once closed. The
core's ``read_back()`` reports rest for any closed actuator without asking the backend, so
a backend whose ``_close`` re-sends a drive (a queue "flushed" after the stop) passed;
the kit now asks the simulated backend itself after its declared settle time."""

from __future__ import annotations

from typing import ClassVar

import pytest

from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.testing import check
from kit_variants import LagCoil


class _FlushOnClose(LagCoil):
    """Its _close re-sends the last non-zero drive after the stop."""

    name = "kit-flush-on-close"
    _last = 0.0

    def _command(self, cmd: ChannelCommand) -> None:
        super()._command(cmd)
        if self.drive_a:
            self._last = self.drive_a

    def _close(self) -> None:
        self.drive_a = self._last


class _RefusesWhenClosed(LagCoil):
    """A backend that refuses to be read once closed: not a violation."""

    name = "kit-refuses-closed"

    def _read_back(self) -> ChannelCommand:
        if not self.is_open:
            raise OSError("port closed")
        return super()._read_back()


@pytest.mark.parametrize("cls", [LagCoil, _RefusesWhenClosed])
def test_honest_simulated_actuators_pass(cls):
    v = check("actuator", cls)
    assert not [x for x in v if x.rule == "close"], v


def test_a_drive_resent_by_close_is_caught():
    v = [x for x in check("actuator", _FlushOnClose) if x.rule == "close"]
    assert v and "after close()" in v[0].message, v


class _HoldsAPort(LagCoil):
    """Takes a resource in open() and gives it back in _close (a port, a thread)."""

    name = "kit-holds-a-port"
    held: ClassVar[set[int]] = set()

    def _open(self) -> None:
        super()._open()
        type(self).held.add(id(self))

    def _close(self) -> None:
        type(self).held.discard(id(self))
        super()._close()


def test_the_close_rule_releases_what_its_injected_failure_left_open():
    """The rule checks that a failing backend ``_close`` is reported; that failure is the
    kit's own, so the instance's backend is then closed for real. Left open, its port and
    threads outlived the rule and shared the device with the next one (an emulated serial
    bridge saw a second owner's writes and reported the link lost under load)."""
    _HoldsAPort.held.clear()
    v = [x for x in check("actuator", _HoldsAPort, rules=["close"]) if x.rule == "close"]
    assert not v, v
    assert not _HoldsAPort.held, f"{len(_HoldsAPort.held)} instance(s) still hold their resource"
