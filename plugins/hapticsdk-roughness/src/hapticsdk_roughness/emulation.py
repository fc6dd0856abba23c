"""Emulators for tests and demos without hardware (SIMULATED devices, not drivers).

* :class:`DRV2667Emulator`: the DRV2667 register file (page 0 control registers, pages
  1..8 RAM, FIFO with 8 kHz drain and NAK when full, reset, standby, the ID field), the
  waveform-synthesis sequencer in time (a finite repeat count plays the waveform that many
  times and then stops; see :class:`DRV2667Emulator`), with an I2C transaction log and a
  decoder of what it would play (:meth:`DRV2667Emulator.output`).
* :class:`SerialBridgeEmulator`: the bridge microcontroller's firmware speaking
  :mod:`~hapticsdk_roughness.bridge_protocol` on the master end of a pseudo-terminal
  (``os.openpty``) in a thread, so the real pyserial code runs on the other end. Fault
  knobs: ``mute`` (stops answering), ``nak_all`` (answers every request with a CRC error),
  ``corrupt_replies`` (n replies with a broken CRC), ``garbage`` (bytes sent before the
  next reply), :meth:`~SerialBridgeEmulator.unplug` (closes the pty: cable pulled).

This module uses only the standard library (no pyserial, no pyusb).
"""

from __future__ import annotations

import os
import select
import threading
import time
from typing import Any

from . import bridge_protocol as bp
from . import drv2667 as d


class I2CNak(Exception):
    """The target NAK'd a byte; ``accepted`` bytes (register byte included) were taken."""

    def __init__(self, accepted: int, what: str = "data") -> None:
        self.accepted = accepted
        self.what = what
        super().__init__(f"{what} NACK after {accepted} byte(s)")


class DRV2667Emulator:
    """Register-level model of a DRV2667 (see :mod:`hapticsdk_roughness.drv2667`).

    ``fifo_drain_hz`` is the FIFO read-out rate (8 kHz; 0 = never drains). ``clock`` gives
    the emulated time (s); a test may pass its own to advance the chip's time by hand.

    Waveform-synthesis sequencer (mode 3), modelled in time from the datasheet facts: a
    waveform (header identifier) is the chunks from its start to its stop address; chunk
    ``k`` lasts ``cycles / (7.8125 Hz * code)`` plus its envelope's ramp-down time, and its
    bytes are read when the chunk starts (so amplitude/frequency/cycles rewrites land on
    chunk boundaries). Repeat count 0 plays until GO is cleared; a repeat count ``R > 0``
    plays the whole set ``R`` times, then the sequencer stops and the output is zero.
    Modelling choices where the public documents are silent (to be checked on hardware,
    see docs/devices.md): (1) the repeat count is latched when GO is written; (2) writing
    GO = 1 while the sequence plays re-arms it: the pass in progress finishes, then ``R``
    further passes play (no restart mid-cycle, no gap); (3) GO clears itself when the
    sequence ends. ``sequence_ends`` lists the emulated times at which a finite sequence
    ran out; ``last_write_t`` is the emulated time of the last I2C write received.
    :meth:`output` reports the playing chunk's bytes as they are in RAM now (a rewrite
    shows at once, though the chip applies it at the next chunk start): conservative for
    "is it still driving" checks.
    """

    def __init__(self, *, fifo_drain_hz: float = d.FIFO_RATE_HZ, clock=time.monotonic) -> None:
        self.clock = clock
        self.fifo_drain_hz = fifo_drain_hz
        self.log: list[tuple[str, bytes]] = []
        self.fifo_log = bytearray()
        self.lock = threading.Lock()
        self.ram = [bytearray(256) for _ in range(9)]     # index 1..8 used
        self.sequence_ends: list[float] = []
        self.gos = 0
        self.last_write_t: float | None = None
        self.reset()

    def reset(self) -> None:
        """Power-on state: registers cleared, FIFO empty, device id set."""
        self.regs = bytearray(256)
        self.regs[d.REG_STATUS] = d.STATUS_FIFO_EMPTY
        self.regs[d.REG_CONTROL1] = d.DEVICE_ID << 3
        self.regs[d.REG_CONTROL2] = d.CTRL2_STANDBY
        self.page = 0
        self.fifo = 0.0
        self._fifo_t = self.clock()
        self._seq_stop()
        self.resets = getattr(self, "resets", -1) + 1

    # -- synthesis sequencer time model -------------------------------------------
    def _seq_stop(self) -> None:
        self._seq_active = False
        self._seq_idx = 0
        self._seq_end = 0.0
        self._seq_passes = 0          # passes left, the one in progress included (0 = infinite)

    def _waveform(self) -> tuple[int, int, int] | None:
        """(RAM address from page 1, number of chunks, repeat count) of the waveform in
        sequencer slot 0, or None when there is none in synthesis mode."""
        wid = self.regs[d.REG_SEQ0]
        if wid == 0:
            return None
        p1 = self.ram[1]
        base = 1 + 5 * (wid - 1)
        if base + 4 > p1[0] or not p1[base] & 0x80:
            return None
        start = ((p1[base] & 0x07) << 8) | p1[base + 1]
        stop = ((p1[base + 2] & 0x07) << 8) | p1[base + 3]
        n = max(1, (stop - start + 1) // 4)
        return start, n, p1[base + 4]

    def _chunk(self, k: int) -> bytes:
        wf = self._waveform()
        addr = (wf[0] if wf else d.CHUNK_ADDR) + 4 * k
        page, off = 1 + addr // 256, addr % 256
        return bytes(self.ram[page][off:off + 4]) if page <= 8 else bytes(4)

    @staticmethod
    def _chunk_s(chunk: bytes) -> float:
        """Play time (s) of a chunk: ``cycles / (7.8125 Hz * code)`` + the ramp-down time."""
        code, cycles, env = chunk[1], chunk[2], chunk[3]
        if code == 0:
            return 0.0
        return cycles / (d.FREQ_STEP_HZ * code) + d.ENVELOPE_MS[env & 0x0F] / 1000.0

    def _seq_go(self) -> None:
        """A CONTROL2 write with GO = 1 (and STANDBY = 0): start, or re-arm while playing."""
        self._seq_advance()
        wf = self._waveform()
        self.gos += 1
        if wf is None:
            self._seq_stop()
            return
        repeat = wf[2]
        if self._seq_active:
            self._seq_passes = 0 if repeat == 0 else repeat + 1     # the pass in progress, then R more
            return
        self._seq_active, self._seq_idx = True, 0
        self._seq_passes = repeat
        self._seq_end = self.clock() + self._chunk_s(self._chunk(0))

    def _seq_advance(self) -> None:
        """Move the sequencer to the emulated time now (chunk bytes are read as each chunk
        starts; called before every transaction applies, so bytes written later are not
        applied to chunks that started earlier)."""
        c2 = self.regs[d.REG_CONTROL2]
        if not self._seq_active or not c2 & d.CTRL2_GO or c2 & d.CTRL2_STANDBY:
            self._seq_active = False
            return
        wf = self._waveform()
        if wf is None:
            self._seq_stop()
            return
        now = self.clock()
        nchunks = wf[1]
        guard = 0
        while now >= self._seq_end:
            self._seq_idx += 1
            if self._seq_idx >= nchunks:
                self._seq_idx = 0
                if self._seq_passes > 0:
                    self._seq_passes -= 1
                    if self._seq_passes == 0:
                        self.sequence_ends.append(self._seq_end)
                        self.regs[d.REG_CONTROL2] &= ~d.CTRL2_GO & 0xFF     # GO clears itself
                        self._seq_stop()
                        return
            dur = self._chunk_s(self._chunk(self._seq_idx))
            guard = guard + 1 if dur <= 0 else 0
            if guard > nchunks:             # a waveform of zero length: nothing to play
                self._seq_stop()
                return
            self._seq_end += dur

    # -- FIFO time model ------------------------------------------------------
    def _drain(self) -> None:
        now = self.clock()
        if self.fifo_drain_hz > 0:
            self.fifo = max(0.0, self.fifo - (now - self._fifo_t) * self.fifo_drain_hz)
        self._fifo_t = now

    def _status(self) -> int:
        self._drain()
        st = self.regs[d.REG_STATUS] & ~(d.STATUS_FIFO_FULL | d.STATUS_FIFO_EMPTY)
        if self.fifo >= d.FIFO_DEPTH:
            st |= d.STATUS_FIFO_FULL
        if self.fifo < 1:
            st |= d.STATUS_FIFO_EMPTY
        return st

    # -- I2C ---------------------------------------------------------------------
    def i2c_write(self, data: bytes) -> None:
        """A write transaction ``[reg, data...]``; raises :class:`I2CNak` on a full FIFO."""
        with self.lock:
            self.log.append(("w", bytes(data)))
            self.last_write_t = self.clock()
            self._seq_advance()
            if not data:
                return
            reg, payload = data[0], data[1:]
            if reg == d.REG_PAGE and len(payload) == 1:        # PAGE: a single-byte write, any page
                if payload[0] > 8:
                    self.regs[d.REG_STATUS] |= d.STATUS_ILLEGAL_ADDR
                    return
                self.page = payload[0]
                return
            if self.page == 0:
                if reg == d.REG_PAGE:
                    self.regs[d.REG_STATUS] |= d.STATUS_ILLEGAL_ADDR
                    return
                if reg == d.REG_FIFO:
                    self._drain()
                    for i, b in enumerate(payload):
                        if self.fifo >= d.FIFO_DEPTH:
                            raise I2CNak(1 + i)
                        self.fifo += 1
                        self.fifo_log.append(b)
                        self.regs[d.REG_CONTROL2] &= ~d.CTRL2_STANDBY & 0xFF   # a FIFO write wakes it
                    return
                for i, b in enumerate(payload):
                    r = reg + i
                    if r > d.REG_FIFO:
                        self.regs[d.REG_STATUS] |= d.STATUS_ILLEGAL_ADDR
                        return
                    if r == d.REG_STATUS:
                        continue                                   # read-only
                    if r == d.REG_CONTROL1:
                        b = (d.DEVICE_ID << 3) | (b & 0x07)          # ID bits read-only
                    if r == d.REG_CONTROL2 and b & d.CTRL2_DEV_RST:
                        self.reset()
                        return
                    self.regs[r] = b
                    if r == d.REG_CONTROL2:
                        if b & d.CTRL2_GO and not b & d.CTRL2_STANDBY:
                            self._seq_go()
                        else:
                            self._seq_stop()
                return
            page, addr = self.page, reg
            for b in payload:
                self.ram[page][addr] = b
                addr += 1
                if addr == 256:                                  # auto-increment across pages
                    addr, page = 0, page + 1
                    if page > 8:
                        self.regs[d.REG_STATUS] |= d.STATUS_ILLEGAL_ADDR
                        return

    def i2c_write_read(self, data: bytes, n: int) -> bytes:
        """An I2C write of ``data`` (register address last) followed by a read of ``n``
        bytes, as the chip answers it.
        """
        with self.lock:
            self.log.append(("r", bytes(data) + bytes((n,))))
            self._seq_advance()
            reg = data[-1] if data else 0
            if self.page == 0:
                out = bytearray()
                for i in range(n):
                    r = reg + i
                    out.append(self._status() if r == d.REG_STATUS else
                               self.page if r == d.REG_PAGE else self.regs[r & 0xFF])
                return bytes(out)
            return bytes(self.ram[self.page][reg:reg + n])

    # -- faults ---------------------------------------------------------------------
    def inject_overcurrent(self) -> None:
        """Latch the (assumed) over-current flag; the output stage shuts down."""
        with self.lock:
            self.regs[d.REG_STATUS] |= d.STATUS_OVERCURRENT
            self.regs[d.REG_CONTROL2] = (self.regs[d.REG_CONTROL2] | d.CTRL2_STANDBY) & ~d.CTRL2_GO & 0xFF

    # -- what it plays --------------------------------------------------------------
    @property
    def standby(self) -> bool:
        """Whether the chip is in standby (control register 2)."""
        return bool(self.regs[d.REG_CONTROL2] & d.CTRL2_STANDBY)

    @property
    def gain(self) -> int:
        """The gain setting, 0..3 (25, 50, 75, 100 V peak)."""
        return self.regs[d.REG_CONTROL1] & 0x03

    def output(self) -> dict[str, Any]:
        """Decoded output: ``{"playing", "amplitude_v", "frequency_hz", "fifo_bytes"}``."""
        with self.lock:
            self._seq_advance()
            c2 = self.regs[d.REG_CONTROL2]
            playing = bool(c2 & d.CTRL2_GO) and not c2 & d.CTRL2_STANDBY and self.regs[d.REG_SEQ0] != 0
            amp_v = freq = 0.0
            if playing and self._waveform() is not None:
                # a GO set behind the sequencer's back (a test poking regs) plays as before
                chunk = self._chunk(self._seq_idx if self._seq_active else 0)
                amp_v = chunk[0] / 255.0 * d.GAIN_FULL_SCALE_V[self.gain]
                freq = chunk[1] * d.FREQ_STEP_HZ
            self._drain()
            fifo = 0 if c2 & d.CTRL2_STANDBY else int(self.fifo)
            return {"playing": playing, "amplitude_v": amp_v, "frequency_hz": freq, "fifo_bytes": fifo}

    @property
    def driving(self) -> bool:
        """True when the output stage would put a non-zero voltage on the piezo."""
        o = self.output()
        return (o["playing"] and o["amplitude_v"] > 0) or o["fifo_bytes"] > 0

    def writes(self) -> list[bytes]:
        """Every I2C write received, in order."""
        return [b for k, b in self.log if k == "w"]


class SerialBridgeEmulator:
    """The bridge firmware on a pseudo-terminal, serving I2C targets ``{addr: emulator}``.

    ``port`` is the name to open with pyserial. Use as a context manager or call
    :meth:`start` / :meth:`stop`.
    """

    def __init__(self, targets: dict[int, DRV2667Emulator] | None = None, *, serial_number: str = "SIM0001",
                 reply_delay_s: float = 0.0, watchdog_s: float = 0.25) -> None:
        import tty
        self.targets = targets if targets is not None else {d.ADDRESS: DRV2667Emulator()}
        self.serial_number = serial_number
        self.reply_delay_s = reply_delay_s
        self.master, self.slave = os.openpty()
        tty.setraw(self.master)
        tty.setraw(self.slave)
        self.port = os.ttyname(self.slave)
        self.parser = bp.FrameParser()
        self.mute = False
        self.nak_all = False
        self.corrupt_replies = 0
        self.garbage = b""
        self.requests: list[bp.Frame] = []
        self.executed = 0
        self._last: tuple[int, int, bytes] | None = None
        self._last_reply = b""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.unplugged = False
        #: firmware watchdog: no valid request for this long -> every DRV2667 to standby
        self.watchdog_s = watchdog_s
        self.watchdog_trips = 0
        self._last_rx = time.monotonic()

    @property
    def drv(self) -> DRV2667Emulator:
        """The emulated DRV2667 behind the bridge."""
        return self.targets[d.ADDRESS]

    def start(self) -> "SerialBridgeEmulator":
        """Serve the bridge protocol on the port in a daemon thread; returns self."""
        self._thread = threading.Thread(target=self._run, name=f"bridge-emu {self.port}", daemon=True)
        self._thread.start()
        return self

    def __enter__(self) -> "SerialBridgeEmulator":
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    def stop(self) -> None:
        """Stop serving and wait (up to 2 s) for the thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass
        self.master = self.slave = -1

    def unplug(self) -> None:
        """Cable pulled: the link disappears (the pty is closed); the firmware, still powered,
        keeps running its watchdog."""
        self.unplugged = True
        if self._thread is None or not self._thread.is_alive():
            self._close_master()
            return
        deadline = time.monotonic() + 2.0
        while self.master >= 0 and time.monotonic() < deadline:   # the firmware thread closes it
            time.sleep(0.005)

    def _close_master(self) -> None:
        fd, self.master = self.master, -1
        try:
            os.close(fd)
        except OSError:
            pass

    def _watchdog(self) -> None:
        if self.watchdog_s and time.monotonic() - self._last_rx > self.watchdog_s:
            for t in self.targets.values():
                if not t.standby:
                    with t.lock:     # counted before the standby is visible to a reader
                        self.watchdog_trips += 1
                        t.regs[d.REG_CONTROL2] = d.CTRL2_STANDBY
            self._last_rx = time.monotonic()

    # -- firmware loop --------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            self._watchdog()
            if self.unplugged and self.master >= 0:
                self._close_master()
            if self.master < 0:
                time.sleep(0.01)
                continue
            try:
                r, _, _ = select.select([self.master], [], [], 0.02)
                if not r:
                    continue
                data = os.read(self.master, 4096)
            except (OSError, ValueError):
                self.master = -1
                continue
            if not data or self.unplugged:      # nothing sent after the cable is pulled arrives
                continue
            crc_before = self.parser.crc_errors
            frames = self.parser.feed(data)
            if self.parser.crc_errors > crc_before and not self.mute:
                self._send(bp.Frame(bp.SEQ_UNKNOWN, bp.CMD_ERROR, bytes((bp.ERR_CRC, 0))))
            for fr in frames:
                self.requests.append(fr)
                if not self.mute:
                    self._last_rx = time.monotonic()
                if self.mute:
                    continue
                if self.nak_all:
                    self._send(bp.Frame(bp.SEQ_UNKNOWN, bp.CMD_ERROR, bytes((bp.ERR_CRC, 0))))
                    continue
                key = (fr.seq, fr.cmd, fr.payload)
                if key == self._last:
                    self._send_raw(self._last_reply)
                    continue
                reply = self._execute(fr).encode()
                self._last, self._last_reply = key, reply
                self._send_raw(reply)

    def _execute(self, fr: bp.Frame) -> bp.Frame:
        self.executed += 1
        err = lambda code, detail=0: bp.Frame(fr.seq, bp.CMD_ERROR, bytes((code, detail)))  # noqa: E731
        if fr.cmd == bp.CMD_PING:
            return bp.Frame(fr.seq, bp.CMD_PING | bp.REPLY,
                            bytes((bp.PROTOCOL_VERSION,)) + self.serial_number.encode())
        if fr.cmd in (bp.CMD_I2C_WRITE, bp.CMD_I2C_WRITE_READ):
            need = 1 if fr.cmd == bp.CMD_I2C_WRITE else 2
            if len(fr.payload) < need:
                return err(bp.ERR_LENGTH)
            target = self.targets.get(fr.payload[0])
            if target is None:
                return err(bp.ERR_ADDR_NACK)
            try:
                if fr.cmd == bp.CMD_I2C_WRITE:
                    target.i2c_write(fr.payload[1:])
                    return bp.Frame(fr.seq, fr.cmd | bp.REPLY)
                data = target.i2c_write_read(fr.payload[2:], fr.payload[1])
                return bp.Frame(fr.seq, fr.cmd | bp.REPLY, data)
            except I2CNak as nak:
                return err(bp.ERR_DATA_NACK, min(255, nak.accepted))
        return err(bp.ERR_COMMAND)

    def _send(self, fr: bp.Frame) -> None:
        self._send_raw(fr.encode())

    def _send_raw(self, raw: bytes) -> None:
        if self.reply_delay_s:
            time.sleep(self.reply_delay_s)
        if self.corrupt_replies > 0:
            self.corrupt_replies -= 1
            raw = raw[:-1] + bytes(((raw[-1] ^ 0x5A),))
        if self.garbage:
            raw, self.garbage = self.garbage + raw, b""
        try:
            os.write(self.master, raw)
        except (OSError, ValueError):
            pass
