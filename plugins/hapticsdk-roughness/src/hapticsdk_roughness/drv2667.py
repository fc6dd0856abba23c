"""Register-level driver of the TI DRV2667 piezo haptic driver over an abstract I2C bus.

Facts (from the datasheet and public drivers, see docs/devices.md):

* 7-bit address 0x59; a write is ``[reg, data...]`` with auto-increment, a read writes
  ``[reg]`` then reads (repeated start).
* Page 0 (control): 0x00 STATUS (bit0 FIFO_FULL, bit1 FIFO_EMPTY, bit2 ILLEGAL_ADDR),
  0x01 CONTROL1 (bits 6:3 ID = 7, bit2 INPUT_MUX, bits 1:0 GAIN), 0x02 CONTROL2
  (bit7 DEV_RST, bit6 STANDBY, bits 3:2 TIMEOUT, bit1 EN_OVERRIDE, bit0 GO),
  0x03..0x0A waveform sequencer, 0x0B FIFO, 0xFF PAGE. Pages 1..8: waveform RAM.
* GAIN 0..3: 25/50/75/100 V peak full scale.
* Waveform synthesis (mode 3): a header on page 1 (byte 0 = header size - 1, then 5
  bytes per waveform: start hi (bit 7 = synthesis mode, low bits = page - 1), start lo,
  stop hi, stop lo, repeat count (0 = until GO is cleared)) and 4-byte chunks
  ``amplitude (V = amp/255 * full scale), frequency code (f = 7.8125 Hz * code, code
  1..255), cycles, envelope (ramp-up nibble, ramp-down nibble)``.
* FIFO (mode 1): 8-bit two's complement samples at 8 kHz into register 0x0B, 100 bytes
  deep; a full FIFO NAKs the byte.

Status: the public register map documents no over-current bit; this driver treats any
STATUS bit other than FIFO_FULL/FIFO_EMPTY as a fault and names bit 3 "overcurrent" as
an *assumption* (see :data:`STATUS_OVERCURRENT`), so a bridge or board that reports an
over-current there is handled, and a real device with all reserved bits 0 never trips it.
"""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Sequence

from hapticsdk.errors import DeviceError, SafetyError, TransportError, ValidationError

ADDRESS = 0x59

REG_STATUS = 0x00
REG_CONTROL1 = 0x01
REG_CONTROL2 = 0x02
REG_SEQ0 = 0x03
REG_FIFO = 0x0B
REG_PAGE = 0xFF

STATUS_FIFO_FULL = 0x01
STATUS_FIFO_EMPTY = 0x02
STATUS_ILLEGAL_ADDR = 0x04
#: ASSUMED over-current flag (not in the public register map; see module docstring)
STATUS_OVERCURRENT = 0x08
STATUS_FAULT_MASK = 0xFC

CTRL1_INPUT_MUX = 0x04
CTRL2_DEV_RST = 0x80
CTRL2_STANDBY = 0x40
CTRL2_EN_OVERRIDE = 0x02
CTRL2_GO = 0x01

DEVICE_ID = 7
#: full-scale peak voltage (V) per GAIN setting 0..3
GAIN_FULL_SCALE_V = (25.0, 50.0, 75.0, 100.0)
#: synthesis frequency step (Hz per code)
FREQ_STEP_HZ = 7.8125
SYNTH_FREQ_RANGE_HZ = (FREQ_STEP_HZ, 255 * FREQ_STEP_HZ)
#: envelope nibble -> full-scale ramp time (ms)
ENVELOPE_MS = (0, 32, 64, 96, 128, 160, 192, 224, 256, 512, 768, 1024, 1280, 1536, 1792, 2048)
TIMEOUT_MS = (5, 10, 15, 20)
FIFO_DEPTH = 100
FIFO_RATE_HZ = 8000.0

#: layout used by :meth:`DRV2667.load_synthesis`: one waveform, header 0x00..0x05, chunk at 0x06
HEADER_END = 0x05
CHUNK_ADDR = 0x06


class I2CBus(ABC):
    """Abstract I2C master: the two transactions the DRV2667 needs.

    Implementations raise :class:`~hapticsdk.errors.TransportError` (naming the bus) on a
    NAK, timeout or broken link.
    """

    #: text naming the bus for error messages ("serial bridge /dev/ttyUSB0")
    name: str = "i2c"

    @abstractmethod
    def write(self, addr: int, data: bytes) -> None:
        """One write transaction: START, addr+W, ``data``, STOP."""

    @abstractmethod
    def write_read(self, addr: int, data: bytes, n: int) -> bytes:
        """Write ``data`` (no STOP), repeated START, read ``n`` bytes, STOP."""

    def close(self) -> None:
        """Release the bus."""


def gain_for_voltage(max_v: float) -> int:
    """Smallest GAIN whose full scale (V peak) covers ``max_v``."""
    for g, fs in enumerate(GAIN_FULL_SCALE_V):
        if max_v <= fs + 1e-9:
            return g
    raise ValidationError(f"{max_v:g} V peak exceeds the DRV2667 maximum {GAIN_FULL_SCALE_V[-1]:g} V",
                          field="max_voltage_v")


def frequency_code(f_hz: float) -> int:
    """Synthesis frequency code ``round(f / 7.8125)`` clamped to 1..255."""
    if not math.isfinite(f_hz):
        raise ValidationError("frequency is not finite", field="frequency_hz")
    return int(min(255, max(1, round(f_hz / FREQ_STEP_HZ))))


def amplitude_code(volts: float, gain: int) -> int:
    """Synthesis amplitude byte for ``volts`` (V peak) at ``gain``: ``round(V/FS*255)``, 0..255."""
    fs = GAIN_FULL_SCALE_V[gain]
    return int(min(255, max(0, round(volts / fs * 255.0))))


def envelope_code(ramp_up_ms: float = 0.0, ramp_down_ms: float = 0.0) -> int:
    """Envelope byte: nearest ramp-up nibble (upper) and ramp-down nibble (lower)."""
    def nib(ms: float) -> int:
        return min(range(16), key=lambda i: abs(ENVELOPE_MS[i] - ms))
    return (nib(ramp_up_ms) << 4) | nib(ramp_down_ms)


@dataclass(frozen=True)
class SynthChunk:
    """One mode-3 chunk: amplitude byte, frequency code, cycles (1..255), envelope byte."""

    amplitude: int
    frequency: int
    cycles: int = 1
    envelope: int = 0

    def __post_init__(self) -> None:
        for name, v, lo in (("amplitude", self.amplitude, 0), ("frequency", self.frequency, 1),
                            ("cycles", self.cycles, 0), ("envelope", self.envelope, 0)):
            if not lo <= int(v) <= 255:
                raise ValidationError(f"{v} outside {lo}..255", field=f"chunk.{name}")

    def to_bytes(self) -> bytes:
        """The chunk as the DRV2667's four synthesis bytes (amplitude, frequency, cycles,
        envelope).
        """
        return bytes((self.amplitude, self.frequency, self.cycles, self.envelope))


def synthesis_ram_image(chunks: Sequence[SynthChunk], repeat: int = 0) -> bytes:
    """Page-1 bytes from address 0 for one waveform made of ``chunks``:
    ``[0x05, 0x80, 0x06, 0x00, stop_lo, repeat] + chunk bytes``."""
    if not chunks:
        raise ValidationError("need at least one chunk", field="chunks")
    stop = CHUNK_ADDR + 4 * len(chunks) - 1
    if stop > 0xFE:
        raise ValidationError(f"{len(chunks)} chunks do not fit in page 1", field="chunks")
    if not 0 <= repeat <= 255:
        raise ValidationError("repeat must be 0..255", field="repeat")
    header = bytes((HEADER_END, 0x80, CHUNK_ADDR, 0x00, stop, repeat))
    return header + b"".join(c.to_bytes() for c in chunks)


def chunk_seconds(frequency: int, cycles: int) -> float:
    """Play time (s) of a synthesis chunk without envelope: ``cycles / (7.8125 Hz * code)``."""
    return cycles / (FREQ_STEP_HZ * frequency)


def cycles_for(frequency: int, chunk_s: float) -> int:
    """Whole cycles per chunk at frequency ``code`` so the chunk lasts at most ``chunk_s``
    (s), at least one cycle (below ``1 / chunk_s`` Hz one cycle is longer), at most 255."""
    return int(min(255, max(1, math.floor(chunk_s * FREQ_STEP_HZ * frequency + 1e-9))))


def repeat_for(frequency: int, cycles: int, window_s: float) -> int:
    """Smallest repeat count (1..255) whose chunks play at least ``window_s`` (s):
    ``ceil(window_s / chunk_seconds)``."""
    return int(min(255, max(1, math.ceil(window_s / chunk_seconds(frequency, cycles) - 1e-9))))


def decode_status(status: int) -> list[str]:
    """Names of the set STATUS flags."""
    names = []
    for bit, name in ((STATUS_FIFO_FULL, "fifo_full"), (STATUS_FIFO_EMPTY, "fifo_empty"),
                      (STATUS_ILLEGAL_ADDR, "illegal_addr"), (STATUS_OVERCURRENT, "overcurrent")):
        if status & bit:
            names.append(name)
    other = status & STATUS_FAULT_MASK & ~(STATUS_ILLEGAL_ADDR | STATUS_OVERCURRENT)
    if other:
        names.append(f"reserved_0x{other:02x}")
    return names


class DRV2667:
    """A DRV2667 on ``bus`` at ``address``. ``device`` names it in errors.

    The driver caches the PAGE register so that playback updates (amplitude and frequency
    bytes on page 1) cost one I2C write per change.
    """

    def __init__(self, bus: I2CBus, *, address: int = ADDRESS, device: str = "drv2667") -> None:
        self.bus = bus
        self.address = int(address)
        self.device = device
        self._page: int | None = None
        self.gain = 0
        self.chunk: SynthChunk | None = None
        #: repeat count last written to the header of waveform 1 (0 = until GO is cleared)
        self.repeat = 0

    # -- raw access ----------------------------------------------------------
    def write(self, reg: int, *data: int) -> None:
        """Write ``data`` to register ``reg`` (and the following ones)."""
        self.bus.write(self.address, bytes((reg, *data)))

    def read(self, reg: int, n: int = 1) -> bytes:
        """Read ``n`` bytes from register ``reg``; raises
        :class:`~hapticsdk.errors.TransportError` on a short read.
        """
        out = self.bus.write_read(self.address, bytes((reg,)), n)
        if len(out) != n:
            raise TransportError(f"read of register 0x{reg:02x}: expected {n} bytes, got {len(out)}",
                                 device=self.device)
        return out

    def set_page(self, page: int) -> None:
        """Select page 0 (control) or 1..8 (RAM); a single-byte write as the datasheet requires."""
        if not 0 <= page <= 8:
            raise ValidationError(f"page {page} outside 0..8", field="page")
        if self._page != page:
            self.write(REG_PAGE, page)
            self._page = page

    # -- control -------------------------------------------------------------
    def probe(self) -> int:
        """Read CONTROL1 and check the ID field (7); returns the ID."""
        self._page = None
        self.set_page(0)
        c1 = self.read(REG_CONTROL1)[0]
        dev_id = (c1 >> 3) & 0x0F
        if dev_id != DEVICE_ID:
            raise DeviceError(f"device at I2C 0x{self.address:02x} on {self.bus.name} reports ID {dev_id} "
                              f"(CONTROL1=0x{c1:02x}); a DRV2667 reports ID {DEVICE_ID}", device=self.device)
        return dev_id

    def reset(self) -> None:
        """DEV_RST; the device comes back in standby with page 0 selected."""
        self.set_page(0)
        self.write(REG_CONTROL2, CTRL2_DEV_RST)
        self._page = 0

    def standby(self) -> None:
        """STANDBY=1, GO=0: boost and amplifier off (the safe state)."""
        self.set_page(0)
        self.write(REG_CONTROL2, CTRL2_STANDBY)

    def wake(self, timeout_ms: int = 20) -> None:
        """STANDBY=0 with the idle TIMEOUT (5/10/15/20 ms)."""
        if timeout_ms not in TIMEOUT_MS:
            raise ValidationError(f"timeout_ms must be one of {TIMEOUT_MS}", field="timeout_ms")
        self.set_page(0)
        self.write(REG_CONTROL2, TIMEOUT_MS.index(timeout_ms) << 2)

    def set_gain(self, gain: int, *, analog_input: bool = False) -> None:
        """GAIN 0..3 (25/50/75/100 V peak), digital input unless ``analog_input``."""
        if gain not in (0, 1, 2, 3):
            raise ValidationError(f"gain {gain} not in 0..3", field="gain")
        self.set_page(0)
        self.write(REG_CONTROL1, (CTRL1_INPUT_MUX if analog_input else 0) | gain)
        self.gain = gain

    def status(self) -> int:
        """The status register (page 0)."""
        self.set_page(0)
        return self.read(REG_STATUS)[0]

    def check_status(self) -> int:
        """Read STATUS; a fault bit puts the device in standby and raises :class:`SafetyError`."""
        st = self.status()
        if st & STATUS_FAULT_MASK:
            try:
                self.standby()
            finally:
                raise SafetyError(f"DRV2667 STATUS=0x{st:02x} ({', '.join(decode_status(st))}); "
                                  "device put in standby", device=self.device)
        return st

    # -- waveform synthesis (mode 3) ------------------------------------------
    def load_synthesis(self, chunks: Sequence[SynthChunk], repeat: int = 0) -> None:
        """Write the page-1 header + chunks and point sequencer slot 0 at waveform 1."""
        image = synthesis_ram_image(chunks, repeat)
        self.set_page(1)
        self.write(0x00, *image)
        self.set_page(0)
        self.write(REG_SEQ0, 1, 0)
        self.chunk = chunks[0]
        self.repeat = int(repeat)

    def go(self, timeout_ms: int = 20) -> None:
        """Start the sequencer (STANDBY=0, GO=1)."""
        self.set_page(0)
        self.write(REG_CONTROL2, (TIMEOUT_MS.index(timeout_ms) << 2) | CTRL2_GO)

    def stop_playback(self) -> None:
        """Clear GO (stays awake)."""
        self.set_page(0)
        self.write(REG_CONTROL2, 0)

    def update_chunk(self, amplitude: int, frequency: int) -> bool:
        """Rewrite the amplitude and frequency bytes of the first chunk while playing
        (one write on page 1 when either changed). Returns True when bytes were sent."""
        cur = self.chunk
        if cur is not None and cur.amplitude == amplitude and cur.frequency == frequency:
            return False
        new = SynthChunk(amplitude, frequency, cur.cycles if cur else 1, cur.envelope if cur else 0)
        self.set_page(1)
        self.write(CHUNK_ADDR, amplitude, frequency)
        self.chunk = new
        return True

    def update_waveform(self, amplitude: int, frequency: int, cycles: int, repeat: int) -> bool:
        """Rewrite the first chunk's amplitude, frequency and cycles bytes, and the
        waveform's repeat count when it changed, in one page-1 write (``[0x06, amp, freq,
        cycles]``, or ``[0x05, repeat, amp, freq, cycles]``). The chip latches the repeat
        count at the next GO (see :meth:`go`). Returns True when bytes were sent."""
        new = SynthChunk(amplitude, frequency, cycles, self.chunk.envelope if self.chunk else 0)
        if not 0 <= repeat <= 255:
            raise ValidationError(f"repeat {repeat} outside 0..255", field="repeat")
        if new == self.chunk and repeat == self.repeat:
            return False
        self.set_page(1)
        if repeat != self.repeat:
            self.write(HEADER_END, repeat, amplitude, frequency, cycles)
        else:
            self.write(CHUNK_ADDR, amplitude, frequency, cycles)
        self.chunk, self.repeat = new, int(repeat)
        return True

    # -- FIFO (mode 1) ---------------------------------------------------------
    def stream_fifo(self, samples: bytes, *, chunk: int = 32, max_retries: int = 50) -> int:
        """Write signed 8-bit samples to the FIFO (multi-byte writes of ``chunk`` bytes).

        A FIFO-full NAK (the bus reports it as a :class:`TransportError` with ``nak=True`` and
        ``accepted`` bytes) is resent from the NAK'd byte after about one chunk's drain time,
        up to ``max_retries`` NAKs in a row; returns the number of bytes written.
        """
        self.set_page(0)
        sent = 0
        retries = 0
        while sent < len(samples):
            part = samples[sent:sent + chunk]
            try:
                self.bus.write(self.address, bytes((REG_FIFO,)) + part)
            except TransportError as exc:
                if not getattr(exc, "nak", False) or retries >= max_retries:
                    raise
                retries += 1
                accepted = int(getattr(exc, "accepted", 0) or 0)
                sent += max(0, accepted - 1)   # resend from the NAK'd byte (first byte is the register)
                time.sleep(chunk / FIFO_RATE_HZ)   # let the FIFO drain by about one chunk
                continue
            retries = 0
            sent += len(part)
        return sent

    @staticmethod
    def to_fifo_samples(wave_v: Sequence[float], full_scale_v: float) -> bytes:
        """Volts -> 8-bit two's complement FIFO samples (0x7F = +full scale)."""
        out = bytearray()
        for v in wave_v:
            q = int(round(max(-1.0, min(1.0, v / full_scale_v)) * 127))
            out.append(q & 0xFF)
        return bytes(out)
