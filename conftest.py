"""Suite-wide test set-up: the tests never touch the real home directory.

Before any test module is imported, ``HOME`` and the XDG base folders (which
``platformdirs`` and :func:`hapticsdk.fileio.cache_dir` follow on Linux) point into one
temporary folder for the session, inherited by every subprocess a test starts; it is
removed at the end. The SDK's own path and option variables (``HAPTICSDK_CACHE_DIR``,
``HAPTICSDK_CALIBRATION_DIR``, ``HAPTICSDK_DEVICE_CONFIG``, ...) are unset, so the tests
see the per-user defaults, inside that folder, whatever the developer's shell sets. ``tests/packaging/test_test_home.py`` checks it.

Property-based tests (hypothesis) draw the same examples on every run (profile
``derandomized``, the default), so the README's test command passes or fails the same way on
every machine. ``HYPOTHESIS_PROFILE=explore python -m pytest`` draws new examples each run
(a search for counterexamples, by hand; a failure it finds becomes a fixed example).
"""

from __future__ import annotations

import os
import shutil
import tempfile

_REAL_HOME = os.path.expanduser("~")
TEST_HOME = tempfile.mkdtemp(prefix="hapticsdk-test-home-")

#: the per-user base folders platformdirs reads on Linux (macOS and Windows derive theirs
#: from HOME / USERPROFILE / APPDATA / LOCALAPPDATA, set below too)
_XDG = {"XDG_CACHE_HOME": ".cache", "XDG_CONFIG_HOME": ".config", "XDG_DATA_HOME": ".local/share",
        "XDG_STATE_HOME": ".local/state", "XDG_RUNTIME_DIR": "run"}

os.environ["HOME"] = TEST_HOME
os.environ["USERPROFILE"] = TEST_HOME
os.environ["APPDATA"] = os.path.join(TEST_HOME, "AppData", "Roaming")
os.environ["LOCALAPPDATA"] = os.path.join(TEST_HOME, "AppData", "Local")
for _var, _sub in _XDG.items():
    _path = os.path.join(TEST_HOME, _sub)
    os.makedirs(_path, mode=0o700, exist_ok=True)
    os.environ[_var] = _path
for _var in ("HAPTICSDK_CACHE_DIR", "HAPTICSDK_CACHE_MAX_MB", "HAPTICSDK_CALIBRATION_DIR",
             "HAPTICSDK_DEVICE_CONFIG", "HAPTICSDK_DEVICE_OPTIONS"):
    os.environ.pop(_var, None)


from hypothesis import settings as _hyp_settings  # noqa: E402

_hyp_settings.register_profile("derandomized", derandomize=True)
_hyp_settings.register_profile("explore", derandomize=False)
_hyp_settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "derandomized"))


def pytest_report_header(config):  # noqa: ANN001, ANN201 - pytest hook
    return (f"hapticsdk tests: HOME and XDG folders in {TEST_HOME} (not {_REAL_HOME}); "
            f"hypothesis profile {os.environ.get('HYPOTHESIS_PROFILE', 'derandomized')}")


def pytest_unconfigure(config):  # noqa: ANN001, ANN201 - pytest hook
    shutil.rmtree(TEST_HOME, ignore_errors=True)
