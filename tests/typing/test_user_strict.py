"""A user's ``mypy --strict`` accepts ``hs.<name>`` for every name of ``hapticsdk.__all__``
(issue 29): the names are re-exported explicitly, ``__all__`` is a literal list."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

import hapticsdk as hs

ROOT = Path(__file__).resolve().parents[2]


def test_all_is_a_literal_and_matches_the_lazy_table():
    tree = ast.parse((ROOT / "hapticsdk" / "__init__.py").read_text())
    (node,) = [n for n in tree.body if isinstance(n, ast.Assign)
               and any(isinstance(t, ast.Name) and t.id == "__all__" for t in n.targets)]
    literal = ast.literal_eval(node.value)          # raises if computed
    assert sorted(literal) == sorted([*hs._LAZY, "render", "__version__"])  # noqa: SLF001
    for name in literal:
        assert getattr(hs, name) is not None


def test_mypy_strict_accepts_every_public_name(tmp_path):
    if subprocess.run([sys.executable, "-c", "import mypy"], capture_output=True).returncode:
        if os.environ.get("CI") == "true":
            pytest.fail("mypy is not installed (requirements-dev.txt installs it)")
        pytest.skip("mypy is not installed (pip install mypy)")
    names = [n for n in hs.__all__ if n != "__version__"]
    user = tmp_path / "user_script.py"
    user.write_text("import hapticsdk as hs\n\n"
                    "res = hs.solve({'hardness': 0.8, 'roughness': 0.3}, seed=1)\n"
                    "print(res.success, res.x_dict, hs.__version__)\n"
                    + "".join(f"print(hs.{n})\n" for n in names))
    cfg = tmp_path / "mypy.ini"
    cfg.write_text("[mypy]\n")                       # the user's settings, not the project's
    # the source tree on MYPYPATH (mypy cannot follow an editable install's import hook);
    # follow_imports=silent: the SDK's own modules are checked by CI, this is the user's view
    env = dict(os.environ, MYPYPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-m", "mypy", "--strict", "--follow-imports=silent",
                        "--config-file", str(cfg), "--cache-dir", str(tmp_path / "cache"), str(user)],
                       capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
