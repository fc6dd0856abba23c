"""The suite runs with its own home (root conftest.py): no test reads or writes the real
one (issue 29 item 4 / issue 31 item 9)."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import platformdirs

from hapticsdk.calibration.store import calibration_dir
from hapticsdk.devices.device_options import device_config_path
from hapticsdk.fileio import cache_dir


def _under_test_home(p: Path) -> bool:
    home = Path(os.environ["HOME"]).resolve()
    return Path(p).resolve().is_relative_to(home)


def test_home_and_user_folders_are_a_temporary_folder():
    home = Path(os.environ["HOME"]).resolve()
    assert home.name.startswith("hapticsdk-test-home-")
    assert home.is_relative_to(Path(tempfile.gettempdir()).resolve())
    assert Path.home().resolve() == home
    for p in (cache_dir(), calibration_dir(), device_config_path(), platformdirs.user_cache_path("x"),
              platformdirs.user_config_path("x"), platformdirs.user_data_path("x")):
        assert _under_test_home(p), p


def test_a_subprocess_inherits_the_test_home():
    out = subprocess.run([sys.executable, "-c", "from hapticsdk.fileio import cache_dir; print(cache_dir())"],
                         capture_output=True, text=True, timeout=60)
    assert _under_test_home(Path(out.stdout.strip())) and "hapticsdk-test-home-" in out.stdout, out
