"""``piezo-virtual``: a simulated DRV2667 + piezo (the default vibration actuator).

Each command synthesises the drive voltage waveform of one servo period with
:class:`hapticsdk.synthesis.Oscillator` (phase accumulator, so the frequency can change
every tick without phase jumps; amplitude ramps of ``ramp_s`` >= 5 ms, so the 20 mm/s gate
never clicks) and keeps it for inspection (:meth:`PiezoVirtual.waveform`). Limits follow
the DRV2667: frequency within the synthesiser's 7.8125..1992 Hz (or a narrower piezo band
given as ``frequency_range_hz``), amplitude up to the full scale of ``gain``
(25/50/75/100 V peak). Optionally ``quantize=True`` rounds frequency and amplitude to the
DRV2667 synthesis codes, like the real backends do.
"""

from __future__ import annotations

from typing import Any, ClassVar, cast

import numpy as np

from hapticsdk.devices.actuators import Actuator, ActuatorLimits, DriveCapability
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import ValidationError
from hapticsdk.sim.samples import SampleWindow
from hapticsdk.synthesis import Oscillator

from .drv2667 import FREQ_STEP_HZ, GAIN_FULL_SCALE_V, SYNTH_FREQ_RANGE_HZ, amplitude_code, frequency_code


def piezo_limits(gain: int, frequency_range_hz: tuple[float, float] | None, *,
                 quantised: bool = True) -> ActuatorLimits:
    """Declared limits of a DRV2667-driven piezo at ``gain`` (0..3); ``quantised``: the
    output moves in the synthesiser's steps (7.8125 Hz, full scale / 255)."""
    if gain not in (0, 1, 2, 3):
        raise ValidationError(f"gain {gain!r} not in 0..3 (25/50/75/100 V peak)", field="options.gain")
    lo, hi = SYNTH_FREQ_RANGE_HZ if frequency_range_hz is None else (float(frequency_range_hz[0]),
                                                                      float(frequency_range_hz[1]))
    if not SYNTH_FREQ_RANGE_HZ[0] - 1e-9 <= lo < hi <= SYNTH_FREQ_RANGE_HZ[1] + 1e-9:
        raise ValidationError(f"frequency_range_hz {(lo, hi)} must lie within the DRV2667 synthesiser range "
                              f"{SYNTH_FREQ_RANGE_HZ} Hz", field="options.frequency_range_hz")
    return ActuatorLimits(frequency_range_hz=(lo, hi), max_amplitude=GAIN_FULL_SCALE_V[gain], amplitude_unit="V",
                          frequency_resolution_hz=FREQ_STEP_HZ if quantised else None,
                          amplitude_resolution=GAIN_FULL_SCALE_V[gain] / 255.0 if quantised else None)


class PiezoVirtual(Actuator):
    """Simulated DRV2667 + piezo.

    Options:
        gain: DRV2667 GAIN 0..3 -> full scale 25/50/75/100 V peak (default 1, 50 V:
            enough for the generated table's usual requests; a real board should start at 0).
        fs: output sample rate of the synthesised waveform (Hz, default 8000 = DRV2667 FIFO rate).
        period_s: servo period one command covers (s, default 0.001).
        ramp_s: amplitude ramp time from 0 to full scale (s, >= 0.005).
        frequency_range_hz: piezo band (default the synthesiser's range).
        quantize: round to the DRV2667 synthesis codes (7.8125 Hz, amplitude/255 steps).
        keep_s: seconds of waveform kept (default 60; older samples are dropped).
    """

    name: ClassVar[str] = "piezo-virtual"
    channel: ClassVar[str] = "vibration"
    accepts: ClassVar[dict[str, str]] = {"frequency_hz": "Hz", "amplitude": "V"}
    simulated: ClassVar[bool] = True
    #: raise the voltage the piezo gets: a scene or plan may give ``gain`` only up to the
    #: default (hapticsdk.devices.device_options.check_data_options)
    energy_options: ClassVar[dict[str, str]] = {"gain": "DRV2667 gain: full scale 25/50/75/100 V peak for 0..3"}
    limits = piezo_limits(1, None, quantised=False)

    def __init__(self, *, gain: int = 1, fs: float = 8000.0, period_s: float = 0.001, ramp_s: float = 0.005,
                 frequency_range_hz: tuple[float, float] | None = None, quantize: bool = False,
                 keep_s: float = 60.0, **options: Any) -> None:
        from hapticsdk.argcheck import number
        self.limits = piezo_limits(gain, frequency_range_hz, quantised=bool(quantize))
        period_s = number(period_s, "period_s", lo=0.0, lo_open=True)
        keep_s = number(keep_s, "keep_s", lo=0.0, lo_open=True)
        ramp_s = number(ramp_s, "ramp_s")
        if ramp_s < 0.005:
            raise ValidationError(f"ramp_s {ramp_s} s < 5 ms would click", field="options.ramp_s")
        from hapticsdk.budgets import check_sample_rate  # at most 384 kHz (a named ceiling)
        top_hz = cast("tuple[float, float]", self.limits.frequency_range_hz)[1]   # piezo_limits sets it
        fs = check_sample_rate(fs, "fs", at_least_hz=2 * top_hz)
        super().__init__(**options)
        self.gain = int(gain)
        self.fs = float(fs)
        self.period_s = float(period_s)
        self.ramp_s = float(ramp_s)
        self.quantize = bool(quantize)
        self.keep_samples = int(keep_s * fs)
        self.osc = Oscillator(self.fs, ramp_s=self.ramp_s,
                              max_amplitude=cast(float, self.limits.max_amplitude))  # piezo_limits sets it
        #: the kept output (the last keep_s of it)
        self._window = SampleWindow(max(1, self.keep_samples))
        #: (frequency Hz, amplitude V, samples) per command not yet synthesised: the servo
        #: tick only records the command (as a real DRV2667 host only writes registers);
        #: the waveform the chip would play is synthesised in :meth:`step` (the loop's
        #: simulation phase) or when it is read.
        self._pending: list[tuple[float, float, int]] = []
        self._frac = 0.0
        self._target_amp = 0.0
        self._freq = 0.0
        self.samples_total = 0
        self.commands = 0

    @classmethod
    def calibration_info(cls) -> list[dict[str, Any]]:
        """The roughness ``Tab`` used by default (for ``hapticsdk doctor``)."""
        from .table import resolve_table
        t = resolve_table(None)
        return [{"kind": "piezo", "scope": "roughness Tab (default)", "generated": t.generated, "source": t.source,
                 "frequency_range_hz": list(t.frequency_range_hz),
                 "voltage_range_v": [float(t.voltages_v[0]), float(t.voltages_v[-1])]}]

    # -- backend ----------------------------------------------------------------
    def _open(self) -> None:
        self.osc.reset()
        self._pending.clear()
        self._target_amp = 0.0

    def _emit(self, block: np.ndarray) -> None:
        if block.size == 0:
            return
        self._window.append(block)
        self.samples_total += block.size

    def _command(self, cmd: ChannelCommand) -> None:
        f = cmd.frequency_hz
        f = self._freq if f is None else float(f)
        a = cmd.amplitude
        a = self._target_amp if a is None else float(a)
        if self.quantize:
            f = frequency_code(f) * FREQ_STEP_HZ
            a = amplitude_code(a, self.gain) / 255.0 * GAIN_FULL_SCALE_V[self.gain]
        self._freq = f
        self._target_amp = a
        self.commands += 1
        # the samples this command covers (period_s x fs plus the carried fraction), inline: every servo tick
        exact = self.period_s * self.fs + self._frac
        n = int(exact)
        self._frac = exact - n
        self._pending.append((f, a, n))

    def _flush(self) -> None:
        """Synthesise the commands recorded since the last flush, in order."""
        if self._pending:
            for f, a, n in self._pending:
                self._emit(self.osc.render(f, a, n))
            self._pending.clear()

    def step(self, dt: float) -> None:
        """Simulation phase of a servo tick: synthesise the waveform commanded so far."""
        self._flush()

    @classmethod
    def capability_for(cls, options: Any = None) -> DriveCapability:
        """Band and full scale of the DRV2667 at the ``gain`` / ``frequency_range_hz``
        options; the drive table is the roughness dimension's (calibrated) ``Tab``."""
        o = dict(options or {})
        lim = piezo_limits(int(o.get("gain", 1)), o.get("frequency_range_hz"))
        return DriveCapability("vibration", lim.frequency_range_hz, lim.max_amplitude, "V",
                               source=f"{cls.name}: DRV2667 gain {int(o.get('gain', 1))}, "
                                      f"{lim.max_amplitude:g} V peak full scale")

    def _read_back(self) -> ChannelCommand:
        """The drive the simulated chip was last set to (after quantisation when on)."""
        return ChannelCommand("vibration", frequency_hz=self._freq, amplitude=self._target_amp)

    def _stop(self) -> None:
        """Vibration off: the amplitude ramps to 0 (``ramp_s``) so the record ends silent."""
        self._flush()
        self._target_amp = 0.0
        if self.osc.amplitude > 0:
            n = int(np.ceil(self.osc.amplitude / self.osc.max_step)) + 1
            self._emit(self.osc.render(self._freq, 0.0, n))

    # -- inspection --------------------------------------------------------------
    @property
    def driving(self) -> bool:
        """True while the output amplitude or its target is above zero."""
        self._flush()
        return self.osc.amplitude > 0 or self._target_amp > 0

    @property
    def output_amplitude_v(self) -> float:
        """Current output amplitude of the simulated piezo (V peak)."""
        self._flush()
        return float(self.osc.amplitude)

    def waveform(self) -> tuple[np.ndarray, np.ndarray]:
        """(t in s, drive voltage in V) of the kept samples."""
        self._flush()
        v = self._window.samples()
        start = self.samples_total - v.size
        return (start + np.arange(v.size)) / self.fs, v

    def clear_waveform(self) -> None:
        """Forget the recorded output waveform."""
        self._flush()
        self._window.clear()

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d.update({"gain": self.gain, "full_scale_v": GAIN_FULL_SCALE_V[self.gain], "fs_hz": self.fs,
                  "ramp_s": self.ramp_s, "quantize": self.quantize, "samples": self.samples_total})
        return d
