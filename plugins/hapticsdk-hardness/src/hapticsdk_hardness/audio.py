"""``voicecoil-audio``: a voice coil (Haptuator, tactor, the paper's C-2) on a sound card,
through PortAudio with ``sounddevice`` (``pip install -e 'plugins/hapticsdk-hardness[audio]'`` from a checkout; on
Linux also the system PortAudio, Debian ``libportaudio2``).

A callback stream runs at the card's rate (its default sample rate unless
``samplerate`` is given). The servo thread only sets a target -- frequency (Hz) and
amplitude (0..1) -- with one attribute write per command; the audio callback renders each
block with :class:`hapticsdk.synthesis.Oscillator`: the phase is accumulated, so a new
frequency continues the waveform without a jump, and the amplitude slews to its target
at most full scale per ``ramp_s``. Frequency and amplitude are clamped by the core
safety layer (``limits``) before they reach the target.

Amplitude calibration: ``full_scale`` is the sample peak at amplitude 1 (default 1.0,
the card's full scale); the sample peak is ``amplitude x full_scale``. The amplifier
and the coil after the card are the user's calibration (docs/devices.md).

Silence on every stop path:

* ``stop()`` (the servo loop's stop, a fault, ``close()``, the interpreter's exit
  handler) sets the output to zero at once: the next block the callback renders is
  silent (no ramp down: the safe state is now, as for ``voicecoil-virtual``);
* a stalled or dead servo: the callback itself renders silence when the last command is
  older than ``command_timeout_s`` (the audio thread's own dead-man's switch);
* ``close()`` stops and closes the stream; a process that dies leaves the audio server,
  which drops its ports.
* the audio server (or the device) goes away: the stream stops being active, the next
  command raises :class:`~hapticsdk.errors.DeviceError` (the loop stops every actuator),
  and ``close()`` leaves the dead stream alone: with JACK, PortAudio hangs or aborts the
  process when such a stream is stopped or closed, and also in its own exit handler
  (``Pa_Terminate``), so a process that lost its JACK server may hang at exit.

The device is chosen by ``device``, a PortAudio device name (substring, as
``sounddevice`` matches it) or index: a privileged option (it picks hardware that a
scene file must not choose), set in the user device configuration, the environment
or on the command line (:mod:`hapticsdk.device_options`).
"""

from __future__ import annotations

import importlib
import sys
import time
from typing import Any, ClassVar

import numpy as np

from hapticsdk.actuators import Actuator, ActuatorLimits
from hapticsdk.dimensions import ChannelCommand
from hapticsdk.errors import DeviceError, DeviceNotFoundError, ValidationError
from hapticsdk.install_hints import pip_hint
from hapticsdk.synthesis import Oscillator

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
            the servo resumes (:func:`hapticsdk.safety.default_command_timeout_s`).
        switch_interval_s: while open, the interpreter's thread switch interval
            (``sys.setswitchinterval``) is at most this (s; None: left alone). The
            callback is Python code: it needs the interpreter lock once per audio
            period, and a busy Python thread of the application hands it over only
            every switch interval (5 ms by default, longer than a 128-frame period at
            48 kHz, 2.7 ms): that would be an underrun. Restored at close.
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
                 command_timeout_s: float | None = None, switch_interval_s: float | None = 1e-4,
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
        from hapticsdk.safety import command_timeout_s as _deadline  # default: the restart gap (see Args)
        command_timeout_s = _deadline(self.safety, command_timeout_s)
        if switch_interval_s is not None and not (isinstance(switch_interval_s, (int, float))
                                                  and 1e-6 <= switch_interval_s <= 0.1):
            raise ValidationError("must be in 1e-6..0.1 s or None", field="options.switch_interval_s")
        self.switch_interval_s = switch_interval_s
        self._old_switch: float | None = None
        self.device = device
        self.samplerate = samplerate
        self.blocksize = blocksize
        self.channel_index = channel_index
        self.full_scale = float(full_scale)
        self.ramp_s = float(ramp_s)
        self.command_timeout_s = command_timeout_s
        self.stream: Any = None
        self.fs = 0.0
        self.osc: Oscillator | None = None
        #: (frequency Hz, amplitude 0..1, time.monotonic() of the command); one write per command
        self._target = (0.0, 0.0, 0.0)
        self._silent = True
        self.underruns = 0
        self.callbacks = 0
        self.timeouts = 0
        self.device_name: str | None = None
        self._cb_error: BaseException | None = None
        #: the stream was left unclosed because the audio server went away
        self.abandoned = False

    # -- audio thread -------------------------------------------------------------------------
    def _callback(self, out: np.ndarray, frames: int, _time: Any, status: Any) -> None:
        try:
            self.callbacks += 1
            if status.output_underflow:
                self.underruns += 1
            osc = self.osc
            freq, amp, t_cmd = self._target
            if self._silent or osc is None:
                out.fill(0.0)
                if osc is not None:
                    osc.amplitude = 0.0
                return
            if time.monotonic() - t_cmd > self.command_timeout_s:
                self.timeouts += 1
                self._silent = True
                osc.amplitude = 0.0
                out.fill(0.0)
                return
            y = osc.render(freq, amp, frames)
            if out.shape[1] > 1:
                out.fill(0.0)
            out[:, self.channel_index] = y * self.full_scale
        except BaseException as exc:  # never into PortAudio
            self._cb_error = exc
            self._silent = True
            out.fill(0.0)

    # -- backend ------------------------------------------------------------------------------
    def _open(self) -> None:
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
        self.osc = Oscillator(self.fs, ramp_s=self.ramp_s, max_amplitude=1.0)
        self._target = (0.0, 0.0, 0.0)
        self._silent = True
        self._cb_error = None
        self.underruns = self.callbacks = self.timeouts = 0
        if self.switch_interval_s is not None and sys.getswitchinterval() > self.switch_interval_s:
            self._old_switch = sys.getswitchinterval()
            sys.setswitchinterval(self.switch_interval_s)
        self.stream = sd.OutputStream(samplerate=self.fs, blocksize=self.blocksize, device=self.device,
                                      channels=self.channel_index + 1, dtype="float32", latency="low",
                                      callback=self._callback)
        _LIVE.add(self.stream)
        try:
            self.stream.start()
        except BaseException:
            self._close()
            raise

    def _command(self, cmd: ChannelCommand) -> None:
        if self._cb_error is not None:
            raise DeviceError(f"audio callback failed: {type(self._cb_error).__name__}: {self._cb_error}",
                              device=self.label)
        if self.stream is not None and not self.stream.active:
            raise DeviceError("the audio stream stopped (device gone or audio server stopped)", device=self.label)
        freq, amp, _ = self._target
        if cmd.frequency_hz is not None:
            freq = float(cmd.frequency_hz)
        if cmd.amplitude is not None:
            amp = float(cmd.amplitude)
        self._target = (freq, amp, time.monotonic())
        self._silent = False

    def _read_back(self) -> ChannelCommand:
        """The target the audio callback renders (Hz, amplitude 0..1; 0 when silenced)."""
        freq, amp, _ = self._target
        return ChannelCommand("vibration", frequency_hz=freq, amplitude=0.0 if self._silent else amp)

    def _stop(self) -> None:
        self._silent = True
        freq = self._target[0]
        self._target = (freq, 0.0, 0.0)

    def _close(self) -> None:
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
        lat = None
        if self.stream is not None:
            try:
                lat = float(self.stream.latency)
            except Exception:
                lat = None
        d.update({"device": self.device, "device_name": self.device_name, "samplerate": self.fs,
                  "blocksize": self.blocksize, "output_latency_s": lat, "full_scale": self.full_scale,
                  "ramp_s": self.ramp_s, "underruns": self.underruns, "callbacks": self.callbacks,
                  "command_timeouts": self.timeouts,
                  "capabilities": {"frequency_range_hz": list(self.limits.frequency_range_hz or ()),
                                   "bandwidth_hz": min(1000.0, self.fs / 2) if self.fs else None,
                                   "amplitude_resolution": 2.0 ** -23, "max_amplitude": self.limits.max_amplitude}})
        return d
