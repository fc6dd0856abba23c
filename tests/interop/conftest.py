"""The interop tests share the document builders of ``hjif_docs.py`` (the suite runs with
``--import-mode=importlib``, which puts no test folder on ``sys.path``)."""

import sys
from pathlib import Path

_HERE = str(Path(__file__).resolve().parent)
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)


import pytest  # noqa: E402


@pytest.fixture(autouse=True, scope="module")
def _no_real_home(tmp_path_factory):
    """The interop tests compile scenes and play content: every cache they write (the
    SDK's, onnxruntime's) goes to a temporary home, never the real one (module scope, so
    it is in place before the module-scoped plan fixtures run)."""
    home = tmp_path_factory.mktemp("home")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("HOME", str(home))
        mp.setenv("XDG_CACHE_HOME", str(home / ".cache"))
        mp.setenv("HAPTICSDK_CACHE_DIR", str(home / ".cache" / "hapticsdk"))
        yield home
