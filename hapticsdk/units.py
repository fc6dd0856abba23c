"""Unit strings, parsed: ``"newton"`` and ``"N"`` name the same unit, ``"N/mm"`` and
``"N/m"`` do not.

A unit string is a product of factors separated by ``*``, ``·`` or white space, with
``/`` (or the word ``per``) dividing, each factor a unit name with an optional integer
power (``m/s^2``, ``m s**-2``, ``mm2``). Names are looked up in :data:`ALIASES` (symbols,
singular and plural words, British and American spellings; case matters only where SI
symbols differ by case: ``mm`` vs ``Mm`` are not both listed, ``ms`` is milliseconds).
Each name maps to a scale in SI base units and a vector of base-dimension powers, so two
strings are the same unit when both agree (``N/mm`` = ``kN/m``; ``Hz`` = ``1/s``).
Dimensionless spellings (``""``, ``"1"``, ``"-"``, ``"dimensionless"``, ``"unitless"``)
are all the unit 1. A string that cannot be parsed is compared as text (white space
aside), as before.
"""

from __future__ import annotations

import math
import re
from functools import lru_cache

# base dimensions: kg, m, s, A, K
_KG, _M, _S, _A, _K = ((1, 0, 0, 0, 0), (0, 1, 0, 0, 0), (0, 0, 1, 0, 0), (0, 0, 0, 1, 0), (0, 0, 0, 0, 1))
_N = (1, 1, -2, 0, 0)
_V = (1, 2, -3, -1, 0)
_ONE = (0, 0, 0, 0, 0)


def _u(scale: float, dims: tuple[int, ...]) -> tuple[float, tuple[int, ...]]:
    return scale, dims


#: unit name -> (scale to SI, base-dimension powers (kg, m, s, A, K))
ALIASES: dict[str, tuple[float, tuple[int, ...]]] = {}
for names, unit in [
    (("N", "newton", "newtons"), _u(1.0, _N)),
    (("mN", "millinewton", "millinewtons"), _u(1e-3, _N)),
    (("kN", "kilonewton", "kilonewtons"), _u(1e3, _N)),
    (("m", "metre", "metres", "meter", "meters"), _u(1.0, _M)),
    (("mm", "millimetre", "millimetres", "millimeter", "millimeters"), _u(1e-3, _M)),
    (("um", "µm", "μm", "micrometre", "micrometres", "micrometer", "micrometers", "micron", "microns"),
     _u(1e-6, _M)),
    (("cm", "centimetre", "centimetres", "centimeter", "centimeters"), _u(1e-2, _M)),
    (("s", "sec", "second", "seconds"), _u(1.0, _S)),
    (("ms", "millisecond", "milliseconds"), _u(1e-3, _S)),
    (("us", "µs", "μs", "microsecond", "microseconds"), _u(1e-6, _S)),
    (("Hz", "hz", "hertz"), _u(1.0, (0, 0, -1, 0, 0))),
    (("kHz", "khz", "kilohertz"), _u(1e3, (0, 0, -1, 0, 0))),
    (("kg", "kilogram", "kilograms"), _u(1.0, _KG)),
    (("g", "gram", "grams"), _u(1e-3, _KG)),
    (("V", "volt", "volts"), _u(1.0, _V)),
    (("mV", "millivolt", "millivolts"), _u(1e-3, _V)),
    (("A", "ampere", "amperes", "amp", "amps"), _u(1.0, _A)),
    (("mA", "milliampere", "milliamperes"), _u(1e-3, _A)),
    (("W", "watt", "watts"), _u(1.0, (1, 2, -3, 0, 0))),
    (("J", "joule", "joules"), _u(1.0, (1, 2, -2, 0, 0))),
    (("Pa", "pascal", "pascals"), _u(1.0, (1, -1, -2, 0, 0))),
    (("K", "kelvin"), _u(1.0, _K)),
    (("1", "-", "dimensionless", "unitless", "none"), _u(1.0, _ONE)),
    (("%", "percent"), _u(0.01, _ONE)),
]:
    for n in names:
        ALIASES[n] = unit
#: temperatures on an offset scale: equal only to themselves (a Celsius degree is not a kelvin)
OFFSET_UNITS: dict[str, str] = {n: "degC" for n in ("degC", "°C", "℃", "celsius", "degree_Celsius", "deg C")}
OFFSET_UNITS.update({n: "degF" for n in ("degF", "°F", "fahrenheit")})

#: decades of scale a parsed unit may span (a float spans about +-307); beyond, the string
#: is compared as text
_MAX_DECADES = 300

_TOKEN = re.compile(r"^(?P<name>[^\d^*+-]+|1|%|-)(?:(?:\^|\*\*)?(?P<pow>[+-]?\d+))?$")


@lru_cache(maxsize=512)
def parse_unit(text: str) -> tuple[float, tuple[int, ...]] | str | None:
    """``(scale, dimension powers)`` of a unit string; the canonical name of an offset
    temperature scale (``"degC"``); ``None`` when it cannot be parsed."""
    t = " ".join(str(text).split())
    if t in OFFSET_UNITS:
        return OFFSET_UNITS[t]
    if t in ("", "1", "-"):
        return 1.0, _ONE
    t = re.sub(r"\s+per\s+", "/", t.replace("**", "^"))
    t = re.sub(r"\s*([/*·])\s*", r"\1", t)
    log_scale, dims = 0.0, [0, 0, 0, 0, 0]
    sign = 1
    for i, part in enumerate(re.split(r"(/)", t)):
        if part == "/":
            sign = -1
            continue
        for tok in re.split(r"[*· ]", part):
            if not tok:
                continue
            if tok == "1" and i == 0:
                continue
            m = _TOKEN.match(tok)
            if not m:
                return None
            name, p = m.group("name"), int(m.group("pow") or 1)
            unit = ALIASES.get(name) or ALIASES.get(name.lower() if len(name) > 2 else name)
            if unit is None:
                return None
            log_scale += sign * p * math.log10(unit[0])
            dims = [d + sign * p * u for d, u in zip(dims, unit[1])]
    if abs(log_scale) > _MAX_DECADES:   # kN^999: no float holds it (it would overflow or become 0)
        return None
    return 10.0 ** log_scale, tuple(dims)


def same_unit(a: str, b: str) -> bool:
    """Whether two unit strings name the same unit (parsed; text comparison, white space
    aside, when either cannot be parsed)."""
    pa, pb = parse_unit(str(a)), parse_unit(str(b))
    if pa is None or pb is None:
        return "".join(str(a).split()) == "".join(str(b).split())
    if isinstance(pa, str) or isinstance(pb, str):
        return pa == pb
    return pa[1] == pb[1] and math.isclose(pa[0], pb[0], rel_tol=1e-9)


def is_force_unit(unit: str) -> bool:
    """Whether ``unit`` is a force (kg m s^-2 at any scale: ``"N"``, ``"newton"``, ``"mN"``)."""
    p = parse_unit(str(unit))
    return isinstance(p, tuple) and p[1] == _N
