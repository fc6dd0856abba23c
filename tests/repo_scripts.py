"""Load a script of the repository that is not in a package (``.ci/api_check.py``,
``.ci/check_floors.py``) as a module, for the tests that check its rules.

Importable as ``repo_scripts`` through ``tests/conftest.py``."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

#: the repository's root folder
ROOT = Path(__file__).resolve().parents[1]


def load_script(relpath: str) -> ModuleType:
    """The script at ``ROOT / relpath``, executed as a fresh module named after its file."""
    path = ROOT / relpath
    spec = importlib.util.spec_from_file_location(path.stem, path)
    assert spec is not None and spec.loader is not None, path
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
