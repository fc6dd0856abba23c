"""Privileged actuator options: what a scene or plan file may not choose.

Scenes and plans are data a user opens (shared, downloaded, generated). Some actuator
options are not data: they name a native library to load into the process
(``omni-openhaptics`` ``library``) or a file to write (``voicecoil-virtual``
``sink: "wav:PATH"``). An actuator class lists such options in
:attr:`hapticsdk.actuators.Actuator.privileged_options` (option name -> what it names);
the core then refuses them wherever they come from a scene or a plan -- whatever the
plugin -- with an error naming the option and where it may be set instead:

1. the application's code: ``render_plan(plan, ..., actuator_options={role: {key: value}})``
   (or the actuator's constructor / :func:`~hapticsdk.actuators.create_actuator`);
2. the command line: ``hapticsdk render ... --device-option ROLE.KEY=VALUE``;
3. the environment: ``HAPTICSDK_DEVICE_OPTIONS='{"omni-openhaptics": {"library": "/opt/..."}}'``
   (JSON object: actuator name -> options);
4. the user's device configuration file, same JSON form as 3: ``$HAPTICSDK_DEVICE_CONFIG``
   if set, else ``devices.json`` in the user configuration directory
   (``platformdirs.user_config_dir("hapticsdk")``, ``~/.config/hapticsdk/devices.json`` on
   Linux). It must be a regular file owned by the user and not writable by others.

Later sources override earlier ones per option: plan < configuration file < environment <
code / command line. Options that are not privileged may come from every source.
"""

from __future__ import annotations

import copy
import json
import os
import stat
from pathlib import Path
from typing import Any, Mapping

from .errors import ValidationError

ENV_OPTIONS = "HAPTICSDK_DEVICE_OPTIONS"
ENV_CONFIG = "HAPTICSDK_DEVICE_CONFIG"
#: largest device configuration file read (bytes)
MAX_CONFIG_BYTES = 1 << 20

__all__ = ["ENV_OPTIONS", "ENV_CONFIG", "PrivilegedOptionError", "privileged_options",
           "check_data_options", "device_config_path", "trusted_options", "parse_device_option",
           "WHERE_TO_SET"]

#: the sentence every refusal ends with
WHERE_TO_SET = ("set it from the application's code (render_plan(..., actuator_options={{{role!r}: "
                "{{{key!r}: ...}}}})), on the command line (--device-option {role}.{key}=VALUE), in "
                "${env} ({{{actuator!r}: {{{key!r}: ...}}}}) or in the user device configuration file "
                "{config}")


class PrivilegedOptionError(ValidationError):
    """A scene or plan file gives an option that names native code to load or a file to
    write. ``field`` is the option's path in the file; ``option`` its name."""

    def __init__(self, message: str, *, field: str, option: str) -> None:
        self.option = option
        super().__init__(message, field=field)


def privileged_options(cls: Any) -> dict[str, str]:
    """Privileged options of an actuator class (or instance), merged over its bases:
    option name -> what it names (``"native library"``, ``"output file"``). A class may
    declare a dict or any collection of names
    (:func:`hapticsdk.plugin_api.normalise_privileged_options`); a declaration that cannot
    be read raises :class:`~hapticsdk.errors.PluginError` (fail closed)."""
    from .plugin_api import normalise_privileged_options
    klass = cls if isinstance(cls, type) else type(cls)
    out: dict[str, str] = {}
    for base in reversed(klass.__mro__):
        if "privileged_options" in base.__dict__:   # dict, tuple, list, set or frozenset of names
            out.update(normalise_privileged_options(base.__dict__["privileged_options"],
                                                    owner=getattr(klass, "name", "") or klass.__name__))
    return out


def check_data_options(cls: Any, actuator: str, role: str, options: Mapping[str, Any], *, field: str) -> None:
    """Raise :class:`PrivilegedOptionError` when ``options`` (read from a scene or plan)
    contain a privileged option of actuator class ``cls``; ``field`` is the path of the
    options object in that file (``scene.devices.coil.options``)."""
    priv = privileged_options(cls)
    for key in sorted(options):
        if key in priv:
            where = WHERE_TO_SET.format(role=role, key=key, env=ENV_OPTIONS, actuator=actuator,
                                        config=device_config_path())
            raise PrivilegedOptionError(
                f"option {key!r} of actuator {actuator!r} is privileged ({priv[key]}); scene and plan "
                f"files may not set it (a file you open must not choose native code to load or files "
                f"to write): {where}", field=f"{field}.{key}", option=key)


def device_config_path() -> Path:
    """The user device configuration file (it need not exist)."""
    env = os.environ.get(ENV_CONFIG)
    if env:
        return Path(env).expanduser()
    try:
        import platformdirs
        base = Path(platformdirs.user_config_dir("hapticsdk", appauthor=False))
    except ImportError:  # declared dependency; keep working in a bare environment
        base = Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config") / "hapticsdk"
    return base / "devices.json"


def _by_actuator(data: Any, source: str) -> dict[str, dict[str, Any]]:
    if not isinstance(data, Mapping) or not all(isinstance(v, Mapping) for v in data.values()):
        raise ValidationError("expected a JSON object: actuator name -> {option: value}", field=source)
    return {str(k): dict(v) for k, v in data.items()}


#: the last device configuration file read: ``{"key": (path, inode, mtime_ns, size), "by_actuator": ...}``
_CONFIG_CACHE: dict[str, Any] = {}


def _read_config(path: Path) -> dict[str, dict[str, Any]]:
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return {}
    except OSError as exc:
        raise ValidationError(f"cannot read: {exc.strerror or exc}", field=str(path)) from None
    if not stat.S_ISREG(st.st_mode):
        raise ValidationError("not a regular file", field=str(path))
    if hasattr(os, "geteuid") and (st.st_uid != os.geteuid() or st.st_mode & stat.S_IWOTH):
        raise ValidationError("refused: the device configuration file must be owned by you and not "
                              "writable by others", field=str(path))
    if st.st_size > MAX_CONFIG_BYTES:
        raise ValidationError(f"larger than {MAX_CONFIG_BYTES} bytes", field=str(path))
    # read and parsed once per version of the file (a compile asks once per role)
    key = (str(path), st.st_ino, st.st_mtime_ns, st.st_size)
    if _CONFIG_CACHE.get("key") != key:
        try:
            with open(path, "rb") as fh:
                text = fh.read(MAX_CONFIG_BYTES + 1).decode("utf-8")
            data = json.loads(text)
        except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
            raise ValidationError(f"not a readable UTF-8 JSON file: {exc}", field=str(path)) from None
        _CONFIG_CACHE.clear()
        _CONFIG_CACHE.update(key=key, by_actuator=_by_actuator(data, str(path)))
    return copy.deepcopy(_CONFIG_CACHE["by_actuator"])


def trusted_options(actuator: str) -> dict[str, Any]:
    """Options for actuator ``actuator`` from the user device configuration file and the
    ``HAPTICSDK_DEVICE_OPTIONS`` environment variable (the latter wins)."""
    out = dict(_read_config(device_config_path()).get(actuator, {}))
    env = os.environ.get(ENV_OPTIONS)
    if env:
        try:
            data = json.loads(env)
        except (ValueError, RecursionError) as exc:
            raise ValidationError(f"not valid JSON: {exc}", field=ENV_OPTIONS) from None
        out.update(_by_actuator(data, ENV_OPTIONS).get(actuator, {}))
    return out


def parse_device_option(text: str) -> tuple[str, str, Any]:
    """``"ROLE.KEY=VALUE"`` -> ``(role, key, value)``; VALUE is read as JSON when it parses
    (numbers, ``true``, objects), else kept as a string."""
    head, sep, raw = str(text).partition("=")
    role, dot, key = head.partition(".")
    if not sep or not dot or not role.strip() or not key.strip():
        raise ValidationError(f"expected ROLE.KEY=VALUE (e.g. force.library=/opt/libHD.so), got {text!r}",
                              field="device-option")
    try:
        value: Any = json.loads(raw)
    except (ValueError, RecursionError):
        value = raw
    return role.strip(), key.strip(), value
