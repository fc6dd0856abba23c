"""Every name a benchmark script under ``bench/`` takes from ``hapticsdk`` exists, without
a ``DeprecationWarning``.

The benchmark scripts are run by hand, never by the suite (speed and memory goals are not
timed tests), so a module that moved broke one unnoticed: ``bench_batch_memory.py`` read
``hapticsdk.solvers._BatchData`` after the solvers became a package, and stopped with an
``AttributeError`` before its first chunk. This test reads each script's syntax tree
instead of running it: every ``from hapticsdk... import name`` and every ``module.name``
where ``module`` was bound by an import of a ``hapticsdk`` module must resolve (an
attribute of the module, or a submodule that imports).
"""

from __future__ import annotations

import ast
import importlib
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = sorted((ROOT / "bench").glob("*.py"))


def _resolve(module: str, name: str) -> str | None:
    """None when ``module.name`` exists without a DeprecationWarning, else why not."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        try:
            mod = importlib.import_module(module)
            if hasattr(mod, name):
                getattr(mod, name)
                return None
            importlib.import_module(f"{module}.{name}")
            return None
        except DeprecationWarning as w:
            return f"{module}.{name} is deprecated: {w}"
        except ImportError as exc:
            return f"{module}.{name} does not exist ({exc})"


def references(tree: ast.AST) -> list[tuple[int, str, str]]:
    """``(line, module, name)`` for each name the script takes from a hapticsdk module."""
    bound: dict[str, str] = {}     # local name -> the hapticsdk module it is bound to
    refs: list[tuple[int, str, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "hapticsdk":
                    if a.asname:
                        bound[a.asname] = a.name
                    else:
                        bound["hapticsdk"] = "hapticsdk"
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module \
                and node.module.split(".")[0] == "hapticsdk":
            for a in node.names:
                refs.append((node.lineno, node.module, a.name))
                # the name may itself be a module (``from hapticsdk import solvers``)
                try:
                    sub = importlib.import_module(f"{node.module}.{a.name}")
                except ImportError:
                    continue
                bound[a.asname or a.name] = sub.__name__
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                and node.value.id in bound:
            refs.append((node.lineno, bound[node.value.id], node.attr))
    return refs


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: p.name)
def test_every_hapticsdk_name_a_benchmark_script_uses_exists(path: Path) -> None:
    refs = references(ast.parse(path.read_text(), str(path)))
    bad = [f"line {line}: {why}" for line, mod, name in refs
           if (why := _resolve(mod, name)) is not None]
    assert not bad, f"{path.name}: " + "; ".join(bad)


def test_the_check_finds_a_name_that_moved() -> None:
    # the defect this test was written for, and its import forms
    for src in ("from hapticsdk import solvers\nsolvers._BatchData.add\n",
                "import hapticsdk.solvers as s\ns._NoSuchThing\n",
                "from hapticsdk.solvers import _NoSuchThing\n"):
        refs = references(ast.parse(src))
        assert any(_resolve(m, n) for _, m, n in refs), src
    ok = "from hapticsdk.solvers import base\nbase._BatchData.add\n"
    assert all(_resolve(m, n) is None for _, m, n in references(ast.parse(ok)))


def test_there_are_scripts_to_check() -> None:
    assert len(SCRIPTS) >= 10
