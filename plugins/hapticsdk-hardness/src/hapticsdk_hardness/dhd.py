"""``dhd``: Force Dimension arms (omega, delta, sigma, lambda) and the Novint Falcon through
Force Dimension's DHD library, by the vendor's Python binding ``forcedimension-core``
(``pip install -e 'plugins/hapticsdk-hardness[dhd]'`` from a checkout).

The binding loads ``libdrd`` (which carries the DHD API) when it is imported; it looks in
``$FDSDK/lib/release/<platform>-<machine>-<compiler>/`` (``lin-x86_64-gcc`` on Linux),
``$FORCEDIM_SDK`` (same layout), ``~/.local/lib`` and ``/usr/local/lib``, and refuses a
library older than SDK 3.16. It is imported when the device is opened, checked or
discovered (never at import of this module). The ``sdk`` option (privileged: it chooses
native code) sets ``FDSDK`` for that import; once the binding is imported in a process
its library stays.

Each servo tick reads position and linear velocity (``dhdGetPosition``,
``dhdGetLinearVelocity``) and writes the force (``dhdSetForce``) from the servo thread;
DHD devices take 4 kHz and more, so the servo loop's 0.25 ms period is their natural rate.
At open: gravity compensation on (``dhdSetGravityCompensation``), the device's own force
limit read (``dhdGetMaxForce``; negative = none set) and the system name
(``dhdGetSystemName``) picks the declared figures of :data:`MODELS`. Frames: DHD's x
points to the user, y to the right, z up; the SDK's (x, y, z) is DHD's (y, z, x), so the
surface normal is DHD's z.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import io
import os
import sys
from typing import Any, ClassVar

from hapticsdk.install_hints import pip_hint
from hapticsdk.errors import DeviceError, DeviceNotFoundError, ValidationError

from .arm import ArmModel, ForceArm

#: continuous force, closed-loop stiffness and resolution as Force Dimension's data sheets
#: give them; CHAI3D's device table (CDeltaDevices.cpp) is NOT their source: it declares a
#: lower stiffness for rendering (5 N/mm omega.x and delta.3, 4 N/mm and 12 N for sigma.7)
_FD = "Force Dimension data sheet (continuous force, closed-loop stiffness, resolution)"
#: declared figures per DHD system name (see docs/devices.md)
MODELS: dict[str, ArmModel] = {m.name: m for m in (
    ArmModel("omega.3", 12.0, 14.5, 0.01, 4000.0, source=_FD),
    ArmModel("omega.6", 12.0, 14.5, 0.01, 4000.0, source=_FD),
    ArmModel("omega.7", 12.0, 14.5, 0.01, 4000.0, source=_FD),
    ArmModel("delta.3", 20.0, 14.5, 0.03, 4000.0, source=_FD),
    ArmModel("sigma.7", 20.0, 14.5, 0.0015, 4000.0, source=_FD),
    ArmModel("lambda.7", 20.0, 14.5, 0.0015, 4000.0, source=_FD),
    ArmModel("falcon", 8.9, 3.0, 0.06, 1000.0,
             source="Novint Falcon data sheet (2 lbf = 8.9 N, 400 dpi); stiffness: CHAI3D's table "
                    "(3 N/mm; it gives 8 N for the force)"),
)}

INSTALL_HINT = ("install the Force Dimension SDK (3.16 or later; it has libdrd.so and the Falcon driver) and "
                "set FDSDK to its folder (or copy libdrd.so to /usr/local/lib), and `"
                + pip_hint("hapticsdk-hardness", "dhd") + "` for the forcedimension-core binding; the simulated `omni-virtual` "
                "needs none of this")


def import_binding(sdk: str | None = None, *, device: str = "dhd") -> Any:
    """Import ``forcedimension_core.dhd`` (loading libdrd); raise :class:`DeviceNotFoundError`
    naming what is missing. ``sdk``: the Force Dimension SDK folder (sets ``FDSDK``)."""
    if sdk is not None:
        if not (isinstance(sdk, str) and os.path.isabs(sdk) and os.path.isdir(sdk)):
            raise ValidationError(f"sdk must be the absolute path of a folder, got {sdk!r}", field="options.sdk")
        if "forcedimension_core.runtime" not in sys.modules:
            os.environ["FDSDK"] = sdk
    if importlib.util.find_spec("forcedimension_core") is None:
        raise DeviceNotFoundError(f"the Python package forcedimension-core is not installed. {INSTALL_HINT}",
                                  device=device)
    try:
        with contextlib.redirect_stderr(io.StringIO()):   # the binding prints its own failure
            return importlib.import_module("forcedimension_core.dhd")
    except ImportError as exc:
        where = os.environ.get("FDSDK") or os.environ.get("FORCEDIM_SDK")
        raise DeviceNotFoundError(
            f"forcedimension-core could not load libdrd ({exc}); searched "
            f"{'FDSDK=' + where + ', ' if where else ''}~/.local/lib, /usr/local/lib. {INSTALL_HINT}",
            device=device) from None


class DhdDevice(ForceArm):
    """A Force Dimension or Novint arm through DHD (entry point ``dhd``).

    Args:
        device_id: index of the device to open (``dhdOpenID``); default the first one.
        sdk: Force Dimension SDK folder (privileged; default: the binding's search).
        gravity_compensation: let DHD compensate the arm's weight (default on).
        surface_mm, command_timeout_s, model, label, safety: see
            :class:`~hapticsdk_hardness.arm.ForceArm`.
    """

    name: ClassVar[str] = "dhd"
    MODELS: ClassVar[dict[str, ArmModel]] = MODELS
    AXES: ClassVar[tuple[int, int, int]] = (1, 2, 0)
    privileged_options: ClassVar[dict[str, str]] = {"sdk": "native library folder"}

    def __init__(self, *, device_id: int | None = None, sdk: str | None = None, gravity_compensation: bool = True,
                 **options: Any) -> None:
        options.setdefault("label", "dhd" if device_id is None else f"dhd:{device_id}")
        super().__init__(**options)
        if device_id is not None and not (isinstance(device_id, int) and 0 <= device_id < 128):
            raise ValidationError("must be a device index 0..127", field="options.device_id")
        self.device_id = device_id
        self.sdk = sdk
        self.gravity_compensation = bool(gravity_compensation)
        self.dhd: Any = None
        self.id = -1
        self._fbuf = [0.0, 0.0, 0.0]
        self._pbuf = [0.0, 0.0, 0.0]
        self._vbuf = [0.0, 0.0, 0.0]
        self.device_max_force_n: float | None = None

    def _err(self, what: str) -> DeviceError:
        try:
            detail = self.dhd.errorGetLastStr()
        except Exception:
            detail = "?"
        return DeviceError(f"{what} failed: {detail}", device=self.label)

    def _io_open(self) -> str | None:
        self.dhd = import_binding(self.sdk, device=self.label)
        d = self.dhd
        self.id = d.open() if self.device_id is None else d.openID(self.device_id)
        if self.id < 0:
            which = "the first device" if self.device_id is None else f"device {self.device_id}"
            raise DeviceNotFoundError(f"dhdOpen of {which} failed: {d.errorGetLastStr()} "
                                      f"({d.getDeviceCount()} device(s) seen)", device=self.label)
        if d.setGravityCompensation(self.gravity_compensation, self.id) < 0:
            raise self._err("dhdSetGravityCompensation")
        mf = float(d.getMaxForce(self.id))
        self.device_max_force_n = mf if mf > 0 else None
        name = d.getSystemName(self.id)
        return str(name) if name else None

    def _io_max_force_n(self) -> float | None:
        return self.device_max_force_n

    def _io_enable(self) -> None:
        if self.dhd.enableForce(True, self.id) < 0:
            raise self._err("dhdEnableForce")

    def _io_read(self) -> tuple[Any, Any]:
        d, p, v = self.dhd, self._pbuf, self._vbuf
        if d.getPosition(p, self.id) < 0:
            raise self._err("dhdGetPosition")
        if d.getLinearVelocity(v, self.id) < 0:
            raise self._err("dhdGetLinearVelocity")
        return p, v

    def _io_force(self, f: tuple[float, float, float]) -> None:
        b = self._fbuf
        b[0], b[1], b[2] = f
        if self.dhd is not None and self.id >= 0 and self.dhd.setForce(b, self.id) < 0:
            raise self._err("dhdSetForce")

    def _io_release(self) -> None:
        if self.dhd is not None and self.id >= 0:
            self.dhd.enableForce(False, self.id)

    def _io_close(self) -> None:
        if self.dhd is not None and self.id >= 0:
            self.dhd.close(self.id)
        self.id = -1

    @classmethod
    def check_available(cls) -> tuple[bool, str]:
        try:
            d = import_binding()
        except DeviceNotFoundError as exc:
            return False, str(exc)
        return True, f"forcedimension-core with DHD {d.getSDKVersion()}"

    @classmethod
    def discover(cls) -> list[dict[str, Any]]:
        try:
            n = import_binding().getDeviceCount()
        except DeviceNotFoundError:
            return []
        return [{"device_id": i, "note": "open with device_id=N"} for i in range(max(0, int(n)))]

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d.update({"device_id": self.device_id, "dhd_id": self.id, "gravity_compensation": self.gravity_compensation,
                  "device_max_force_n": self.device_max_force_n})
        return d
