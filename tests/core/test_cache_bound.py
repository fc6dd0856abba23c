"""The cache folder: per-user path, size bound (markers included), clear (issue 29 item 4)."""

from __future__ import annotations

import json
import os

import pytest

from hapticsdk import cache
from hapticsdk.cli import main
from hapticsdk.fileio import atomic_write_bytes, cache_dir


@pytest.fixture()
def cdir(tmp_path, monkeypatch):
    d = tmp_path / "hapticsdk"
    monkeypatch.setenv("HAPTICSDK_CACHE_DIR", str(d))
    return d


def _fill(folder, n, size, t0=1_000_000.0):
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(n):
        p = folder / f"f{i:04d}"
        p.write_bytes(b"x" * size)
        os.utime(p, (t0 + i, t0 + i))


def test_default_is_the_platform_user_cache_folder(monkeypatch):
    import platformdirs
    monkeypatch.delenv("HAPTICSDK_CACHE_DIR", raising=False)
    assert cache_dir() == platformdirs.user_cache_path("hapticsdk", appauthor=False)


def test_prune_removes_the_oldest_until_it_fits(cdir):
    _fill(cdir / "amortised", 10, 10_000)
    removed = cache.prune(limit=5 * 10_000, root=cdir)
    left = sorted(p.name for p in (cdir / "amortised").iterdir())
    assert removed == 5 and left == [f"f{i:04d}" for i in range(5, 10)]   # the newest kept
    assert cache.info(cdir)["bytes"] <= 5 * 10_000


def test_empty_markers_count_a_block_each(cdir):
    _fill(cdir / "validated", 100, 0)
    assert cache.info(cdir)["bytes"] == 100 * cache.BLOCK_BYTES
    cache.prune(limit=10 * cache.BLOCK_BYTES, root=cdir)
    assert len(list((cdir / "validated").iterdir())) == 10


def test_a_write_into_the_cache_keeps_the_bound(cdir, monkeypatch):
    monkeypatch.setenv("HAPTICSDK_CACHE_MAX_MB", str(20 * cache.BLOCK_BYTES / 1e6))
    _fill(cdir / "validated", 50, 0)
    atomic_write_bytes(cdir / "validated" / "new", b"")
    names = {p.name for p in (cdir / "validated").iterdir()}
    assert "new" in names and len(names) <= 20
    assert (cdir / cache.TAG_NAME).is_file()


def test_validation_markers_do_not_pile_up(cdir, monkeypatch, tmp_path):
    from hapticsdk.schemas_io import load_json
    monkeypatch.setenv("HAPTICSDK_CACHE_MAX_MB", str(8 * cache.BLOCK_BYTES / 1e6))
    doc = {"schema_version": 1, "name": "s", "objects": [{"name": "pad", "material": "S7"}]}
    for i in range(30):
        doc["name"] = f"scene {i}"
        f = tmp_path / f"s{i}.json"
        f.write_text(json.dumps(doc))
        load_json(f, "scene")
    assert 1 <= len(list((cdir / "validated").iterdir())) <= 8


def test_clear_empties_and_refuses_a_foreign_folder(cdir, tmp_path, capsys):
    _fill(cdir / "amortised", 3, 100)
    assert main(["cache", "clear", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["removed_files"] == 3 and not (cdir / "amortised").exists()
    foreign = tmp_path / "Documents"
    _fill(foreign, 2, 10)
    with pytest.raises(ValueError, match="does not look like the hapticsdk cache"):
        cache.clear(foreign)
    assert len(list(foreign.iterdir())) == 2


def test_info_reports_the_bound(cdir, monkeypatch, capsys):
    monkeypatch.setenv("HAPTICSDK_CACHE_MAX_MB", "12.5")
    assert main(["cache", "info", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["path"] == str(cdir) and rep["max_bytes"] == 12_500_000


def test_prune_leaves_a_write_in_progress_alone(cdir):
    """A temporary file another writer is filling (``.<name>.<random>.tmp``) is neither
    counted nor removed: removing it would fail that writer's rename."""
    _fill(cdir / "amortised", 3, 10_000)
    busy = cdir / "onnx-desc" / ".abc.npz.k2j4h5g6.tmp"
    busy.parent.mkdir()
    busy.write_bytes(b"x" * 50_000)
    os.utime(busy, (1.0, 1.0))  # the oldest file of all
    assert cache.info(cdir)["bytes"] == 3 * 10_000
    cache.prune(limit=10_000, root=cdir)
    assert busy.is_file() and len(list((cdir / "amortised").iterdir())) == 1
