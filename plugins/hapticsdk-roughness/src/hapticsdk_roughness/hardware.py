"""Real DRV2667 piezo actuators: ``piezo-serial`` and ``piezo-mcp2221``.

Both drive the DRV2667 in waveform-synthesis mode (mode 3): one 1-cycle chunk repeated
until GO is cleared, whose amplitude and frequency bytes are rewritten when the command
changes (frequency in 7.8125 Hz steps, amplitude in full-scale/255 steps; each chunk
starts and ends at a zero crossing, so updates land on cycle boundaries). The amplitude is
ramped in software by at most full scale per ``ramp_s`` (>= 5 ms) so the 20 mm/s gate
never clicks. STATUS is read every ``status_interval_s`` (also a keep-alive for the
bridge watchdog); a fault bit stops the piezo.

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

import threading
import time
from typing import Any, ClassVar

from hapticsdk.actuators import Actuator, DriveCapability
from hapticsdk.dimensions import ChannelCommand
from hapticsdk.errors import DeviceError, ValidationError
from hapticsdk.runtime.watchdog import CommandWatchdog

from .drv2667 import (ADDRESS, DRV2667, FREQ_STEP_HZ, GAIN_FULL_SCALE_V, I2CBus, SynthChunk, amplitude_code,
                      frequency_code)
from .virtual import piezo_limits


#: default shortest host-side command deadline (s) before the DRV2667 is put in standby
WATCHDOG_S = 0.010
#: allowed range of the ``watchdog_s`` option (s)
WATCHDOG_RANGE_S = (0.002, 0.25)


class DRV2667Actuator(Actuator):
    """Base of the DRV2667 backends; subclasses build the bus in :meth:`_make_bus`.

    Options: ``gain`` (0..3 = 25/50/75/100 V peak; default 0, the safe start of
    docs/devices.md), ``frequency_range_hz`` (piezo band within 7.8125..1992 Hz),
    ``ramp_s`` (amplitude ramp, >= 0.005 s), ``period_s`` (servo period, s),
    ``status_interval_s`` (STATUS poll, s), ``address`` (I2C, 0x59), ``watchdog_s``
    (shortest command deadline before the host puts the chip in standby, 0.002..0.25 s,
    default 0.010; the deadline is at least 3 servo periods).
    """

    channel: ClassVar[str] = "vibration"
    accepts: ClassVar[dict[str, str]] = {"frequency_hz": "Hz", "amplitude": "V"}
    simulated: ClassVar[bool] = False
    limits = piezo_limits(0, None)

    def __init__(self, *, gain: int = 0, frequency_range_hz: tuple[float, float] | None = None,
                 ramp_s: float = 0.005, period_s: float = 0.001, status_interval_s: float = 0.05,
                 address: int = ADDRESS, watchdog_s: float = WATCHDOG_S, **options: Any) -> None:
        self.limits = piezo_limits(gain, frequency_range_hz)
        if ramp_s < 0.005 or period_s <= 0 or status_interval_s <= 0:
            raise ValidationError("ramp_s must be >= 0.005 s, period_s and status_interval_s > 0", field="options")
        if not (isinstance(watchdog_s, (int, float)) and WATCHDOG_RANGE_S[0] <= watchdog_s <= WATCHDOG_RANGE_S[1]):
            raise ValidationError(f"watchdog_s must be {WATCHDOG_RANGE_S[0]:g}..{WATCHDOG_RANGE_S[1]:g} s "
                                  f"(the command deadline cannot be turned off), got {watchdog_s!r}",
                                  field="options.watchdog_s")
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

    def _make_bus(self) -> I2CBus:
        raise NotImplementedError

    # -- backend API --------------------------------------------------------------------------
    def _open(self) -> None:
        bus = self._make_bus()
        try:
            drv = DRV2667(bus, address=self.address, device=self.label)
            drv.probe()
            drv.reset()
            drv.set_gain(self.gain)
            f0 = self.limits.frequency_range_hz[0]
            self._freq = f0
            drv.load_synthesis([SynthChunk(amplitude=0, frequency=frequency_code(f0), cycles=1)], repeat=0)
            drv.check_status()
            drv.go()
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
        self._last_status = time.monotonic()
        self._watchdog = CommandWatchdog(self._watchdog_standby, deadline_s=self.command_deadline_s,
                                         lock=self._io_lock, on_error=self._watchdog_failed,
                                         name=f"watchdog {self.label}").start(armed=False)
        # armed by the first command: until then the chunk amplitude is 0 (0 V out)

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
        drv.update_chunk(0, frequency_code(self._freq))
        drv.go()
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
            if drv.update_chunk(amplitude_code(self._amp_v, self.gain), frequency_code(self._freq)):
                self.updates += 1
            now = time.monotonic()
            if now - self._last_status >= self.status_interval_s:
                self._last_status = now
                drv.check_status()
            if self._watchdog is not None:
                self._watchdog.feed()

    @classmethod
    def capability_for(cls, options: Any = None) -> DriveCapability:
        """Band and full scale of the DRV2667 at the ``gain`` / ``frequency_range_hz``
        options (default gain 0, 25 V peak); the table is the dimension's ``Tab``."""
        o = dict(options or {})
        gain = int(o.get("gain", 0))
        lim = piezo_limits(gain, o.get("frequency_range_hz"))
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
                # every deadline until it succeeds or the actuator is closed
                if self._watchdog is not None:
                    self._watchdog.feed()
                raise
            if self._watchdog is not None:
                self._watchdog.disarm()

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
