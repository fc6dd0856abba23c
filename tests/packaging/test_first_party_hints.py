"""After a core-only install, a missing first-party plugin names its distribution.

A subprocess hides one distribution's entry points (as ``pip uninstall`` would) and runs
the command line / registry there.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from hapticsdk.plugins import FIRST_PARTY, GROUPS

ROOT = Path(__file__).resolve().parents[2]

HIDE = r"""
import importlib.metadata as md, json, sys
hidden = set(sys.argv[1].split(","))
real = md.entry_points
def entry_points(**kw):
    eps = real(**kw)
    return md.EntryPoints([ep for ep in eps if ep.dist is None or ep.dist.metadata["Name"] not in hidden])
md.entry_points = entry_points
what = sys.argv[2]
if what == "cli":
    from hapticsdk.cli import main
    sys.exit(main(sys.argv[3:]))
if what == "doctor":
    from hapticsdk import doctor
    rep = doctor.collect()
    print(json.dumps({"missing": rep["missing_plugins"], "text": doctor.format_report(rep)}))
if what == "load":
    from hapticsdk.plugins import registry
    try:
        registry(sys.argv[3]).load(sys.argv[4])
    except Exception as exc:
        print(exc)
"""


def _run(hidden: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", HIDE, hidden, *args], capture_output=True, text=True,
                          timeout=120, cwd=ROOT)


def test_first_party_table_matches_the_plugins_entry_points():
    declared: dict[str, dict[str, str]] = {}
    kind_of = {g: k for k, g in GROUPS.items()}
    for pp in sorted((ROOT / "plugins").glob("*/pyproject.toml")):
        doc = tomllib.loads(pp.read_text())
        for group, eps in doc["project"]["entry-points"].items():
            kind = kind_of[group]
            if kind == "hooks":
                continue
            for name in eps:
                declared.setdefault(kind, {})[name] = doc["project"]["name"]
    assert declared == FIRST_PARTY


@pytest.mark.parametrize("dist, kind, name", [
    ("hapticsdk-ga", "solver", "ga"), ("hapticsdk-onnx", "model", "default"),
    ("hapticsdk-roughness", "actuator", "piezo-virtual"),
])
def test_registry_error_names_the_distribution(dist, kind, name):
    out = _run(dist, "load", kind, name)
    assert out.returncode == 0, out.stderr
    # run in the checkout: the hint is the checkout's own path, never the index name
    assert f"pip install -e plugins/{dist}" in out.stdout, out.stdout
    assert f"pip install {dist}" not in out.stdout


def test_render_without_the_hardness_plugin_names_it():
    out = _run("hapticsdk-hardness", "cli", "render", "S7", "--seconds", "0.05")
    assert out.returncode == 2, (out.stdout, out.stderr)
    assert out.stderr.startswith("hapticsdk: error: ")
    assert "pip install -e plugins/hapticsdk-hardness" in out.stderr, out.stderr


def test_doctor_reports_missing_first_party_plugins():
    out = _run("hapticsdk-hardness,hapticsdk-ga", "doctor")
    assert out.returncode == 0, out.stderr
    rep = json.loads(out.stdout)
    assert {m["distribution"] for m in rep["missing"]} == {"hapticsdk-hardness", "hapticsdk-ga"}
    assert {(m["kind"], m["name"]) for m in rep["missing"]} >= {("dimension", "hardness"), ("solver", "ga")}
    assert "hapticsdk-hardness not installed (pip install -e plugins/hapticsdk-hardness)" in rep["text"]
    everything = _run("", "doctor")
    assert json.loads(everything.stdout)["missing"] == []


def test_hints_follow_where_the_sdk_was_installed(monkeypatch, tmp_path):
    from hapticsdk import install_hints as ih
    monkeypatch.chdir(tmp_path)                       # outside the checkout: its full path
    assert ih.pip_hint("hapticsdk-ga") == f"pip install -e {ROOT / 'plugins' / 'hapticsdk-ga'}"
    assert ih.pip_hint("hapticsdk", "plot") == f"pip install -e '{ROOT}[plot]'"
    assert ih.pip_hint("pyserial") == "pip install pyserial"   # on the index
    monkeypatch.setattr(ih, "source_checkout", lambda: None)   # installed from a wheel
    hint = ih.pip_hint("hapticsdk-roughness", "serial")
    assert hint.startswith("pip install -e 'plugins/hapticsdk-roughness[serial]' in a hapticsdk source checkout")
    assert "not on the package index" in hint


def test_no_hint_names_a_first_party_distribution_as_an_index_package():
    """``pip install hapticsdk-X`` (or ``hapticsdk[extra]``) typed as written would ask the
    package index for a name that is not ours: no message of the SDK says it."""
    import re
    pattern = re.compile(r"pip install '?hapticsdk(-[a-z]+)?(\[|\b)(?!\.)")
    offenders = []
    for path in [*ROOT.glob("hapticsdk/**/*.py"), *ROOT.glob("plugins/*/src/**/*.py")]:
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if pattern.search(line):
                offenders.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()}")
    assert not offenders, "\n".join(offenders)
