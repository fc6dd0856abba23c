"""Real DRV2667 piezo actuators: ``piezo-serial`` and ``piezo-mcp2221``.

Both drive the DRV2667 in waveform-synthesis mode (mode 3): one chunk of whole cycles,
whose amplitude, frequency and cycles bytes are rewritten when the command changes
(frequency in 7.8125 Hz steps, amplitude in full-scale/255 steps; each chunk starts and
ends at a zero crossing, so updates land on chunk boundaries, at most ``CHUNK_S`` = 4 ms
apart above 250 Hz, one cycle apart below). The amplitude is ramped in software by at
most full scale per ``ramp_s`` (>= 5 ms) so the 20 mm/s gate never clicks. STATUS is
read every ``status_interval_s`` (also a keep-alive for the bridge watchdog); a fault
bit stops the piezo.

Chip-side dead-man's switch (issue 13: the chip must stop by itself when the host can no
longer reach it, e.g. MCP2221A unplugged or serial link gone): the waveform's repeat count
is finite, so each GO plays a bounded time, and the host re-arms it with a GO write
before it runs out. Per frequency code ``c`` (f = 7.8125 Hz * c): ``cycles(c) =
max(1, floor(CHUNK_S * f))`` (chunk time ``Tc(c) = cycles / f``), ``repeat(c) =
ceil(chip_window_s / Tc(c))`` (so one GO plays at least ``chip_window_s``, default
15 ms, and less than ``chip_window_s + Tc``). The host re-arms (page 0, CONTROL2 = GO)
every ``rearm_s`` (default 4 ms, also counted in commands: every ``rearm_s / period_s``
commands) and at once when the repeat count changes with the frequency. Continuity:
a re-arm lands at least ``chip_window_s - rearm_s`` (11 ms) before the play would end,
so commands flowing with gaps shorter than that never leave a gap in the output. Bound:
after the last re-arm that reached the chip, it plays at most the chunk in progress plus
``repeat`` chunks: :meth:`DRV2667Actuator.chip_stop_bound_s` (max over the band's codes
of ``Tc``, plus max of ``repeat * Tc``): 22.7 ms for a band of 250..1992 Hz, 49.8 ms
for a band from 46.875 Hz, but 256 ms at 7.8125 Hz (two cycles), because a synthesis
cycle cannot be cut short; ``describe()["chip_stop"]`` reports it. Assumed,
not documented by TI (see docs/devices.md): a GO write during playback re-arms without
restarting the cycle in progress, and GO clears itself when the sequence ends.

Command deadline (host watchdog, :class:`hapticsdk.runtime.watchdog.CommandWatchdog`):
while open, a daemon thread puts the DRV2667 in standby when no command arrived for
``max(watchdog_s, 3 servo periods)`` (default ``watchdog_s`` 0.010 s; the servo period is
the larger of the ``period_s`` option and the period the servo loop gives the safety
layer). Its write takes the same lock as the servo thread's writes. The next command
wakes the chip again with the amplitude byte at 0 and ramps up (``ramp_s``). If the
standby write fails (MCP2221A unplugged or timing out, serial port gone) the actuator is
marked faulted (the servo thread's next command raises :class:`DeviceError`, so the loop
stops everything and reports it) and the failure is counted in ``describe()["watchdog"]``.

Safe state (``stop``): CONTROL2 = STANDBY (boost and amplifier off, GO cleared). On any
transport or device error the core's :meth:`Actuator.command` calls ``stop`` and raises a
:class:`~hapticsdk.errors.DeviceError` naming the actuator. pyserial / pyusb are imported
only inside ``open``, ``check_available`` and ``discover``.
"""

from __future__ import annotations

from abc import abstractmethod

import threading
import time
from collections.abc import Callable
from typing import Any, ClassVar

from hapticsdk.devices.actuators import Actuator, DriveCapability
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import DeviceError, ValidationError
from hapticsdk.runtime.watchdog import CommandWatchdog

from .drv2667 import (
    ADDRESS,
    DRV2667,
    FREQ_STEP_HZ,
    GAIN_FULL_SCALE_V,
    SYNTH_FREQ_RANGE_HZ,
    I2CBus,
    SynthChunk,
    amplitude_code,
    chunk_seconds,
    cycles_for,
    frequency_code,
    repeat_for,
)
from .virtual import piezo_limits

#: default shortest host-side command deadline (s) before the DRV2667 is put in standby
WATCHDOG_S = 0.010
#: allowed range of the ``watchdog_s`` option (s)
WATCHDOG_RANGE_S = (0.002, 0.25)
#: longest synthesis chunk (s) above 1/CHUNK_S Hz: cycles per chunk = floor(CHUNK_S * f)
CHUNK_S = 0.004
#: default shortest play time of one GO (s) (the chip-side dead-man's window)
CHIP_WINDOW_S = 0.015
#: default longest time between two GO re-arms while commands flow (s)
REARM_S = 0.004


#: default band of the hardware backends (Hz): from 6 synthesiser steps (46.875 Hz), where
#: the chip-side dead-man's switch stops the chip within 50 ms of the last GO that reached
#: it (``chip_stop_bound_s``; one cycle at 7.8 Hz alone lasts 128 ms), to the top code.
#: Lower frequencies need an explicit ``frequency_range_hz`` and lengthen that bound.
DEFAULT_BAND_HZ = (6 * FREQ_STEP_HZ, SYNTH_FREQ_RANGE_HZ[1])


class DRV2667Actuator(Actuator):
    """Base of the DRV2667 backends; subclasses build the bus in :meth:`_make_bus`.

    Options: ``gain`` (0..3 = 25/50/75/100 V peak; default 0, the safe start of
    docs/devices.md), ``frequency_range_hz`` (piezo band within 7.8125..1992 Hz),
    ``ramp_s`` (amplitude ramp, >= 0.005 s), ``period_s`` (servo period, s),
    ``status_interval_s`` (STATUS poll, s), ``address`` (I2C, 0x59), ``watchdog_s``
    (shortest command deadline before the host puts the chip in standby, 0.002..0.25 s,
    default 0.010; the deadline is at least 3 servo periods), ``chip_window_s`` (shortest
    play time of one GO, 0.005..0.04 s, default 0.015) and ``rearm_s`` (GO re-arm interval,
    0.001 s..``chip_window_s``/2, default 0.004): the chip-side dead-man's switch of the
    module docstring.
    """

    channel: ClassVar[str] = "vibration"
    accepts: ClassVar[dict[str, str]] = {"frequency_hz": "Hz", "amplitude": "V"}
    simulated: ClassVar[bool] = False
    #: raise the voltage the piezo gets: a scene or plan may give ``gain`` only up to the
    #: default (hapticsdk.devices.device_options.check_data_options)
    energy_options: ClassVar[dict[str, str]] = {"gain": "DRV2667 gain: full scale 25/50/75/100 V peak for 0..3"}
    limits = piezo_limits(0, None)  # replaced per instance (gain, band: DEFAULT_BAND_HZ)
    #: time source (s) of the re-arm and STATUS intervals; a test may set its own on an
    #: instance to run the host on an emulated chip's clock
    clock: Callable[[], float] = staticmethod(time.monotonic)

    def __init__(self, *, gain: int = 0, frequency_range_hz: tuple[float, float] | None = None,
                 ramp_s: float = 0.005, period_s: float = 0.001, status_interval_s: float = 0.05,
                 address: int = ADDRESS, watchdog_s: float = WATCHDOG_S, chip_window_s: float = CHIP_WINDOW_S,
                 rearm_s: float = REARM_S, **options: Any) -> None:
        # the default band starts where the chip-side stop bound is within 50 ms
        self.limits = piezo_limits(gain, DEFAULT_BAND_HZ if frequency_range_hz is None else frequency_range_hz)
        if ramp_s < 0.005 or period_s <= 0 or status_interval_s <= 0:
            raise ValidationError("ramp_s must be >= 0.005 s, period_s and status_interval_s > 0", field="options")
        if not (isinstance(watchdog_s, (int, float)) and WATCHDOG_RANGE_S[0] <= watchdog_s <= WATCHDOG_RANGE_S[1]):
            raise ValidationError(f"watchdog_s must be {WATCHDOG_RANGE_S[0]:g}..{WATCHDOG_RANGE_S[1]:g} s "
                                  f"(the command deadline cannot be turned off), got {watchdog_s!r}",
                                  field="options.watchdog_s")
        if not (isinstance(chip_window_s, (int, float)) and 0.005 <= chip_window_s <= 0.04):
            raise ValidationError(f"chip_window_s must be 0.005..0.04 s, got {chip_window_s!r}",
                                  field="options.chip_window_s")
        if not (isinstance(rearm_s, (int, float)) and 0.001 <= rearm_s <= chip_window_s / 2):
            raise ValidationError(f"rearm_s must be 0.001 s..chip_window_s/2 ({chip_window_s / 2:g} s), "
                                  f"got {rearm_s!r}", field="options.rearm_s")
        super().__init__(**options)
        self.gain = int(gain)
        self.ramp_s = float(ramp_s)
        self.period_s = float(period_s)
        self.status_interval_s = float(status_interval_s)
        self.address = int(address)
        self.bus: I2CBus | None = None
        self.drv: DRV2667 | None = None
        self._amp_v = 0.0
        self._freq = 0.0
        self._last_status = 0.0
        self.updates = 0
        self.watchdog_s = float(watchdog_s)
        #: serialises the servo thread's transport writes with the watchdog's
        self._io_lock = threading.RLock()
        self._watchdog: CommandWatchdog | None = None
        #: the chip is in standby (stop or watchdog): the next command wakes it
        self._asleep = True
        self.wakes = 0
        self.chip_window_s = float(chip_window_s)
        self.rearm_s = float(rearm_s)
        self._rearm_every = max(1, int(self.rearm_s / self.period_s + 1e-9))
        self._go_t = 0.0
        self._go_repeat = 0
        self._since_go = 0
        self.rearms = 0

    @abstractmethod
    def _make_bus(self) -> I2CBus:
        """The I2C bus the DRV2667 is on (a serial bridge, an MCP2221A), not yet used."""

    # -- backend API --------------------------------------------------------------------------
    def _open(self) -> None:
        bus = self._make_bus()
        try:
            drv = DRV2667(bus, address=self.address, device=self.label)
            drv.probe()
            drv.reset()
            drv.set_gain(self.gain)
            f0, f1 = self._band()
            self._freq = f0
            # the silent first chunk at the band's top: the shortest chunk, so the first
            # command's bytes play within CHUNK_S (one 128 ms cycle at 7.8 Hz otherwise)
            code = frequency_code(f1)
            cycles, repeat = self._synth_counts(code)
            drv.load_synthesis([SynthChunk(amplitude=0, frequency=code, cycles=cycles)], repeat=repeat)
            drv.check_status()
            drv.go()
            self._armed(repeat)
        except BaseException:
            try:
                DRV2667(bus, address=self.address, device=self.label).standby()
            except Exception:
                pass
            bus.close()
            raise
        self.bus, self.drv = bus, drv
        self._amp_v = 0.0
        self._asleep = False
        self._last_status = self.clock()
        self._watchdog = CommandWatchdog(self._watchdog_standby, deadline_s=self.command_deadline_s,
                                         lock=self._io_lock, on_error=self._watchdog_failed,
                                         name=f"watchdog {self.label}").start(armed=False)
        # armed by the first command: until then the chunk amplitude is 0 (0 V out)

    def _band(self) -> tuple[float, float]:
        """The piezo band (Hz); the synthesiser's range if the limits give none."""
        return self.limits.frequency_range_hz or SYNTH_FREQ_RANGE_HZ

    def _synth_counts(self, code: int) -> tuple[int, int]:
        """(cycles per chunk, repeat count) at frequency ``code`` (module docstring)."""
        cycles = cycles_for(code, CHUNK_S)
        return cycles, repeat_for(code, cycles, self.chip_window_s)

    def _armed(self, repeat: int) -> None:
        self._go_t = self.clock()
        self._go_repeat = repeat
        self._since_go = 0
        self.rearms += 1

    def chip_stop_bound_s(self) -> float:
        """Longest time (s) the DRV2667 can play after the last GO that reached it, over
        every frequency code of the band: the chunk in progress (at most the longest chunk)
        plus ``repeat`` chunks at the last frequency written (at most the longest
        ``repeat * Tc``). This is the stop time when the host can no longer write (USB
        unplugged, serial link gone, host process dead)."""
        lo, hi = self._band()
        longest_chunk = longest_play = 0.0
        for code in range(frequency_code(lo), frequency_code(hi) + 1):
            cycles, repeat = self._synth_counts(code)
            tc = chunk_seconds(code, cycles)
            longest_chunk, longest_play = max(longest_chunk, tc), max(longest_play, repeat * tc)
        return longest_chunk + longest_play

    def command_deadline_s(self) -> float:
        """The host watchdog's deadline (s): ``max(watchdog_s, 3 servo periods)``."""
        s = getattr(self.safety, "settings", None)
        period = max(self.period_s, float(getattr(s, "stale_after_s", 0.0) or 0.0))
        return max(self.watchdog_s, 3.0 * period)

    def _watchdog_standby(self) -> None:
        # watchdog thread, io lock held
        self._amp_v = 0.0
        self._asleep = True
        if self.drv is not None:
            self.drv.standby()

    def _watchdog_failed(self, exc: BaseException) -> None:
        # watchdog thread, io lock held: the servo thread's next command raises DeviceError
        self.fault = self.fault or DeviceError(
            f"no command for {self.command_deadline_s() * 1e3:.0f} ms and the standby write failed "
            f"({type(exc).__name__}: {exc}); the DRV2667 may still be playing", device=self.label)

    def _wake(self, drv: DRV2667) -> None:
        """After stop or a watchdog standby: silence the chunk first, then GO, and ramp up
        from 0 (so the old amplitude never plays on wake)."""
        self._amp_v = 0.0
        code = frequency_code(self._freq)
        cycles, repeat = self._synth_counts(code)
        drv.update_waveform(0, code, cycles, repeat)
        drv.go()
        self._armed(repeat)
        self._asleep = False
        self.wakes += 1

    def _command(self, cmd: ChannelCommand) -> None:
        with self._io_lock:
            drv = self._require()
            target = self._amp_v if cmd.amplitude is None else float(cmd.amplitude)
            if cmd.frequency_hz is not None:
                self._freq = float(cmd.frequency_hz)
            if self._asleep:
                self._wake(drv)
            step = GAIN_FULL_SCALE_V[self.gain] * self.period_s / self.ramp_s
            self._amp_v += max(-step, min(step, target - self._amp_v))
            code = frequency_code(self._freq)
            cycles, repeat = self._synth_counts(code)
            if drv.update_waveform(amplitude_code(self._amp_v, self.gain), code, cycles, repeat):
                self.updates += 1
            now = self.clock()
            if now - self._last_status >= self.status_interval_s:
                self._last_status = now
                drv.check_status()
            # chip-side dead-man's switch: re-arm the finite sequence before it runs out
            self._since_go += 1
            if (repeat != self._go_repeat or self._since_go >= self._rearm_every
                    or now - self._go_t >= self.rearm_s):
                drv.go()
                self._armed(repeat)
            if self._watchdog is not None:
                self._watchdog.feed()

    @classmethod
    def capability_for(cls, options: Any = None) -> DriveCapability:
        """Band and full scale of the DRV2667 at the ``gain`` / ``frequency_range_hz``
        options (default gain 0, 25 V peak); the table is the dimension's ``Tab``."""
        o = dict(options or {})
        gain = int(o.get("gain", 0))
        lim = piezo_limits(gain, o.get("frequency_range_hz") or DEFAULT_BAND_HZ)
        return DriveCapability("vibration", lim.frequency_range_hz, lim.max_amplitude, "V",
                               source=f"{cls.name}: DRV2667 gain {gain}, {lim.max_amplitude:g} V peak full scale")

    def _read_back(self) -> ChannelCommand:
        """The synthesis chunk last written to the DRV2667 (its amplitude and frequency
        codes, in V and Hz); 0 V while the chip is in standby."""
        with self._io_lock:
            amp = 0.0 if self._asleep else amplitude_code(self._amp_v, self.gain) / 255.0 * GAIN_FULL_SCALE_V[self.gain]
            return ChannelCommand("vibration", frequency_hz=frequency_code(self._freq) * FREQ_STEP_HZ, amplitude=amp)

    def _stop(self) -> None:
        with self._io_lock:
            self._amp_v = 0.0
            if self.drv is None:
                return
            self._asleep = True
            try:
                self.drv.standby()
            except BaseException:
                # the chip may still play: the watchdog keeps retrying the standby write
                # (with backoff) until it succeeds or the actuator is closed
                if self._watchdog is not None:
                    self._watchdog.feed()
                raise
            if self._watchdog is not None:
                self._watchdog.disarm()

    def standby_detached(self) -> None:
        """Put the chip in standby from a process that does not hold the device open (the
        application's supervisor after the servo process died,
        :mod:`hapticsdk.runtime.supervisor`): open the bus, CONTROL2 = STANDBY, close.
        Nothing else is written: no reset, no gain, no GO. Raises what opening the bus or
        the write raises."""
        bus = self._make_bus()
        try:
            DRV2667(bus, address=self.address, device=self.label).standby()
        finally:
            bus.close()

    def _close(self) -> None:
        if self._watchdog is not None:
            self._watchdog.stop()       # kept: describe() still shows its counts
        with self._io_lock:
            if self.bus is not None:
                self.bus.close()
            self.bus = self.drv = None

    def _require(self) -> DRV2667:
        if self.drv is None:
            raise DeviceError("not open", device=self.label)
        return self.drv

    # -- inspection -------------------------------------------------------------------------------
    @property
    def driving(self) -> bool:
        """Host-side view: a non-zero amplitude is being commanded."""
        return self._amp_v > 0

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d.update({"gain": self.gain, "full_scale_v": GAIN_FULL_SCALE_V[self.gain], "bus": getattr(self.bus, "name", None),
                  "chunk_updates": self.updates,
                  "chip_stop": {"bound_s": self.chip_stop_bound_s(), "window_s": self.chip_window_s,
                                "rearm_s": self.rearm_s, "rearms": self.rearms},
                  "watchdog": dict(self._watchdog.stats() if self._watchdog is not None else
                                   {"deadline_s": self.command_deadline_s(), "running": False},
                                   wakes=self.wakes)})
        return d


class PiezoSerial(DRV2667Actuator):
    """DRV2667 behind a serial I2C bridge (``port=``), protocol :mod:`~hapticsdk_roughness.bridge_protocol`.

    Extra options: ``port`` (required), ``baudrate`` (115200), ``timeout`` (s per reply,
    0.05), ``retries`` (3), ``serial_number`` (the bridge's, checked on open; lets two boards
    be told apart).
    """

    name: ClassVar[str] = "piezo-serial"
    #: ``port`` is a machine address, not material data: a scene shared between machines
    #: would send bridge frames to whatever device sits there, and pyserial URLs
    #: (``spy://...?logfile=``, ``socket://``, ``rfc2217://``) write files or open network
    #: connections. It comes from code, ``--device-option``, the environment or the user's
    #: device configuration; a scene may give ``serial_number`` (checked on open).
    privileged_options: ClassVar[dict[str, str]] = {"port": "serial port or pyserial URL (device address)"}

    def __init__(self, *, port: str | None = None, baudrate: int = 115200, timeout: float = 0.05,
                 retries: int = 3, serial_number: str | None = None, **options: Any) -> None:
        if not port:
            raise ValidationError("piezo-serial needs port= (e.g. /dev/ttyACM0 or COM5); "
                                  "`hapticsdk doctor` lists the ports found", field="options.port")
        options.setdefault("label", f"piezo-serial:{serial_number or port}")
        super().__init__(**options)
        self.port, self.baudrate, self.timeout, self.retries = port, int(baudrate), float(timeout), int(retries)
        self.serial_number = serial_number

    def _make_bus(self) -> I2CBus:
        from .serial_bridge import SerialBridgeBus
        return SerialBridgeBus(self.port, baudrate=self.baudrate, timeout=self.timeout, retries=self.retries,
                               serial_number=self.serial_number, device=self.label).open()

    @classmethod
    def check_available(cls) -> tuple[bool, str]:
        try:
            import serial
        except ImportError:
            return False, "pyserial not installed (pip install pyserial)"
        return True, f"pyserial {getattr(serial, '__version__', '?')}"

    @classmethod
    def discover(cls) -> list[dict[str, Any]]:
        from .serial_bridge import list_ports
        return [dict(p, backend=cls.name, note="serial port (bridge not probed)") for p in list_ports()]


class PiezoMCP2221(DRV2667Actuator):
    """DRV2667 behind an MCP2221A USB-I2C bridge (pyusb).

    Extra options: ``serial_number`` (USB serial of the board; required when several are
    attached), ``speed_hz`` (I2C clock, 400 kHz), ``timeout_ms`` (USB, 100), ``backend``
    (a pyusb backend object, e.g. :class:`hapticsdk_roughness.usb_emulation.MCP2221Backend`).
    """

    name: ClassVar[str] = "piezo-mcp2221"
    #: ``backend`` is a Python object (a pyusb backend): code only
    privileged_options: ClassVar[dict[str, str]] = {"backend": "USB backend object"}

    def __init__(self, *, serial_number: str | None = None, speed_hz: int = 400_000, timeout_ms: int = 100,
                 backend: Any = None, **options: Any) -> None:
        options.setdefault("label", f"piezo-mcp2221:{serial_number}" if serial_number else "piezo-mcp2221")
        super().__init__(**options)
        self.serial_number, self.speed_hz, self.timeout_ms, self.backend = serial_number, speed_hz, timeout_ms, backend

    def _make_bus(self) -> I2CBus:
        from .mcp2221 import MCP2221Bus
        return MCP2221Bus(serial_number=self.serial_number, speed_hz=self.speed_hz, timeout_ms=self.timeout_ms,
                          backend=self.backend, device=self.label).open()

    @classmethod
    def check_available(cls) -> tuple[bool, str]:
        try:
            import usb.backend.libusb0
            import usb.backend.libusb1
            import usb.backend.openusb
            import usb.core
        except ImportError:
            return False, "pyusb not installed (pip install pyusb)"
        for mod in (usb.backend.libusb1, usb.backend.openusb, usb.backend.libusb0):
            try:
                if mod.get_backend() is not None:
                    return True, f"pyusb {usb.__version__} with {mod.__name__.rsplit('.', 1)[-1]}"
            except Exception:
                continue
        return False, ("pyusb installed but no USB library found (tried libusb1, openusb, libusb0): "
                       "install libusb-1.0 (apt install libusb-1.0-0 / brew install libusb)")

    @classmethod
    def discover(cls) -> list[dict[str, Any]]:
        from .mcp2221 import _serial_of, find_devices
        return [{"backend": cls.name, "usb": "04D8:00DD", "serial_number": _serial_of(d),
                 "bus": getattr(d, "bus", None), "address": getattr(d, "address", None)} for d in find_devices()]
