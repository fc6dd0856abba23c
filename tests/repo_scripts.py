"""Load a script of the repository that is not in a package (``.ci/api_check.py``,
``.ci/check_floors.py``) as a module, for the tests that check its rules.

Importable as ``repo_scripts`` through ``tests/conftest.py``."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path
from types import ModuleType

#: the repository's root folder
ROOT = Path(__file__).resolve().parents[1]


def load_script(relpath: str) -> ModuleType:
    """The script at ``ROOT / relpath``, executed as a fresh module named after its file.

    The process environment is left as it was: a script run as a program may set
    variables for itself at import (the benches' ``OMP_NUM_THREADS=1``), which would
    otherwise reach every later test and the subprocesses they start."""
    path = ROOT / relpath
    spec = importlib.util.spec_from_file_location(path.stem, path)
    assert spec is not None and spec.loader is not None, path
    mod = importlib.util.module_from_spec(spec)
    before = dict(os.environ)
    try:
        spec.loader.exec_module(mod)
    finally:
        if dict(os.environ) != before:
            os.environ.clear()
            os.environ.update(before)
    return mod
