"""Error hierarchy of hapticsdk.

Every error the SDK raises on purpose derives from :class:`HapticSDKError`, so an
application can catch one class. Subclasses also derive from the matching builtin
(``ValueError``, ``LookupError``, ``RuntimeError``) where that helps callers that
already catch those.
"""

from __future__ import annotations


class HapticSDKError(Exception):
    """Base class of every error raised by hapticsdk and its plugins."""


class ValidationError(HapticSDKError, ValueError):
    """Bad input: a value out of range, NaN, a wrong shape, a malformed file.

    ``field`` names the offending field (``"targets.hardness"``, ``"scene.objects[0]"``).
    """

    def __init__(self, message: str, *, field: str | None = None) -> None:
        self.field = field
        #: the message without the field in front
        self.reason = message
        super().__init__(f"{field}: {message}" if field else message)


class PluginError(HapticSDKError, LookupError):
    """A plugin could not be found, imported or used.

    ``plugin`` names the plugin (entry point name), ``kind`` its kind.
    """

    def __init__(self, message: str, *, plugin: str | None = None, kind: str | None = None) -> None:
        self.plugin = plugin
        self.kind = kind
        super().__init__(message)


class UnknownPluginError(PluginError):
    """No installed plugin of that kind has that name; the message lists the valid ones."""


class ModelError(HapticSDKError):
    """A perception model is missing, malformed or inconsistent with a feature space."""


class SolverError(HapticSDKError):
    """A solver failed to run (not: failed to reach a target, which is ``success=False``)."""


class DeviceError(HapticSDKError, RuntimeError):
    """A device or actuator failed: init, transport, fault. ``device`` names it."""

    def __init__(self, message: str, *, device: str | None = None) -> None:
        self.device = device
        super().__init__(f"[{device}] {message}" if device else message)


class DeviceNotFoundError(DeviceError):
    """A library, port or device was not found. The message says what was tried."""


class TransportError(DeviceError):
    """A bus or link (serial, USB, I2C) failed: timeout, NAK, corrupted frame."""


class SafetyError(DeviceError):
    """A safety rule stopped the output (fault latched, limit exceeded on start)."""


class CalibrationError(HapticSDKError, ValueError):
    """A calibration file or fit is invalid."""


class RecordingError(ValidationError):
    """A recording (trial data) is broken; the message names file/trial and field."""


class FormatError(ValidationError):
    """An interchange file (e.g. MPEG-I haptics ``.hjif``) is malformed: bad JSON, wrong
    type, missing or unknown field, unresolved reference, too large or too deep.
    ``field`` is the JSON path (``perceptions[0].channels[1].bands[0].effects[3]``) or,
    for file-level problems (size, encoding, JSON syntax), the file name."""


class FileWriteError(ValidationError):
    """A file could not be written (missing directory, disk full, permission); the old
    file, if any, is unchanged. ``field`` names the path or the option that gave it."""


class FeatureConflictError(ValidationError):
    """Two plugins (or a model and a dimension) declare one feature name in two units."""


class SessionError(HapticSDKError, RuntimeError):
    """A live :class:`~hapticsdk.runtime.session.Session` cannot do what was asked (it is
    closed, or its servo has stopped); the message says why."""


class ServoProcessDied(SessionError):
    """The servo of a live session is gone: its process died or was killed, stopped on a
    signal, or ended on a device fault. ``reason`` says which (``"killed by SIGKILL"``,
    ``"stopped by SIGTERM"``, ``"device fault: ..."``); ``exitcode`` is the servo
    process's exit status (None in thread isolation)."""

    def __init__(self, message: str, *, reason: str = "", exitcode: int | None = None) -> None:
        self.reason = reason
        self.exitcode = exitcode
        super().__init__(message)
