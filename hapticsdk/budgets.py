"""Ceilings on what a scene, plan or caller can make the SDK allocate (docs/safety.md,
"Budgets"): each is derived from a device parameter, refused beyond with a
:class:`~hapticsdk.errors.ValidationError` naming the field, and held by a test.

* :data:`MAX_SAMPLE_RATE_HZ`: 384 kHz, the highest rate audio interfaces commonly offer
  (the top rate of USB Audio Class 2 DACs and of the sound cards the voice coil's sinks
  play to). The voice coil's band ends at 1 kHz (``voicecoil-virtual`` limits) and the
  DRV2667 synthesiser plays 8 kHz, so the ceiling is 192 times the Nyquist rate of the
  coil band's top (2 kHz) and 48 times the piezo's FIFO rate: no rendering needs more.
  Per servo tick (1 ms) it is 384 samples, 3 kB of float64, where 1e9 Hz was 8 MB per
  tick and a MemoryError. It is a budget, not a limit of the format: the interop
  synthesis ceiling (:data:`hapticsdk.interop.budget.MAX_SAMPLE_RATE_HZ`, 48 kHz) is a
  different quantity, the finest time step an ``.hjif`` file expresses.

The floor is the band: :func:`check_sample_rate` takes ``at_least_hz``, twice the top of
the actuator's declared band (Nyquist), so no drive frequency the actuator accepts aliases.
"""

from __future__ import annotations

from typing import Any

__all__ = ["MAX_SAMPLE_RATE_HZ", "check_sample_rate"]

#: highest waveform sample rate an actuator option may ask for (Hz); see the module text
MAX_SAMPLE_RATE_HZ = 384_000.0


def check_sample_rate(value: Any, field: str, *, at_least_hz: float = 0.0) -> float:
    """``value`` as a sample rate in Hz: a finite number above ``at_least_hz`` (e.g. twice
    the top of the band) and at most :data:`MAX_SAMPLE_RATE_HZ`."""
    from .argcheck import number
    from .errors import ValidationError

    v = number(value, field, lo=0.0, lo_open=True, hi=MAX_SAMPLE_RATE_HZ)
    if v < at_least_hz:
        raise ValidationError(f"{v:g} Hz is below twice the top drive frequency ({at_least_hz:g} Hz)", field=field)
    return v
