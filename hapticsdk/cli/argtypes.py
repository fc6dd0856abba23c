"""argparse ``type=`` functions shared by every ``hapticsdk`` command.

Each one turns the text of a command-line argument into a checked value, or raises
:class:`argparse.ArgumentTypeError` with the reason; the parser then prints
``hapticsdk: error: --option: <reason>`` and exits with status 2 (see
:class:`hapticsdk.cli.Parser`). NaN, infinities, booleans and out-of-range values are
refused here, before any command runs.
"""

from __future__ import annotations

import argparse
import math
from typing import Any, Callable

__all__ = ["nonneg_int", "positive_int", "finite_float", "positive_float", "nonneg_float", "unit_interval",
           "open_unit_interval", "int_list", "intensity", "bounded_int", "serial", "figure_file"]


def _from_check(check: Callable[..., Any], name: str) -> Callable[[str], Any]:
    """An argparse type from a :mod:`hapticsdk.argcheck` function: the API's rule, with
    its reason as the parser's message (the parser adds the option's name)."""
    from ..errors import ValidationError

    def convert(text: str) -> Any:
        try:
            return check(text, "value")
        except ValidationError as exc:
            raise argparse.ArgumentTypeError(str(exc).split(": ", 1)[-1]) from None

    convert.__name__ = name
    return convert


def serial(text: str) -> str:
    """A device serial number (:func:`hapticsdk.argcheck.serial_number`: at most 126
    characters, no control characters)."""
    from ..argcheck import serial_number
    return _from_check(serial_number, "serial")(text)


def figure_file(text: str) -> str:
    """A figure path in a format the plotting backend writes (:func:`hapticsdk.argcheck.figure_path`)."""
    from ..argcheck import figure_path
    return _from_check(figure_path, "figure_file")(text)


#: largest magnitude of a whole-number argument: what an int64 holds (seeds, counts, CPU
#: indices all go to numpy or the operating system, which take no more)
MAX_INT = 2 ** 63 - 1


def _int(text: str) -> int:
    s = str(text).strip()
    try:
        v = int(s, 10)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r:.60}") from None
    if abs(v) > MAX_INT:   # a 401-digit seed reached numpy; a 401-digit CPU index the OS
        raise argparse.ArgumentTypeError(f"must be within -2**63+1..2**63-1, got a number of {len(str(abs(v)))} digits")
    return v


def _float(text: str) -> float:
    try:
        v = float(str(text).strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return v


def nonneg_int(text: str) -> int:
    """A whole number >= 0 (seeds, counts that may be zero)."""
    v = _int(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {v}")
    return v


def positive_int(text: str) -> int:
    """A whole number >= 1 (sample, trial, people counts)."""
    v = _int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {v}")
    return v


def bounded_int(lo: int, hi: int) -> Callable[[str], int]:
    """A type accepting whole numbers in ``lo..hi`` (inclusive)."""

    def check(text: str) -> int:
        v = _int(text)
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"must be in {lo}..{hi}, got {v}")
        return v

    check.__name__ = f"int_{lo}_{hi}"
    return check


def finite_float(text: str) -> float:
    """Any finite number (NaN and infinities refused)."""
    return _float(text)


def positive_float(text: str) -> float:
    """A finite number > 0 (durations, periods, tolerances, gains)."""
    v = _float(text)
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text!r}")
    return v


def nonneg_float(text: str) -> float:
    """A finite number >= 0 (thresholds in percent)."""
    v = _float(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text!r}")
    return v


def unit_interval(text: str) -> float:
    """A finite number in [0, 1]."""
    v = _float(text)
    if not 0.0 <= v <= 1.0:
        raise argparse.ArgumentTypeError(f"must be in 0..1, got {text!r}")
    return v


def open_unit_interval(text: str) -> float:
    """A finite number strictly between 0 and 1 (confidence levels)."""
    v = _float(text)
    if not 0.0 < v < 1.0:
        raise argparse.ArgumentTypeError(f"must be strictly between 0 and 1, got {text!r}")
    return v


def intensity(text: str) -> float:
    """A 0..1 perceptual intensity (same rule as :func:`hapticsdk.perception.dimensions.check_intensity`)."""
    from ..perception.dimensions import check_intensity
    from ..errors import ValidationError

    try:
        return check_intensity(str(text).strip(), "intensity", text=True)
    except ValidationError as exc:
        # the option's name is added by the parser; keep only the reason
        raise argparse.ArgumentTypeError(str(exc).split(": ", 1)[-1]) from None


def int_list(text: str) -> list[int]:
    """A comma-separated list of whole numbers >= 1 (``23,46,92``); at least one."""
    parts = [s.strip() for s in str(text).split(",")]
    if not any(parts):
        raise argparse.ArgumentTypeError(f"expected comma-separated whole numbers, got {text!r}")
    out = []
    for s in parts:
        if not s:
            raise argparse.ArgumentTypeError(f"empty item in {text!r}")
        try:
            v = _int(s)
        except argparse.ArgumentTypeError as exc:
            raise argparse.ArgumentTypeError(f"{exc} in {text!r:.60}") from None
        if v < 1:
            raise argparse.ArgumentTypeError(f"items must be >= 1, got {v}")
        out.append(v)
    return out
