"""Framed protocol between the PC and a serial I2C bridge (a microcontroller next to the DRV2667).

Wire format (both directions)::

    0xA5 | LEN | SEQ | CMD | PAYLOAD (LEN bytes) | CRC_HI | CRC_LO

* ``LEN`` 0..250 payload bytes; ``SEQ`` 0..254 chosen by the host per request (a retry
  keeps its SEQ; 0xFF in a reply means "the request could not be parsed");
* CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over ``LEN SEQ CMD PAYLOAD``.

Requests (host -> bridge) and their replies (``CMD | 0x80`` on success):

=========  =========================================  ==========================
``0x01``   PING, no payload                            ``0x81 [version, serial...]``
``0x10``   I2C WRITE ``[addr7, data...]``              ``0x90`` (empty)
``0x11``   I2C WRITE-READ ``[addr7, n, data...]``      ``0x91 [n bytes read]``
=========  =========================================  ==========================

Errors come back as ``CMD = 0xFF`` with payload ``[code, detail]``: :data:`ERR_CRC`
(request corrupted: the host resends, same SEQ), :data:`ERR_LENGTH`, :data:`ERR_COMMAND`,
:data:`ERR_ADDR_NACK` (no device at the address), :data:`ERR_DATA_NACK` (detail = bytes
the target acknowledged, e.g. a full DRV2667 FIFO), :data:`ERR_BUS_TIMEOUT`.

The bridge executes a request once: a request repeating the SEQ, CMD and payload of the
last one gets the cached reply again (so a retried write after a lost reply is not
applied twice). The receiver resynchronises after garbage by scanning for ``0xA5`` and
dropping candidates whose CRC fails.
"""

from __future__ import annotations

import binascii
from dataclasses import dataclass

START = 0xA5
MAX_PAYLOAD = 250
SEQ_UNKNOWN = 0xFF
PROTOCOL_VERSION = 1

CMD_PING = 0x01
CMD_I2C_WRITE = 0x10
CMD_I2C_WRITE_READ = 0x11
CMD_ERROR = 0xFF
REPLY = 0x80

ERR_CRC = 0x01
ERR_LENGTH = 0x02
ERR_COMMAND = 0x03
ERR_ADDR_NACK = 0x10
ERR_DATA_NACK = 0x11
ERR_BUS_TIMEOUT = 0x12

ERROR_NAMES = {ERR_CRC: "frame CRC error", ERR_LENGTH: "bad length", ERR_COMMAND: "unknown command",
               ERR_ADDR_NACK: "I2C address NACK", ERR_DATA_NACK: "I2C data NACK",
               ERR_BUS_TIMEOUT: "I2C bus timeout"}


def crc16(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor).

    :func:`binascii.crc_hqx` computes exactly this CRC (MSB first, poly 0x1021, the
    initial value given) in C: ~0.3 us for a 104-byte frame instead of ~70-300 us for a
    bit loop in Python."""
    return binascii.crc_hqx(data, crc)


@dataclass(frozen=True)
class Frame:
    seq: int
    cmd: int
    payload: bytes = b""

    def encode(self) -> bytes:
        """The frame as bytes on the wire (start byte, payload length, sequence, command,
        payload, CRC-16); raises :class:`ValueError` for a payload over the maximum.
        """
        if len(self.payload) > MAX_PAYLOAD:
            raise ValueError(f"payload of {len(self.payload)} bytes > {MAX_PAYLOAD}")
        body = bytes((len(self.payload), self.seq & 0xFF, self.cmd & 0xFF)) + bytes(self.payload)
        c = crc16(body)
        return bytes((START,)) + body + bytes((c >> 8, c & 0xFF))


class FrameParser:
    """Incremental decoder: ``feed(bytes)`` returns the complete valid frames found.

    Bytes before a start byte are skipped (counted in ``garbage``); a candidate whose CRC
    fails drops its start byte and scanning resumes at the next byte (``crc_errors``).
    """

    def __init__(self) -> None:
        self.buf = bytearray()
        self.garbage = 0
        self.crc_errors = 0

    def reset(self) -> None:
        """Drop any partial frame."""
        self.buf.clear()

    def feed(self, data: bytes) -> list[Frame]:
        """Add received bytes; return the complete frames they finish (a partial frame
        waits for more bytes; bytes before a start byte and frames with a bad length or CRC
        are skipped and counted in ``garbage`` / ``crc_errors``).
        """
        self.buf += data
        out: list[Frame] = []
        while True:
            i = self.buf.find(START)
            if i < 0:
                self.garbage += len(self.buf)
                self.buf.clear()
                return out
            if i:
                self.garbage += i
                del self.buf[:i]
            if len(self.buf) < 4:
                return out
            n = self.buf[1]
            if n > MAX_PAYLOAD:
                self.crc_errors += 1
                del self.buf[:1]
                continue
            total = 4 + n + 2
            if len(self.buf) < total:
                return out
            body = bytes(self.buf[1:4 + n])
            crc = (self.buf[4 + n] << 8) | self.buf[5 + n]
            if crc16(body) != crc:
                self.crc_errors += 1
                del self.buf[:1]
                continue
            out.append(Frame(seq=body[1], cmd=body[2], payload=body[3:]))
            del self.buf[:total]
