"""The versioned plugin API: a plugin declares the range it was built for (on its object
or its top-level package); the registry refuses a mismatch by name with both versions."""

import logging
import sys
import textwrap
from importlib import metadata

import pytest

from hapticsdk.errors import PluginError
from hapticsdk.plugin_api import (API_HISTORY, PLUGIN_API_VERSION, PluginAPIError, admitted_versions, api_compatible,
                                  check_plugin_api, declared_api, rules_new_since)
from hapticsdk.plugins import Registry, list_plugins


@pytest.fixture
def fake_plugin(tmp_path, monkeypatch):
    """Write a package ``pkgname`` with an actuator-like class and return a registry whose
    table has an entry point ``name -> pkgname.mod:Thing`` (as an installed one would)."""
    made = []

    def make(pkgname, *, package_api=None, object_api=None, kind="actuator"):
        root = tmp_path / pkgname
        root.mkdir()
        (root / "__init__.py").write_text(f"hapticsdk_api = {package_api!r}\n" if package_api else "")
        body = "class Thing:\n    pass\n"
        if object_api:
            body = f"class Thing:\n    hapticsdk_api = {object_api!r}\n"
        (root / "mod.py").write_text(textwrap.dedent(body))
        monkeypatch.syspath_prepend(str(tmp_path))
        made.append(pkgname)
        reg = Registry(kind)
        ep = metadata.EntryPoint(name=f"{pkgname}-thing", value=f"{pkgname}.mod:Thing", group=reg.group)
        reg._eps = {ep.name: ep}
        return reg, ep.name

    yield make
    for p in made:
        for m in [m for m in sys.modules if m == p or m.startswith(p + ".")]:
            del sys.modules[m]


def test_a_plugin_built_for_another_major_version_is_refused_by_name(fake_plugin):
    reg, name = fake_plugin("fut_plugin", package_api=">=2.0,<3")
    with pytest.raises(PluginError) as ei:
        reg.load(name)
    msg = str(ei.value)
    assert name in msg and ">=2.0,<3" in msg and PLUGIN_API_VERSION in msg
    assert ei.value.plugin == name and ei.value.kind == "actuator"


def test_the_objects_own_declaration_wins_over_its_packages(fake_plugin):
    reg, name = fake_plugin("mixed_plugin", package_api=">=2.0", object_api=">=1.0,<2")
    assert reg.load(name).__name__ == "Thing"


def test_a_compatible_package_declaration_loads(fake_plugin):
    reg, name = fake_plugin("ok_plugin", package_api=">=1.0,<2")
    obj = reg.load(name)
    assert declared_api(obj) == (">=1.0,<2", "package ok_plugin")


def test_an_undeclared_plugin_loads_with_a_warning_naming_it(fake_plugin, caplog):
    reg, name = fake_plugin("bare_plugin")
    with caplog.at_level(logging.WARNING, logger="hapticsdk.plugin_api"):
        reg.load(name)
    assert any(name in r.getMessage() and "hapticsdk_api" in r.getMessage() for r in caplog.records)
    with pytest.raises(PluginError, match="declares no hapticsdk_api"):
        check_plugin_api(reg.load(name), name=name, require=True)


def test_an_unreadable_range_is_an_error(fake_plugin):
    reg, name = fake_plugin("odd_plugin", package_api="~1.0")      # not PEP 440 (~= is)
    with pytest.raises(PluginAPIError, match="unreadable"):
        reg.load(name)


@pytest.mark.parametrize("spec, ok", [
    (">=1.0,<2", True), ("~=1.1", True), ("~=1.0", True), ("==1.*", True), ("==1.2.*", True),
    ("==1.0", False), (">=2.0", False), ("==1.0.*", False), ("~=1.3", False), ("<1.2", False), ("!=1.2", False),
])
def test_ranges_are_pep440_specifiers(spec, ok):
    """~= (compatible release) and wildcards are read as packaging reads them, against
    this core's 1.2."""
    assert PLUGIN_API_VERSION == "1.2"
    assert api_compatible(spec) is ok


def test_the_rules_new_since_a_declared_version():
    assert set(rules_new_since("~=1.2")) == set()
    new11 = rules_new_since(">=1.1,<2")
    assert "plugin-api-declared" in new11 and "read-back" not in new11
    assert "read-back" in rules_new_since(">=1.0,<2") and rules_new_since(None) == rules_new_since(">=1.0")
    assert admitted_versions("==1.*") == list(API_HISTORY)


@pytest.mark.parametrize("decl, names", [
    ({"library": "native library"}, {"library"}), (("library", "sink"), {"library", "sink"}),
    (["library"], {"library"}), ({"library"}, {"library"}), (frozenset({"sink"}), {"sink"}), ((), set()),
])
def test_privileged_options_any_collection_of_names(decl, names):
    """One reading of privileged_options: a dict or any collection of names; the scene
    check refuses each of them."""
    from hapticsdk.devices.device_options import PrivilegedOptionError, check_data_options, privileged_options
    Cls = type("Cls", (), {"privileged_options": decl, "name": "x"})
    assert set(privileged_options(Cls)) == names
    for n in names:
        with pytest.raises(PrivilegedOptionError):
            check_data_options(Cls, "x", "role", {n: 1}, field="scene.devices.role.options")


@pytest.mark.parametrize("decl", ["library", 3, ("library", 3), ("",)])
def test_an_unreadable_privileged_declaration_fails_closed(decl):
    from hapticsdk.devices.device_options import check_data_options
    Cls = type("Cls", (), {"privileged_options": decl, "name": "x"})
    with pytest.raises(PluginError, match="privileged_options"):
        check_data_options(Cls, "x", "role", {"library": "/tmp/x.so"}, field="f")


def test_every_installed_plugin_declares_a_compatible_range():
    rows = list_plugins(check=True)
    assert rows
    for r in rows:
        assert r["error"] is None, r
    from hapticsdk.plugins import registry
    for r in rows:
        if r["value"].startswith("hapticsdk."):
            continue   # the core's own entry points
        obj = registry(r["kind"]).load(r["name"])
        spec, _ = declared_api(obj)
        assert spec is not None, r


def test_plugins_listing_includes_hook_modules():
    kinds = {r["kind"] for r in list_plugins()}
    assert "hooks" in kinds
