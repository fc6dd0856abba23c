"""``voicecoil-audio``: a voice coil (Haptuator, tactor, the paper's C-2) on a sound card,
through PortAudio with ``sounddevice`` (``pip install -e 'plugins/hapticsdk-hardness[audio]'`` from a checkout; on
Linux also the system PortAudio, Debian ``libportaudio2``).

A callback stream runs at the card's rate (its default sample rate unless
``samplerate`` is given). The servo side only sets a target -- frequency (Hz) and
amplitude (0..1) -- per command; the audio callback renders each block
(:class:`~hapticsdk_hardness.audio_process.BlockRenderer`, with
:class:`hapticsdk.synthesis.Oscillator`): the phase is accumulated, so a new frequency
continues the waveform without a jump, and the amplitude slews to its target at most
full scale per ``ramp_s``. Frequency and amplitude are clamped by the core safety layer
(``limits``) before they reach the target.

Where the stream runs (``isolation``):

* ``"process"`` (the default on POSIX): in an audio process of its own
  (:mod:`hapticsdk_hardness.audio_process`); the target goes through shared memory under
  a sequence lock, nothing is pickled per command. The callback is Python code and needs
  its interpreter's lock once per audio period; in its own process no application thread
  can hold that lock (a busy pure-Python thread holds it for up to the switch interval,
  5 ms, longer than a 128-frame period at 48 kHz, 2.7 ms).
* ``"thread"``: in this process (PortAudio's audio thread), the interpreter's switch
  interval lowered while open (``switch_interval_s``); periods come late while the
  application runs busy Python threads. The default where a child cannot be handed
  descriptors (Windows).

Amplitude calibration: ``full_scale`` is the sample peak at amplitude 1 (default 1.0,
the card's full scale); the sample peak is ``amplitude x full_scale``. The amplifier
and the coil after the card are the user's calibration (docs/devices.md).

Silence on every stop path:

* ``stop()`` (the servo loop's stop, a fault, ``close()``, the interpreter's exit
  handler) sets the output to zero at once: the next block the callback renders is
  silent (no ramp down: the safe state is now, as for ``voicecoil-virtual``);
* a stalled or dead servo: the callback itself renders silence when the last command is
  older than ``command_timeout_s`` (the audio side's own dead-man's switch);
* ``close()`` stops and closes the stream (and ends the audio process);
* the process that opened the coil dies (the application, or a live session's servo
  process): the audio process reads end of file on its control pipe, goes silent and
  exits; in the thread isolation the stream dies with the process (the audio server drops
  its ports);
* the audio process dies: nothing plays (its client left the audio server); the next
  command raises :class:`AudioProcessDied` (a :class:`~hapticsdk.errors.DeviceError`);
* the audio server (or the device) goes away: the stream stops being active, the next
  command raises :class:`~hapticsdk.errors.DeviceError` ("the audio stream stopped"), and
  the dead stream is never stopped or closed: with JACK, PortAudio hangs or aborts the
  process when such a stream is stopped or closed, and also in its own exit handler
  (``Pa_Terminate``). The audio process then leaves with ``os._exit``; in the thread
  isolation the stream is abandoned and the process may hang at exit.

The device is chosen by ``device``, a PortAudio device name (substring, as
``sounddevice`` matches it) or index: a privileged option (it picks hardware that a
scene file must not choose), set in the user device configuration, the environment
or on the command line (:mod:`hapticsdk.devices.device_options`).
"""

from __future__ import annotations

import importlib
import json
import logging
import os
import select
import signal
import subprocess
import sys
import time
from typing import Any, ClassVar

import numpy as np

from hapticsdk.devices.actuators import Actuator, ActuatorLimits
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import DeviceError, DeviceNotFoundError, ValidationError
from hapticsdk.install_hints import pip_hint
from hapticsdk.synthesis import Oscillator

from .audio_process import (CALLBACK_MAX_S, CALLBACKS, EXIT_WAIT_S, LATE_STARTS, START_WAIT_S, TIMEOUTS,
                            UNDERRUNS, BlockRenderer, SharedTarget)

log = logging.getLogger(__name__)

#: every stream opened and not yet closed: a sounddevice stream dropped without close()
#: frees its C callback while PortAudio still calls it (a crash), e.g. when a backend's
#: close failed; kept here until closed, and for good when its audio server went away
#: (abandoned, never touched again; see VoiceCoilAudio._close)
_LIVE: set[Any] = set()

INSTALL_HINT = (pip_hint("hapticsdk-hardness", "audio") + " (sounddevice) and the system PortAudio "
                "(Debian/Ubuntu: apt install libportaudio2; JACK needs a JACK-enabled PortAudio, as Debian's)")


def import_sounddevice(device: str = "voicecoil-audio") -> Any:
    """``sounddevice``, or :class:`DeviceNotFoundError` naming what to install."""
    try:
        return importlib.import_module("sounddevice")
    except Exception as exc:  # ImportError, or OSError when the PortAudio library is missing
        raise DeviceNotFoundError(f"audio output needs sounddevice and PortAudio ({INSTALL_HINT}); "
                                  f"import failed: {type(exc).__name__}: {exc}", device=device) from None


class AudioProcessDied(DeviceError):
    """The audio process of a ``voicecoil-audio`` (``isolation="process"``) is gone:
    killed, crashed, or ended because its stream stopped or its callback failed.
    ``reason`` says which (``"killed by SIGKILL"``, ``"the audio stream stopped (...)"``);
    ``exitcode`` is the process's exit status (negative: the signal that killed it)."""

    def __init__(self, message: str, *, device: str | None = None, reason: str = "",
                 exitcode: int | None = None) -> None:
        self.reason = reason
        self.exitcode = exitcode
        super().__init__(message, device=device)


#: where the stream can run (see the module doc)
ISOLATIONS = ("process", "thread")
#: ``"process"`` where a child can be handed descriptors (POSIX), else ``"thread"``
DEFAULT_ISOLATION = "process" if os.name == "posix" else "thread"
#: thread pools of numerical libraries in the audio process: one thread (it renders one
#: block per period and must not wake idle pool workers on a loaded machine)
_POOL_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")


class VoiceCoilAudio(Actuator):
    """A voice coil on a sound card output (entry point ``voicecoil-audio``).

    Args:
        device: PortAudio output device name or index (privileged); default the
            system's default output.
        samplerate: stream rate (Hz); default the device's own rate.
        blocksize: frames per callback (0: the host's choice, e.g. the JACK period).
        channel_index: output channel the coil is wired to (0-based; other channels
            carry silence).
        full_scale: sample peak at amplitude 1 (0 < full_scale <= 1).
        ramp_s: amplitude slew time from 0 to full scale (s).
        command_timeout_s: the callback renders silence when the last command is older
            (s). Default (None): the safety layer's ``restart_after_s`` (50 ms by default;
            at most 1 s), so sound the switch cut returns through the layer's ramp when
            the servo resumes (:func:`hapticsdk.devices.safety.default_command_timeout_s`).
        isolation: ``"process"`` (default on POSIX): the stream runs in an audio process
            of its own, fed through shared memory, so no thread of the application shares
            the callback's interpreter lock; ``"thread"``: in this process (the default
            where a child cannot be handed descriptors, i.e. Windows). See the module doc.
        switch_interval_s: ``isolation="thread"`` only: while open, the interpreter's
            thread switch interval (``sys.setswitchinterval``) is at most this (s; None:
            left alone). The callback is Python code: it needs the interpreter lock once
            per audio period, and a busy Python thread of the application hands it over
            only every switch interval (5 ms by default, longer than a 128-frame period
            at 48 kHz, 2.7 ms): that would be an underrun. Restored at close. The process
            isolation leaves the application's interpreter alone.
        label, safety: as for every actuator.
    """

    name: ClassVar[str] = "voicecoil-audio"
    channel: ClassVar[str] = "vibration"
    accepts: ClassVar[dict[str, str]] = {"frequency_hz": "Hz", "amplitude": "1"}
    simulated: ClassVar[bool] = False
    #: the voice coil's band (the paper's C-2 and common Haptuators: tens of Hz to ~1 kHz)
    limits = ActuatorLimits(frequency_range_hz=(1.0, 1000.0), max_amplitude=1.0, amplitude_unit="1")
    privileged_options: ClassVar[dict[str, str]] = {"device": "audio output device"}

    def __init__(self, *, device: int | str | None = None, samplerate: float | None = None, blocksize: int = 0,
                 channel_index: int = 0, full_scale: float = 1.0, ramp_s: float = 0.005,
                 command_timeout_s: float | None = None, isolation: str | None = None,
                 switch_interval_s: float | None = 1e-4,
                 label: str | None = None, safety: Any = None, **options: Any) -> None:
        super().__init__(label=label or (f"voicecoil-audio:{device}" if device is not None else None),
                         safety=safety, **options)
        if device is not None and not (isinstance(device, str) or (isinstance(device, int) and device >= 0)):
            raise ValidationError("must be a device name or index >= 0", field="options.device")
        if samplerate is not None:  # the SDK's sample-rate budget: Nyquist of the band .. 384 kHz
            from hapticsdk.budgets import check_sample_rate
            samplerate = check_sample_rate(samplerate, "options.samplerate",
                                           at_least_hz=2 * (self.limits.frequency_range_hz or (0.0, 0.0))[1])
        if not (isinstance(blocksize, int) and 0 <= blocksize <= 8192):
            raise ValidationError("must be 0..8192 frames", field="options.blocksize")
        if not (isinstance(channel_index, int) and 0 <= channel_index < 64):
            raise ValidationError("must be 0..63", field="options.channel_index")
        if not (isinstance(full_scale, (int, float)) and 0 < full_scale <= 1):
            raise ValidationError("must be in (0, 1]", field="options.full_scale")
        if not (isinstance(ramp_s, (int, float)) and 0 < ramp_s <= 1):
            raise ValidationError("must be in (0, 1] s", field="options.ramp_s")
        from hapticsdk.devices.safety import command_timeout_s as _deadline  # default: the restart gap (see Args)
        command_timeout_s = _deadline(self.safety, command_timeout_s)
        isolation = DEFAULT_ISOLATION if isolation is None else isolation
        if isolation not in ISOLATIONS:
            raise ValidationError(f"must be one of {ISOLATIONS}", field="options.isolation")
        if isolation == "process" and os.name != "posix":
            raise ValidationError("'process' needs POSIX (descriptors handed to a child); use 'thread'",
                                  field="options.isolation")
        if switch_interval_s is not None and not (isinstance(switch_interval_s, (int, float))
                                                  and 1e-6 <= switch_interval_s <= 0.1):
            raise ValidationError("must be in 1e-6..0.1 s or None", field="options.switch_interval_s")
        self.isolation = isolation
        self.switch_interval_s = switch_interval_s
        self._old_switch: float | None = None
        self.device = device
        self.samplerate = samplerate
        self.blocksize = blocksize
        self.channel_index = channel_index
        self.full_scale = float(full_scale)
        self.ramp_s = float(ramp_s)
        self.command_timeout_s = command_timeout_s
        #: the PortAudio stream (thread isolation; None in the process isolation)
        self.stream: Any = None
        self.fs = 0.0
        #: the stream's output latency as PortAudio reports it at open (s)
        self.output_latency_s: float | None = None
        #: the audio process's pid (process isolation, while open)
        self.audio_pid: int | None = None
        #: the callback's oscillator (thread isolation)
        self.osc: Oscillator | None = None
        self._renderer: BlockRenderer | None = None
        #: (frequency Hz, amplitude 0..1, time.monotonic() of the command); one write per command
        self._target = (0.0, 0.0, 0.0)
        self._silent = True
        self._final = (0, 0, 0)
        self.device_name: str | None = None
        #: the stream was left unclosed because the audio server went away
        self.abandoned = False
        # process isolation
        self._proc: Any = None
        self._shared: SharedTarget | None = None
        self._ctl: int | None = None
        self._status: int | None = None
        self._status_buf = b""
        self._gone: AudioProcessDied | None = None

    # -- counters (the callback's, in whichever process it runs) --------------------------------
    def _count(self, slot: int, i: int) -> int:
        if self._shared is not None:
            return self._shared.counter(slot)
        r = self._renderer
        if r is not None and self.isolation == "thread":
            return (r.callbacks, r.underruns, r.timeouts)[i]
        return self._final[i]

    @property
    def callbacks(self) -> int:
        """Audio callbacks since open."""
        return self._count(CALLBACKS, 0)

    @property
    def underruns(self) -> int:
        """Callbacks PortAudio flagged with an output underflow since open."""
        return self._count(UNDERRUNS, 1)

    @property
    def timeouts(self) -> int:
        """Times the callback went silent because the last command was older than
        ``command_timeout_s``."""
        return self._count(TIMEOUTS, 2)

    def audio_process_timing(self) -> dict[str, float] | None:
        """The audio process's own timing (``isolation="process"``, while open): the
        longest callback (ms) and the callbacks that started more than 1.5 blocks after
        the previous one (late starts); None otherwise."""
        sh = self._shared
        if sh is None:
            return None
        return {"callback_max_ms": float(sh.mv[CALLBACK_MAX_S]) * 1e3, "late_starts": int(sh.mv[LATE_STARTS])}

    # -- audio thread (isolation="thread") ----------------------------------------------------------
    def _callback(self, out: np.ndarray, frames: int, _time: Any, status: Any) -> None:
        r = self._renderer
        if r is None:
            out.fill(0.0)
            return
        freq, amp, t_cmd = self._target
        # reads only: the servo thread is the one writer of the target and the silence
        # flag (a write here, after the render, could land over a command the servo made
        # meanwhile -- the switch interval is 0.1 ms -- and silence it); a timeout or an
        # error silences each block by the renderer's own rules, and _read_back applies them
        r(out, frames, status.output_underflow, freq, amp, t_cmd, self._silent, time.monotonic())

    # -- backend ------------------------------------------------------------------------------
    def _new_renderer(self, fs: float) -> BlockRenderer:
        return BlockRenderer(fs, ramp_s=self.ramp_s, full_scale=self.full_scale, channel_index=self.channel_index,
                             command_timeout_s=self.command_timeout_s,
                             frequency_range_hz=self.limits.frequency_range_hz or (1.0, 1000.0),
                             max_amplitude=float(self.limits.max_amplitude or 1.0))

    def _open(self) -> None:
        self._target = (0.0, 0.0, 0.0)
        self._silent = True
        self._gone = None
        self.abandoned = False
        self._final = (0, 0, 0)
        if self.isolation == "process":
            self._open_process()
        else:
            self._open_thread()

    def _open_thread(self) -> None:
        sd = import_sounddevice(self.label)
        try:
            info = sd.query_devices(self.device, "output")
        except Exception as exc:
            outs = [f"{i}: {d['name']}" for i, d in enumerate(sd.query_devices()) if d["max_output_channels"] > 0]
            raise DeviceNotFoundError(f"no audio output {self.device!r} ({exc}); outputs: {outs or 'none'}",
                                      device=self.label) from None
        if self.channel_index >= int(info["max_output_channels"]):
            raise ValidationError(f"channel_index {self.channel_index} but {info['name']!r} has "
                                  f"{info['max_output_channels']} output channel(s)", field="options.channel_index")
        self.device_name = str(info["name"])
        self.fs = float(self.samplerate or info["default_samplerate"])
        self._renderer = self._new_renderer(self.fs)
        self.osc = self._renderer.osc
        if self.switch_interval_s is not None and sys.getswitchinterval() > self.switch_interval_s:
            self._old_switch = sys.getswitchinterval()
            sys.setswitchinterval(self.switch_interval_s)
        self.stream = sd.OutputStream(samplerate=self.fs, blocksize=self.blocksize, device=self.device,
                                      channels=self.channel_index + 1, dtype="float32", latency="low",
                                      callback=self._callback)
        _LIVE.add(self.stream)
        try:
            self.stream.start()
            self.output_latency_s = float(self.stream.latency)
        except BaseException:
            self._close()
            raise

    def _open_process(self) -> None:
        from . import audio_process as ap
        fd = ap.new_shared_file()
        ctl_r, ctl_w = os.pipe()
        st_r, st_w = os.pipe()
        try:
            self._shared = SharedTarget(fd)
            self._shared.write(0.0, 0.0, 0.0, True)
            cfg = {"device": self.device, "samplerate": self.samplerate, "blocksize": self.blocksize,
                   "channel_index": self.channel_index, "full_scale": self.full_scale, "ramp_s": self.ramp_s,
                   "command_timeout_s": self.command_timeout_s,
                   "frequency_range_hz": list(self.limits.frequency_range_hz or (1.0, 1000.0)),
                   "max_amplitude": float(self.limits.max_amplitude or 1.0),
                   "ctl_fd": ctl_r, "status_fd": st_w, "shm_fd": fd, "ppid": os.getpid()}
            env = dict(os.environ)
            for k in _POOL_ENV:
                env.setdefault(k, "1")
            try:    # the audio process's stdout is the application's stderr (its stdout may be data)
                out: Any = sys.stderr.fileno()
            except (AttributeError, OSError, ValueError):
                out = subprocess.DEVNULL
            self._proc = subprocess.Popen([sys.executable, "-m", "hapticsdk_hardness.audio_process", json.dumps(cfg)],
                                          stdin=subprocess.DEVNULL, stdout=out, pass_fds=(ctl_r, st_w, fd), env=env)
            self._ctl, self._status = ctl_w, st_r
        except BaseException:
            for f in (ctl_w, st_r):
                os.close(f)
            if self._shared is not None:
                self._shared.close()
                self._shared = None
            raise
        finally:
            for f in (ctl_r, st_w, fd):
                os.close(f)
        msg = self._next_status(time.monotonic() + START_WAIT_S)
        if msg is not None and msg.get("ok"):
            self.device_name = str(msg["device_name"])
            self.fs = float(msg["samplerate"])
            self.output_latency_s = float(msg["latency"])
            self.audio_pid = int(msg["pid"])
            return
        err: DeviceError | ValidationError
        if msg is None:
            try:    # end of file: the audio process is ending (reaped here); else it hangs
                self._proc.wait(1.0)
            except subprocess.TimeoutExpired:
                pass
            alive = self._proc.poll() is None
            err = (DeviceError(f"the audio process did not start within {START_WAIT_S:g} s", device=self.label)
                   if alive else self._process_gone())
        elif msg.get("kind") == "import":
            err = DeviceNotFoundError(f"audio output needs sounddevice and PortAudio ({INSTALL_HINT}); "
                                      f"{msg['message']}", device=self.label)
        elif msg.get("error") == "ValidationError":
            err = ValidationError(str(msg["message"]), field=msg.get("field"))
        elif msg.get("error") == "DeviceNotFoundError":
            err = DeviceNotFoundError(str(msg["message"]), device=self.label)
        else:
            err = DeviceError(str(msg.get("message", msg)), device=self.label)
        self._close()
        raise err

    def _next_status(self, deadline: float) -> dict[str, Any] | None:
        """The next line of the status pipe (None: end of file, or none by ``deadline``;
        ``deadline`` in the past: what is there now, without waiting)."""
        fd = self._status
        while fd is not None and b"\n" not in self._status_buf:
            wait = max(0.0, deadline - time.monotonic())
            if not select.select([fd], [], [], wait)[0]:
                return None
            data = os.read(fd, 4096)
            if not data:
                break
            self._status_buf += data
        if b"\n" not in self._status_buf:
            return None
        line, self._status_buf = self._status_buf.split(b"\n", 1)
        try:
            msg = json.loads(line)
        except ValueError:
            return {"error": "DeviceError", "message": line.decode(errors="replace")}
        return msg if isinstance(msg, dict) else {"error": "DeviceError", "message": str(msg)}

    def _process_gone(self) -> AudioProcessDied:
        """The error for an audio process that has ended (why, from its last status line
        or its exit status)."""
        if self._gone is not None:
            return self._gone
        code = self._proc.returncode if self._proc is not None else None
        reason = ""
        while (msg := self._next_status(0.0)) is not None:
            if msg.get("event") or msg.get("error"):
                reason = str(msg.get("message", ""))
                if msg.get("event") == "stream_stopped":
                    self.abandoned = True   # the audio process left its dead stream alone
        if not reason:
            if code is not None and code < 0:
                try:
                    reason = f"killed by {signal.Signals(-code).name}"
                except ValueError:
                    reason = f"killed by signal {-code}"
            else:
                reason = f"exited with status {code}"
        self._gone = AudioProcessDied(f"the audio process (pid {self.audio_pid}) is gone: {reason}",
                                      device=self.label, reason=reason, exitcode=code)
        return self._gone

    def _command(self, cmd: ChannelCommand) -> None:
        if self.isolation == "process":
            p = self._proc
            if p is None or p.poll() is not None:
                raise self._process_gone()
        else:
            r = self._renderer
            if r is not None and r.error is not None:
                raise DeviceError(f"audio callback failed: {type(r.error).__name__}: {r.error}", device=self.label)
            if self.stream is not None and not self.stream.active:
                raise DeviceError("the audio stream stopped (device gone or audio server stopped)",
                                  device=self.label)
        freq, amp, _ = self._target
        if cmd.frequency_hz is not None:
            freq = float(cmd.frequency_hz)
        if cmd.amplitude is not None:
            amp = float(cmd.amplitude)
        t = time.monotonic()
        self._target = (freq, amp, t)
        self._silent = False
        if self._shared is not None:
            self._shared.write(freq, amp, t, False)

    def _read_back(self) -> ChannelCommand:
        """The target the audio callback renders (Hz, amplitude 0..1; 0 when silenced:
        stopped, timed out, or no audio process any more)."""
        freq, amp, t_cmd = self._target
        # the callback's own dead-man rule, judged here on the same clock (time.monotonic()
        # is system-wide): what the callback last did describes its last block, which may
        # predate the newest command by a period or more on a busy machine, so it would
        # report a fresh command as silenced
        silent = self._silent or time.monotonic() - t_cmd > self.command_timeout_s
        if self.isolation == "process":
            sh, p = self._shared, self._proc
            silent = silent or sh is None or p is None or p.poll() is not None
        else:
            r = self._renderer
            silent = silent or r is None or r.error is not None
        return ChannelCommand("vibration", frequency_hz=freq, amplitude=0.0 if silent else amp)

    def _stop(self) -> None:
        self._silent = True
        freq = self._target[0]
        self._target = (freq, 0.0, 0.0)
        if self._shared is not None:
            self._shared.write(freq, 0.0, 0.0, True)

    def _close(self) -> None:
        if self.isolation == "process":
            self._close_process()
        else:
            self._close_thread()

    def _close_process(self) -> None:
        p, self._proc = self._proc, None
        ctl, self._ctl = self._ctl, None
        try:
            if self._shared is not None:
                self._shared.write(self._target[0], 0.0, 0.0, True)
            if ctl is not None:
                try:
                    os.write(ctl, b"q")
                except OSError:   # the audio process is gone
                    pass
                os.close(ctl)
            if p is not None:
                try:
                    p.wait(EXIT_WAIT_S)
                except subprocess.TimeoutExpired:
                    log.warning("%s: the audio process (pid %s) did not exit in %g s: killed", self.label, p.pid,
                                EXIT_WAIT_S)
                    p.kill()
                    try:
                        p.wait(EXIT_WAIT_S)
                    except subprocess.TimeoutExpired:
                        log.error("%s: the audio process (pid %s) outlived SIGKILL", self.label, p.pid)
                self._proc = p   # for the exit status (_process_gone)
                while (msg := self._next_status(0.0)) is not None:
                    if msg.get("event") == "close_failed":
                        log.warning("%s: audio process: closing the stream failed: %s", self.label,
                                    msg.get("message"))
                    elif msg.get("event") == "stream_stopped":
                        self.abandoned = True
        finally:
            self._proc = None
            sh, self._shared = self._shared, None
            if sh is not None:
                self._final = (sh.counter(CALLBACKS), sh.counter(UNDERRUNS), sh.counter(TIMEOUTS))
                sh.close()
            st, self._status = self._status, None
            if st is not None:
                os.close(st)
            self.audio_pid = None

    def _close_thread(self) -> None:
        s, self.stream = self.stream, None
        try:
            if s is not None and not s.active and not s.stopped:
                # the audio server or device went away under a running stream: PortAudio's
                # JACK backend hangs or aborts the process when such a stream is stopped or
                # closed, and there is no output left to silence; the stream is abandoned
                # (it stays in _LIVE)
                self.abandoned = True
            elif s is not None:
                try:
                    s.stop()
                finally:
                    s.close()
                    _LIVE.discard(s)
        finally:
            if self._old_switch is not None and sys.getswitchinterval() == self.switch_interval_s:
                sys.setswitchinterval(self._old_switch)
            self._old_switch = None

    # -- discovery ------------------------------------------------------------------------------
    @classmethod
    def check_available(cls) -> tuple[bool, str]:
        try:
            sd = import_sounddevice()
        except DeviceNotFoundError as exc:
            return False, str(exc)
        try:
            apis = ", ".join(h["name"] for h in sd.query_hostapis())
            n = sum(1 for d in sd.query_devices() if d["max_output_channels"] > 0)
        except Exception as exc:
            return False, f"PortAudio found but not usable: {type(exc).__name__}: {exc}"
        if n == 0:
            return False, f"sounddevice {sd.__version__}: no audio output device (host APIs: {apis or 'none'})"
        return True, f"sounddevice {sd.__version__}, {sd.get_portaudio_version()[1]}; host APIs: {apis}"

    @classmethod
    def discover(cls) -> list[dict[str, Any]]:
        try:   # one import and one query (check_available would make both again)
            sd = import_sounddevice()
            apis, devices = sd.query_hostapis(), sd.query_devices()
        except Exception:   # not installed (DeviceNotFoundError) or PortAudio not usable
            return []
        return [{"device": i, "name": d["name"], "hostapi": apis[d["hostapi"]]["name"],
                 "channels": d["max_output_channels"], "samplerate": d["default_samplerate"]}
                for i, d in enumerate(devices) if d["max_output_channels"] > 0]

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d.update({"device": self.device, "device_name": self.device_name, "samplerate": self.fs,
                  "blocksize": self.blocksize, "output_latency_s": self.output_latency_s,
                  "isolation": self.isolation, "audio_pid": self.audio_pid, "full_scale": self.full_scale,
                  "ramp_s": self.ramp_s, "underruns": self.underruns, "callbacks": self.callbacks,
                  "command_timeouts": self.timeouts,
                  "capabilities": {"frequency_range_hz": list(self.limits.frequency_range_hz or ()),
                                   "bandwidth_hz": min(1000.0, self.fs / 2) if self.fs else None,
                                   "amplitude_resolution": 2.0 ** -23, "max_amplitude": self.limits.max_amplitude}})
        return d
