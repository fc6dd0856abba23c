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
