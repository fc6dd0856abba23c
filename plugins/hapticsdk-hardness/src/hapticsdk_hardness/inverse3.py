"""``inverse3``: the Haply Inverse3 (3-DoF arm) through Haply's compiled Python module
``HaplyHardwareAPI`` (``pip install -e 'plugins/hapticsdk-hardness[haply]'`` from a checkout; the package is
``haplyhardwareapi``, a binary wheel that talks to the device over its USB serial port).

Calls used (``haplyhardwareapi`` 0.1.13): ``detect_inverse3s()`` (serial ports of the
devices found), ``SerialStream(port)``, ``Inverse3(stream, timeout)``,
``device_wakeup_dict()`` (the device's answer: ``device_id``, model, versions) and
``end_effector_force([fx, fy, fz])``, which sends a force (N) and returns the
end-effector position (m) and velocity (m/s): on this device every state read is a force
write, so a read sends the force last commanded. Frames: the Inverse3's z axis is
vertical; the SDK's (x, y, z) is the device's (x, z, y), so the surface normal is its z.

The serial protocol is not published as a specification, so the wire is NOT tested
here: the tests run this backend against a fake of the vendor module (see
docs/devices.md).
"""

from __future__ import annotations

import importlib
import importlib.util
from typing import Any, ClassVar

from hapticsdk.errors import DeviceNotFoundError, ValidationError
from hapticsdk.install_hints import pip_hint

from .arm import ArmModel, ForceArm

MODULE = "HaplyHardwareAPI"
MODELS: dict[str, ArmModel] = {
    "inverse3": ArmModel("inverse3", 3.3, 2.0, 0.01, 4000.0,
                         source="Haply Inverse3 product page (3.3 N continuous); stiffness and resolution: "
                                "conservative figures, not published by Haply (check docs/devices.md)"),
}
INSTALL_HINT = (pip_hint("hapticsdk-hardness", "haply") + " (haplyhardwareapi, a binary wheel), plug the Inverse3 in "
                "(USB serial; Linux: add yourself to the dialout group)")


def import_api(device: str = "inverse3") -> Any:
    """The vendor module, or :class:`DeviceNotFoundError` naming what to install."""
    if importlib.util.find_spec(MODULE) is None:
        raise DeviceNotFoundError(f"the Python module {MODULE} is not installed: {INSTALL_HINT}", device=device)
    try:
        return importlib.import_module(MODULE)
    except Exception as exc:
        raise DeviceNotFoundError(f"{MODULE} failed to import ({type(exc).__name__}: {exc}); {INSTALL_HINT}",
                                  device=device) from None


class Inverse3(ForceArm):
    """Haply Inverse3 (entry point ``inverse3``).

    Args:
        port: serial port of the device (privileged; default the first
            ``detect_inverse3s()`` finds).
        timeout_s: serial timeout of the vendor module (s).
        surface_mm, command_timeout_s, model, label, safety: see
            :class:`~hapticsdk_hardness.arm.ForceArm`.
    """

    name: ClassVar[str] = "inverse3"
    MODELS: ClassVar[dict[str, ArmModel]] = MODELS
    AXES: ClassVar[tuple[int, int, int]] = (0, 2, 1)
    privileged_options: ClassVar[dict[str, str]] = {"port": "serial port"}

    def __init__(self, *, port: str | None = None, timeout_s: float = 1.0, **options: Any) -> None:
        options.setdefault("label", f"inverse3:{port}" if port else "inverse3")
        super().__init__(**options)
        if port is not None and not (isinstance(port, str) and port):
            raise ValidationError("must be a serial port name", field="options.port")
        if not (isinstance(timeout_s, (int, float)) and 0 < timeout_s <= 10):
            raise ValidationError("must be in (0, 10] s", field="options.timeout_s")
        self.port = port
        self.timeout_s = float(timeout_s)
        self.api: Any = None
        self.dev: Any = None
        self.stream: Any = None
        self.device_info: dict[str, Any] = {}
        self.port_used: str | None = None
        self._last = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))

    def _io_open(self) -> str | None:
        api = self.api = import_api(self.label)
        port = self.port
        if port is None:
            found = list(api.detect_inverse3s())
            if not found:
                raise DeviceNotFoundError(f"no Inverse3 found ({MODULE}.detect_inverse3s() is empty); plug it in "
                                          "and check the serial port permissions", device=self.label)
            port = found[0]
        self.port_used = port
        try:
            self.stream = api.SerialStream(port)
            self.dev = api.Inverse3(self.stream, self.timeout_s)
            info = self.dev.device_wakeup_dict()
        except Exception as exc:
            raise DeviceNotFoundError(f"Inverse3 on {port} did not answer: {type(exc).__name__}: {exc}",
                                      device=self.label) from None
        self.device_info = dict(info or {})
        return "inverse3"

    def _exchange(self, f: Any) -> None:
        pos, vel = self.dev.end_effector_force(list(f))
        p, v = tuple(float(x) for x in pos), tuple(float(x) for x in vel)
        if len(p) != 3 or len(v) != 3:
            raise ValueError(f"end_effector_force returned {pos!r}, {vel!r}")
        self._last = (p, v)

    def _io_read(self) -> tuple[Any, Any]:
        self._exchange(self._force_dev)
        return self._last

    def _io_force(self, f: tuple[float, float, float]) -> None:
        if self.dev is not None:
            self._exchange(f)

    def _io_release(self) -> None:
        """The Inverse3 has no force-enable switch: zero force is its safe state."""

    def _io_close(self) -> None:
        self.dev = None
        self.stream = None

    @classmethod
    def check_available(cls) -> tuple[bool, str]:
        try:
            api = import_api()
        except DeviceNotFoundError as exc:
            return False, str(exc)
        return True, f"{MODULE} ({getattr(api, '__doc__', '') or 'imported'})".strip()

    @classmethod
    def discover(cls) -> list[dict[str, Any]]:
        try:
            api = import_api()
        except DeviceNotFoundError:
            return []
        return [{"port": p, "note": "open with port=PORT"} for p in api.detect_inverse3s()]

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d.update({"port": self.port_used, "device_info": {k: str(v) for k, v in self.device_info.items()},
                  "wire": "untested (no public protocol specification; tested against a fake of the vendor module)"})
        return d
