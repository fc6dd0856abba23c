"""I2C over a serial bridge (pyserial), speaking :mod:`~hapticsdk_roughness.bridge_protocol`.

pyserial is imported inside :meth:`SerialBridgeBus.open` (and :func:`list_ports`), never at
module import. Each request waits ``timeout`` seconds for its reply; a lost or corrupted
reply, or a CRC error reported by the bridge, resends the same frame (same SEQ, so the
bridge does not execute it twice) up to ``retries`` times, then a
:class:`~hapticsdk.errors.TransportError` names the port and what happened. A vanished
port (cable pulled) raises at once.
"""

from __future__ import annotations

import time
from typing import Any

from hapticsdk.errors import DeviceNotFoundError, TransportError, ValidationError

from . import bridge_protocol as bp
from .drv2667 import I2CBus


class BridgeNak(TransportError):
    """The bridge reported an I2C NACK; ``nak`` True, ``accepted`` bytes the target took."""

    def __init__(self, message: str, *, device: str | None, accepted: int, address_nack: bool) -> None:
        super().__init__(message, device=device)
        self.nak = not address_nack
        self.address_nack = address_nack
        self.accepted = accepted


def list_ports() -> list[dict[str, Any]]:
    """Serial ports pyserial sees (``[]`` without pyserial)."""
    try:
        from serial.tools import list_ports as lp
    except ImportError:
        return []
    out = []
    for p in lp.comports():
        out.append({"port": p.device, "description": p.description, "serial_number": p.serial_number,
                    "vid_pid": f"{p.vid:04X}:{p.pid:04X}" if p.vid is not None else None})
    return out


class SerialBridgeBus(I2CBus):
    """The I2C master of a bridge microcontroller on serial ``port``.

    Args:
        port: device name (``/dev/ttyACM0``, ``COM5``) or a pyserial URL.
        baudrate: link speed (the bridge firmware's; ignored on a pty).
        timeout: seconds to wait for each reply.
        retries: resends after a timeout or corrupted frame before giving up.
        serial_number: if given, the bridge's PING answer must report this serial number.
        device: name used in errors.
    """

    def __init__(self, port: str, *, baudrate: int = 115200, timeout: float = 0.05, retries: int = 3,
                 serial_number: str | None = None, device: str = "piezo-serial") -> None:
        if not port or not isinstance(port, str):
            raise ValidationError("port must be a serial device name or URL, e.g. /dev/ttyACM0 or COM5",
                                  field="options.port")
        if timeout <= 0 or retries < 0:
            raise ValidationError("timeout must be > 0 s and retries >= 0", field="options")
        self.port = port
        self.baudrate = int(baudrate)
        self.timeout = float(timeout)
        self.retries = int(retries)
        self.serial_number = serial_number
        self.device = device
        self.name = f"serial bridge {port}"
        self.ser: Any = None
        self.parser = bp.FrameParser()
        self._seq = 0
        self.stats = {"requests": 0, "resends": 0, "timeouts": 0, "crc_errors": 0, "stale": 0}
        self.bridge_info: dict[str, Any] = {}
        #: pyserial read timeout: the reply deadline is checked between reads
        self._poll_s = min(self.timeout, 0.01)

    # -- link ---------------------------------------------------------------------
    def open(self) -> "SerialBridgeBus":
        """Open the serial port (pyserial) and check the bridge answers; returns self."""
        try:
            import serial
        except ImportError:
            raise DeviceNotFoundError(
                f"pyserial is not installed (needed for port {self.port}); install it with "
                "`pip install pyserial`", device=self.device) from None
        try:
            if "://" in self.port:
                self.ser = serial.serial_for_url(self.port, baudrate=self.baudrate, timeout=self._poll_s,
                                                 write_timeout=self.timeout * 4)
            else:
                # exclusive: one bridge, one owner. A second instance (or another program)
                # on the same port would interleave its frames with ours and read our
                # replies; the lock (POSIX flock, pyserial >= 3.3) makes it fail here instead
                self.ser = serial.Serial(self.port, baudrate=self.baudrate, timeout=self._poll_s,
                                         write_timeout=self.timeout * 4, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            if "exclusively lock" in str(exc):
                raise DeviceNotFoundError(
                    f"serial port {self.port!r} is in use: another instance or program has it open ({exc}); "
                    "close it first (one bridge takes one owner)", device=self.device) from None
            ports = [p["port"] for p in list_ports()]
            raise DeviceNotFoundError(
                f"could not open serial port {self.port!r} at {self.baudrate} baud ({exc}); ports present: "
                f"{ports or 'none'}; check the cable, the port name (option port=) and permissions "
                "(Linux: add the user to group dialout)", device=self.device) from None
        try:
            info = self.request(bp.CMD_PING, b"")
        except TransportError as exc:
            self.close()
            raise DeviceNotFoundError(
                f"no bridge answered a PING on {self.port!r} at {self.baudrate} baud "
                f"({self.retries + 1} attempts, {self.timeout:g} s each): {exc}. Is the hapticsdk bridge "
                "firmware flashed and the baud rate right (option baudrate=)?", device=self.device) from None
        version = info[0] if info else None
        sn = info[1:].decode(errors="replace") if info else ""
        self.bridge_info = {"protocol_version": version, "serial_number": sn, "port": self.port}
        if version != bp.PROTOCOL_VERSION:
            self.close()
            raise DeviceNotFoundError(f"bridge on {self.port!r} speaks protocol version {version}, "
                                      f"this SDK version {bp.PROTOCOL_VERSION}; update the bridge firmware",
                                      device=self.device)
        if self.serial_number is not None and sn != self.serial_number:
            self.close()
            raise DeviceNotFoundError(f"bridge on {self.port!r} has serial number {sn!r}, "
                                      f"expected {self.serial_number!r}", device=self.device)
        return self

    def close(self) -> None:
        if self.ser is not None:
            try:
                self.ser.close()
            except Exception:
                pass
            self.ser = None

    def _next_seq(self) -> int:
        self._seq = (self._seq + 1) % bp.SEQ_UNKNOWN        # 0..254
        return self._seq

    def _lost(self, exc: BaseException) -> TransportError:
        return TransportError(f"serial link to {self.port} lost ({type(exc).__name__}: {exc}); "
                              "cable pulled or bridge reset?", device=self.device)

    def request(self, cmd: int, payload: bytes) -> bytes:
        """Send one request and return the reply payload (retrying as documented)."""
        if self.ser is None:
            raise TransportError(f"{self.name} is not open", device=self.device)
        frame = bp.Frame(self._next_seq(), cmd, payload)
        raw = frame.encode()
        self.stats["requests"] += 1
        last = "no reply"
        for attempt in range(self.retries + 1):
            if attempt:
                self.stats["resends"] += 1
            try:
                self.ser.reset_input_buffer()
                self.parser.reset()
                self.ser.write(raw)
                self.ser.flush()
            except Exception as exc:
                raise self._lost(exc) from exc
            reply, why = self._await(frame.seq)
            if reply is None:
                last = why
                continue
            if reply.cmd == bp.CMD_ERROR:
                code = reply.payload[0] if reply.payload else 0
                detail = reply.payload[1] if len(reply.payload) > 1 else 0
                if code == bp.ERR_CRC:
                    last = "bridge reported a CRC error in the request"
                    self.stats["crc_errors"] += 1
                    continue
                what = bp.ERROR_NAMES.get(code, f"error 0x{code:02x}")
                if code in (bp.ERR_ADDR_NACK, bp.ERR_DATA_NACK):
                    addr = payload[0] if payload else -1
                    raise BridgeNak(f"{what} from I2C address 0x{addr:02x} via {self.name} "
                                    f"(target accepted {detail} byte(s))", device=self.device,
                                    accepted=detail, address_nack=code == bp.ERR_ADDR_NACK)
                raise TransportError(f"{self.name}: {what} (request 0x{cmd:02x})", device=self.device)
            if reply.cmd != cmd | bp.REPLY:
                raise TransportError(f"{self.name}: reply 0x{reply.cmd:02x} to request 0x{cmd:02x}",
                                     device=self.device)
            return reply.payload
        raise TransportError(f"{self.name}: request 0x{cmd:02x} failed after {self.retries + 1} attempts "
                             f"({self.timeout:g} s timeout each): {last}", device=self.device)

    def _await(self, seq: int) -> tuple[bp.Frame | None, str]:
        deadline = time.monotonic() + self.timeout
        crc0 = self.parser.crc_errors
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                self.stats["timeouts"] += 1
                return None, "timeout waiting for the reply"
            try:
                chunk = self.ser.read(max(1, self.ser.in_waiting))
            except Exception as exc:
                raise self._lost(exc) from exc
            if not chunk:
                continue
            for fr in self.parser.feed(chunk):
                if fr.seq == seq or (fr.seq == bp.SEQ_UNKNOWN and fr.cmd == bp.CMD_ERROR):
                    return fr, ""
                self.stats["stale"] += 1
            if self.parser.crc_errors > crc0:
                self.stats["crc_errors"] += self.parser.crc_errors - crc0
                return None, "corrupted reply (CRC mismatch)"

    # -- I2CBus -----------------------------------------------------------------------
    def write(self, addr: int, data: bytes) -> None:
        if len(data) > bp.MAX_PAYLOAD - 1:
            raise ValidationError(f"I2C write of {len(data)} bytes > {bp.MAX_PAYLOAD - 1}", field="data")
        self.request(bp.CMD_I2C_WRITE, bytes((addr,)) + bytes(data))

    def write_read(self, addr: int, data: bytes, n: int) -> bytes:
        if not 0 < n <= bp.MAX_PAYLOAD:
            raise ValidationError(f"read length {n} outside 1..{bp.MAX_PAYLOAD}", field="n")
        return self.request(bp.CMD_I2C_WRITE_READ, bytes((addr, n)) + bytes(data))
