"""Checks of single numeric values given to the SDK (arguments, file fields).

One rule everywhere: a number is an ``int`` or ``float`` (numpy scalars included),
never a ``bool`` (``True`` is not 1.0 here), finite unless said otherwise, and inside
its declared range. A failed check raises :class:`~hapticsdk.errors.ValidationError`
(or the ``error`` class given) naming the field.
"""

from __future__ import annotations

import math
import numbers
from typing import Any

from .errors import ValidationError

__all__ = ["is_number", "check_number", "check_seed", "MAX_SEED"]

#: largest seed accepted (numpy's SeedSequence takes any non-negative int; 2**63-1 keeps
#: seeds storable as int64 in files)
MAX_SEED = 2 ** 63 - 1


def is_number(value: Any) -> bool:
    """True for real numbers (int, float, numpy integer/floating), False for bool and others."""
    if isinstance(value, bool):
        return False
    try:
        import numpy as np
        if isinstance(value, np.bool_):
            return False
    except ImportError:  # pragma: no cover
        pass
    return isinstance(value, numbers.Real)


def finite_float(value: Any) -> float | None:
    """``value`` as a float when it is a finite int or float (not a bool), else None: NaN,
    an infinity, an int beyond the float range (JSON can hold one; float() of it raises
    OverflowError) and any other type give None. For readers of JSON numbers."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        v = float(value)
    except OverflowError:
        return None
    return v if math.isfinite(v) else None


def check_number(value: Any, field: str, *, minimum: float | None = None, maximum: float | None = None,
                 exclusive_minimum: float | None = None, exclusive_maximum: float | None = None,
                 unit: str = "", error: type[ValidationError] = ValidationError) -> float:
    """``value`` as a finite float inside the given bounds, else ``error`` naming ``field``.

    Args:
        value: the number (``bool``, strings and ``None`` are refused).
        field: name of the field in messages (``"amplifier_gain"``, ``"frequencies_hz[2]"``).
        minimum, maximum: inclusive bounds; exclusive_minimum, exclusive_maximum: strict ones.
        unit: unit text for messages (``"Hz"``).
    """
    if not is_number(value):
        raise error(f"must be a number, got {value!r}", field=field)
    try:
        v = float(value)
    except OverflowError:   # an int beyond the float range (JSON reads 1 followed by 400 zeros as one)
        raise error(f"must be finite, got {value!r:.40}", field=field) from None
    u = f" {unit}" if unit else ""
    if not math.isfinite(v):
        raise error(f"must be finite, got {v!r}", field=field)
    if minimum is not None and v < minimum:
        raise error(f"{v:g}{u} is below the minimum {minimum:g}{u}", field=field)
    if exclusive_minimum is not None and v <= exclusive_minimum:
        raise error(f"{v:g}{u} must be > {exclusive_minimum:g}{u}", field=field)
    if maximum is not None and v > maximum:
        raise error(f"{v:g}{u} is above the maximum {maximum:g}{u}", field=field)
    if exclusive_maximum is not None and v >= exclusive_maximum:
        raise error(f"{v:g}{u} must be < {exclusive_maximum:g}{u}", field=field)
    return v


def check_seed(seed: Any, field: str = "seed") -> int | None:
    """A random seed: ``None`` (fresh entropy) or a whole number in ``0..2**63-1``
    (numpy integers accepted; bools, floats and strings refused)."""
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise ValidationError(f"must be a whole number >= 0 or None, got {seed!r}", field=field)
    s = int(seed)
    if not 0 <= s <= MAX_SEED:
        raise ValidationError(f"must be in 0..2**63-1, got {s}", field=field)
    return s
