"""Privileged actuator options: what a scene or plan file may not choose.

Scenes and plans are data a user opens (shared, downloaded, generated). Some actuator
options are not data: they name a native library to load into the process
(``omni-openhaptics`` ``library``) or a file to write (``voicecoil-virtual``
``sink: "wav:PATH"``). An actuator class lists such options in
:attr:`hapticsdk.devices.actuators.Actuator.privileged_options` (option name -> what it names);
the core then refuses them wherever they come from a scene or a plan -- whatever the
plugin -- with an error naming the option and where it may be set instead:

1. the application's code: ``render_plan(plan, ..., actuator_options={role: {key: value}})``
   (or the actuator's constructor / :func:`~hapticsdk.devices.actuators.create_actuator`);
2. the command line: ``hapticsdk render ... --device-option ROLE.KEY=VALUE``;
3. the environment: ``HAPTICSDK_DEVICE_OPTIONS='{"omni-openhaptics": {"library": "/opt/..."}}'``
   (JSON object: actuator name -> options);
4. the user's device configuration file, same JSON form as 3: ``$HAPTICSDK_DEVICE_CONFIG``
   if set, else ``devices.json`` in the user configuration directory
   (``platformdirs.user_config_dir("hapticsdk")``, ``~/.config/hapticsdk/devices.json`` on
   Linux). It must be a regular file owned by the user and not writable by others.

Later sources override earlier ones per option: plan < configuration file < environment <
code / command line. Options that are not privileged may come from every source.

Safety is not data either. Two more kinds of setting are refused in a scene or plan
(same error class, same four places to set them instead):

* settings that switch a safeguard off (:data:`PRIVILEGED_SETTINGS`): a scene or plan
  may give ``servo.passivity`` only as ``true`` (switching the passivity controller off
  is ``render_plan(..., passivity=False)`` or ``ServoLoop(passivity=False)`` in code);
* options that raise the energy or voltage a device can deliver: an actuator class lists
  them in ``energy_options`` (option -> what it raises); a scene or plan may give such an
  option only as a number at or below the class's own default (the constructor's).
  The DRV2667 backends list ``gain`` (0..3 = 25/50/75/100 V full scale): a scene may
  lower it, never raise it.

The user device configuration file, and the folder holding it, must be owned by the
user (or root) and writable by nobody else (no group or other write bit).
"""

from __future__ import annotations

import copy
import json
import math
import os
import stat
from pathlib import Path
from typing import Any, Mapping

from ..errors import ValidationError

ENV_OPTIONS = "HAPTICSDK_DEVICE_OPTIONS"
ENV_CONFIG = "HAPTICSDK_DEVICE_CONFIG"
#: largest device configuration file read (bytes)
MAX_CONFIG_BYTES = 1 << 20

__all__ = ["ENV_OPTIONS", "ENV_CONFIG", "PrivilegedOptionError", "privileged_options",
           "check_data_options", "check_data_settings", "check_data_model", "PRIVILEGED_SETTINGS", "energy_option_ceilings", "device_config_path", "trusted_options", "parse_device_option",
           "parse_option",
           "WHERE_TO_SET", "parse_device"]

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
    from ..plugin_api import normalise_privileged_options
    klass = cls if isinstance(cls, type) else type(cls)
    out: dict[str, str] = {}
    for base in reversed(klass.__mro__):
        if "privileged_options" in base.__dict__:   # dict, tuple, list, set or frozenset of names
            out.update(normalise_privileged_options(base.__dict__["privileged_options"],
                                                    owner=getattr(klass, "name", "") or klass.__name__))
    return out


def energy_option_ceilings(cls: Any) -> dict[str, tuple[Any, str]]:
    """Options of actuator class ``cls`` that raise the energy or voltage it can deliver
    (its ``energy_options``, merged over the bases): option -> (the largest value a scene
    or plan may give: the constructor's default, what the option raises)."""
    import inspect

    klass = cls if isinstance(cls, type) else type(cls)
    from ..plugin_api import normalise_privileged_options
    out: dict[str, tuple[Any, str]] = {}
    for base in reversed(klass.__mro__):
        if "energy_options" in base.__dict__:  # read as privileged_options is: any collection, fail closed
            decl = normalise_privileged_options(base.__dict__["energy_options"],
                                                owner=getattr(klass, "name", "") or klass.__name__)
            for k, v in decl.items():
                out[k] = (None, v)
    for key in list(out):
        default = None
        for base in klass.__mro__:  # the nearest constructor that declares the option
            init = base.__dict__.get("__init__")
            if init is None:
                continue
            try:
                par = inspect.signature(init).parameters.get(key)
            except (TypeError, ValueError):
                continue
            if par is not None and par.default is not inspect.Parameter.empty:
                default = par.default
                break
        out[key] = (default, out[key][1])
    return out


def _refuse(actuator: str, role: str, key: str, field: str, why: str) -> None:
    where = WHERE_TO_SET.format(role=role, key=key, env=ENV_OPTIONS, actuator=actuator,
                                config=device_config_path())
    raise PrivilegedOptionError(f"option {key!r} of actuator {actuator!r} {why}: {where}",
                                field=f"{field}.{key}", option=key)


def check_data_options(cls: Any, actuator: str, role: str, options: Mapping[str, Any], *, field: str) -> None:
    """Raise :class:`PrivilegedOptionError` when ``options`` (read from a scene or plan)
    contain a privileged option of actuator class ``cls``, or one of its energy options
    above the class's default; ``field`` is the path of the options object in that file
    (``scene.devices.coil.options``)."""
    from ..checks import is_number

    for key, (ceiling, what) in energy_option_ceilings(cls).items():
        if key not in options:
            continue
        v = options[key]
        try:
            fv = float(v) if is_number(v) else math.nan
        except OverflowError:   # an int beyond the float range: no finite number, refused below
            fv = math.nan
        ok = is_number(ceiling) and math.isfinite(fv) and fv <= float(ceiling)
        if not ok:
            _refuse(actuator, role, key, field,
                    f"raises the energy or voltage the device can deliver ({what}); a scene or plan file may "
                    f"give it only as a number up to the default {ceiling!r}, got {v!r}")
    priv = privileged_options(cls)
    for key in sorted(options):
        if key in priv:
            where = WHERE_TO_SET.format(role=role, key=key, env=ENV_OPTIONS, actuator=actuator,
                                        config=device_config_path())
            raise PrivilegedOptionError(
                f"option {key!r} of actuator {actuator!r} is privileged ({priv[key]}); scene and plan "
                f"files may not set it (a file you open must not choose native code to load or files "
                f"to write): {where}", field=f"{field}.{key}", option=key)


#: settings a scene or plan may give only with one value, because any other switches a
#: safeguard off: path under ``settings`` -> (the only value accepted from data, what it guards)
PRIVILEGED_SETTINGS: dict[tuple[str, ...], tuple[Any, str]] = {
    ("servo", "passivity"): (True, "the passivity observer/controller, which takes out the energy a sampled "
                                   "stiff wall would inject"),
}


def check_data_settings(settings: Any, *, field: str) -> None:
    """Raise :class:`PrivilegedOptionError` when ``settings`` (a scene's or plan's
    ``settings`` object, read from a file) set one of :data:`PRIVILEGED_SETTINGS` to
    anything but its safe value (``0``, ``"false"`` and ``null`` included); ``field`` is
    the path of the settings object (``scene.settings``, ``plan.settings``)."""
    if not isinstance(settings, Mapping):
        return
    for path, (safe, what) in PRIVILEGED_SETTINGS.items():
        node: Any = settings
        for part in path:
            if not isinstance(node, Mapping) or part not in node:
                node = _ABSENT
                break
            node = node[part]
        if node is _ABSENT or (node is safe):
            continue
        dotted = ".".join(path)
        raise PrivilegedOptionError(
            f"setting {dotted!r} is privileged ({what}); a scene or plan file may give it only as "
            f"{json.dumps(safe)}, got {node!r}: switch it off from the application's code "
            f"(render_plan(..., {path[-1]}=False), ServoLoop({path[-1]}=False))",
            field=f"{field}.{dotted}", option=dotted)


_ABSENT = object()


def check_data_model(settings: Any, *, field: str) -> None:
    """Raise :class:`PrivilegedOptionError` when ``settings`` (a scene's ``settings``
    object, read from a file) name a model *file* (``"model": "x.onnx"``, or any path),
    which compiling the scene would read: a file somebody hands you chooses no file to
    read. A model plugin's name (``"default"``) is data; a path is given from the
    application's code (``hs.solve(..., model=PATH)``, ``Scene(..., settings={"model":
    PATH})``). (Rendering a plan reads no model: a plan's ``settings.model`` is a record.)"""
    model = settings.get("model") if isinstance(settings, Mapping) else None
    if isinstance(model, str) and (model.lower().endswith(".onnx") or "/" in model or "\\" in model):
        raise PrivilegedOptionError(
            f"a scene file names no model file to read, got {model!r:.80}: give a model plugin's name "
            f"(hapticsdk plugins lists them), or pass the path from the application's code "
            f"(hs.solve(..., model=PATH), Scene(..., settings={{'model': PATH}}))", field=f"{field}.model",
            option="model")


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
    _refuse_non_finite(data, source)
    return {str(k): dict(v) for k, v in data.items()}


def _refuse_non_finite(value: Any, field: str) -> None:
    """A NaN, an infinity (``json`` reads ``NaN``, ``Infinity`` and ``1e400``) or an
    integer beyond the float range in trusted options raises :class:`ValidationError`
    naming its path: as in every SDK file, no option is a non-finite number, whether or
    not the actuator plugin checks its own options."""
    from ..schemas_io import non_finite_at
    bad = non_finite_at(value)
    if bad is not None:
        raise ValidationError(f"{bad[1]} is not a finite number", field=f"{field}{bad[0]}")


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
    _check_trusted(path, st, "the device configuration file")
    parent = path.parent if str(path.parent) else Path(".")
    try:
        pst = os.stat(parent)
    except OSError as exc:
        raise ValidationError(f"cannot read its folder: {exc.strerror or exc}", field=str(path)) from None
    _check_trusted(path, pst, f"its folder {str(parent)!r}")
    if st.st_size > MAX_CONFIG_BYTES:
        raise ValidationError(f"larger than {MAX_CONFIG_BYTES} bytes", field=str(path))
    # read and parsed once per version of the file (a compile asks once per role)
    key = (str(path), st.st_ino, st.st_mtime_ns, st.st_size)
    if _CONFIG_CACHE.get("key") != key:
        from ..schemas_io import read_json
        # the SDK's JSON reader: regular file, size cap, depth, NaN named by its path
        data = read_json(path, field=str(path), max_bytes=MAX_CONFIG_BYTES)
        _CONFIG_CACHE.clear()
        _CONFIG_CACHE.update(key=key, by_actuator=_by_actuator(data, str(path)))
    return copy.deepcopy(_CONFIG_CACHE["by_actuator"])


def _check_trusted(path: Path, st: os.stat_result, what: str) -> None:
    """Refuse a configuration file (or its folder) that someone else could have written:
    owned by another user than you or root, or with the group or other write bit set."""
    if not hasattr(os, "geteuid"):  # pragma: no cover - Windows: ACLs, not mode bits
        return
    if st.st_uid not in (os.geteuid(), 0):
        raise ValidationError(f"refused: {what} is owned by uid {st.st_uid}, not by you or root; the device "
                              "configuration must be owned by you and not writable by others", field=str(path))
    if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        raise ValidationError(f"refused: {what} is writable by {'others' if st.st_mode & stat.S_IWOTH else 'its group'}"
                              f" (mode {stat.S_IMODE(st.st_mode):o}); the device configuration must be owned by "
                              "you and not writable by others (chmod go-w)", field=str(path))


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


def _option_value(raw: str, where: str) -> Any:
    """An option's VALUE: read as JSON when it parses (numbers, ``true``, objects), else
    kept as a string; a number that is not finite is refused, naming ``where``."""
    try:
        value: Any = json.loads(raw)
    except (ValueError, RecursionError):
        value = raw
    _refuse_non_finite(value, where)
    return value


def parse_device_option(text: str) -> tuple[str, str, Any]:
    """``"ROLE.KEY=VALUE"`` -> ``(role, key, value)``; VALUE is read as JSON when it parses
    (numbers, ``true``, objects), else kept as a string."""
    head, sep, raw = str(text).partition("=")
    role, dot, key = head.partition(".")
    if not sep or not dot or not role.strip() or not key.strip():
        raise ValidationError(f"expected ROLE.KEY=VALUE (e.g. force.library=/opt/libHD.so), got {text!r}",
                              field="device-option")
    return role.strip(), key.strip(), _option_value(raw, f"device-option {role.strip()}.{key.strip()}")


def parse_option(text: str) -> tuple[str, Any]:
    """``"KEY=VALUE"`` (one device's option, no role) -> ``(key, value)``; VALUE as in
    :func:`parse_device_option`."""
    key, sep, raw = str(text).partition("=")
    if not sep or not key.strip():
        raise ValidationError(f"expected KEY=VALUE (e.g. finger=none), got {text!r}", field="device-option")
    return key.strip(), _option_value(raw, f"device-option {key.strip()}")


def parse_device(text: str) -> tuple[str, str]:
    """``"ROLE=ACTUATOR"`` (``coil=voicecoil-audio``) -> ``(role, actuator)``; the actuator
    must be an installed actuator plugin."""
    role, sep, name = str(text).partition("=")
    role, name = role.strip(), name.strip()
    if not sep or not role or not name or "." in role:
        raise ValidationError(f"expected ROLE=ACTUATOR (e.g. coil=voicecoil-audio), got {text!r}", field="device")
    from ..plugins import registry
    if name not in registry("actuator"):
        raise ValidationError(f"no actuator plugin {name!r}; installed: {', '.join(registry('actuator').names())}",
                              field="device")
    return role, name
