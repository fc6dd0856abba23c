"""What a fresh ``hapticsdk render S7`` process does besides rendering (issue 30, round 7),
checked without timing: each test names work the process used to do and no longer needs.
Timings are in docs/runtime.md ("Start-up"), measured by hand.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

#: prints, from the last ``atexit`` handler (after ``run()`` returned), how many objects
#: were frozen and that the handlers still ran
EXIT_PROBE = r"""
import atexit, gc, json, runpy, sys
atexit.register(lambda: print(json.dumps({"frozen": gc.get_freeze_count()})))
sys.argv = ["hapticsdk", "render", "S7", "--seconds", "0.05"]
CALL
"""


def _exit_probe(call: str) -> tuple[int, dict[str, int], str]:
    code = EXIT_PROBE.replace("CALL", call)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    return out.returncode, json.loads(out.stdout.strip().splitlines()[-1]), out.stdout


@pytest.mark.parametrize("module", ["hapticsdk", "hapticsdk.cli"])
def test_the_command_skips_the_last_collection_at_exit(module):
    """``python -m hapticsdk`` (and ``-m hapticsdk.cli``) exits through ``run()``, which
    freezes the heap once the command is done (the interpreter's last full collection and
    the freeing of every cycle cost 25-35 ms of a render); the exit status, the output and
    the ``atexit`` handlers (the probe's own, and the actuators' ``stop_all``) are
    unchanged."""
    rc, got, stdout = _exit_probe(f"runpy.run_module({module!r}, run_name='__main__')")
    assert rc == 0
    assert "servo loop:" in stdout
    assert got["frozen"] > 1000   # the whole heap: modules, classes, functions


def test_main_called_in_process_does_not_freeze():
    """An application or a test calling ``main()`` keeps a normal heap afterwards."""
    rc, got, _ = _exit_probe("from hapticsdk.cli import main\nsys.exit(main())")
    assert rc == 0
    assert got["frozen"] == 0


def test_the_installed_script_exits_through_run():
    """The ``hapticsdk`` script runs ``hapticsdk.cli:run`` (``main`` plus the exit above),
    as ``python -m hapticsdk`` does."""
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["hapticsdk"] == "hapticsdk.cli:run"


#: imported by no ``render S7`` that finds its caches (each 5-120 ms of import time):
#: the entry-point scan's metadata reader and its mail parser (the plugin index), the
#: schema validator (validation markers), the ONNX readers (model description and chain)
#: and the plotting library (only with --plot)
NOT_ON_A_CACHED_RENDER = ("importlib.metadata", "email", "jsonschema", "onnx", "onnxruntime", "matplotlib",
                          "scipy")

RENDER_PROBE = r"""
import json, runpy, sys
sys.argv = ["hapticsdk", "render", "S7", "--seconds", "0.05"]
try:
    runpy.run_module("hapticsdk", run_name="__main__")
finally:
    sys.stderr.write(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in NAMES
                                       or m in NAMES)) + "\n")
"""


def test_a_render_that_finds_its_caches_imports_none_of_the_heavy_readers(tmp_path):
    """Two fresh ``python -m hapticsdk render S7`` processes with an empty cache folder:
    the first fills it (scans entry points, validates the library, reads the model), the
    second imports none of :data:`NOT_ON_A_CACHED_RENDER` and prints the same report."""
    import os

    env = {**os.environ, "HAPTICSDK_CACHE_DIR": str(tmp_path)}
    code = RENDER_PROBE.replace("NAMES", repr(NOT_ON_A_CACHED_RENDER))
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
            for _ in range(2)]
    for out in runs:
        assert out.returncode == 0, out.stderr[-3000:]
    first, second = (json.loads(out.stderr.strip().splitlines()[-1]) for out in runs)
    assert "importlib.metadata" in first          # the first run had to scan
    assert second == []
    strip = [[ln.split(" in ")[0] for ln in out.stdout.splitlines() if not ln.startswith("servo loop")]
             for out in runs]
    assert strip[0] == strip[1]
