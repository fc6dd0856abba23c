"""``omni-openhaptics``: a PHANTOM Omni / Touch through OpenHaptics' HD API (``libHD``), by ctypes.

The HD library is loaded when the device is opened (never at import). The servo runs in
the OpenHaptics scheduler thread at ``rate_hz`` (1 kHz default): each tick reads position
and velocity and writes the last commanded force inside ``hdBeginFrame``/``hdEndFrame``;
the Python side (:meth:`read_state`, :meth:`command`) only exchanges values with it. Device
limits (nominal max force, continuous force, max stiffness) are read from the device at
open and replace the declared ones (the safety layer then clamps to them).

On an HD error in the servo tick the callback writes zero force, unschedules itself, and
the next :meth:`command` or :meth:`read_state` raises a :class:`DeviceError` naming the
device and the HD error; the core then stops it (zero force, force output disabled).

Constants are the OpenHaptics 3.30 ``hdDefines.h`` values (kept in this one module).
Library lookup order: ``library=`` option, ``$HAPTICSDK_LIBHD``, ``ctypes.util.find_library("HD")``,
then the platform names below; a failure names every file tried and how to install.

Only trusted code is loaded: ``library`` is a privileged option (never from a scene or plan
file, see :mod:`hapticsdk.devices.device_options`); a bare name is looked up by the system loader
and must be an HD library name (``libHD.so[.N]``, ``libHD.dylib``, ``HD.dll``); an
explicit path must be absolute and a regular file (a relative path would resolve against
the current directory, e.g. a downloaded scene's folder).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import re
import stat
import sys
import threading
import time
from typing import Any, ClassVar

import numpy as np

from hapticsdk.devices.actuators import ActuatorLimits, DeviceState, HapticDevice
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import DeviceError, DeviceNotFoundError, ValidationError

# -- hdDefines.h (OpenHaptics 3.30) -------------------------------------------------------
HD_SUCCESS = 0x0000
HD_INVALID_HANDLE = 0xFFFFFFFF
HD_CURRENT_BUTTONS = 0x2000
HD_CURRENT_POSITION = 0x2050
HD_CURRENT_VELOCITY = 0x2051
HD_DEVICE_MODEL_TYPE = 0x2501
HD_DEVICE_SERIAL_NUMBER = 0x2504
HD_USABLE_WORKSPACE_DIMENSIONS = 0x2551
HD_UPDATE_RATE = 0x2600
HD_NOMINAL_MAX_STIFFNESS = 0x2602
HD_NOMINAL_MAX_FORCE = 0x2603
HD_NOMINAL_MAX_CONTINUOUS_FORCE = 0x2604
HD_SOFTWARE_VELOCITY_LIMIT = 0x2606
HD_CURRENT_FORCE = 0x2700
HD_FORCE_OUTPUT = 0x4000
HD_CALLBACK_DONE = 0
HD_CALLBACK_CONTINUE = 1
HD_MAX_SCHEDULER_PRIORITY = 65535
HD_DEFAULT_SCHEDULER_PRIORITY = 32767
HD_WAIT_CHECK_STATUS = 0

HD_ERROR_NAMES = {
    0x0100: "HD_INVALID_ENUM", 0x0101: "HD_INVALID_VALUE", 0x0102: "HD_INVALID_OPERATION",
    0x0103: "HD_INVALID_INPUT_TYPE", 0x0104: "HD_BAD_HANDLE", 0x0200: "HD_WARM_MOTORS",
    0x0201: "HD_EXCEEDED_MAX_FORCE", 0x0202: "HD_EXCEEDED_MAX_FORCE_IMPULSE",
    0x0203: "HD_EXCEEDED_MAX_VELOCITY", 0x0204: "HD_FORCE_ERROR", 0x0300: "HD_DEVICE_FAULT",
    0x0301: "HD_DEVICE_ALREADY_INITIATED", 0x0302: "HD_COMM_ERROR", 0x0303: "HD_COMM_CONFIG_ERROR",
    0x0304: "HD_TIMER_ERROR", 0x0400: "HD_ILLEGAL_BEGIN", 0x0401: "HD_ILLEGAL_END",
    0x0402: "HD_FRAME_ERROR", 0x0500: "HD_INVALID_PRIORITY", 0x0501: "HD_SCHEDULER_FULL",
    0x0600: "HD_INVALID_LICENSE"}

HHD = ctypes.c_uint
HDenum = ctypes.c_uint
HDerror = ctypes.c_uint
HDulong = ctypes.c_ulong
HDushort = ctypes.c_ushort
HDboolean = ctypes.c_ubyte
HDSchedulerHandle = ctypes.c_ulong
HDCallbackCode = ctypes.c_uint
#: ``HDCallbackCode (*)(void *pUserData)``
HDSchedulerCallback = ctypes.CFUNCTYPE(HDCallbackCode, ctypes.c_void_p)


class HDErrorInfo(ctypes.Structure):
    """``struct { HDerror errorCode; int internalErrorCode; HHD hHD; }`` (returned by value)."""

    _fields_ = [("errorCode", HDerror), ("internalErrorCode", ctypes.c_int), ("hHD", HHD)]


#: name -> (restype, argtypes)
PROTOTYPES: dict[str, tuple[Any, list[Any]]] = {
    "hdInitDevice": (HHD, [ctypes.c_char_p]),
    "hdDisableDevice": (None, [HHD]),
    "hdMakeCurrentDevice": (None, [HHD]),
    "hdGetCurrentDevice": (HHD, []),
    "hdBeginFrame": (None, [HHD]),
    "hdEndFrame": (None, [HHD]),
    "hdGetError": (HDErrorInfo, []),
    "hdGetErrorString": (ctypes.c_char_p, [HDerror]),
    "hdEnable": (None, [HDenum]),
    "hdDisable": (None, [HDenum]),
    "hdIsEnabled": (HDboolean, [HDenum]),
    "hdGetDoublev": (None, [HDenum, ctypes.POINTER(ctypes.c_double)]),
    "hdGetIntegerv": (None, [HDenum, ctypes.POINTER(ctypes.c_int)]),
    "hdGetString": (ctypes.c_char_p, [HDenum]),
    "hdSetDoublev": (None, [HDenum, ctypes.POINTER(ctypes.c_double)]),
    "hdStartScheduler": (None, []),
    "hdStopScheduler": (None, []),
    "hdSetSchedulerRate": (None, [HDulong]),
    "hdScheduleSynchronous": (None, [HDSchedulerCallback, ctypes.c_void_p, HDushort]),
    "hdScheduleAsynchronous": (HDSchedulerHandle, [HDSchedulerCallback, ctypes.c_void_p, HDushort]),
    "hdUnschedule": (None, [HDSchedulerHandle]),
    "hdWaitForCompletion": (HDboolean, [HDSchedulerHandle, ctypes.c_uint]),
    "hdGetSchedulerTimeStamp": (ctypes.c_double, []),
}

INSTALL_HINT = ("install the OpenHaptics runtime / Touch device drivers from 3D Systems "
                "(Linux: the openhaptics .deb/.tgz puts libHD.so in /usr/lib; Windows: HD.dll from "
                "OpenHaptics, with OH_SDK_BASE set), or point HAPTICSDK_LIBHD (or library=) at the file; "
                "the simulated `omni-virtual` needs none of this")


def library_candidates(explicit: str | None = None) -> list[str]:
    """File names / paths tried, in order."""
    names: list[str] = []
    for c in (explicit, os.environ.get("HAPTICSDK_LIBHD"), ctypes.util.find_library("HD")):
        if c and c not in names:
            names.append(c)
    if explicit:
        return names
    if sys.platform == "win32":
        base = os.environ.get("OH_SDK_BASE")
        extra = ["HD.dll"] + ([os.path.join(base, "lib", "x64", "Release", "HD.dll")] if base else [])
    elif sys.platform == "darwin":
        extra = ["libHD.dylib", "/usr/local/lib/libHD.dylib"]
    else:
        extra = ["libHD.so", "libHD.so.3", "/usr/lib/libHD.so", "/usr/lib64/libHD.so", "/usr/local/lib/libHD.so",
                 "/opt/OpenHaptics/Developer/lib/libHD.so"]
    return names + [e for e in extra if e not in names]


_HD_NAME = re.compile(r"^(lib)?HD(\.so(\.[0-9]+)*|\.dylib|\.dll)?$")


def check_candidate(cand: str) -> str | None:
    """Why ``cand`` may not be loaded (``None``: it may). See the module docstring."""
    if os.path.sep not in cand and (os.path.altsep or "/") not in cand:
        return None if _HD_NAME.match(cand) else "not an HD library name (libHD.so, libHD.dylib, HD.dll)"
    if not os.path.isabs(cand):
        return "a relative path; give an absolute path"
    try:
        st = os.stat(cand)
    except OSError as exc:
        return exc.strerror or str(exc)
    if not stat.S_ISREG(st.st_mode):
        return "not a regular file"
    return None


def bind(lib: Any) -> Any:
    """Set ``restype``/``argtypes`` of every HD function used (once per library)."""
    for fname, (res, args) in PROTOTYPES.items():
        fn = getattr(lib, fname)
        fn.restype = res
        fn.argtypes = args
    return lib


def load_library(explicit: str | None = None, *, device: str = "omni-openhaptics") -> tuple[Any, str]:
    """Load and bind libHD; returns ``(lib, path)`` or raises :class:`DeviceNotFoundError`
    naming every file tried and what to install."""
    tried: list[str] = []
    for cand in library_candidates(explicit):
        why = check_candidate(cand)
        if why is not None:
            tried.append(f"{cand} (refused: {why})")
            continue
        try:
            lib = ctypes.CDLL(cand)
        except OSError as exc:
            tried.append(f"{cand} ({exc})" if os.path.sep in cand else cand)
            continue
        try:
            return bind(lib), cand
        except AttributeError as exc:
            tried.append(f"{cand} (not the HD API: {exc})")
    raise DeviceNotFoundError(f"OpenHaptics HD library not found; tried: {'; '.join(tried)}. {INSTALL_HINT}",
                              device=device)


class OmniOpenHaptics(HapticDevice):
    """A real Omni / Touch via OpenHaptics (entry point ``omni-openhaptics``).

    Args:
        config: OpenHaptics device configuration name (``None`` = ``HD_DEFAULT_DEVICE``;
            names like ``"Default Device"`` or ``"Left"`` select one of several devices).
        library: path of libHD / HD.dll (default: search, see module docstring).
        rate_hz: scheduler rate (Hz, 1000).
        surface_y_mm: Omni y coordinate of the material surface (mm); state positions are
            reported relative to it (y < 0 inside the material).
        command_timeout_s: device-side watchdog (s): the servo writes zero force when the last
            command is older than this (the Python loop stalled or died). Default (None):
            the safety layer's ``restart_after_s`` (50 ms by default; at most 1 s), so force
            the watchdog cut returns through the layer's ramp when the servo resumes
            (:func:`hapticsdk.devices.safety.default_command_timeout_s`).
        label, safety: as for every actuator.
    """

    name: ClassVar[str] = "omni-openhaptics"
    channel: ClassVar[str] = "force"
    accepts: ClassVar[dict[str, str]] = {"force_n": "N"}
    simulated: ClassVar[bool] = False
    limits = ActuatorLimits(max_force_n=3.3, max_stiffness_n_per_mm=2.3)
    #: ``library`` is loaded into the process: never from a scene/plan file
    privileged_options: ClassVar[dict[str, str]] = {"library": "native library"}

    def __init__(self, *, config: str | None = None, library: str | None = None, rate_hz: int = 1000,
                 surface_y_mm: float = 0.0, command_timeout_s: float | None = None, **options: Any) -> None:
        if not 100 <= int(rate_hz) <= 4000:
            raise ValidationError(f"rate_hz {rate_hz} outside 100..4000", field="options.rate_hz")
        options.setdefault("label", f"omni-openhaptics:{config}" if config else "omni-openhaptics")
        super().__init__(**options)
        self.config = config
        self.library = library
        self.rate_hz = int(rate_hz)
        self.surface_y_mm = float(surface_y_mm)
        from hapticsdk.devices.safety import command_timeout_s as _deadline  # default: the restart gap (see Args)
        command_timeout_s = _deadline(self.safety, command_timeout_s, at_most=None)
        self.command_timeout_s = command_timeout_s
        self._force_t = 0.0
        self.watchdog_zeroed = 0
        self.lib: Any = None
        self.lib_path: str | None = None
        self.handle: int | None = None
        self._sched: int | None = None
        self._cb = HDSchedulerCallback(self._servo)          # kept alive while scheduled
        #: servo-tick buffers, allocated once (the values are copied out / in every tick)
        self._get_buf = (ctypes.c_double * 3)()
        self._force_buf = (ctypes.c_double * 3)()
        self._lock = threading.Lock()
        self._force = (0.0, 0.0, 0.0)
        self._pos = (0.0, 0.0, 0.0)
        self._vel = (0.0, 0.0, 0.0)
        self._t = 0.0
        self._hd_error: tuple[int, int] | None = None
        self._callback_error: BaseException | None = None
        self.ticks = 0
        self.device_info: dict[str, Any] = {}

    # -- HD helpers -------------------------------------------------------------------
    def _error(self) -> tuple[int, int] | None:
        e = self.lib.hdGetError()
        return (int(e.errorCode), int(e.internalErrorCode)) if e.errorCode != HD_SUCCESS else None

    def _error_text(self, err: tuple[int, int]) -> str:
        code, internal = err
        try:
            s = self.lib.hdGetErrorString(code)
            text = s.decode(errors="replace") if s else ""
        except Exception:
            text = ""
        return f"{HD_ERROR_NAMES.get(code, 'HD error')} 0x{code:04x} (internal {internal}){': ' + text if text else ''}"

    def _get3(self, what: int) -> tuple[float, float, float]:
        buf = self._get_buf
        self.lib.hdGetDoublev(what, buf)
        return (buf[0], buf[1], buf[2])

    # -- scheduler callbacks (OpenHaptics thread: never raise) --------------------------------
    def _servo(self, _user: Any) -> int:
        try:
            lib, h = self.lib, self.handle
            lib.hdBeginFrame(h)
            pos = self._get3(HD_CURRENT_POSITION)
            vel = self._get3(HD_CURRENT_VELOCITY)
            f = self._force
            if self._hd_error is not None:
                f = (0.0, 0.0, 0.0)
            elif f[1] != 0.0 and time.monotonic() - self._force_t > self.command_timeout_s:
                f = (0.0, 0.0, 0.0)                # stale command: device-side watchdog
                self.watchdog_zeroed += 1
            fb = self._force_buf
            fb[0], fb[1], fb[2] = f
            lib.hdSetDoublev(HD_CURRENT_FORCE, fb)
            lib.hdEndFrame(h)
            err = self._error()
            with self._lock:
                self._pos, self._vel = pos, vel
                self._t = lib.hdGetSchedulerTimeStamp()
                self.ticks += 1
            if err is not None:
                self._hd_error = err
                self._zero_now()
                return HD_CALLBACK_DONE
            return HD_CALLBACK_CONTINUE
        except BaseException as exc:  # an exception must not cross the C boundary
            self._callback_error = exc
            self._hd_error = self._hd_error or (-1, 0)
            return HD_CALLBACK_DONE

    def _zero_now(self) -> None:
        """Write zero force in the current frame (scheduler thread)."""
        try:
            self.lib.hdBeginFrame(self.handle)
            self.lib.hdSetDoublev(HD_CURRENT_FORCE, (ctypes.c_double * 3)())
            self.lib.hdEndFrame(self.handle)
            self.lib.hdGetError()
        except Exception:
            pass

    def _read_limits(self, _user: Any) -> int:
        try:
            lib, h = self.lib, self.handle
            lib.hdBeginFrame(h)
            vals: dict[str, Any] = {}
            for key, enum in (("max_force_n", HD_NOMINAL_MAX_FORCE),
                              ("max_continuous_force_n", HD_NOMINAL_MAX_CONTINUOUS_FORCE),
                              ("max_stiffness_n_per_mm", HD_NOMINAL_MAX_STIFFNESS)):
                v = ctypes.c_double(float("nan"))
                lib.hdGetDoublev(enum, ctypes.byref(v))
                vals[key] = v.value
            ws = (ctypes.c_double * 6)()
            lib.hdGetDoublev(HD_USABLE_WORKSPACE_DIMENSIONS, ws)
            vals["usable_workspace_mm"] = list(ws)
            lib.hdEndFrame(h)
            self.device_info.update(vals)
            err = self._error()
            if err:
                self.device_info["error"] = err
        except BaseException as exc:
            self.device_info["error"] = repr(exc)
        return HD_CALLBACK_DONE

    # -- backend API ---------------------------------------------------------------------------
    def _open(self) -> None:
        self.lib, self.lib_path = load_library(self.library, device=self.label)
        lib = self.lib
        cfg = self.config.encode() if self.config else None
        h = int(lib.hdInitDevice(cfg))
        err = self._error()
        if h == HD_INVALID_HANDLE or err is not None:
            what = self._error_text(err) if err else "invalid handle"
            raise DeviceNotFoundError(
                f"hdInitDevice({self.config or 'HD_DEFAULT_DEVICE'!r}) failed: {what}; library {self.lib_path}. "
                "Check that the device is connected and powered, that its configuration exists (Phantom "
                "Configuration / Touch Setup) and that no other program holds it; choose another with config=",
                device=self.label)
        self.handle = h
        self._hd_error = None
        try:
            lib.hdMakeCurrentDevice(h)
            lib.hdEnable(HD_FORCE_OUTPUT)
            lib.hdSetSchedulerRate(self.rate_hz)
            lib.hdStartScheduler()
            err = self._error()
            if err:
                raise DeviceError(f"starting the scheduler failed: {self._error_text(err)}", device=self.label)
            lib.hdScheduleSynchronous(HDSchedulerCallback(self._read_limits), None, HD_DEFAULT_SCHEDULER_PRIORITY)
            info = self.device_info
            if "error" in info:
                raise DeviceError(f"reading device limits failed: {info['error']}", device=self.label)
            mf, ms = info.get("max_force_n"), info.get("max_stiffness_n_per_mm")
            if not (mf and np.isfinite(mf) and mf > 0 and ms and np.isfinite(ms) and ms > 0):
                raise DeviceError(f"device reported invalid limits {info}", device=self.label)
            self.limits = ActuatorLimits(max_force_n=float(mf), max_stiffness_n_per_mm=float(ms))
            if hasattr(self.safety, "limits"):
                self.safety.limits = self.limits
            self._sched = int(lib.hdScheduleAsynchronous(self._cb, None, HD_MAX_SCHEDULER_PRIORITY))
        except BaseException:
            self._shutdown()
            raise

    def _check(self) -> None:
        if self._hd_error is not None:
            err = self._hd_error
            detail = (repr(self._callback_error) if self._callback_error is not None and err[0] == -1
                      else self._error_text(err))
            raise DeviceError(f"OpenHaptics servo stopped: {detail}", device=self.label)

    def _command(self, cmd: ChannelCommand) -> None:
        self._check()
        if cmd.force_n is not None:
            # the whole vector along the command's direction (the contact normal of a
            # spatial scene; +y, the version-1 plane's normal, when it has none): the device
            # renders three axes, and the servo frame's axes are the SDK's
            f = float(cmd.force_n)
            d = cmd.direction
            self._force_t = time.monotonic()
            self._force = (0.0, f, 0.0) if d is None else (f * float(d[0]), f * float(d[1]), f * float(d[2]))

    def _read_back(self) -> ChannelCommand:
        """The force the servo callback hands to ``hdSetDoublev(HD_CURRENT_FORCE)``, its y
        component (N): along the version-1 plane's normal, as the force arms report it."""
        return ChannelCommand("force", force_n=float(self._force[1]))

    def _stop(self) -> None:
        self._force = (0.0, 0.0, 0.0)
        if self.lib is not None and self.handle is not None and self._hd_error is not None:
            self.lib.hdDisable(HD_FORCE_OUTPUT)     # the servo is gone: cut force output directly

    def _read_state(self) -> DeviceState:
        if self._hd_error is not None:
            self.stop()
            self._check()
        with self._lock:
            pos, vel, t, f = self._pos, self._vel, self._t, self._force
        p = np.array(pos, float)
        p[1] -= self.surface_y_mm
        return DeviceState(t=float(t), position_mm=p, velocity_mm_s=np.array(vel, float), force_n=np.array(f, float))

    def _shutdown(self) -> None:
        lib = self.lib
        if lib is None:
            return
        self._force = (0.0, 0.0, 0.0)
        try:
            lib.hdStopScheduler()
            if self._sched is not None:
                lib.hdUnschedule(self._sched)
            if self.handle is not None:
                lib.hdDisable(HD_FORCE_OUTPUT)
                lib.hdDisableDevice(self.handle)
        finally:
            self._sched = None
            self.handle = None

    def _close(self) -> None:
        self._shutdown()

    # -- discovery ------------------------------------------------------------------------------
    @classmethod
    def check_available(cls) -> tuple[bool, str]:
        try:
            _, path = load_library()
        except DeviceNotFoundError as exc:
            return False, str(exc)
        return True, f"OpenHaptics HD library {path}"

    @classmethod
    def discover(cls) -> list[dict[str, Any]]:
        """OpenHaptics cannot list devices without opening them: report the library only."""
        ok, why = cls.check_available()
        return [{"library": why, "note": "devices are configured in Touch Setup / Phantom Configuration; "
                                         "open with config=NAME"}] if ok else []

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d.update({"library": self.lib_path, "config": self.config, "rate_hz": self.rate_hz,
                  "device_info": dict(self.device_info), "ticks": self.ticks})
        return d
