"""The entry-point index kept between processes (:mod:`hapticsdk.plugin_index`, issue 30
round 7): a process that finds it imports no :mod:`importlib.metadata` (nor :mod:`email`),
and every change to the installed distributions is seen by the next process."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from hapticsdk import plugin_index
from hapticsdk.plugins import GROUPS

#: lists the solver plugins of a fresh process and what it imported
PROBE = r"""
import json, os, sys
read = []                     # every distribution metadata file this process opens
def _audit(event, args):
    if event == "open" and isinstance(args[0], (str, bytes, os.PathLike)):
        name = os.path.basename(os.fsdecode(args[0]))
        if name in ("entry_points.txt", "METADATA", "PKG-INFO"):
            read.append(os.fsdecode(args[0]))
sys.addaudithook(_audit)
from hapticsdk.plugins import list_plugins
rows = [r for r in list_plugins(["solver"]) if r["name"].startswith("idx-")]
print(json.dumps({"rows": sorted((r["name"], r["value"], r["distribution"], r["version"]) for r in rows),
                  "metadata": "importlib.metadata" in sys.modules, "email": "email" in sys.modules,
                  "read": read}))
"""


def _fresh(cache: Path, extra: Path, code: str = PROBE) -> dict:
    env = {**os.environ, "HAPTICSDK_CACHE_DIR": str(cache), "PYTHONPATH": str(extra)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def _dist(site: Path, name: str, version: str, entries: str) -> Path:
    info = site / f"{name}-{version}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
    (info / "entry_points.txt").write_text("[hapticsdk.solvers]\n" + textwrap.dedent(entries))
    return info


def test_a_second_process_reads_the_index_and_imports_no_metadata(tmp_path):
    site = tmp_path / "site"
    site.mkdir()
    _dist(site, "idxa", "1.0", "idx-a = idx_mod:A\n")
    first = _fresh(tmp_path / "cache", site)
    assert first["rows"] == [["idx-a", "idx_mod:A", "idxa", "1.0"]]
    assert first["metadata"]                      # scanned, and stored
    assert any(p.endswith("entry_points.txt") for p in first["read"])
    assert list((tmp_path / "cache" / "plugin-index").glob("*.json"))
    again = _fresh(tmp_path / "cache", site)
    assert again["rows"] == first["rows"]
    assert again["read"] == []                    # no distribution's metadata was opened
    # nor imported by any module (pluggy >= 1.4, the declared floor, defers its import)
    assert not again["metadata"] and not again["email"]


def test_every_change_to_the_installed_distributions_is_seen(tmp_path):
    """Install, upgrade in place, edit the entry points, uninstall: each is seen by the
    next process, with an index stored after every step."""
    site = tmp_path / "site"
    site.mkdir()
    cache = tmp_path / "cache"
    info_a = _dist(site, "idxa", "1.0", "idx-a = idx_mod:A\n")
    assert [r[0] for r in _fresh(cache, site)["rows"]] == ["idx-a"]
    _dist(site, "idxb", "2.0", "idx-b = idx_mod:B\n")                          # pip install
    assert [r[0] for r in _fresh(cache, site)["rows"]] == ["idx-a", "idx-b"]
    (info_a / "METADATA").write_text("Metadata-Version: 2.1\nName: idxa\nVersion: 1.1\n")  # in place
    assert _fresh(cache, site)["rows"][0] == ["idx-a", "idx_mod:A", "idxa", "1.1"]
    (info_a / "entry_points.txt").write_text("[hapticsdk.solvers]\nidx-a = idx_mod:A2\nidx-c = idx_mod:C\n")
    assert [r[:2] for r in _fresh(cache, site)["rows"]] == [["idx-a", "idx_mod:A2"], ["idx-b", "idx_mod:B"],
                                                           ["idx-c", "idx_mod:C"]]
    for f in info_a.iterdir():                                                      # pip uninstall
        f.unlink()
    info_a.rmdir()
    assert [r[0] for r in _fresh(cache, site)["rows"]] == ["idx-b"]


def test_an_unreadable_index_is_scanned_again(tmp_path):
    site = tmp_path / "site"
    site.mkdir()
    _dist(site, "idxa", "1.0", "idx-a = idx_mod:A\n")
    cache = tmp_path / "cache"
    first = _fresh(cache, site)
    for f in (cache / "plugin-index").glob("*.json"):
        f.write_text('{"format": 1, "entry_points": [["broken"')
    again = _fresh(cache, site)
    assert again["rows"] == first["rows"] and again["metadata"]


def test_the_index_holds_what_importlib_metadata_returns(tmp_path, monkeypatch):
    """Every ``hapticsdk.*`` entry point of this environment, stored and read back, has the
    scan's group, name, value and distribution, and loads the same object."""
    from importlib import metadata

    monkeypatch.setenv("HAPTICSDK_CACHE_DIR", str(tmp_path))
    stored = plugin_index.load(plugin_index._scan_sdk_groups, use_stored=False)["entry_points"]
    read = plugin_index.load(plugin_index._scan_sdk_groups)["entry_points"]
    assert read == stored
    groups = sorted({e.group for e in read} | set(GROUPS.values()))
    real = sorted((ep for g in groups for ep in metadata.entry_points(group=g)),
                  key=lambda e: (e.group, e.name, e.value))
    read = sorted(read, key=lambda e: (e.group, e.name, e.value))
    assert [(e.group, e.name, e.value) for e in read] == [(e.group, e.name, e.value) for e in real]
    assert [(e.distribution, e.version) for e in read] == [
        (e.dist.metadata["Name"], e.dist.version) for e in real]
    loaded = 0
    for ours, theirs in zip(read, real):
        try:
            want = theirs.load()
        except Exception:      # an optional backend's library is missing here
            continue
        assert ours.load() is want, ours
        loaded += 1
    assert loaded >= 10


def test_a_replaced_metadata_function_disables_the_index(monkeypatch):
    from importlib import metadata

    assert plugin_index.fingerprint() is not None
    real = metadata.entry_points
    monkeypatch.setattr(metadata, "entry_points", lambda **kw: real(**kw))
    assert plugin_index.fingerprint() is None


@pytest.mark.parametrize("name", ["jsonschema", "hapticsdk"])
def test_recorded_versions_are_those_of_importlib_metadata(name):
    from importlib import metadata

    assert name in plugin_index.VERSIONS
    assert plugin_index.version(name) == metadata.version(name)
