"""Record a device run and play it back as a simulated device.

A *run* is what the servo loop saw and did on every tick: the device state (position
mm, velocity mm/s, device force N, buttons) and, per role, the command actually applied
(force N, frequency Hz, amplitude in the actuator's unit). :class:`RunRecorder` is the
servo loop's ``recorder=`` (``record(t, state, sent)`` per tick, ``close()`` at the
end) and writes one ``.npz`` file holding numpy arrays plus a JSON header (key
``header_json``). :func:`load_run` reads it back as a :class:`RunLog`.

:class:`PlaybackDevice` (entry point ``playback-virtual``) is a
:class:`~hapticsdk.actuators.HapticDevice` that returns the recorded states tick by
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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Mapping

import numpy as np

from .actuators import ActuatorLimits, DeviceState, HapticDevice
from .dimensions import ChannelCommand
from .errors import DeviceError, RecordingError, ValidationError

FORMAT = "hapticsdk-run"
VERSION = 1
_CMD_FIELDS = ("force_n", "frequency_hz", "amplitude")


def _as_vec3(v: Any) -> np.ndarray:
    a = np.zeros(3) if v is None else np.asarray(v, float).reshape(-1)
    out = np.full(3, np.nan)
    out[: min(3, a.size)] = a[:3]
    return out


class RunRecorder:
    """Collects one run tick by tick and writes it to ``path`` (``.npz``) on :meth:`close`.

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
        self._t: list[float] = []
        self._state_t: list[float] = []
        self._pos: list[np.ndarray] = []
        self._vel: list[np.ndarray] = []
        self._force: list[np.ndarray] = []
        self._buttons: list[int] = []
        self._cmd: dict[str, dict[str, list[float]]] = {}
        self.closed = False

    def __len__(self) -> int:
        return len(self._t)

    def record(self, t: float, state: DeviceState | None, sent: Mapping[str, ChannelCommand]) -> None:
        """Append one tick: loop time ``t`` (s), the device ``state`` read this tick
        (``None`` without a sensing device) and ``sent`` (role -> command applied)."""
        if self.closed:
            raise RecordingError("record() after close()", field="runlog")
        n = len(self._t)
        self._t.append(float(t))
        if state is None:
            self._state_t.append(np.nan)
            self._pos.append(np.full(3, np.nan))
            self._vel.append(np.full(3, np.nan))
            self._force.append(np.full(3, np.nan))
            self._buttons.append(0)
        else:
            self._state_t.append(float(state.t))
            self._pos.append(_as_vec3(state.position_mm))
            self._vel.append(_as_vec3(state.velocity_mm_s))
            self._force.append(_as_vec3(getattr(state, "force_n", None)))
            self._buttons.append(int(getattr(state, "buttons", 0)))
        for role, cmd in sent.items():
            cols = self._cmd.get(role)
            if cols is None:  # a role first seen now: pad its earlier ticks with NaN
                cols = self._cmd[role] = {f: [np.nan] * n for f in _CMD_FIELDS}
            for f in _CMD_FIELDS:
                v = getattr(cmd, f)
                cols[f].append(np.nan if v is None else float(v))
        for role, cols in self._cmd.items():
            if role not in sent:
                for f in _CMD_FIELDS:
                    cols[f].append(np.nan)

    def to_runlog(self) -> "RunLog":
        """The run recorded so far, as a :class:`RunLog`."""
        n = len(self._t)
        t = np.asarray(self._t, float)
        period = float(np.median(np.diff(t))) if n > 1 else None
        header = {"format": FORMAT, "version": VERSION,
                  "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                  "n_ticks": n, "period_s": period, "roles": sorted(self._cmd),
                  "device": self.device_info, "meta": self.meta}
        cmds = {role: {f: np.asarray(v, float) for f, v in cols.items()} for role, cols in self._cmd.items()}
        return RunLog(header=header, t=t, state_t=np.asarray(self._state_t, float),
                      position_mm=np.asarray(self._pos, float).reshape(n, 3),
                      velocity_mm_s=np.asarray(self._vel, float).reshape(n, 3),
                      device_force_n=np.asarray(self._force, float).reshape(n, 3),
                      buttons=np.asarray(self._buttons, np.int64), commands=cmds)

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
        return sorted(self.commands)

    @property
    def period_s(self) -> float | None:
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
        return ChannelCommand(role, **vals)

    def save(self, path: str | Path) -> Path:
        """Write the run as ``.npz`` (arrays + ``header_json``)."""
        p = Path(path)
        arrays: dict[str, np.ndarray] = {
            "t": self.t, "state_t": self.state_t, "position_mm": self.position_mm,
            "velocity_mm_s": self.velocity_mm_s, "device_force_n": self.device_force_n,
            "buttons": self.buttons,
            "header_json": np.array(json.dumps(self.header, default=_json_default))}
        for role, cols in self.commands.items():
            if "/" in role:
                raise ValidationError(f"role name {role!r} must not contain '/'", field="runlog.roles")
            for f, v in cols.items():
                arrays[f"cmd/{role}/{f}"] = v
        p.parent.mkdir(parents=True, exist_ok=True)
        with open(p, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        return p

    def summary(self) -> dict[str, Any]:
        """Ticks, duration, rate, per-role command ranges and the header, JSON-ready."""
        n = len(self)
        out: dict[str, Any] = {"n_ticks": n, "duration_s": float(self.t[-1] - self.t[0]) if n > 1 else 0.0,
                               "period_s": self.period_s, "roles": {}, "header": self.header}
        if n and np.isfinite(self.position_mm).any():
            out["penetration_mm_max"] = float(np.nanmax(-self.position_mm[:, 1]))
            out["speed_mm_s_max"] = float(np.nanmax(np.linalg.norm(self.velocity_mm_s, axis=1)))
        for role, cols in self.commands.items():
            r: dict[str, Any] = {}
            for f, v in cols.items():
                ok = np.isfinite(v)
                if ok.any():
                    r[f] = {"min": float(v[ok].min()), "max": float(v[ok].max()), "ticks": int(ok.sum())}
            out["roles"][role] = r
        return out


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    if isinstance(o, tuple):
        return list(o)
    return str(o)


def load_run(path: str | Path) -> RunLog:
    """Read a run file written by :class:`RunRecorder` / :meth:`RunLog.save`.
    Raises :class:`RecordingError` naming the file and the missing/broken field."""
    p = Path(path)
    if not p.is_file():
        raise RecordingError(f"run file not found: {p}", field="runlog")
    try:
        with np.load(p, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except Exception as exc:
        raise RecordingError(f"{p}: not a readable .npz run file ({exc})", field="runlog") from None
    if "header_json" not in data:
        raise RecordingError(f"{p}: no header_json (not a hapticsdk run file)", field="runlog.header_json")
    header = json.loads(str(data["header_json"]))
    if header.get("format") != FORMAT or header.get("version") != VERSION:
        raise RecordingError(f"{p}: format {header.get('format')!r} v{header.get('version')!r}, "
                             f"expected {FORMAT!r} v{VERSION}", field="runlog.header_json")
    for key in ("t", "state_t", "position_mm", "velocity_mm_s", "device_force_n", "buttons"):
        if key not in data:
            raise RecordingError(f"{p}: array {key!r} missing", field=f"runlog.{key}")
    n = data["t"].shape[0]
    for key in ("state_t", "buttons"):
        if data[key].shape != (n,):
            raise RecordingError(f"{p}: {key} has shape {data[key].shape}, expected ({n},)", field=f"runlog.{key}")
    for key in ("position_mm", "velocity_mm_s", "device_force_n"):
        if data[key].shape != (n, 3):
            raise RecordingError(f"{p}: {key} has shape {data[key].shape}, expected ({n}, 3)", field=f"runlog.{key}")
    cmds: dict[str, dict[str, np.ndarray]] = {}
    for key, v in data.items():
        if key.startswith("cmd/"):
            _, role, f = key.split("/", 2)
            if v.shape != (n,):
                raise RecordingError(f"{p}: {key} has shape {v.shape}, expected ({n},)", field=f"runlog.{key}")
            cmds.setdefault(role, {})[f] = v.astype(float)
    return RunLog(header=header, t=data["t"].astype(float), state_t=data["state_t"].astype(float),
                  position_mm=data["position_mm"].astype(float), velocity_mm_s=data["velocity_mm_s"].astype(float),
                  device_force_n=data["device_force_n"].astype(float), buttons=data["buttons"].astype(np.int64),
                  commands=cmds)


class PlaybackDevice(HapticDevice):
    """A simulated device that replays the states of a recorded run, tick by tick.

    Every :meth:`step` advances one recorded tick (whatever ``dt``); every
    :meth:`read_state` returns the state of the current tick, and the first read after
    :meth:`open` returns tick 0 whether or not the loop stepped before reading. At the
    end of the run the last state is held (``at_end="hold"``, :attr:`finished` turns
    True) or reading raises :class:`DeviceError` (``at_end="error"``). The limits and
    safety settings recorded in the header are applied again, unless ``limits`` or
    ``safety`` are given. Commands received are kept in :attr:`received`.

    Args:
        run: a :class:`RunLog` or the path of a run file.
        at_end: ``"hold"`` or ``"error"``.
        limits: override the recorded :class:`ActuatorLimits`.
        label, safety: as for every actuator.
    """

    name: ClassVar[str] = "playback-virtual"
    simulated: ClassVar[bool] = True

    def __init__(self, *, run: RunLog | str | Path, at_end: str = "hold", limits: ActuatorLimits | None = None,
                 label: str | None = None, safety: Any = None) -> None:
        self.run = run if isinstance(run, RunLog) else load_run(run)
        if at_end not in ("hold", "error"):
            raise ValidationError(f"at_end must be 'hold' or 'error', got {at_end!r}", field="at_end")
        if len(self.run) == 0:
            raise RecordingError("the run has no ticks", field="runlog.t")
        dev = self.run.header.get("device") or {}
        if limits is None and dev.get("limits"):
            lim = dict(dev["limits"])
            if lim.get("frequency_range_hz") is not None:
                lim["frequency_range_hz"] = tuple(lim["frequency_range_hz"])
            limits = ActuatorLimits(**{k: v for k, v in lim.items() if k in ActuatorLimits.__dataclass_fields__})
        if limits is not None:
            self.limits = limits
        if safety is None and dev.get("safety_settings"):
            from .safety import SafetyLayer, SafetySettings
            known = SafetySettings.__dataclass_fields__
            safety = SafetyLayer(self.limits, SafetySettings(**{k: v for k, v in dev["safety_settings"].items()
                                                                 if k in known}))
        super().__init__(label=label or f"playback:{dev.get('label') or dev.get('name') or 'run'}", safety=safety)
        self.at_end = at_end
        self.index = 0
        self._reads = 0
        self._pending = 0
        self.finished = False
        self.received: list[ChannelCommand] = []

    def _open(self) -> None:
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

    def _stop(self) -> None:
        pass

    def received_array(self, field_name: str = "force_n") -> np.ndarray:
        """One field of the commands received so far, ``(n,)`` (NaN where ``None``)."""
        return np.array([np.nan if getattr(c, field_name) is None else getattr(c, field_name)
                         for c in self.received], float)

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d.update({"run_ticks": len(self.run), "index": self.index, "finished": self.finished,
                  "recorded_device": self.run.header.get("device")})
        return d
