"""Puts ``tests/`` on ``sys.path`` for the builders shared across test folders
(``kit_variants.py``, ``repo_scripts.py``): the suite runs with ``--import-mode=importlib``, which puts no
test folder there."""

import sys
from pathlib import Path

_HERE = str(Path(__file__).resolve().parent)
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)
