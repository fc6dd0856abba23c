"""Phase-continuous vibration synthesis.

Formula (9) of the reference paper writes ``V(t) = V_out sin(2 pi f_p t)`` with ``f_p``
changing every tick; evaluated literally that jumps in phase whenever ``f_p`` changes.
Here the phase is integrated instead (``phi += f dt``) in *cycles*, wrapped to [0, 1)
with compensated (two-sum) accumulation, so it stays exact over arbitrarily long runs,
and the amplitude moves towards its target along a ramp of time constant ``ramp_s``
instead of stepping (no clicks when the 20 mm/s gate opens or closes).
"""

from __future__ import annotations

import math

import numpy as np


class PhaseAccumulator:
    """Phase in cycles, wrapped to [0, 1), with a compensation term for rounding.

    ``advance(f, dt)`` adds ``f*dt`` cycles. The running error stays at the level of one
    float64 rounding of the increment, independent of run length.
    """

    __slots__ = ("phase", "_comp", "cycles")

    def __init__(self, phase: float = 0.0) -> None:
        self.phase = float(phase) % 1.0
        self._comp = 0.0
        #: whole cycles completed (an int: exact for any run length)
        self.cycles = 0

    def advance(self, frequency_hz: float, dt: float) -> float:
        """Add ``frequency_hz * dt`` cycles; return the new wrapped phase (cycles)."""
        inc = frequency_hz * dt
        # two-sum of phase + inc, carrying the rounding error in _comp
        y = inc - self._comp
        s = self.phase + y
        self._comp = (s - self.phase) - y
        whole = math.floor(s)
        if whole:
            self.cycles += int(whole)
            s -= whole
            if s >= 1.0:  # guard against s == 1.0 after rounding
                s -= 1.0
                self.cycles += 1
        self.phase = s
        return s

    def total_cycles(self) -> float:
        return self.cycles + self.phase

    def block(self, frequency_hz: float, n: int, fs: float) -> np.ndarray:
        """Phases (cycles, wrapped) of the next ``n`` samples at rate ``fs`` (Hz) and a
        constant frequency; the accumulator ends after the last sample."""
        inc = frequency_hz / fs
        k = np.arange(1, n + 1)
        ph = np.mod(self.phase - self._comp + inc * k, 1.0)
        self.advance(frequency_hz, n / fs)
        return ph


class Oscillator:
    """Sine oscillator with phase accumulation and amplitude ramps.

    Args:
        fs: output sample rate (Hz).
        ramp_s: time to ramp from 0 to full amplitude (s); amplitude changes by at most
            ``max_amplitude * dt / ramp_s`` per sample.
        max_amplitude: amplitude scale used for the ramp slope (the actuator's full scale).
    """

    def __init__(self, fs: float, *, ramp_s: float = 0.005, max_amplitude: float = 1.0) -> None:
        if fs <= 0 or ramp_s <= 0 or max_amplitude <= 0:
            raise ValueError("fs, ramp_s and max_amplitude must be positive")
        self.fs = float(fs)
        self.ramp_s = float(ramp_s)
        self.max_amplitude = float(max_amplitude)
        self.acc = PhaseAccumulator()
        self.amplitude = 0.0
        self.frequency_hz = 0.0

    @property
    def max_step(self) -> float:
        """Largest amplitude change per sample."""
        return self.max_amplitude / (self.ramp_s * self.fs)

    def render(self, frequency_hz: float, amplitude: float, n: int) -> np.ndarray:
        """Next ``n`` samples at the given frequency (Hz), amplitude ramping to ``amplitude``."""
        step = self.max_step
        k = np.arange(1, n + 1)
        delta = amplitude - self.amplitude
        amps = self.amplitude + np.sign(delta) * np.minimum(np.abs(delta), step * k)
        ph = self.acc.block(frequency_hz, n, self.fs)
        self.amplitude = float(amps[-1]) if n else self.amplitude
        self.frequency_hz = float(frequency_hz)
        return amps * np.sin(2.0 * np.pi * ph)

    def reset(self) -> None:
        self.acc = PhaseAccumulator()
        self.amplitude = 0.0
