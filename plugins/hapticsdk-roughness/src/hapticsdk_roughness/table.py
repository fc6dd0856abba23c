"""The piezo voltage table ``Tab`` of formula (9): a GENERATED default, or a user's file.

The paper characterises its Samsung PHAT423535XX piezo (driven by a TI DRV2667) only as a
figure (acceleration over drive frequency and voltage, its Fig. 12), so no measured numbers
exist. :func:`generated_table` builds a *plausible* grid from a documented physical model
instead; the result is a :class:`hapticsdk.calibration.PiezoTable` with ``generated=True``
and a ``source`` saying so. It is never presented as a measurement: replace it with a
measured table (same format, :func:`load_table`) as soon as one exists.

Model (all assumptions, stated so they can be checked against a measurement):

* The piezo plate with the finger on it is a single-degree-of-freedom resonator driven by
  a force proportional to the drive voltage ``V`` (V peak). Its displacement amplitude is
  ``x(f, V) = d_eff * V * s(V) / sqrt((1 - r^2)^2 + (2 zeta r)^2)`` with ``r = f / f0``
  (standard second-order mechanical response), so the acceleration amplitude is
  ``a = (2 pi f)^2 x`` (m/s^2).
* ``f0 = 250 Hz`` loaded resonance and ``zeta = 0.35`` (a finger damps the plate
  heavily). The DRV2667 load ratings are quoted at 300 Hz (hardware.md §1.5), the typical
  band of piezo haptic actuators; PHAT423535XX data are unknown (hardware.md §6.2 [U]).
* ``d_eff = 0.36 um/V`` effective quasi-static displacement per volt: chosen so that the
  DRV2667's lowest gain (25 V peak, the safe default of hardware.md §6.2) reaches about
  4 m/s^2 at 100 Hz and ~30 m/s^2 (3 g) at resonance, the order of magnitude of
  commercial piezo haptic modules.
* ``s(V) = 1 - c (V / V_max)^2`` with ``c = 0.08``: mild softening at high drive
  (piezo hysteresis); ``c < 1/3`` keeps acceleration strictly increasing in voltage,
  which the table's inversion needs.
* Grid: 5..500 Hz (``Fpeak < 250 Hz`` for 500 Hz recordings, and ``f_p`` of formula (9)
  reaches ~2 Fpeak at twice the reference speed), 0..100 V peak (the DRV2667's largest
  full scale, hardware.md §1.2).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from hapticsdk.calibration import PiezoTable
from hapticsdk.errors import CalibrationError

#: parameters of the generated model (see module docstring)
GENERATED_MODEL: dict[str, float] = {
    "f0_hz": 250.0,
    "zeta": 0.35,
    "d_eff_m_per_v": 0.36e-6,
    "softening": 0.08,
    "v_max_v": 100.0,
}

GENERATED_SOURCE = ("GENERATED (not measured): second-order resonator model of a PHAT423535XX-class "
                    "piezo on a DRV2667, hapticsdk_roughness.table.generated_table {params}")


def model_acceleration(f_hz: Any, volts: Any, *, f0_hz: float = 250.0, zeta: float = 0.35,
                       d_eff_m_per_v: float = 0.36e-6, softening: float = 0.08,
                       v_max_v: float = 100.0) -> np.ndarray:
    """Acceleration amplitude (m/s^2) of the generated piezo model at ``f_hz`` (Hz) and
    ``volts`` (V peak); broadcasts over numpy arrays."""
    f = np.asarray(f_hz, float)
    v = np.asarray(volts, float)
    r = f / f0_hz
    gain = 1.0 / np.sqrt((1.0 - r ** 2) ** 2 + (2.0 * zeta * r) ** 2)
    x = d_eff_m_per_v * v * (1.0 - softening * (v / v_max_v) ** 2) * gain
    return (2.0 * np.pi * f) ** 2 * x


def generated_table(frequencies_hz: Any = None, voltages_v: Any = None,
                    **params: float) -> PiezoTable:
    """The default ``Tab``: a GENERATED :class:`PiezoTable` from :func:`model_acceleration`.

    Args:
        frequencies_hz: grid (Hz); default 5..500 Hz in 5 Hz steps.
        voltages_v: grid (V peak); default 0..100 V in 2.5 V steps.
        params: overrides of :data:`GENERATED_MODEL`.
    """
    p = dict(GENERATED_MODEL)
    unknown = set(params) - set(p)
    if unknown:
        raise CalibrationError(f"unknown model parameter(s) {sorted(unknown)}; valid: {sorted(p)}")
    p.update({k: float(v) for k, v in params.items()})
    f = np.arange(5.0, 500.0 + 1e-9, 5.0) if frequencies_hz is None else np.asarray(frequencies_hz, float)
    v = np.arange(0.0, p["v_max_v"] + 1e-9, 2.5) if voltages_v is None else np.asarray(voltages_v, float)
    acc = model_acceleration(f[:, None], v[None, :], **p)
    return PiezoTable(frequencies_hz=f, voltages_v=v, acceleration=acc, generated=True,
                      source=GENERATED_SOURCE.format(params=json.dumps(p, sort_keys=True)))


def table_from_dict(data: dict) -> PiezoTable:
    """A :class:`PiezoTable` from the dict of :meth:`PiezoTable.to_dict` (``kind: piezo``)."""
    if not isinstance(data, dict) or data.get("kind", "piezo") != "piezo":
        raise CalibrationError(f"not a piezo table (kind={data.get('kind') if isinstance(data, dict) else type(data).__name__!r})")
    # the core's reader: every column checked, a bad element named by its index
    table = PiezoTable.from_dict({k: v for k, v in data.items() if k != "serial"})
    table.serial = None
    return table


def load_table(path: str | Path) -> PiezoTable:
    """Load a measured (or generated) table from a JSON file in :meth:`PiezoTable.to_dict` form."""
    from hapticsdk.errors import ValidationError
    from hapticsdk.schemas_io import read_json

    p = Path(path)
    if not p.exists():
        raise CalibrationError(f"piezo table file not found: {p}")
    try:  # a regular UTF-8 file of bounded size and depth (a scene may name this path)
        data = read_json(p, field="table")
    except ValidationError as exc:
        raise CalibrationError(f"piezo table {p}: {exc}") from None
    table = table_from_dict(data)
    if not table.source:
        table.source = str(p)
    return table


def save_table(table: PiezoTable, path: str | Path) -> Path:
    """Write ``table`` as JSON (:meth:`PiezoTable.to_dict` form); returns the path."""
    from hapticsdk.fileio import atomic_write_text
    # read back by load_table (its size and depth caps, the table checks) before the rename
    return atomic_write_text(path, json.dumps(table.to_dict(), indent=1), verify=load_table)


def resolve_table(table: Any = None) -> PiezoTable:
    """``None`` -> the generated default; a :class:`PiezoTable` as is; a dict or a path -> loaded."""
    if table is None:
        return _default()
    if isinstance(table, PiezoTable):
        return table
    if isinstance(table, dict):
        return table_from_dict(table)
    if isinstance(table, (str, Path)):
        return load_table(table)
    raise CalibrationError(f"piezo table must be a PiezoTable, dict or path, got {type(table).__name__}")


_DEFAULT: PiezoTable | None = None


def _default() -> PiezoTable:
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = generated_table()
    return _DEFAULT
