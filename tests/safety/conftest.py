"""Every test under tests/safety runs with a temporary home: caches, calibrations and the
device configuration go to a folder of the test session, never to the real ``~``
(session scope, so module-scoped fixtures such as a live session are covered too)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session", autouse=True)
def _temporary_home(tmp_path_factory):
    home = tmp_path_factory.mktemp("home")
    mp = pytest.MonkeyPatch()
    mp.setenv("HOME", str(home))
    mp.setenv("XDG_CACHE_HOME", str(home / ".cache"))
    mp.setenv("XDG_CONFIG_HOME", str(home / ".config"))
    mp.setenv("HAPTICSDK_CACHE_DIR", str(home / ".cache" / "hapticsdk"))
    mp.setenv("HAPTICSDK_CALIBRATION_DIR", str(home / ".config" / "hapticsdk" / "calibration"))
    mp.delenv("HAPTICSDK_DEVICE_CONFIG", raising=False)
    mp.delenv("HAPTICSDK_DEVICE_OPTIONS", raising=False)
    yield home
    mp.undo()
