"""``voicecoil-virtual``: a simulated voice-coil tactor (the paper's EAI C-2 on a linear
amplifier) that synthesises its drive waveform.

Every :meth:`VoiceCoilVirtual.step` renders the samples of the elapsed time (5 kHz by
default, as in the paper) with :class:`hapticsdk.synthesis.Oscillator`: the phase is
accumulated (continuous across frequency changes) and the amplitude ramps instead of
stepping when contact starts or ends. The waveform goes to a pluggable sink
(:mod:`hapticsdk_hardness.sinks`): memory (default), WAV file, callback, sound device.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from hapticsdk.devices.actuators import Actuator, ActuatorLimits
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import ValidationError
from hapticsdk.synthesis import Oscillator

from .sinks import make_sink


class VoiceCoilVirtual(Actuator):
    """Simulated voice coil (entry point ``voicecoil-virtual``).

    Args:
        sample_rate_hz: waveform rate (Hz), default 5000.
        sink: where samples go (``"buffer"``, ``"wav:PATH"``, callable, ``"sounddevice"``,
            or an object with ``write``).
        ramp_s: amplitude ramp time from 0 to full scale (s), default 5 ms.
        label, safety: as for every actuator.
    """

    name: ClassVar[str] = "voicecoil-virtual"
    channel: ClassVar[str] = "vibration"
    accepts: ClassVar[dict[str, str]] = {"frequency_hz": "Hz", "amplitude": "1"}
    simulated: ClassVar[bool] = True
    #: ``sink`` can name a file to write (``"wav:PATH"``) or an audio device: never from a scene/plan file
    privileged_options: ClassVar[dict[str, str]] = {"sink": "output file or audio device"}
    limits = ActuatorLimits(frequency_range_hz=(1.0, 1000.0), max_amplitude=1.0, amplitude_unit="1")

    def __init__(self, *, sample_rate_hz: float = 5000.0, sink: Any = None, ramp_s: float = 0.005,
                 label: str | None = None, safety: Any = None, **options: Any) -> None:
        super().__init__(label=label, safety=safety, **options)
        from hapticsdk.budgets import check_sample_rate  # finite, Nyquist of the band .. 384 kHz (named)
        self.fs = check_sample_rate(sample_rate_hz, "sample_rate_hz",
                                    at_least_hz=2 * (self.limits.frequency_range_hz or (0.0, 0.0))[1])
        self.osc = Oscillator(self.fs, ramp_s=ramp_s, max_amplitude=self.limits.max_amplitude or 1.0)
        self.sink = make_sink(sink, self.fs)
        self._freq = 0.0
        self._amp = 0.0
        self._carry = 0.0
        self.samples_written = 0

    def _command(self, cmd: ChannelCommand) -> None:
        if cmd.frequency_hz is not None:
            self._freq = cmd.frequency_hz
        if cmd.amplitude is not None:
            self._amp = cmd.amplitude

    def _read_back(self) -> ChannelCommand:
        """The drive the oscillator is set to (frequency Hz, amplitude 0..1)."""
        return ChannelCommand("vibration", frequency_hz=self._freq, amplitude=self._amp)

    def _open(self) -> None:
        self._amp = 0.0

    def _stop(self) -> None:
        self._amp = 0.0
        self.osc.amplitude = 0.0  # safe state: output off now, not after a ramp

    def _close(self) -> None:
        self.sink.close()

    def step(self, dt: float) -> np.ndarray:
        """Synthesise the samples of the next ``dt`` seconds into the sink; returns them."""
        if not (dt > 0 and math.isfinite(dt)):
            raise ValidationError(f"dt must be > 0 s, got {dt!r}", field="dt")
        x = self._carry + dt * self.fs
        n = int(x)
        self._carry = x - n
        if n <= 0:
            return np.zeros(0)
        y = self.osc.render(self._freq, self._amp, n)
        self.sink.write(y)
        self.samples_written += n
        return y

    @property
    def frequency_hz(self) -> float:
        """Current drive frequency (Hz)."""
        return self._freq

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d["sample_rate_hz"] = self.fs
        d["ramp_s"] = self.osc.ramp_s
        d["sink"] = type(self.sink).__name__
        return d
