"""Validated ranges of a render's servo period and duration.

Checked by :func:`hapticsdk.runtime.render.render_plan` (so by ``hapticsdk render``) and
by scene loading, before any actuator is opened or any buffer allocated, each failure a
:class:`~hapticsdk.errors.ValidationError` naming the field.

They belong to the request (a scene's ``servo.period_s``, a render's ``seconds``), so
they live with the first stage: the runtime imports them from here, and a scene never
imports the runtime (was ``hapticsdk.runtime.limits`` before 0.2, a deprecated shim now).

* Servo period: 0.1 ms .. 100 ms (10 kHz .. 10 Hz). Haptic servo loops run at about
  1 kHz (the paper, OpenHaptics); no supported device takes commands faster than
  10 kHz, and below 10 Hz a "servo" loop renders nothing the dimensions model.
* Duration: up to 24 h (86400 s) of servo time per render. The servo log is a ring
  buffer of the last ``log_seconds`` whatever the duration, so memory does not grow with
  it; the bound caps the compute a single command can ask for in simulated time
  (24 h at 1 kHz is 8.64e7 ticks).
"""

from __future__ import annotations

from typing import Any

from ..errors import ValidationError

#: servo period range (s), inclusive
PERIOD_RANGE_S = (1e-4, 0.1)
#: longest render (s of servo time)
MAX_SECONDS = 86400.0


def _number(value: Any, field: str) -> float:
    # hapticsdk.argcheck's rule: a string ("0.001"), a bool or an int beyond the float
    # range is no number of seconds
    from ..argcheck import number
    return number(value, field)


def check_period(value: Any, field: str = "servo.period_s") -> float:
    """The servo period (s) if within :data:`PERIOD_RANGE_S`, else ValidationError."""
    v = _number(value, field)
    lo, hi = PERIOD_RANGE_S
    if not lo <= v <= hi:
        raise ValidationError(f"servo period must be {lo:g}..{hi:g} s ({1 / hi:g} Hz .. {1 / lo:g} Hz), "
                              f"got {value!r}", field=field)
    return v


def check_seconds(value: Any, field: str = "seconds") -> float:
    """A render duration (s) in (0, :data:`MAX_SECONDS`], else ValidationError."""
    v = _number(value, field)
    if not 0 < v <= MAX_SECONDS:
        raise ValidationError(f"render duration must be > 0 and at most {MAX_SECONDS:g} s (24 h), "
                              f"got {value!r}", field=field)
    return v
