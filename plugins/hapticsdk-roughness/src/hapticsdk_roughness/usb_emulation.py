"""A pyusb backend emulating MCP2221A boards with a DRV2667 behind each (SIMULATED).

Pass :class:`MCP2221Backend` as ``backend=`` to ``usb.core.find`` (or to the
``piezo-mcp2221`` actuator): pyusb's real ``Device``/``Configuration``/``Interface``
machinery runs, and the backend answers the MCP2221A HID command set (hardware facts in
docs/devices.md). This module imports ``usb`` at import time: only tests and demos import it.

Fault knobs per board (:class:`EmulatedMCP2221`): ``unplugged`` (every transfer raises
``USBError`` errno 19, like libusb after the cable is pulled), ``stalled`` (reads time out),
``busy`` (n write reports answered "engine busy").
"""

from __future__ import annotations

import array
from types import SimpleNamespace
from typing import Any

import usb.backend
import usb.core

from . import mcp2221 as m
from .emulation import DRV2667Emulator, I2CNak


def _desc(**kw: Any) -> SimpleNamespace:
    return SimpleNamespace(**kw)


class EmulatedMCP2221:
    """One MCP2221A board: I2C engine + targets ``{addr7: emulator}``."""

    def __init__(self, serial_number: str = "0001234567", targets: dict[int, Any] | None = None,
                 address: int = 1) -> None:
        self.serial_number = serial_number
        self.targets = targets if targets is not None else {0x59: DRV2667Emulator()}
        self.address = address
        self.unplugged = False
        self.stalled = False
        self.busy = 0
        self.reports: list[bytes] = []
        self._resp: list[bytes] = []
        self.state = 0x00
        self.nack = False
        self.divider = 0
        self._wbuf = bytearray()
        self._wlen = 0
        self._waddr = 0
        self._pending_reg = b""
        self._rdata = b""

    @property
    def drv(self) -> DRV2667Emulator:
        """The emulated DRV2667 on the I2C bus (address 0x59)."""
        return self.targets[0x59]

    # -- HID command set ------------------------------------------------------------
    def handle(self, rep: bytes) -> bytes:
        """Answer one 64-byte HID report as the MCP2221A would."""
        self.reports.append(bytes(rep))
        cmd = rep[0]
        out = bytearray(64)
        out[0] = cmd
        if cmd == m.CMD_STATUS:
            if rep[2] == 0x10:
                out[2] = 0x10 if self.state else 0x11
                self.state, self.nack, self._wbuf, self._wlen = 0, False, bytearray(), 0
            if rep[3] == 0x20:
                if self.state == 0:
                    self.divider = rep[4]
                    out[3] = 0x20
                else:
                    out[3] = 0x21
            out[8] = self.state
            out[14] = self.divider
            out[20] = 0x40 if self.nack else 0
            return bytes(out)
        if cmd in (m.CMD_I2C_WRITE, m.CMD_I2C_WRITE_NOSTOP):
            if self.busy > 0:
                self.busy -= 1
                out[1], out[2] = 0x01, self.state or 0x21
                return bytes(out)
            n = rep[1] | (rep[2] << 8)
            if self._wlen == 0:
                self._wlen, self._waddr, self._wbuf = n, rep[3] >> 1, bytearray()
            take = min(60, self._wlen - len(self._wbuf))
            self._wbuf += rep[4:4 + take]
            if len(self._wbuf) >= self._wlen:
                data, addr = bytes(self._wbuf), self._waddr
                self._wlen, self._wbuf = 0, bytearray()
                target = self.targets.get(addr)
                if target is None:
                    self.state, self.nack = 0x25, True
                elif cmd == m.CMD_I2C_WRITE_NOSTOP:
                    self._pending_reg, self.state = data, 0x00
                else:
                    try:
                        target.i2c_write(data)
                        self.state = 0x00
                    except I2CNak:
                        self.state = 0x44
            out[1], out[2] = 0x00, self.state
            return bytes(out)
        if cmd == m.CMD_I2C_READ_RS:
            n = rep[1] | (rep[2] << 8)
            target = self.targets.get(rep[3] >> 1)
            if target is None:
                self.state, self.nack = 0x25, True
                self._rdata = b""
            else:
                self._rdata = target.i2c_write_read(self._pending_reg, n)
                self.state = m.STATE_READ_DONE
            out[1], out[2] = 0x00, self.state
            return bytes(out)
        if cmd == m.CMD_I2C_GET_DATA:
            if self.state == 0x25:
                out[1], out[2], out[3] = 0x41, 0x25, 127
                return bytes(out)
            out[1], out[2], out[3] = 0x00, m.STATE_READ_DONE, len(self._rdata)
            out[4:4 + len(self._rdata)] = self._rdata
            self.state = 0x00
            return bytes(out)
        out[1] = 0x01
        return bytes(out)


class MCP2221Backend(usb.backend.IBackend):
    """pyusb backend serving a list of :class:`EmulatedMCP2221` boards."""

    def __init__(self, boards: list[EmulatedMCP2221] | None = None) -> None:
        self.boards = boards if boards is not None else [EmulatedMCP2221()]

    # -- descriptors --------------------------------------------------------------------
    def enumerate_devices(self):
        return iter(self.boards)

    def get_device_descriptor(self, dev: EmulatedMCP2221):
        return _desc(bLength=18, bDescriptorType=1, bcdUSB=0x0200, bDeviceClass=0xEF, bDeviceSubClass=2,
                     bDeviceProtocol=1, bMaxPacketSize0=64, idVendor=m.VID, idProduct=m.PID, bcdDevice=0x0100,
                     iManufacturer=1, iProduct=2, iSerialNumber=3, bNumConfigurations=1,
                     address=dev.address, bus=1, port_number=dev.address, port_numbers=(dev.address,), speed=2)

    def get_configuration_descriptor(self, dev, config):
        if config != 0:
            raise IndexError(config)
        return _desc(bLength=9, bDescriptorType=2, wTotalLength=107, bNumInterfaces=3, bConfigurationValue=1,
                     iConfiguration=0, bmAttributes=0x80, bMaxPower=50, extra_descriptors=[])

    _INTF = {0: (0x02, 1), 1: (0x0A, 2), 2: (0x03, 2)}   # CDC comm, CDC data, HID

    def get_interface_descriptor(self, dev, intf, alt, config):
        if intf not in self._INTF or alt != 0 or config != 0:
            raise IndexError((intf, alt))
        cls, neps = self._INTF[intf]
        return _desc(bLength=9, bDescriptorType=4, bInterfaceNumber=intf, bAlternateSetting=0, bNumEndpoints=neps,
                     bInterfaceClass=cls, bInterfaceSubClass=0, bInterfaceProtocol=0, iInterface=0,
                     extra_descriptors=[])

    def get_endpoint_descriptor(self, dev, ep, intf, alt, config):
        table = {0: [(0x81, 3)], 1: [(0x02, 2), (0x82, 2)], 2: [(0x83, 3), (0x03, 3)]}
        eps = table.get(intf, [])
        if ep >= len(eps):
            raise IndexError(ep)
        addr, kind = eps[ep]
        return _desc(bLength=7, bDescriptorType=5, bEndpointAddress=addr, bmAttributes=kind, wMaxPacketSize=64,
                     bInterval=1, bRefresh=0, bSynchAddress=0, extra_descriptors=[])

    # -- handles ----------------------------------------------------------------------------
    def open_device(self, dev):
        if dev.unplugged:
            raise usb.core.USBError("No such device (it may have been disconnected)", errno=19)
        return dev

    def close_device(self, handle):
        pass

    def set_configuration(self, handle, value):
        handle.config = value

    def get_configuration(self, handle):
        return getattr(handle, "config", 1)

    def claim_interface(self, handle, intf):
        pass

    def release_interface(self, handle, intf):
        pass

    def is_kernel_driver_active(self, handle, intf):
        return False

    def detach_kernel_driver(self, handle, intf):
        pass

    def ctrl_transfer(self, handle, bmRequestType, bRequest, wValue, wIndex, data, timeout):
        if handle.unplugged:
            raise usb.core.USBError("No such device (it may have been disconnected)", errno=19)
        if bmRequestType & 0x80 and bRequest == 6 and wValue >> 8 == 3:      # GET_DESCRIPTOR string
            idx = wValue & 0xFF
            if idx == 0:
                raw = bytes((4, 3, 0x09, 0x04))
            else:
                text = {1: "Microchip Technology Inc.", 2: "MCP2221 USB-I2C/UART Combo",
                        3: handle.serial_number}.get(idx, "")
                enc = text.encode("utf-16-le")
                raw = bytes((2 + len(enc), 3)) + enc
            n = min(len(data), len(raw))
            data[:n] = array.array("B", raw[:n])
            return n
        raise usb.core.USBError("Pipe error", errno=32)

    def intr_write(self, handle, ep, intf, data, timeout):
        if handle.unplugged:
            raise usb.core.USBError("No such device (it may have been disconnected)", errno=19)
        handle._resp.append(handle.handle(bytes(data)))
        return len(data)

    def intr_read(self, handle, ep, intf, buff, timeout):
        if handle.unplugged:
            raise usb.core.USBError("No such device (it may have been disconnected)", errno=19)
        if handle.stalled or not handle._resp:
            raise usb.core.USBTimeoutError("Operation timed out", errno=110)
        resp = handle._resp.pop(0)
        n = min(len(buff), len(resp))
        buff[:n] = array.array("B", resp[:n])
        return n


# -- one board shared between processes ------------------------------------------------
class BoardServer:
    """Serve one :class:`EmulatedMCP2221` to other processes (a loopback UNIX socket):
    a servo process and the application then talk to the same emulated board, as two
    processes of a real machine share one USB device. :meth:`remote` gives the
    picklable stand-in to put in a :class:`MCP2221Backend`."""

    def __init__(self, board: EmulatedMCP2221) -> None:
        import threading
        from multiprocessing.connection import Listener

        self.board = board
        self._lock = threading.Lock()
        self._listener = Listener(family="AF_UNIX")
        self.address = self._listener.address
        self._closed = False
        threading.Thread(target=self._accept, name="mcp2221-board-server", daemon=True).start()

    def _accept(self) -> None:
        import threading
        while not self._closed:
            try:
                conn = self._listener.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn: Any) -> None:
        try:
            while True:
                rep = conn.recv_bytes()
                with self._lock:
                    if self.board.unplugged:
                        conn.send_bytes(b"")
                        continue
                    out = self.board.handle(rep)
                conn.send_bytes(out)
        except (EOFError, OSError):  # the client process ended (or was killed)
            conn.close()

    def remote(self) -> "RemoteMCP2221":
        """A picklable board whose reports go to this server."""
        return RemoteMCP2221(self.address, self.board.serial_number, self.board.address)

    def close(self) -> None:
        """Stop accepting connections (connected clients are served until they close)."""
        self._closed = True
        self._listener.close()


class RemoteMCP2221:
    """Stand-in for an :class:`EmulatedMCP2221` served by a :class:`BoardServer`, usable
    from any process (it connects on first use in each process)."""

    def __init__(self, server_address: str, serial_number: str, address: int) -> None:
        self.server_address = server_address
        self.serial_number = serial_number
        self.address = address
        self.stalled = False
        self._resp: list[bytes] = []
        self._conn: Any = None

    def __getstate__(self) -> dict[str, Any]:
        return {"server_address": self.server_address, "serial_number": self.serial_number,
                "address": self.address}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["server_address"], state["serial_number"], state["address"])  # type: ignore[misc]

    @property
    def unplugged(self) -> bool:
        """Always False here: an unplugged served board answers with ``USBError`` errno 19."""
        return False

    def handle(self, rep: bytes) -> bytes:
        """Send one HID report to the served board; its answer."""
        from multiprocessing.connection import Client
        if self._conn is None:
            self._conn = Client(self.server_address, family="AF_UNIX")
        self._conn.send_bytes(bytes(rep))
        out = self._conn.recv_bytes()
        if not out:
            raise usb.core.USBError("No such device (it may have been disconnected)", errno=19)
        return out
