"""I2C through a Microchip MCP2221A USB-I2C bridge, with pyusb (HID reports, no hidapi).

The MCP2221A (USB 04D8:00DD) answers 64-byte HID reports on interface 2: one command at
a time, each answered before the next is sent. Commands used (byte 0):

* ``0x10`` STATUS/SET PARAMETERS: ``[2]=0x10`` cancels a stuck transfer, ``[3]=0x20,
  [4]=divider`` sets the I2C speed (divider = 12 MHz / bitrate - 3); reply ``[8]`` engine
  state, ``[20] & 0x40`` address NACK.
* ``0x90`` I2C WRITE ``[len lo, len hi, addr<<1, up to 60 data bytes]`` (longer writes repeat
  the header with the next 60 bytes); ``0x94`` the same without STOP.
* ``0x93`` I2C READ REPEATED-START ``[len lo, len hi, addr<<1 | 1]``; ``0x40`` GET I2C DATA
  returns ``[2]`` state (0x55 = complete), ``[3]`` count (127 = error), ``[4..]`` data.

pyusb is imported inside :meth:`MCP2221Bus.open` and :func:`find_devices`; pass a pyusb
backend object (``backend=``) to run against an emulator (see
:mod:`hapticsdk_roughness.usb_emulation`).
"""

from __future__ import annotations

import time
from typing import Any

from hapticsdk.errors import DeviceNotFoundError, TransportError, ValidationError

from .drv2667 import I2CBus

VID, PID = 0x04D8, 0x00DD
HID_INTERFACE = 2
REPORT = 64

CMD_STATUS = 0x10
CMD_I2C_WRITE = 0x90
CMD_I2C_WRITE_NOSTOP = 0x94
CMD_I2C_READ_RS = 0x93
CMD_I2C_GET_DATA = 0x40

STATE_IDLE = 0x00
STATE_READ_DONE = 0x55
#: engine states after which retrying a write is pointless (timeouts, address NACK)
FATAL_STATES = {0x12: "START timeout", 0x23: "write-address timeout", 0x25: "address NACK",
                0x44: "write-data timeout", 0x62: "STOP timeout", 0x52: "read-data timeout",
                0x17: "repeated-START timeout"}

INSTALL_HINT = ("install pyusb (`pip install pyusb`) and libusb-1.0 (Debian/Ubuntu: "
                "`apt install libusb-1.0-0`; macOS: `brew install libusb`; Windows: bind the HID "
                "interface to WinUSB with Zadig); on Linux allow access with a udev rule for 04d8:00dd")


def _import_usb() -> Any:
    try:
        import usb.core
        import usb.util
    except ImportError:
        raise DeviceNotFoundError(f"pyusb is not installed; {INSTALL_HINT}", device="piezo-mcp2221") from None
    return usb


def _serial_of(dev: Any) -> str | None:
    try:
        return dev.serial_number
    except Exception:
        return None


def find_devices(backend: Any = None) -> list[Any]:
    """pyusb ``Device`` objects of every MCP2221A attached (raises if no libusb backend)."""
    usb = _import_usb()
    try:
        return list(usb.core.find(find_all=True, idVendor=VID, idProduct=PID, backend=backend) or [])
    except usb.core.NoBackendError:
        raise DeviceNotFoundError(f"pyusb found no libusb backend (tried libusb1, openusb, libusb0); "
                                  f"{INSTALL_HINT}", device="piezo-mcp2221") from None


class MCP2221Bus(I2CBus):
    """The I2C master of one MCP2221A.

    Args:
        serial_number: USB serial number of the wanted board (several boards at once);
            ``None`` takes the only one attached (an error if there are several).
        speed_hz: I2C clock (50 k..400 kHz).
        timeout_ms: USB transfer timeout per report (ms).
        poll_limit: status polls before a transfer counts as stuck.
        backend: pyusb backend object (``usb.core.find(backend=...)``), for emulators.
    """

    def __init__(self, *, serial_number: str | None = None, speed_hz: int = 400_000, timeout_ms: int = 100,
                 poll_limit: int = 50, backend: Any = None, device: str = "piezo-mcp2221") -> None:
        if not 50_000 <= speed_hz <= 400_000:
            raise ValidationError(f"speed_hz {speed_hz} outside 50000..400000", field="options.speed_hz")
        self.serial_number = serial_number
        self.speed_hz = int(speed_hz)
        self.timeout_ms = int(timeout_ms)
        self.poll_limit = int(poll_limit)
        self.backend = backend
        self.device = device
        self.dev: Any = None
        self.ep_in: Any = None
        self.ep_out: Any = None
        self.name = "MCP2221A (USB 04D8:00DD)"
        self._usb: Any = None
        self.reports = 0
        self.stale = 0

    # -- open / close ------------------------------------------------------------------
    def open(self) -> "MCP2221Bus":
        """Find and claim the MCP2221A (by serial number when given) through pyusb; returns
        self.
        """
        usb = self._usb = _import_usb()
        devs = find_devices(self.backend)
        found = [(_serial_of(d), d) for d in devs]
        want = self.serial_number
        match = [(sn, d) for sn, d in found if want is None or sn == want]
        if not match or (want is None and len(match) > 1):
            listing = [sn or "?" for sn, _ in found]
            why = (f"no MCP2221A with serial number {want!r}" if want is not None and found else
                   "several MCP2221A boards attached; choose one with serial_number=" if match else
                   "no MCP2221A attached")
            raise DeviceNotFoundError(
                f"{why} (searched USB VID:PID 04D8:00DD; found serial numbers: {listing or 'none'}); "
                f"check the cable, the serial number, and USB permissions ({INSTALL_HINT})", device=self.device)
        sn, self.dev = match[0]
        self.name = f"MCP2221A {sn or '?'} (USB 04D8:00DD)"
        try:
            try:
                if self.dev.is_kernel_driver_active(HID_INTERFACE):
                    self.dev.detach_kernel_driver(HID_INTERFACE)
            except (NotImplementedError, usb.core.USBError):
                pass
            self.dev.set_configuration()
            cfg = self.dev.get_active_configuration()
            intf = cfg[(HID_INTERFACE, 0)]
            self.ep_out = usb.util.find_descriptor(intf, custom_match=lambda e: usb.util.endpoint_direction(
                e.bEndpointAddress) == usb.util.ENDPOINT_OUT)
            self.ep_in = usb.util.find_descriptor(intf, custom_match=lambda e: usb.util.endpoint_direction(
                e.bEndpointAddress) == usb.util.ENDPOINT_IN)
            if self.ep_in is None or self.ep_out is None:
                raise DeviceNotFoundError(f"{self.name}: interface {HID_INTERFACE} has no interrupt IN/OUT "
                                          "endpoints; is this an MCP2221A?", device=self.device)
        except usb.core.USBError as exc:
            raise DeviceNotFoundError(f"{self.name}: could not claim HID interface {HID_INTERFACE} ({exc}); "
                                      f"{INSTALL_HINT}", device=self.device) from None
        self._set_speed()
        return self

    def close(self) -> None:
        if self.dev is not None and self._usb is not None:
            try:
                self._usb.util.dispose_resources(self.dev)
            except Exception:
                pass
        self.dev = None

    # -- HID reports ---------------------------------------------------------------------
    def xfer(self, report: bytes) -> bytes:
        """Send one 64-byte command report and return the 64-byte response."""
        if self.dev is None:
            raise TransportError(f"{self.name} is not open", device=self.device)
        usb = self._usb
        buf = bytes(report) + bytes(REPORT - len(report))
        try:
            self.dev.write(self.ep_out.bEndpointAddress, buf, self.timeout_ms)
            for _ in range(4):      # responses left over from a timed-out exchange are skipped
                resp = bytes(self.dev.read(self.ep_in.bEndpointAddress, REPORT, self.timeout_ms))
                if resp[:1] == report[:1]:
                    break
                self.stale += 1
        except usb.core.USBTimeoutError as exc:
            raise TransportError(f"{self.name}: no response to command 0x{report[0]:02x} within "
                                 f"{self.timeout_ms} ms ({exc})", device=self.device) from exc
        except usb.core.USBError as exc:
            raise TransportError(f"{self.name}: USB error on command 0x{report[0]:02x} ({exc}); "
                                 "cable pulled?", device=self.device) from exc
        self.reports += 1
        if len(resp) < 4 or resp[0] != report[0]:
            raise TransportError(f"{self.name}: bad response {resp[:4].hex()} to command 0x{report[0]:02x}",
                                 device=self.device)
        return resp

    def status(self, cancel: bool = False, divider: int | None = None) -> bytes:
        """Send the status/set-parameters report (optionally cancelling the current I2C
        transfer or setting the clock divider) and return the 64-byte answer.
        """
        rep = bytearray(8)
        rep[0] = CMD_STATUS
        if cancel:
            rep[2] = 0x10
        if divider is not None:
            rep[3], rep[4] = 0x20, divider
        return self.xfer(bytes(rep))

    def _set_speed(self) -> None:
        divider = 12_000_000 // self.speed_hz - 3
        for _ in range(3):
            r = self.status(divider=divider)
            if r[3] == 0x20:
                return
            self.status(cancel=True)
            time.sleep(0.001)
        raise TransportError(f"{self.name}: I2C speed {self.speed_hz} Hz not accepted (state 0x{r[8]:02x})",
                             device=self.device)

    def _idle(self) -> None:
        r = self.status()
        if r[8] != STATE_IDLE:
            r = self.status(cancel=True)
            if r[2] == 0x10:
                time.sleep(0.001)

    def _wait_done(self, addr: int) -> None:
        for _ in range(self.poll_limit):
            r = self.status()
            if r[20] & 0x40:
                raise TransportError(f"{self.name}: I2C address 0x{addr:02x} NACK (no device answering there; "
                                     "check wiring, power of the DRV2667 board, address)", device=self.device)
            if r[8] == STATE_IDLE:
                return
            if r[8] in FATAL_STATES:
                self.status(cancel=True)
                raise TransportError(f"{self.name}: {FATAL_STATES[r[8]]} at I2C 0x{addr:02x}", device=self.device)
        self.status(cancel=True)
        raise TransportError(f"{self.name}: I2C transfer to 0x{addr:02x} did not finish after "
                             f"{self.poll_limit} polls", device=self.device)

    def _write(self, cmd: int, addr: int, data: bytes) -> None:
        n = len(data)
        if not 0 < n <= 0xFFFF:
            raise ValidationError(f"I2C write length {n} outside 1..65535", field="data")
        for i in range(0, n, 60):
            part = data[i:i + 60]
            rep = bytes((cmd, n & 0xFF, n >> 8, (addr << 1) & 0xFE)) + part
            for _ in range(self.poll_limit):
                r = self.xfer(rep)
                if r[1] == 0x00:
                    break
                if r[2] in FATAL_STATES:
                    self.status(cancel=True)
                    raise TransportError(f"{self.name}: {FATAL_STATES[r[2]]} writing to I2C 0x{addr:02x}",
                                         device=self.device)
            else:
                self.status(cancel=True)
                raise TransportError(f"{self.name}: engine stayed busy writing to I2C 0x{addr:02x}",
                                     device=self.device)

    # -- I2CBus -----------------------------------------------------------------------------
    def write(self, addr: int, data: bytes) -> None:
        self._idle()
        self._write(CMD_I2C_WRITE, addr, bytes(data))
        self._wait_done(addr)

    def write_read(self, addr: int, data: bytes, n: int) -> bytes:
        if not 0 < n <= 60:
            raise ValidationError(f"read length {n} outside 1..60", field="n")
        self._idle()
        self._write(CMD_I2C_WRITE_NOSTOP, addr, bytes(data))
        r = self.xfer(bytes((CMD_I2C_READ_RS, n & 0xFF, n >> 8, ((addr << 1) | 1) & 0xFF)))
        if r[1] != 0x00:
            self.status(cancel=True)
            raise TransportError(f"{self.name}: read request to I2C 0x{addr:02x} refused (state 0x{r[2]:02x})",
                                 device=self.device)
        for _ in range(self.poll_limit):
            r = self.xfer(bytes((CMD_I2C_GET_DATA,)))
            if r[2] == 0x25 or r[3] == 127:
                self.status(cancel=True)
                raise TransportError(f"{self.name}: I2C address 0x{addr:02x} NACK on read", device=self.device)
            if r[1] == 0x41:          # data not ready yet
                continue
            if r[2] == STATE_READ_DONE or (r[2] == 0 and r[3] == n):
                return bytes(r[4:4 + r[3]])
        self.status(cancel=True)
        raise TransportError(f"{self.name}: read from I2C 0x{addr:02x} did not complete", device=self.device)
