"""The audio side of ``voicecoil-audio``: the block renderer both isolations share, and
the audio process that runs the PortAudio stream apart from the application
(``isolation="process"``, the default on POSIX).

Why a process of its own: the PortAudio callback is Python code, so once per audio
period (2.67 ms for 128 frames at 48 kHz) it needs its interpreter's lock. In the
application's interpreter a busy pure-Python thread holds that lock for up to the switch
interval (5 ms by default) at a time, and about half the periods came late
(issue-28 note, round 3). The audio process's interpreter has two threads: the
callback's (PortAudio's audio thread; JACK's real-time thread when the server runs
real time) and a main thread that sleeps in ``select`` on its control pipe, so the
callback never waits for the lock.

The process is a fresh interpreter (``python -m hapticsdk_hardness.audio_process``,
started with :mod:`subprocess`), not ``multiprocessing``'s ``spawn``: spawn imports the
application's main module again in the child, which re-runs a script's unguarded
top-level code (here: whatever opened the coil); a device backend can be opened from
any script, a REPL or a live session's servo process. Nothing is pickled: the
configuration is one JSON argument, the commands go through shared memory.

Shared memory: one anonymous file (Linux ``memfd_create``; elsewhere an unlinked
temporary file) passed to the child by descriptor and mapped by both; nothing to unlink,
no name to leak, it goes away with the last process that maps it. Float64 slots:

* the target, written by the servo side only (one writer), read by the callback under a
  sequence lock: the writer makes the sequence number odd, writes frequency, amplitude,
  the command's ``time.monotonic()`` and the silence flag, then makes it even; the
  callback reads the number, the four values, the number again, and keeps its previous
  target when the two differ or are odd (a read torn by a write in progress is never
  rendered). ``time.monotonic()`` is the system-wide monotonic clock, the same in both
  processes (Linux ``CLOCK_MONOTONIC``).
* counters and flags, written by the audio process only: callbacks, output underflows,
  dead-servo timeouts, whether the last block was silenced by the timeout.

Pipes: a control pipe (application -> audio process) whose end of file means the
application side is gone, and a status pipe (audio process -> application) carrying
one JSON line when the stream runs (or why it could not open) and one when the process
ends on its own (the stream stopped, the callback failed).

Silence on every stop path of the audio process:

* ``stop()`` on the application side writes the silence flag: the next block is zeros;
* the servo stalls: the callback renders zeros once the last command is older than
  ``command_timeout_s`` (its own dead-man's switch, as in the thread isolation);
* ``close()``: the silence flag, then ``q`` on the control pipe: the audio process
  silences its callback, aborts and closes the stream, and exits; after
  :data:`EXIT_WAIT_S` it is killed (a killed JACK client's ports leave the graph);
* the process that opened the coil dies (the application, or a live session's servo
  process): the kernel closes its end of the control pipe, the audio process reads end
  of file at once, goes silent and exits as on ``close()``; and the callback checks at
  every block that its parent is still its parent (a forked copy of the application may
  still hold the control pipe open), renders silence from the first block after, and
  wakes the main thread to exit;
* the stream stops under it (audio server or device gone): the audio process reports it
  on the status pipe and exits without touching the dead stream (PortAudio's JACK
  backend hangs or aborts when such a stream is closed, and in ``Pa_Terminate``);
* the audio process dies (killed, crashed): its JACK client and ports leave the graph;
  the next command raises :class:`~hapticsdk_hardness.audio.AudioProcessDied`.
"""

from __future__ import annotations

import gc
import json
import math
import mmap
import os
import select
import struct
import sys
import time
from typing import Any

import numpy as np

from hapticsdk.synthesis import Oscillator

# -- shared-memory layout (float64 slots) ----------------------------------------------
SEQ, FREQ, AMP, T_CMD, SILENT = 0, 1, 2, 3, 4          # the target: servo side writes
CALLBACKS, UNDERRUNS, TIMEOUTS, TIMED_OUT = 8, 9, 10, 11  # counters: audio process writes
#: diagnostics the audio process writes: the longest callback (s, from entering the
#: Python callback to leaving it) and the callbacks that started more than 1.5 blocks
#: after the previous one started (this process was late to run its callback: an
#: audio thread waiting for the CPU or the interpreter lock)
CALLBACK_MAX_S, LATE_STARTS = 12, 13
NSLOTS = 16
SIZE = NSLOTS * 8
#: the four target values after the sequence number, in one read
_TARGET = struct.Struct("=4d")

#: how often the audio process's main thread checks that its stream still runs (s): when
#: the audio server or the device vanishes no callback comes to tell. This is the main
#: thread's only periodic wake-up, and every wake-up takes the interpreter lock for a
#: moment the callback may want it (a wake-up preempted by the callback's real-time
#: thread, then kept off the CPU by other processes, would hold the callback up: a late
#: period); it bounds only how long a dead stream goes unreported (nothing plays then).
STREAM_POLL_S = 0.5
#: how long ``close()`` waits for the audio process to exit before killing it (s); a hang
#: guard (the exit takes one audio period plus PortAudio's shutdown), not a timing figure
EXIT_WAIT_S = 5.0
#: how long ``open()`` waits for the stream to run (s); a hang guard for a wedged audio
#: server: starting takes an interpreter, numpy and sounddevice (0.2-0.5 s measured on an
#: idle machine) and PortAudio's device scan
START_WAIT_S = 60.0


class BlockRenderer:
    """One block of the coil's output from a target (frequency Hz, amplitude 0..1, the
    command's ``time.monotonic()``, silence flag): the audio callback of both isolations.

    The phase is carried over between blocks by :class:`~hapticsdk.synthesis.Oscillator`
    (a new frequency continues the waveform), the amplitude slews at most full scale per
    ``ramp_s``, silence is immediate (the safe state is now: no ramp down). A target
    outside the declared band or amplitude range, or not finite, is clamped or silenced
    here too: the safety layer of the servo side clamps first, this is the audio side's
    own copy of the limits."""

    def __init__(self, fs: float, *, ramp_s: float, full_scale: float, channel_index: int,
                 command_timeout_s: float, frequency_range_hz: tuple[float, float], max_amplitude: float) -> None:
        self.osc = Oscillator(fs, ramp_s=ramp_s, max_amplitude=1.0)
        self.full_scale = float(full_scale)
        self.channel_index = int(channel_index)
        self.command_timeout_s = float(command_timeout_s)
        self.fmin, self.fmax = (float(frequency_range_hz[0]), float(frequency_range_hz[1]))
        self.amax = float(max_amplitude)
        self.callbacks = 0
        self.underruns = 0
        self.timeouts = 0
        #: the last block was silenced because the last command was too old
        self.timed_out = False
        self.error: BaseException | None = None

    def __call__(self, out: np.ndarray, frames: int, underflow: bool, freq: float, amp: float, t_cmd: float,
                 silent: bool, now: float) -> None:
        """Fill ``out`` (frames x channels) for the target; ``underflow``: PortAudio's
        flag for this callback; ``now``: ``time.monotonic()``."""
        try:
            self.callbacks += 1
            if underflow:
                self.underruns += 1
            osc = self.osc
            if silent or self.error is not None or not (math.isfinite(freq) and math.isfinite(amp)):
                out.fill(0.0)
                osc.amplitude = 0.0
                return
            if now - t_cmd > self.command_timeout_s:
                if not self.timed_out:
                    self.timeouts += 1
                    self.timed_out = True
                out.fill(0.0)
                osc.amplitude = 0.0
                return
            self.timed_out = False
            y = osc.render(min(max(freq, self.fmin), self.fmax), min(max(amp, 0.0), self.amax), frames)
            if out.shape[1] > 1:
                out.fill(0.0)
            out[:, self.channel_index] = y * self.full_scale
        except BaseException as exc:  # never into PortAudio
            self.error = exc
            out.fill(0.0)


class SharedTarget:
    """The shared-memory block on either side (see the module doc): ``fd`` an open
    descriptor of a file of :data:`SIZE` bytes."""

    def __init__(self, fd: int) -> None:
        self.mm = mmap.mmap(fd, SIZE)
        self.raw = memoryview(self.mm)
        self.mv: Any = self.raw.cast("d")
        self._last = (0.0, 0.0, 0.0, 1.0)

    # servo side (the one writer of the target)
    def write(self, freq: float, amp: float, t_cmd: float, silent: bool) -> None:
        """Publish a target (seqlock write)."""
        mv = self.mv
        s = mv[SEQ]
        mv[SEQ] = s + 1.0
        mv[FREQ] = freq
        mv[AMP] = amp
        mv[T_CMD] = t_cmd
        mv[SILENT] = 1.0 if silent else 0.0
        mv[SEQ] = s + 2.0

    # audio side
    def read(self) -> tuple[float, float, float, float]:
        """The latest consistent target (frequency, amplitude, command time, silence
        flag); the previous one while a write is in progress."""
        mv = self.mv
        s1 = mv[SEQ]
        vals = _TARGET.unpack_from(self.raw, 8)
        if s1 == mv[SEQ] and not int(s1) & 1:
            self._last = vals
        return self._last

    def counter(self, slot: int) -> int:
        """A counter the audio process publishes (``CALLBACKS``, ``UNDERRUNS``, ``TIMEOUTS``)."""
        return int(self.mv[slot])

    def close(self) -> None:
        """Unmap this side's view (the file lives on while the other side maps it)."""
        for v in (self.mv, self.raw):
            try:
                v.release()
            except Exception:  # noqa: BLE001 - a view still exported elsewhere
                pass
        try:
            self.mm.close()
        except Exception:  # noqa: BLE001
            pass


def new_shared_file() -> int:
    """A descriptor of a new anonymous file of :data:`SIZE` bytes (not inherited by
    children unless passed)."""
    if hasattr(os, "memfd_create"):
        fd = os.memfd_create("hapticsdk-voicecoil-audio")
    else:
        import tempfile
        fd, path = tempfile.mkstemp(prefix="hapticsdk-voicecoil-audio-")
        os.unlink(path)
    os.ftruncate(fd, SIZE)
    return fd


# =====================================================================================
# the audio process
# =====================================================================================
def _say(fd: int, **msg: Any) -> None:
    try:
        os.write(fd, (json.dumps(msg) + "\n").encode())
    except OSError:
        pass


def _open_stream(cfg: dict[str, Any], callback: Any) -> tuple[Any, dict[str, Any]]:
    """Open and start the stream as configured; returns it and what the application
    side reports; raises ``_Refused`` with the error to re-raise there."""
    try:
        import sounddevice as sd
    except Exception as exc:  # ImportError, or OSError when the PortAudio library is missing
        raise _Refused("DeviceNotFoundError", f"import failed: {type(exc).__name__}: {exc}", kind="import")
    device = cfg["device"]
    try:
        info = sd.query_devices(device, "output")
    except Exception as exc:
        outs = [f"{i}: {d['name']}" for i, d in enumerate(sd.query_devices()) if d["max_output_channels"] > 0]
        raise _Refused("DeviceNotFoundError", f"no audio output {device!r} ({exc}); outputs: {outs or 'none'}")
    ch = cfg["channel_index"]
    if ch >= int(info["max_output_channels"]):
        raise _Refused("ValidationError", f"channel_index {ch} but {info['name']!r} has "
                       f"{info['max_output_channels']} output channel(s)", field="options.channel_index")
    fs = float(cfg["samplerate"] or info["default_samplerate"])
    stream = sd.OutputStream(samplerate=fs, blocksize=cfg["blocksize"], device=device, channels=ch + 1,
                             dtype="float32", latency="low", callback=callback(fs))
    stream.start()
    return stream, {"device_name": str(info["name"]), "samplerate": fs, "latency": float(stream.latency)}


class _Refused(Exception):
    def __init__(self, error: str, message: str, **extra: Any) -> None:
        super().__init__(message)
        self.msg = {"error": error, "message": message, **extra}


def main(argv: list[str]) -> int:
    """The audio process: ``python -m hapticsdk_hardness.audio_process CONFIG_JSON``."""
    cfg = json.loads(argv[0])
    ctl, status, ppid = int(cfg["ctl_fd"]), int(cfg["status_fd"]), int(cfg["ppid"])
    if os.getppid() != ppid:   # the application died before we started
        return 0
    shared = SharedTarget(int(cfg["shm_fd"]))
    os.close(int(cfg["shm_fd"]))
    mv = shared.mv
    stopping = [False]
    mono = time.monotonic
    getppid = os.getppid
    holder: list[BlockRenderer] = []
    wake_r, wake_w = os.pipe()   # the callback wakes the main thread (parent changed, failure)

    def make_callback(fs: float) -> Any:
        r = BlockRenderer(fs, ramp_s=cfg["ramp_s"], full_scale=cfg["full_scale"],
                          channel_index=cfg["channel_index"], command_timeout_s=cfg["command_timeout_s"],
                          frequency_range_hz=tuple(cfg["frequency_range_hz"]), max_amplitude=cfg["max_amplitude"])
        holder.append(r)
        read = shared.read

        last_start = [0.0]

        def callback(out: np.ndarray, frames: int, _time: Any, st: Any) -> None:
            t0 = mono()
            try:
                if t0 - last_start[0] > 1.5 * frames / fs and last_start[0]:
                    mv[LATE_STARTS] += 1.0
                last_start[0] = t0
                if not stopping[0] and getppid() != ppid:
                    stopping[0] = True     # the owner is gone: silence from this block on
                    os.write(wake_w, b"p")
                f, a, t_cmd, silent = read()
                r(out, frames, st.output_underflow, f, a, t_cmd, silent != 0.0 or stopping[0], t0)
                mv[CALLBACKS] = r.callbacks
                mv[UNDERRUNS] = r.underruns
                mv[TIMEOUTS] = r.timeouts
                mv[TIMED_OUT] = 1.0 if r.timed_out else 0.0
                if r.error is not None and not stopping[0]:
                    stopping[0] = True
                    os.write(wake_w, b"e")
                dt = mono() - t0
                if dt > mv[CALLBACK_MAX_S]:
                    mv[CALLBACK_MAX_S] = dt
            except BaseException as exc:  # never into PortAudio; the main thread reports it
                r.error = r.error or exc
                out.fill(0.0)
        return callback

    try:
        stream, ready = _open_stream(cfg, make_callback)
    except _Refused as exc:
        _say(status, **exc.msg)
        return 1
    except Exception as exc:
        _say(status, error="DeviceError", message=f"open failed: {type(exc).__name__}: {exc}")
        return 1
    _say(status, ok=True, pid=os.getpid(), **ready)
    # everything imported so far lives as long as the process: out of the collector's way
    # (a full collection of numpy's and sounddevice's objects would take the lock for
    # milliseconds, in the middle of an audio period)
    gc.freeze()
    r = holder[0]
    why = ""
    while True:
        ready_fds, _, _ = select.select([ctl, wake_r], [], [], STREAM_POLL_S)
        if ctl in ready_fds:
            data = os.read(ctl, 64)
            if not data:
                why = "parent"     # end of file: the application side is gone
                break
            if b"q" in data:
                why = "close"
                break
        if getppid() != ppid:
            why = "parent"
            break
        if r.error is not None:
            stopping[0] = True
            _say(status, event="callback_failed",
                 message=f"audio callback failed: {type(r.error).__name__}: {r.error}")
            why = "callback"
            break
        if not stream.active:
            # the audio server or device went away under a running stream: leave it alone
            # (see the module doc) and leave without PortAudio's exit handler
            _say(status, event="stream_stopped",
                 message="the audio stream stopped (device gone or audio server stopped)")
            os._exit(3)
    stopping[0] = True   # the next block is zeros, then the stream goes
    try:
        stream.abort()
        stream.close()
        import sounddevice as sd
        sd._terminate()   # closes PortAudio's client of the audio server
    except Exception as exc:  # noqa: BLE001 - exiting anyway
        _say(status, event="close_failed", message=f"{type(exc).__name__}: {exc}")
    os._exit(0 if why in ("close", "parent") else 4)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
