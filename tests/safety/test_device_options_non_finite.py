"""Trusted device options (``--device-option ROLE.KEY=VALUE``, ``HAPTICSDK_DEVICE_OPTIONS``,
the device configuration file) never hold a non-finite number: ``json`` reads ``NaN``,
``Infinity`` and ``1e400`` (as inf), and a 401-digit integer no float holds. Each is a
ValidationError naming where it came from and the option's path, before any actuator
plugin sees it (the shipped plugins check their own options; a third-party one need
not)."""

from __future__ import annotations

import pytest

from hapticsdk.devices import device_options as do
from hapticsdk.devices.device_options import ENV_CONFIG, ENV_OPTIONS, parse_device_option, trusted_options
from hapticsdk.errors import ValidationError

#: (JSON text of the value, path inside it where the bad number is)
VALUES = [("NaN", ""), ("Infinity", ""), ("-Infinity", ""), ("1e400", ""), ("-1e999", ""),
          ("1" + "0" * 400, ""), ("[0.5, NaN]", "[1]"), ('{"a": {"b": 1e400}}', ".a.b")]


@pytest.mark.parametrize("text, where", VALUES)
def test_command_line_option(text, where):
    with pytest.raises(ValidationError, match="not a finite number") as exc:
        parse_device_option(f"vibration.gain={text}")
    assert exc.value.field == f"device-option vibration.gain{where}"


@pytest.mark.parametrize("text, where", VALUES)
def test_environment_options(monkeypatch, tmp_path, text, where):
    monkeypatch.setenv(ENV_CONFIG, str(tmp_path / "none.json"))
    monkeypatch.setenv(ENV_OPTIONS, f'{{"piezo-virtual": {{"gain": {text}}}}}')
    with pytest.raises(ValidationError, match="not a finite number") as exc:
        trusted_options("piezo-virtual")
    assert exc.value.field == f"{ENV_OPTIONS}.piezo-virtual.gain{where}"


@pytest.mark.parametrize("text, where", [v for v in VALUES if "NaN" not in v[0] and "Infinity" not in v[0]])
def test_configuration_file(monkeypatch, tmp_path, text, where):
    """(``NaN`` / ``Infinity`` literals in the file are refused by the JSON reader, by path.)"""
    p = tmp_path / "devices.json"
    p.write_text(f'{{"piezo-virtual": {{"gain": {text}}}}}')
    p.chmod(0o600)
    tmp_path.chmod(0o700)
    monkeypatch.setenv(ENV_CONFIG, str(p))
    monkeypatch.delenv(ENV_OPTIONS, raising=False)
    monkeypatch.setattr(do, "_CONFIG_CACHE", {})
    with pytest.raises(ValidationError, match="not a finite number") as exc:
        trusted_options("piezo-virtual")
    assert exc.value.field == f"{p}.piezo-virtual.gain{where}"


def test_finite_values_and_strings_pass(monkeypatch, tmp_path):
    assert parse_device_option("vibration.gain=1") == ("vibration", "gain", 1)
    assert parse_device_option("force.library=/opt/NaN.so") == ("force", "library", "/opt/NaN.so")
    assert parse_device_option('x.y=["NaN"]') == ("x", "y", ["NaN"])
    monkeypatch.setenv(ENV_CONFIG, str(tmp_path / "none.json"))
    monkeypatch.setenv(ENV_OPTIONS, '{"piezo-virtual": {"gain": 0, "name": "Infinity"}}')
    assert trusted_options("piezo-virtual") == {"gain": 0, "name": "Infinity"}
