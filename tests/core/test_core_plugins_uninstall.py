"""Removing one plugin distribution removes exactly its entries from the listing.

The listing is read from installed metadata only; to check what an uninstall does
without touching the environment, a subprocess hides one distribution's metadata
(as ``pip uninstall`` would) and lists again.
"""

import json
import subprocess
import sys

import pytest

from hapticsdk.plugins import list_plugins

HIDE = r"""
import importlib.metadata as md, json, sys
hidden = sys.argv[1]
real = md.entry_points
def entry_points(**kw):
    eps = real(**kw)
    keep = [ep for ep in eps if ep.dist is None or ep.dist.metadata["Name"] != hidden]
    return md.EntryPoints(keep)
md.entry_points = entry_points
from hapticsdk.plugins import list_plugins
print(json.dumps(list_plugins()))
"""


@pytest.mark.parametrize("dist", ["hapticsdk-ga", "hapticsdk-roughness"])
def test_uninstalling_a_distribution_removes_exactly_its_entries(dist):
    before = {(r["kind"], r["name"], r["distribution"]) for r in list_plugins()}
    mine = {row for row in before if row[2] == dist}
    assert mine, f"{dist} is not installed"
    out = subprocess.run([sys.executable, "-c", HIDE, dist], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    after = {(r["kind"], r["name"], r["distribution"]) for r in json.loads(out.stdout)}
    assert before - after == mine
    assert after == before - mine
