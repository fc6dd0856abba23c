"""The roughness perception dimension: features, constraint (5) and renderer (9).

Features (the paper's G, roughness part):

* ``Fpeak`` (Hz): frequency of the largest FFT peak of the lateral acceleration while
  sliding. Recordings are sampled at 500 Hz, so ``Fpeak < 250 Hz``.
* ``AFpeak`` (m/s^2): one-sided amplitude of that peak.
* ``P`` ((m/s^2)^2): lateral vibration power.

Constraint, formula (5): ``P >= P_F = AFpeak^2 * df`` with ``df`` (Hz) the FFT resolution
of the recordings the model was trained on, passed as ``df_hz`` in the constraint context
(the core takes it from the model metadata). Default :data:`DEFAULT_DF_HZ` = 0.5 Hz:
a 2 s slide at 500 Hz (1000 samples, ``df = fs/n``), the resolution the core's feature
extraction aims for (``df <= 0.5 Hz``).

Renderer, formula (9): ``V_out = Tab(Fpeak, AFpeak)``; ``f_p = Fpeak * |v_x / 80 mm/s|``;
the vibration runs only while ``|v_x| >= 20 mm/s`` (amplitude command 0 below: the
actuator ramps it, never the renderer).
"""

from __future__ import annotations

from typing import Any, ClassVar, Mapping

import numpy as np

from hapticsdk.perception.dimensions import (ChannelCommand, Constraint, DimensionRenderer, PerceptionDimension, RoleSpec,
                                  TickInput)
from hapticsdk.errors import ValidationError
from hapticsdk.perception.features import Feature

#: default FFT resolution (Hz) when no ``df_hz`` is given: 2 s recording at 500 Hz
DEFAULT_DF_HZ = 0.5
#: reference sliding speed of the recordings (mm/s), ``v_const`` of formula (9)
V_REF_MM_S = 80.0
#: below this lateral speed the piezo is silent (mm/s), formula (9)
V_GATE_MM_S = 20.0


class PowerConstraint(Constraint):
    """P >= AFpeak^2 * df (formula (5)): the peak alone carries at least that power."""

    name: ClassVar[str] = "roughness.power"
    features: ClassVar[tuple[str, ...]] = ("AFpeak", "P")

    def __init__(self, df_hz: float = DEFAULT_DF_HZ) -> None:
        df = float(df_hz)
        if not np.isfinite(df) or df <= 0:
            raise ValidationError(f"df_hz must be a positive number of Hz, got {df_hz!r}", field="df_hz")
        self.df_hz = df

    def _bound_and_value(self, cols: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        a = np.asarray(cols["AFpeak"], float)
        pf = np.multiply(a, a)     # (a * a) * df, as ufunc calls (no operator dispatch)
        return np.multiply(pf, self.df_hz, out=pf if type(pf) is np.ndarray else None), np.asarray(cols["P"], float)

    def _bound_and_value_one(self, row: Mapping[str, float]) -> tuple[float, float]:
        a = row["AFpeak"]
        return a * a * self.df_hz, row["P"]      # (a * a) * df, as above

    def describe(self) -> dict:
        d = super().describe()
        d["df_hz"] = self.df_hz
        return d


class RoughnessRenderer(DimensionRenderer):
    """Formula (9) per servo tick, role ``"vibration"``.

    ``V_out`` is looked up once (``Tab(Fpeak, AFpeak)``); each tick commands
    ``frequency_hz = Fpeak * |v_x| / v_ref`` and ``amplitude = V_out`` (V peak) while
    ``|v_x| >= v_gate`` and the probe is in contact (``require_contact``), else amplitude 0
    at the last frequency (so the actuator's ramp-down stays at a steady pitch).

    Out-of-table requests are clamped and reported: ``V_out`` outside the table
    (``table_clamped``), and per tick ``f_p`` outside ``frequency_range_hz``
    (counter ``frequency_clamps``), both in :meth:`describe`; ``table_clamps`` counts the
    active ticks played with a clamped ``V_out``.
    """

    roles = ("vibration",)

    def __init__(self, fpeak_hz: float, afpeak_m_s2: float, *, table: Any = None,
                 v_ref_mm_s: float = V_REF_MM_S, v_gate_mm_s: float = V_GATE_MM_S,
                 frequency_range_hz: tuple[float, float] | None = None,
                 require_contact: bool = True) -> None:
        from .table import resolve_table
        for name, val in (("Fpeak", fpeak_hz), ("AFpeak", afpeak_m_s2)):
            if not np.isfinite(val) or val < 0:
                raise ValidationError(f"must be a finite number >= 0, got {val!r}", field=f"features.{name}")
        if not (v_ref_mm_s > 0 and v_gate_mm_s >= 0):
            raise ValidationError("v_ref_mm_s must be > 0 and v_gate_mm_s >= 0", field="options")
        self.table = resolve_table(table)
        self.fpeak_hz = float(fpeak_hz)
        self.afpeak_m_s2 = float(afpeak_m_s2)
        self.v_ref_mm_s = float(v_ref_mm_s)
        self.v_gate_mm_s = float(v_gate_mm_s)
        self.require_contact = bool(require_contact)
        lo, hi = frequency_range_hz if frequency_range_hz is not None else self.table.frequency_range_hz
        if not 0 <= lo < hi:
            raise ValidationError(f"frequency_range_hz must be (lo, hi) with 0 <= lo < hi, got {(lo, hi)}",
                                  field="options.frequency_range_hz")
        self.f_lo, self.f_hi = float(lo), float(hi)
        self.v_out, self.in_table = self.table.voltage_for(self.fpeak_hz, self.afpeak_m_s2)
        #: acceleration the table predicts at Fpeak for the clamped V_out (m/s^2)
        self.achieved_m_s2 = self.table.acceleration_at(self.fpeak_hz, self.v_out)
        self.frequency_clamps = 0
        #: active ticks played with a clamped V_out (the table could not reach AFpeak at Fpeak)
        self.table_clamps = 0
        self.ticks = 0
        self.active_ticks = 0
        self._last_f = min(max(self.fpeak_hz, self.f_lo), self.f_hi)
        self._gate_open = False

    def frequency_for(self, v_x_mm_s: float) -> float:
        """Formula (9): ``f_p = Fpeak * |v_x / v_ref|`` (Hz), unclamped."""
        return self.fpeak_hz * abs(v_x_mm_s) / self.v_ref_mm_s

    def tick(self, inp: TickInput) -> list[ChannelCommand]:
        self.ticks += 1
        # the floats when the caller gives them (the servo loop does): indexing the array
        # makes a numpy scalar every tick; the same number either way
        vt = getattr(inp, "velocity_floats_mm_s", None)
        avx = abs(float(vt[0] if vt is not None else inp.velocity_mm_s[0]))
        # the speed gate: on a quantised position (speed_step_mm_s > 0) it looks at the
        # filtered speed with a hysteresis of one count's speed step, so count-level
        # chatter never toggles the piezo; on an exact position, the speed itself
        step = getattr(inp, "speed_step_mm_s", 0.0)
        vf = inp.velocity_filtered_mm_s
        gate_v = abs(float(vf[0])) if (step > 0.0 and vf is not None) else avx
        thr = self.v_gate_mm_s - step if self._gate_open else self.v_gate_mm_s
        # written as "not (... >= ...)" so a NaN speed stays silent
        self._gate_open = gate_v >= thr and (inp.in_contact or not self.require_contact)
        if not self._gate_open:
            # positional fields (role, force_n, frequency_hz, amplitude)
            return [ChannelCommand("vibration", None, self._last_f, 0.0)]
        f = self.fpeak_hz * avx / self.v_ref_mm_s  # formula (9), same operation order as frequency_for
        if f < self.f_lo or f > self.f_hi:
            self.frequency_clamps += 1
            f = self.f_lo if f < self.f_lo else self.f_hi
        self._last_f = f
        self.active_ticks += 1
        if not self.in_table:
            self.table_clamps += 1
        return [ChannelCommand("vibration", None, f, self.v_out)]

    def _fast_law(self) -> Any:
        """:meth:`tick` on plain floats (the servo loop's steady-state tick; see
        ``DimensionRenderer._fast_law``): ``(None, frequency_hz, amplitude)`` for the
        role ``vibration``. The gate, the last frequency and the counters are the
        renderer's own attributes, shared with :meth:`tick`; formula (9)'s parameters
        are fixed when the renderer is built."""
        r = self
        fpeak, vref, vgate = self.fpeak_hz, self.v_ref_mm_s, self.v_gate_mm_s
        lo, hi, vout = self.f_lo, self.f_hi, self.v_out
        req, clamped = self.require_contact, not self.in_table

        def law(t: float, dt: float, pen: float, in_contact: bool, v0: float, v1: float, v2: float,
                vf0: float, vf1: float, vf2: float, step: float) -> tuple:
            r.ticks += 1
            avx = abs(v0)
            gate_v = abs(vf0) if step > 0.0 else avx
            thr = vgate - step if r._gate_open else vgate
            gate = r._gate_open = gate_v >= thr and (in_contact or not req)
            if not gate:
                return (None, r._last_f, 0.0)
            f = fpeak * avx / vref  # formula (9), as tick()
            if f < lo or f > hi:
                r.frequency_clamps += 1
                f = lo if f < lo else hi
            r._last_f = f
            r.active_ticks += 1
            if clamped:
                r.table_clamps += 1
            return (None, f, vout)
        return law

    def describe(self) -> dict:
        return {"Fpeak_hz": self.fpeak_hz, "AFpeak_m_s2": self.afpeak_m_s2, "v_out_v": self.v_out,
                "table_in_range": self.in_table, "table_clamped": not self.in_table,
                "achieved_AFpeak_m_s2": self.achieved_m_s2,
                "table_generated": self.table.generated, "table_source": self.table.source,
                "v_ref_mm_s": self.v_ref_mm_s, "v_gate_mm_s": self.v_gate_mm_s,
                "frequency_range_hz": [self.f_lo, self.f_hi],
                "frequency_clamps": self.frequency_clamps, "table_clamps": self.table_clamps, "ticks": self.ticks,
                "active_ticks": self.active_ticks}


class DeviceBandConstraint(Constraint):
    """Fpeak within the band of the actuator that renders roughness (device-aware
    solving): ``Fpeak >= lo`` (``side="low"``) or ``hi >= Fpeak`` (``side="high"``), Hz."""

    features: ClassVar[tuple[str, ...]] = ("Fpeak",)

    def __init__(self, bound_hz: float, side: str, actuator: str = "") -> None:
        if side not in ("low", "high"):
            raise ValidationError(f"side must be 'low' or 'high', got {side!r}", field="side")
        self.bound_hz, self.side, self.actuator = float(bound_hz), side, actuator
        self.name = f"roughness.device-band-{side}"  # type: ignore[misc]  # one name per side

    def _bound_and_value(self, cols: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        f = np.asarray(cols["Fpeak"], float)
        b = np.full_like(f, self.bound_hz)
        return (b, f) if self.side == "low" else (f, b)

    def describe(self) -> dict:
        d = super().describe()
        d.update(bound_hz=self.bound_hz, side=self.side, actuator=self.actuator)
        return d


class DeviceAmplitudeConstraint(Constraint):
    """AFpeak no larger than the actuator reaches at Fpeak with its largest drive:
    ``A_max(Fpeak) >= AFpeak`` (m/s^2), ``A_max`` from the drive table at ``max_drive``."""

    name: ClassVar[str] = "roughness.device-amplitude"
    features: ClassVar[tuple[str, ...]] = ("Fpeak", "AFpeak")

    def __init__(self, table: Any, max_drive: float, f_range_hz: tuple[float, float], actuator: str = "") -> None:
        lo, hi = float(f_range_hz[0]), float(f_range_hz[1])
        self.max_drive, self.actuator = float(max_drive), actuator
        t_lo, t_hi = table.frequency_range_hz
        self._f = np.linspace(lo, hi, 512)
        many = getattr(table, "accelerations_at", None)  # a PiezoTable: vectorised over frequency

        def reach(f: np.ndarray) -> np.ndarray:
            out = np.zeros(f.size)
            inside = (t_lo <= f) & (f <= t_hi)
            if many is not None:
                out[inside] = many(f[inside], self.max_drive)
            else:
                out[inside] = [table.acceleration_at(x, self.max_drive) for x in f[inside]]
            return out

        self._a = reach(self._f)
        # Linear interpolation between the grid points must not promise more than the
        # table: where the curve sags below a chord, both ends of that interval are lowered
        # by the sag at its midpoint (the largest gap for a locally quadratic curve).
        # Intervals reaching past the table's range keep their chord down to 0.
        sag = np.clip(0.5 * (self._a[:-1] + self._a[1:]) - reach(0.5 * (self._f[:-1] + self._f[1:])),
                      0.0, None)
        sag[(self._f[:-1] < t_lo) | (self._f[1:] > t_hi)] = 0.0
        drop = np.zeros(self._a.size)
        drop[:-1] = sag
        drop[1:] = np.maximum(drop[1:], sag)
        self._a = np.maximum(self._a - drop, 0.0)
        self.table_source = getattr(table, "source", "")

    def max_acceleration(self, f_hz: Any) -> np.ndarray:
        """Largest AFpeak (m/s^2) the actuator reaches at ``f_hz`` (Hz)."""
        return np.interp(np.asarray(f_hz, float), self._f, self._a, left=0.0, right=0.0)

    def _bound_and_value(self, cols: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        a = np.asarray(cols["AFpeak"], float)
        return a, self.max_acceleration(cols["Fpeak"])

    def describe(self) -> dict:
        d = super().describe()
        d.update(max_drive=self.max_drive, actuator=self.actuator, table=self.table_source)
        return d


class RoughnessDimension(PerceptionDimension):
    """Perceived roughness (0 smooth .. 1 rough) rendered by a speed-following piezo vibration."""

    name: ClassVar[str] = "roughness"
    description: ClassVar[str] = ("perceived roughness while sliding; rendered as a piezo vibration whose "
                                  "frequency follows the sliding speed (formula (9))")
    features: ClassVar[tuple[Feature, ...]] = (
        Feature("Fpeak", "Hz", 1.0, 249.0,
                "frequency of the largest FFT peak of lateral acceleration (< 250 Hz at 500 Hz sampling)"),
        Feature("AFpeak", "m/s^2", 0.0, 50.0, "one-sided amplitude of that peak"),
        Feature("P", "(m/s^2)^2", 0.0, 500.0,
                "lateral vibration power (mean square of the high-passed acceleration)"),
    )
    default_actuators: ClassVar[dict[str, str]] = {"vibration": "piezo-virtual"}
    roles: ClassVar[dict[str, RoleSpec]] = {
        "vibration": RoleSpec("vibration", {"frequency_hz": "Hz", "amplitude": "V"},
                              "piezo drive V_out sin(2 pi f_p t), f_p following the sliding speed (formula (9))")}
    #: the piezo table Tab comes from the piezo's saved calibration when there is one
    calibrations: ClassVar[dict[str, tuple[str, str]]] = {"table": ("piezo", "vibration")}
    render_features: ClassVar[tuple[str, ...]] = ("Fpeak", "AFpeak")

    def constraints(self, **context: float) -> list[Constraint]:
        """``[PowerConstraint(df_hz)]``; ``df_hz`` defaults to :data:`DEFAULT_DF_HZ`."""
        df = context.get("df_hz")
        return [PowerConstraint(DEFAULT_DF_HZ if df is None else df)]

    def capability_options(self, capabilities: Mapping[str, Any]) -> dict[str, Any]:
        """An actuator with a drive table of its own (an LRA) renders with that table and
        within its band; a piezo uses the (calibrated) ``Tab``."""
        cap = capabilities.get("vibration")
        if cap is None or getattr(cap, "table", None) is None:
            return {}
        out: dict[str, Any] = {"table": cap.table}
        if cap.frequency_range_hz is not None:
            t_lo, t_hi = cap.table.frequency_range_hz
            out["frequency_range_hz"] = (max(cap.frequency_range_hz[0], t_lo), min(cap.frequency_range_hz[1], t_hi))
        return out

    def device_constraints(self, capabilities: Mapping[str, Any], **options: Any) -> list[Constraint]:
        """Fpeak within the mapped actuator's band, AFpeak within what its largest drive
        reaches at Fpeak through the table the renderer will use (``options["table"]``,
        else the actuator's own, else the default ``Tab``)."""
        from .table import resolve_table
        cap = capabilities.get("vibration")
        if cap is None:
            return []
        table = resolve_table(options.get("table") if options.get("table") is not None else cap.table)
        who = getattr(cap, "source", "")
        out: list[Constraint] = []
        f_lo, f_hi = self.features[0].lower, self.features[0].upper
        if cap.frequency_range_hz is not None:
            b_lo, b_hi = (float(v) for v in cap.frequency_range_hz)
            if b_lo > f_lo:
                out.append(DeviceBandConstraint(b_lo, "low", who))
            if b_hi < f_hi:
                out.append(DeviceBandConstraint(b_hi, "high", who))
            f_lo, f_hi = min(max(f_lo, b_lo), f_hi), max(min(f_hi, b_hi), f_lo)
        if cap.max_drive is not None:
            v_max = min(float(cap.max_drive), float(table.voltages_v[-1])) if hasattr(table, "voltages_v") \
                else float(cap.max_drive)
            out.append(DeviceAmplitudeConstraint(table, v_max, (self.features[0].lower, self.features[0].upper), who))
        return out

    def renderer(self, features: Mapping[str, float], **options: Any) -> RoughnessRenderer:
        """Options: ``table`` (PiezoTable, dict or JSON path; default the generated table),
        ``v_ref_mm_s`` (80), ``v_gate_mm_s`` (20), ``frequency_range_hz`` (default the
        table's), ``require_contact`` (True)."""
        missing = [n for n in self.render_features if n not in features]
        if missing:
            raise ValidationError(f"missing features {missing} (roughness renders from {list(self.render_features)})",
                                  field="features")
        return RoughnessRenderer(float(features["Fpeak"]), float(features["AFpeak"]), **options)
