"""``hapticsdk doctor``: what can run on this machine, and why not.

:func:`collect` returns ``{"backends": {...}, "devices": [...], "calibrations": [...],
"libraries": {...}}``:

* ``backends``: every installed actuator plugin, ``name -> {"available", "reason",
  "distribution", "simulated"}`` from its class's ``check_available()``. Each plugin is
  imported on its own; one that fails to import (or whose check raises) is reported by
  name with its error, and never stops the others.
* ``devices``: what each available backend's ``discover()`` finds (a failing discover is
  reported as an entry with ``error``).
* ``calibrations``: calibrations in use: the core defaults, files in the calibration
  directory (``$HAPTICSDK_CALIBRATION_DIR``), and what backends report through an
  optional ``calibration_info()`` classmethod.
* ``missing_plugins``: first-party plugins whose distribution is not installed,
  ``[{"kind", "name", "distribution"}]`` (empty with everything installed).
* ``libraries``: optional Python modules and shared libraries, ``name -> {"found", "detail",
  "needed_by"}``.

Nothing here opens a device.
"""

from __future__ import annotations

import ctypes.util
import importlib.util
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

#: optional Python modules -> what needs them
OPTIONAL_MODULES: dict[str, str] = {
    "serial": "piezo-serial (pyserial)",
    "usb": "piezo-mcp2221 (pyusb)",
    "onnxruntime": "ONNX perception models",
    "onnx": "model export (training extra)",
    "matplotlib": "plots (plot extra)",
    "sounddevice": "voicecoil-audio (hapticsdk-hardness[audio])",
    "forcedimension_core": "dhd (hapticsdk-hardness[dhd], Force Dimension's binding)",
    "HaplyHardwareAPI": "inverse3 (hapticsdk-hardness[haply], Haply's module)",
}
#: what to pip install for a module whose import name differs
PIP_NAMES: dict[str, str] = {"serial": "pyserial", "usb": "pyusb", "sounddevice": "hapticsdk-hardness[audio]",
                             "forcedimension_core": "hapticsdk-hardness[dhd]",
                             "HaplyHardwareAPI": "hapticsdk-hardness[haply]"}
#: optional shared libraries (ctypes names) -> what needs them
OPTIONAL_LIBRARIES: dict[str, str] = {
    "HD": "omni-openhaptics (OpenHaptics libHD)",
    "usb-1.0": "piezo-mcp2221 (libusb-1.0 behind pyusb)",
    "portaudio": "voicecoil-audio (PortAudio behind sounddevice; Debian libportaudio2)",
    "drd": "dhd (Force Dimension SDK libdrd, DHD API; FDSDK=folder)",
}
#: environment variable naming a library's file or folder -> how to find it there
_LIB_ENV: dict[str, str] = {"HD": "HAPTICSDK_LIBHD", "drd": "FDSDK"}


def _error_text(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


def check_backends() -> tuple[dict[str, dict[str, Any]], dict[str, type]]:
    """Backends table and the classes that imported."""
    from .plugins import registry

    reg = registry("actuator")
    table: dict[str, dict[str, Any]] = {}
    classes: dict[str, type] = {}
    for name in reg.names():
        entry: dict[str, Any] = {"available": False, "reason": "", "distribution": None, "simulated": None}
        try:
            entry["distribution"] = reg.info(name).distribution
        except Exception as exc:  # metadata problems are reported, not raised
            entry["distribution"] = f"? ({_error_text(exc)})"
        try:
            cls = reg.load(name)
        except Exception as exc:
            what = "name clash" if name in reg.clashes() else "plugin failed to import"
            entry["reason"] = f"{what}: {_error_text(exc)}"
            table[name] = entry
            continue
        entry["simulated"] = bool(getattr(cls, "simulated", False))
        try:
            ok, reason = cls.check_available()
            entry["available"], entry["reason"] = bool(ok), str(reason)
            classes[name] = cls
        except Exception as exc:
            entry["reason"] = f"check_available() raised {_error_text(exc)}"
        table[name] = entry
    return table, classes


def discover_devices(classes: dict[str, type], backends: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """Devices each available backend's ``discover()`` finds (``{"backend", ...}`` per
    device); a failing discover is reported as an entry with ``error``, never raised.
    """
    devices: list[dict[str, Any]] = []
    for name, cls in classes.items():
        if not backends[name]["available"]:
            continue
        try:
            for dev in getattr(cls, "discover")() or []:
                item = {"backend": name}
                item.update(dev)
                devices.append(item)
        except Exception as exc:
            devices.append({"backend": name, "error": f"discover() raised {_error_text(exc)}"})
    return devices


def check_libraries() -> dict[str, dict[str, Any]]:
    """Optional Python modules and shared libraries: ``name -> {"kind", "found", "detail",
    "needed_by"}`` (``detail`` says what to install when missing).
    """
    out: dict[str, dict[str, Any]] = {}
    for mod, needed in OPTIONAL_MODULES.items():
        try:
            spec = importlib.util.find_spec(mod)
        except (ImportError, ValueError):
            spec = None
        pip_name = PIP_NAMES.get(mod, mod)
        out[mod] = {"kind": "python", "found": spec is not None,
                    "detail": spec.origin if spec is not None else f"not installed (pip install {pip_name})",
                    "needed_by": needed}
    for lib, needed in OPTIONAL_LIBRARIES.items():
        path = ctypes.util.find_library(lib)
        env = _LIB_ENV.get(lib)
        extra = os.environ.get(env) if env else None
        if extra and lib == "drd":   # the binding's layout: $FDSDK/lib/release/<platform>/libdrd.so*
            hits = sorted(Path(extra).glob("lib/release/*/libdrd.so*"))
            extra = str(hits[-1]) if hits else None
        found = bool(path) or bool(extra and Path(extra).exists())
        out[f"lib{lib}"] = {"kind": "shared", "found": found,
                            "detail": path or (extra if found else "not found by ctypes.util.find_library"),
                            "needed_by": needed}
    return out


def list_calibrations(classes: dict[str, type] | None = None) -> list[dict[str, Any]]:
    """Calibrations in use: what :func:`hapticsdk.calibration.load_calibration` picks for
    each kind, every file of the calibration directory (schema-checked, errors kept), and
    what backends report through an optional ``calibration_info()`` classmethod."""
    from .calibration.store import calibrations_in_use, list_calibrations as files

    cals: list[dict[str, Any]] = []
    try:
        cals.extend(dict(c, scope="in use") for c in calibrations_in_use())
    except Exception as exc:
        cals.append({"scope": "in use", "error": _error_text(exc)})
    cals.extend(dict(e.to_dict(), scope="file") for e in files())
    for name, cls in (classes or {}).items():
        info = getattr(cls, "calibration_info", None)
        if info is None:
            continue
        try:
            for c in info() or []:
                cals.append(dict(c, backend=name))
        except Exception as exc:
            cals.append({"backend": name, "error": f"calibration_info() raised {_error_text(exc)}"})
    return cals


def collect() -> dict[str, Any]:
    """The full doctor report (see module docstring)."""
    backends, classes = check_backends()
    from .plugins import missing_first_party
    from .runtime.rtkit import machine_report
    return {"backends": backends, "devices": discover_devices(classes, backends),
            "calibrations": list_calibrations(classes), "libraries": check_libraries(),
            "missing_plugins": missing_first_party(), "realtime": machine_report()}


def format_report(rep: dict[str, Any]) -> str:
    """Human-readable text of :func:`collect`'s report."""
    lines = ["backends:"]
    for name, b in sorted(rep["backends"].items()):
        mark = "ok " if b["available"] else "-- "
        sim = " (simulated)" if b.get("simulated") else ""
        lines.append(f"  {mark}{name}{sim}: {b['reason']}")
    lines.append("devices:" + ("" if rep["devices"] else " none found"))
    for dev in rep["devices"]:
        rest = ", ".join(f"{k}={v}" for k, v in dev.items() if k != "backend")
        lines.append(f"  {dev['backend']}: {rest}")
    missing: dict[str, list[str]] = {}
    for m in rep.get("missing_plugins", []):
        missing.setdefault(m["distribution"], []).append(f"{m['kind']} {m['name']}")
    from .install_hints import pip_hint
    lines.append("first-party plugins:" + ("" if missing else " all installed"))
    for dist, what in sorted(missing.items()):
        lines.append(f"  -- {dist} not installed ({pip_hint(dist)}): provides {', '.join(what)}")
    lines.append("libraries:")
    for name, lib in rep["libraries"].items():
        lines.append(f"  {'ok ' if lib['found'] else '-- '}{name}: {lib['detail']}  [{lib['needed_by']}]")
    lines.append("calibrations:")
    for c in rep["calibrations"]:
        tag = " GENERATED" if c.get("generated") else ""
        where = c.get("backend") or c.get("scope") or c.get("path", "")
        detail = c.get("source") or (f"skipped {c.get('path') or ''}: {c['error']}" if c.get("error") else "")
        lines.append(f"  {c.get('kind') or 'unreadable'} [{where}]{tag}: {detail}")
    rt = rep.get("realtime")
    if rt:
        rk = rt["realtimekit"]
        lines.append("real-time scheduling for the live servo:")
        lines.append(f"  SCHED_FIFO set directly: {rt['sched_fifo_directly']}; RLIMIT_RTPRIO {rt['rlimit_rtprio']}")
        lines.append("  RealtimeKit: " + (rk["error"] if "error" in rk else
                                          f"available, up to priority {rk['MaxRealtimePriority']} "
                                          f"(RLIMIT_RTTIME {rk['RTTimeUSecMax']} us)"))
        lines.append(f"  CPUs {rt['cpus']}; servo pinned to: {rt['servo_cpu']}")
        lines.extend(f"  to get more: {h}" for h in rt["how_to_get_more"])
    return "\n".join(lines)


if not TYPE_CHECKING:  # moved names, deprecated since 0.2 (a type checker sees only the new places)
    from ._deprecation import moved_names
    __getattr__ = moved_names(__name__, {"calibration_dir": "hapticsdk.calibration"})
