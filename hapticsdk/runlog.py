"""Record a device run and play it back as a simulated device.

A *run* is what the servo loop saw and did on every tick: the device state (position
mm, velocity mm/s, device force N, buttons) and, per role, the command actually applied
(force N, frequency Hz, amplitude in the actuator's unit). :class:`RunRecorder` is the
servo loop's ``recorder=`` (``record(t, state, sent)`` per tick, ``close()`` at the
end) and writes one ``.npz`` file holding numpy arrays plus a JSON header (key
``header_json``). :func:`load_run` reads it back as a :class:`RunLog`.

:class:`PlaybackDevice` (entry point ``playback-virtual``) is a
:class:`~hapticsdk.devices.actuators.HapticDevice` that returns the recorded states tick by
tick, so a bug seen on hardware can be re-run in a test: the renderers see the same
inputs, and the forces they command can be compared sample for sample with the
recorded ones (:attr:`PlaybackDevice.received`).

File layout (``format: "hapticsdk-run"``, ``version: 1``):

=====================  =========  ===========================================
key                    shape      meaning
=====================  =========  ===========================================
``t``                  (n,)       loop time of each tick (s)
``state_t``            (n,)       device time of the state (s)
``position_mm``        (n, 3)     probe position (mm)
``velocity_mm_s``      (n, 3)     probe velocity (mm/s)
``device_force_n``     (n, 3)     force the device reported applying (N)
``buttons``            (n,)       button bit mask
``cmd/<role>/force_n``  (n,)      applied force (N), NaN when not sent
``cmd/<role>/frequency_hz`` (n,)  applied drive frequency (Hz), NaN when not sent
``cmd/<role>/amplitude``    (n,)  applied amplitude (actuator unit), NaN when not sent
``header_json``        ()         JSON header: format, version, created, roles,
                                  n_ticks, period_s, device (name, label,
                                  limits, safety settings), meta
=====================  =========  ===========================================
"""

from __future__ import annotations

import datetime as _dt
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Mapping, cast

import numpy as np

from .devices.actuators import ActuatorLimits, DeviceState, HapticDevice
from .perception.dimensions import ChannelCommand
from .errors import DeviceError, RecordingError, ValidationError
from .quantiles import median

FORMAT = "hapticsdk-run"
VERSION = 1
_CMD_FIELDS = ("force_n", "frequency_hz", "amplitude")
#: largest unpacked size of a run file read (bytes): an hour at 1 kHz is about 0.5 GB
MAX_RUN_BYTES = 2 * 1024 ** 3


def _as_vec3(v: Any) -> np.ndarray:
    a = np.zeros(3) if v is None else np.asarray(v, float).reshape(-1)
    out = np.full(3, np.nan)
    out[: min(3, a.size)] = a[:3]
    return out


class _Rows:
    """A growing float64 table of ``width`` columns kept in fixed-size blocks (no copy
    of what is already stored when it grows; about 8 bytes per value, against about
    30-50 for Python floats and small arrays in lists)."""

    __slots__ = ("width", "blocks", "cur", "i")

    BLOCK = 4096

    def __init__(self, width: int) -> None:
        self.width = width
        self.blocks: list[np.ndarray] = []
        self.cur = np.empty((self.BLOCK, width))
        self.i = 0

    def __len__(self) -> int:
        return len(self.blocks) * self.BLOCK + self.i

    def append(self, row: Any) -> None:
        """Store one row (a sequence of ``width`` numbers)."""
        if self.i == self.BLOCK:
            self.blocks.append(self.cur)
            self.cur = np.empty((self.BLOCK, self.width))
            self.i = 0
        self.cur[self.i] = row
        self.i += 1

    def array(self) -> np.ndarray:
        """Every row stored, shape ``(n, width)`` (a new array)."""
        return np.concatenate(self.blocks + [self.cur[:self.i]]) if self.blocks else self.cur[:self.i].copy()


#: the columns of a tick's state row: t, state_t, position (3), velocity (3), force (3), buttons
_STATE_WIDTH = 12
_NAN3 = (np.nan, np.nan, np.nan)


def _vec3(v: Any, none: tuple[float, float, float]) -> tuple[float, float, float]:
    """Three floats from a 3-vector (``none`` for None; a shorter one padded with NaN)."""
    if v is None:
        return none
    try:
        x, y, z = v
        return float(x), float(y), float(z)
    except (TypeError, ValueError):
        a = _as_vec3(v)
        return float(a[0]), float(a[1]), float(a[2])


class RunRecorder:
    """Collects one run tick by tick and writes it to ``path`` (``.npz``) on :meth:`close`.

    The run is kept in memory in blocks of float64 rows until then: about 100 bytes per
    tick plus 24 per commanded role (an hour at 1 kHz with three roles: about 0.6 GB).

    Args:
        path: output file; ``.npz`` is appended when missing. ``None`` keeps the run in
            memory only (:meth:`to_runlog`).
        device: the device being recorded (its name, label, limits and safety settings
            go to the header, so playback applies the same limits).
        meta: free JSON-serialisable information (scene, material, git revision ...).
    """

    def __init__(self, path: str | Path | None, *, device: Any = None,
                 meta: Mapping[str, Any] | None = None) -> None:
        self.path = None if path is None else Path(path)
        if self.path is not None and self.path.suffix != ".npz":
            self.path = self.path.with_name(self.path.name + ".npz")
        self.meta = dict(meta or {})
        self.device_info = _device_info(device) if device is not None else None
        self._rows = _Rows(_STATE_WIDTH)
        #: role -> (first tick it was sent on, its rows of force_n, frequency_hz, amplitude)
        self._cmd: dict[str, tuple[int, _Rows]] = {}
        self.closed = False

    def __len__(self) -> int:
        return len(self._rows)

    def record(self, t: float, state: DeviceState | None, sent: Mapping[str, ChannelCommand]) -> None:
        """Append one tick: loop time ``t`` (s), the device ``state`` read this tick
        (``None`` without a sensing device) and ``sent`` (role -> command applied)."""
        if self.closed:
            raise RecordingError("record() after close()", field="runlog")
        n = len(self._rows)
        if state is None:
            self._rows.append((float(t), np.nan, *_NAN3, *_NAN3, *_NAN3, 0.0))
        else:
            self._rows.append((float(t), float(state.t), *_vec3(state.position_mm, (0.0, 0.0, 0.0)),
                               *_vec3(state.velocity_mm_s, (0.0, 0.0, 0.0)),
                               *_vec3(getattr(state, "force_n", None), (0.0, 0.0, 0.0)),
                               float(int(getattr(state, "buttons", 0)))))
        for role, cmd in sent.items():
            entry = self._cmd.get(role)
            if entry is None:  # a role first seen now: its earlier ticks are NaN
                entry = self._cmd[role] = (n, _Rows(len(_CMD_FIELDS)))
            f, hz, amp = cmd.force_n, cmd.frequency_hz, cmd.amplitude
            entry[1].append((np.nan if f is None else float(f), np.nan if hz is None else float(hz),
                             np.nan if amp is None else float(amp)))
        if len(sent) != len(self._cmd):
            for role, (_, rows) in self._cmd.items():
                if role not in sent:
                    rows.append(_NAN3)

    def to_runlog(self) -> "RunLog":
        """The run recorded so far, as a :class:`RunLog`."""
        n = len(self._rows)
        a = self._rows.array()
        t = a[:, 0].copy()
        period = median(np.diff(t)) if n > 1 else None
        header = {"format": FORMAT, "version": VERSION,
                  "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                  "n_ticks": n, "period_s": period, "roles": sorted(self._cmd),
                  "device": self.device_info, "meta": self.meta}
        cmds: dict[str, dict[str, np.ndarray]] = {}
        for role, (start, rows) in self._cmd.items():
            c = np.full((n, len(_CMD_FIELDS)), np.nan)
            c[start:] = rows.array()
            cmds[role] = {f: c[:, k].copy() for k, f in enumerate(_CMD_FIELDS)}
        return RunLog(header=header, t=t, state_t=a[:, 1].copy(), position_mm=a[:, 2:5].copy(),
                      velocity_mm_s=a[:, 5:8].copy(), device_force_n=a[:, 8:11].copy(),
                      buttons=a[:, 11].astype(np.int64), commands=cmds)

    def close(self) -> Path | None:
        """Write the file (once; later calls do nothing) and return its path."""
        if self.closed:
            return self.path
        self.closed = True
        if self.path is not None:
            self.to_runlog().save(self.path)
        return self.path

    def __enter__(self) -> "RunRecorder":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _device_info(device: Any) -> dict[str, Any]:
    info: dict[str, Any] = {"name": getattr(device, "name", ""), "label": getattr(device, "label", ""),
                            "simulated": bool(getattr(device, "simulated", False))}
    limits = getattr(device, "limits", None)
    if limits is not None and hasattr(limits, "to_dict"):
        info["limits"] = limits.to_dict()
    settings = getattr(getattr(device, "safety", None), "settings", None)
    if settings is not None and hasattr(settings, "to_dict"):
        info["safety_settings"] = settings.to_dict()
    return info


@dataclass
class RunLog:
    """A recorded run (see the module docstring for the arrays and their units)."""

    header: dict[str, Any]
    t: np.ndarray
    state_t: np.ndarray
    position_mm: np.ndarray
    velocity_mm_s: np.ndarray
    device_force_n: np.ndarray
    buttons: np.ndarray
    commands: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def roles(self) -> list[str]:
        """Channel roles with recorded commands, sorted."""
        return sorted(self.commands)

    @property
    def period_s(self) -> float | None:
        """Servo period of the recorded run (s), when the header has it."""
        return self.header.get("period_s")

    def state(self, i: int) -> DeviceState:
        """The recorded device state of tick ``i``."""
        return DeviceState(t=float(self.state_t[i]), position_mm=self.position_mm[i].copy(),
                           velocity_mm_s=self.velocity_mm_s[i].copy(),
                           force_n=self.device_force_n[i].copy(), buttons=int(self.buttons[i]))

    def command(self, role: str, i: int) -> ChannelCommand:
        """The command applied to ``role`` on tick ``i`` (fields ``None`` where not sent)."""
        cols = self.commands[role]
        vals = {f: (None if np.isnan(cols[f][i]) else float(cols[f][i])) for f in _CMD_FIELDS}
        return ChannelCommand(role, **cast("dict[str, Any]", vals))

    def save(self, path: str | Path) -> Path:
        """Write the run as ``.npz`` (arrays + ``header_json``)."""
        p = Path(path)
        arrays: dict[str, Any] = {
            "t": self.t, "state_t": self.state_t, "position_mm": self.position_mm,
            "velocity_mm_s": self.velocity_mm_s, "device_force_n": self.device_force_n,
            "buttons": self.buttons,
            "header_json": np.array(json.dumps(self.header, default=_json_default))}
        for role, cols in self.commands.items():
            if "/" in role:
                raise ValidationError(f"role name {role!r} must not contain '/'", field="runlog.roles")
            for f, v in cols.items():
                arrays[f"cmd/{role}/{f}"] = v
        from .fileio import atomic_savez
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            from .errors import FileWriteError
            raise FileWriteError(f"cannot create the directory: {exc.strerror or exc}", field=str(p)) from None
        # temp file + fsync + read back by load_run (its unpacked-size cap) + rename
        return atomic_savez(p, verify=load_run, **arrays)

    def summary(self) -> dict[str, Any]:
        """Ticks, duration, rate, per-role command ranges and the header, as strict JSON
        (no NaN or infinity: ``json.dumps(..., allow_nan=False)`` takes it). A figure
        that is not a finite float -- a recorded infinity or NaN, or values near the float
        range whose difference or speed overflows it -- is None, and ``not_finite`` names
        it with the reason (``{"speed_mm_s_max": "overflow: ..."}``); a non-finite number
        in the header is None there, named ``header.<path>``."""
        n = len(self)
        notes: dict[str, str] = {}
        with np.errstate(over="ignore", invalid="ignore"):   # an overflow is reported in not_finite
            out: dict[str, Any] = {"n_ticks": n,
                                   "duration_s": _figure(self.t[-1] - self.t[0], "duration_s", notes) if n > 1
                                   else 0.0,
                                   "period_s": self.period_s, "roles": {},
                                   "header": _nulled(self.header, "header", notes)}
            if n and np.isfinite(self.position_mm).any():
                out["penetration_mm_max"] = _figure(_max_not_nan(-self.position_mm[:, 1]), "penetration_mm_max",
                                                    notes)
                v = self.velocity_mm_s   # hypot: components up to the float range do not overflow their length
                speed = np.hypot(np.hypot(v[:, 0], v[:, 1]), v[:, 2])
                out["speed_mm_s_max"] = _figure(_max_not_nan(speed), "speed_mm_s_max", notes)
        for role, cols in self.commands.items():
            r: dict[str, Any] = {}
            for f, v in cols.items():
                ok = np.isfinite(v)
                if ok.any():
                    r[f] = {"min": float(v[ok].min()), "max": float(v[ok].max()), "ticks": int(ok.sum())}
            out["roles"][role] = r
        if notes:
            out["not_finite"] = notes
        return out


def _max_not_nan(v: np.ndarray) -> float:
    """The largest value of ``v`` that is not NaN (an infinity counts); NaN if none."""
    v = v[~np.isnan(v)]
    return float(v.max()) if v.size else math.nan


def _figure(value: Any, name: str, notes: dict[str, str]) -> float | None:
    """``value`` as a float when finite, else None with the reason in ``notes[name]``."""
    v = float(value)
    if math.isfinite(v):
        return v
    notes[name] = ("overflow: beyond the float range (a recorded infinity, or values near the float range)"
                   if math.isinf(v) else "not a number: no finite value recorded")
    return None


def _nulled(o: Any, where: str, notes: dict[str, str]) -> Any:
    """``o`` (parsed JSON) with every non-finite float as None, each named in ``notes``
    by its path. The header's depth is bounded where a file is read (MAX_JSON_DEPTH)."""
    if isinstance(o, float) and not math.isfinite(o):
        notes[where] = f"{o!r} in the file (JSON has no such number)"
        return None
    if isinstance(o, dict):
        return {k: _nulled(v, f"{where}.{k}", notes) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_nulled(v, f"{where}[{i}]", notes) for i, v in enumerate(o)]
    return o


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    if isinstance(o, tuple):
        return list(o)
    return str(o)


def load_run(path: str | Path) -> RunLog:
    """Read a run file written by :class:`RunRecorder` / :meth:`RunLog.save` (``.npz``),
    or a live session's HDF5 recording (``.h5`` / ``.hdf5``, needs h5py).
    Raises :class:`RecordingError` naming the file and the missing/broken field."""
    from .argcheck import file_path
    try:
        p = file_path(path, "runlog")
    except ValidationError as exc:
        raise RecordingError(exc.reason, field="runlog") from None
    if not p.is_file():
        raise RecordingError(f"run file not found: {p}", field="runlog")
    if p.suffix.lower() in (".h5", ".hdf5"):  # a live recording in HDF5 (hapticsdk[h5])
        from .runtime.recorder_h5 import read_arrays
        data = read_arrays(p, max_bytes=MAX_RUN_BYTES)
    else:
        data = _load_npz(p)
    return _runlog_from_arrays(p, data)


def _load_npz(p: Path) -> dict[str, np.ndarray]:
    try:
        with np.load(p, allow_pickle=False) as z:
            unpacked = sum(i.file_size for i in z.zip.infolist()) if hasattr(z, "zip") else 0
            if unpacked > MAX_RUN_BYTES:  # checked before anything is decompressed
                raise RecordingError(f"{p}: unpacks to {unpacked} bytes, more than the {MAX_RUN_BYTES} accepted",
                                     field="runlog")
            data = {k: z[k] for k in z.files}
    except RecordingError:
        raise
    except Exception as exc:
        why = ("pickled data or not an .npz archive; pickles are never loaded" if "pickle" in str(exc)
               else f"{type(exc).__name__}: {exc}")
        raise RecordingError(f"{p}: not a readable .npz run file ({why})", field="runlog") from None
    return data


def _runlog_from_arrays(p: Path, data: dict[str, np.ndarray]) -> RunLog:
    if "header_json" not in data:
        raise RecordingError(f"{p}: no header_json (not a hapticsdk run file)", field="runlog.header_json")
    from .schemas_io import MAX_JSON_DEPTH, json_depth
    text = str(data["header_json"])
    if json_depth(text) > MAX_JSON_DEPTH:
        raise RecordingError(f"{p}: header_json nested deeper than {MAX_JSON_DEPTH} levels", field="runlog.header_json")
    try:
        header = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise RecordingError(f"{p}: header_json is not valid JSON ({exc})", field="runlog.header_json") from None
    if not isinstance(header, dict):
        raise RecordingError(f"{p}: header_json must be a JSON object", field="runlog.header_json")
    if header.get("format") != FORMAT or header.get("version") != VERSION:
        raise RecordingError(f"{p}: format {header.get('format')!r} v{header.get('version')!r}, "
                             f"expected {FORMAT!r} v{VERSION}", field="runlog.header_json")
    period = header.get("period_s")
    if period is not None and not (_finite_number(period) and float(period) > 0):
        # playback steps by it: a 401-digit int, a list or NaN failed there (OverflowError, TypeError)
        raise RecordingError(f"{p}: period_s must be a finite number of seconds > 0 or null, got {period!r:.60}",
                             field="runlog.header_json.period_s")
    for key in ("t", "state_t", "position_mm", "velocity_mm_s", "device_force_n", "buttons"):
        if key not in data:
            raise RecordingError(f"{p}: array {key!r} missing", field=f"runlog.{key}")
    if data["t"].ndim != 1:
        raise RecordingError(f"{p}: t has shape {data['t'].shape}, expected (n,)", field="runlog.t")
    n = data["t"].shape[0]
    for key, v in data.items():
        if key != "header_json" and v.dtype.kind not in "biuf":
            raise RecordingError(f"{p}: {key} holds {v.dtype} values, expected numbers", field=f"runlog.{key}")
    for key in ("state_t", "buttons"):
        if data[key].shape != (n,):
            raise RecordingError(f"{p}: {key} has shape {data[key].shape}, expected ({n},)", field=f"runlog.{key}")
    b = data["buttons"]
    if b.dtype.kind == "f":
        # cast to int64, a NaN, an inf or 1e308 becomes an arbitrary button mask
        ok = np.isfinite(b) & (np.abs(b) < 2.0 ** 63)
        ok[ok] &= b[ok] == np.round(b[ok])
        if not ok.all():
            i = int(np.argmin(ok))
            raise RecordingError(f"{p}: buttons must be whole numbers (a bit mask), got {b[i]!r} at tick {i}",
                                 field="runlog.buttons")
    for key in ("position_mm", "velocity_mm_s", "device_force_n"):
        if data[key].shape != (n, 3):
            raise RecordingError(f"{p}: {key} has shape {data[key].shape}, expected ({n}, 3)", field=f"runlog.{key}")
    cmds: dict[str, dict[str, np.ndarray]] = {}
    for key, v in data.items():
        if key.startswith("cmd/"):
            parts = key.split("/", 2)
            if len(parts) != 3 or parts[2] not in _CMD_FIELDS or not parts[1]:
                raise RecordingError(f"{p}: array {key!r} is not cmd/<role>/<{'|'.join(_CMD_FIELDS)}>",
                                     field=f"runlog.{key}")
            _, role, f = parts
            if v.shape != (n,):
                raise RecordingError(f"{p}: {key} has shape {v.shape}, expected ({n},)", field=f"runlog.{key}")
            cmds.setdefault(role, {})[f] = v.astype(float)
    return RunLog(header=header, t=data["t"].astype(float), state_t=data["state_t"].astype(float),
                  position_mm=data["position_mm"].astype(float), velocity_mm_s=data["velocity_mm_s"].astype(float),
                  device_force_n=data["device_force_n"].astype(float), buttons=data["buttons"].astype(np.int64),
                  commands=cmds)


#: limits of playback when the recorded device is not an installed actuator: the
#: reference force device's (Phantom Omni: 3.3 N, 2.3 N/mm) and its 0..1 drive
PLAYBACK_DEFAULT_LIMITS = ActuatorLimits(max_force_n=3.3, max_stiffness_n_per_mm=2.3)


def device_class_limits(name: Any) -> ActuatorLimits:
    """Declared limits of the installed actuator class ``name`` (entry-point group
    ``hapticsdk.actuators``), or :data:`PLAYBACK_DEFAULT_LIMITS` when there is none."""
    from .errors import HapticSDKError
    from .plugins import registry

    if isinstance(name, str) and name and name != PlaybackDevice.name:
        try:
            reg = registry("actuator")
            if name in reg.names():
                lim = getattr(reg.load(name), "limits", None)
                if isinstance(lim, ActuatorLimits):
                    return lim
        except (HapticSDKError, ImportError):
            pass
    return PLAYBACK_DEFAULT_LIMITS


def narrowed_limits(base: ActuatorLimits, header: Any) -> ActuatorLimits:
    """``base`` narrowed by the limits of a run-file header.

    Every header value must be a finite number > 0 (``frequency_range_hz`` a pair
    ``0 <= lo < hi``) and inside ``base``: a header granting more than the device
    class declares (say 1e9 N on a 3.3 N device) raises :class:`RecordingError`
    naming the field. ``amplitude_unit`` comes from ``base`` when it has one."""
    from .checks import check_number

    if header is None:
        return base
    if not isinstance(header, dict):
        raise RecordingError("device limits must be an object", field="runlog.header_json.device.limits")
    out = dict(base.__dict__)
    for key, value in header.items():
        field_ = f"runlog.header_json.device.limits.{key}"
        if key not in ActuatorLimits.__dataclass_fields__ or value is None:
            continue
        if key == "amplitude_unit":
            if base.amplitude_unit and value != base.amplitude_unit:
                raise RecordingError(f"unit {value!r} differs from the device's {base.amplitude_unit!r}", field=field_)
            out[key] = base.amplitude_unit or str(value)
            continue
        cap = getattr(base, key)
        if key == "frequency_range_hz":
            if not isinstance(value, (list, tuple)) or len(value) != 2:
                raise RecordingError(f"must be a pair [lo, hi], got {value!r}", field=field_)
            lo = check_number(value[0], field_ + "[0]", minimum=0.0, error=RecordingError)
            hi = check_number(value[1], field_ + "[1]", exclusive_minimum=lo, error=RecordingError)
            if cap is not None and (lo < cap[0] or hi > cap[1]):
                raise RecordingError(f"{lo:g}..{hi:g} Hz is wider than the device's {cap[0]:g}..{cap[1]:g} Hz "
                                     "(a run file may only narrow the declared limits)", field=field_)
            out[key] = (lo, hi)
            continue
        v = check_number(value, field_, exclusive_minimum=0.0, error=RecordingError)
        if cap is not None and v > cap:
            raise RecordingError(f"{v:g} is above the device's declared {cap:g} "
                                 "(a run file may only narrow the declared limits)", field=field_)
        out[key] = v
    return ActuatorLimits(**out)


def _finite_number(value: Any) -> bool:
    """A finite real number (not a bool; an int beyond the float range is not finite)."""
    from .checks import is_number
    try:
        return is_number(value) and math.isfinite(float(value))
    except OverflowError:
        return False


def recorded_settings(header: Any) -> Any:
    """The :class:`~hapticsdk.devices.safety.SafetySettings` recorded in a run-file header, checked
    as data: every value must be a number (never a bool; ``ramp_amplitude`` a bool,
    the start gates may be null) inside the ranges :class:`SafetySettings` accepts, else
    :class:`RecordingError` naming the field. Unknown keys are ignored. They are applied
    as recorded, so a replay reproduces the run sample for sample; the playback device
    is simulated, and its force limits stay those of the device class (:func:`narrowed_limits`)."""
    from .devices.safety import SafetySettings

    base = "runlog.header_json.device.safety_settings"
    if not isinstance(header, dict):
        raise RecordingError("safety_settings must be an object", field=base)
    known = SafetySettings.__dataclass_fields__
    out: dict[str, Any] = {}
    for key, value in header.items():
        if key not in known:
            continue
        if key == "ramp_amplitude":
            if not isinstance(value, bool):
                raise RecordingError(f"must be true or false, got {value!r}", field=f"{base}.{key}")
        elif not (value is None and key.startswith("start_")) and not _finite_number(value):
            raise RecordingError(f"must be a finite number, got {value!r:.60}", field=f"{base}.{key}")
        out[key] = value
    try:
        return SafetySettings(**out)
    except ValidationError as exc:
        raise RecordingError(str(exc), field=f"{base}.{exc.field.split('.')[-1] if exc.field else ''}") from None


class PlaybackDevice(HapticDevice):
    """A simulated device that replays the states of a recorded run, tick by tick.

    Every :meth:`step` advances one recorded tick (whatever ``dt``); every
    :meth:`read_state` returns the state of the current tick, and the first read after
    :meth:`open` returns tick 0 whether or not the loop stepped before reading. At the
    end of the run the last state is held (``at_end="hold"``, :attr:`finished` turns
    True) or reading raises :class:`DeviceError` (``at_end="error"``). A run file is
    data: the limits are those the recorded device's class declares (installed
    actuator ``header.device.name``, else :data:`PLAYBACK_DEFAULT_LIMITS`), narrowed
    by the header's limits, which may never widen them (:func:`narrowed_limits`); the
    header's safety settings are checked and applied as recorded (:func:`recorded_settings`).
    ``limits`` / ``safety`` given in code replace both. Commands received are kept in
    :attr:`received`.

    Args:
        run: a :class:`RunLog` or the path of a run file.
        at_end: ``"hold"`` or ``"error"``.
        limits: override the recorded :class:`ActuatorLimits`.
        label, safety: as for every actuator.
    """

    name: ClassVar[str] = "playback-virtual"
    simulated: ClassVar[bool] = True

    def __init__(self, *, run: RunLog | str | Path, at_end: str = "hold", limits: ActuatorLimits | None = None,
                 label: str | None = None, safety: Any = None, **options: Any) -> None:
        if options:
            raise ValidationError(f"unknown option(s) {sorted(options)} for actuator {self.name!r}",
                                  field="options")
        self.run = run if isinstance(run, RunLog) else load_run(run)
        if at_end not in ("hold", "error"):
            raise ValidationError(f"at_end must be 'hold' or 'error', got {at_end!r}", field="at_end")
        if len(self.run) == 0:
            raise RecordingError("the run has no ticks", field="runlog.t")
        dev = self.run.header.get("device") or {}
        if not isinstance(dev, dict):
            raise RecordingError("header 'device' must be an object", field="runlog.header_json.device")
        if limits is None:
            # a run file is data: the limits come from the recorded device's class, and
            # the header may only narrow them (never widen)
            limits = narrowed_limits(device_class_limits(dev.get("name")), dev.get("limits"))
        self.limits = limits
        if safety is None and dev.get("safety_settings"):
            from .devices.safety import SafetyLayer
            safety = SafetyLayer(self.limits, recorded_settings(dev["safety_settings"]))
        super().__init__(label=label or f"playback:{dev.get('label') or dev.get('name') or 'run'}", safety=safety)
        self.at_end = at_end
        self.index = 0
        self._reads = 0
        self._pending = 0
        self.finished = False
        self.received: list[ChannelCommand] = []

    def _open(self) -> None:
        self._out = 0.0
        self.index = 0
        self._reads = 0
        self._pending = 0
        self.finished = False
        self.received = []

    def _read_state(self) -> DeviceState:
        if self._reads > 0:
            self.index += self._pending
        self._pending = 0
        self._reads += 1
        n = len(self.run)
        if self.index >= n:
            self.finished = True
            if self.at_end == "error":
                raise DeviceError(f"playback ran past the end of the run ({n} ticks)", device=self.label)
            self.index = n - 1
        elif self.index == n - 1:
            self.finished = True
        st = self.run.state(self.index)
        if not (np.isfinite(st.position_mm).all() and np.isfinite(st.velocity_mm_s).all()):
            raise DeviceError(f"tick {self.index} of the run has no recorded device state", device=self.label)
        return st

    def _step(self, dt: float) -> None:
        self._pending += 1

    def _command(self, cmd: ChannelCommand) -> None:
        self.received.append(cmd)
        self._out = 0.0 if cmd.force_n is None else float(cmd.force_n)

    def _stop(self) -> None:
        self._out = 0.0

    def _read_back(self) -> ChannelCommand:
        """A playback applies nothing; its record of the last force received (0 after stop)."""
        return ChannelCommand(self.channel, force_n=getattr(self, "_out", 0.0))

    @classmethod
    def conformance_options(cls) -> dict[str, Any]:
        """A self-contained 200-tick run of a probe pressing 2 mm (for the conformance kit)."""
        from .sim.finger import press_slide
        from .sim.probe import VirtualProbe
        rec = RunRecorder(None, device=VirtualProbe(trajectory=press_slide()))
        dev = VirtualProbe(trajectory=press_slide())
        with dev:
            for k in range(200):
                rec.record(k * 1e-3, dev.read_state(), {})
                dev.step(1e-3)
        return {"run": rec.to_runlog()}

    def received_array(self, field_name: str = "force_n") -> np.ndarray:
        """One field of the commands received so far, ``(n,)`` (NaN where ``None``)."""
        return np.array([np.nan if getattr(c, field_name) is None else getattr(c, field_name)
                         for c in self.received], float)

    def describe(self) -> dict[str, Any]:
        """The actuator's description plus the run's length in ticks, the playback position
        and the recorded device's name.
        """
        d = super().describe()
        d.update({"run_ticks": len(self.run), "index": self.index, "finished": self.finished,
                  "recorded_device": self.run.header.get("device")})
        return d
