"""No import cycle among the modules of hapticsdk (issue 29 item 7, asserted now).

Every import counts, at module level or inside a function (a lazy import is still a
dependency), except under ``if TYPE_CHECKING:`` (annotations only). Names resolved by
string are not imports: the lazy top level (``hapticsdk.__init__``'s table, the facade
over every stage) and the deprecation shims (``hapticsdk._deprecation``: a moved name
reached at its new place for one minor version, removed in 0.3).
"""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PKG = ROOT / "hapticsdk"


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(tree: ast.Module, module: str, is_pkg: bool, known: set[str]) -> set[str]:
    """Modules of hapticsdk that ``module`` imports (``known``: every module's name)."""
    out: set[str] = set()
    base = module.split(".") if is_pkg else module.split(".")[:-1]

    def visit(stmts: list[ast.stmt]) -> None:
        for node in stmts:
            if isinstance(node, ast.If) and _is_type_checking(node.test):
                visit(node.orelse)
                continue
            if isinstance(node, ast.Import):
                out.update(a.name for a in node.names if a.name.startswith("hapticsdk"))
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    target = ".".join(base[: len(base) - node.level + 1] + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                if target.startswith("hapticsdk"):
                    subs = {f"{target}.{a.name}" for a in node.names} & known
                    out.update(subs)          # `from . import sub`: the submodule (its package
                    if len(subs) < len(node.names):   # runs first anyway), else the module
                        out.add(target)
            else:   # function and class bodies, loops, with, try, if: every nested statement
                for field in ("body", "orelse", "finalbody", "handlers"):
                    block = getattr(node, field, None)
                    if isinstance(block, list):
                        visit([b for b in block if isinstance(b, ast.stmt)])
                        for h in block:
                            if isinstance(h, ast.ExceptHandler):
                                visit(h.body)
                if isinstance(node, ast.Match):
                    for case in node.cases:
                        visit(case.body)
    visit(tree.body)
    return out


@functools.lru_cache(maxsize=None)
def _parsed_graph() -> dict[str, frozenset[str]]:
    """The graph, each file of the core parsed once per session (the tests below all read
    it; the files do not change while the suite runs)."""
    files = {_module_name(p): p for p in PKG.rglob("*.py")}
    graph: dict[str, frozenset[str]] = {}
    for mod, path in files.items():
        deps = _imports(ast.parse(path.read_text(encoding="utf-8")), mod, path.name == "__init__.py", set(files))
        graph[mod] = frozenset(d for d in deps if d in files and d != mod)
    return graph


def import_graph() -> dict[str, set[str]]:
    """Module -> the core's modules it imports; a fresh copy for each caller."""
    return {mod: set(deps) for mod, deps in _parsed_graph().items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def strong(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    import sys
    old = sys.getrecursionlimit()
    sys.setrecursionlimit(max(old, 10000))
    try:
        for v in sorted(graph):
            if v not in index:
                strong(v)
    finally:
        sys.setrecursionlimit(old)
    return out


def test_the_graph_sees_imports():
    g = import_graph()
    assert "hapticsdk.errors" in g["hapticsdk.perception.features"]
    assert "hapticsdk.perception.features" in g["hapticsdk.perception.dimensions"]
    assert "hapticsdk.perception.channels" in g["hapticsdk.devices.actuators"]
    assert "hapticsdk.devices.actuators" in g["hapticsdk.runtime.loop"]
    assert g["hapticsdk.compiler"] >= {"hapticsdk.compiler.compile"}


def test_the_graph_covers_the_whole_core():
    """Every module file of the core is a node (subpackages, shims and ``__init__`` files
    included), so a cycle anywhere in ``hapticsdk`` is seen."""
    files = {_module_name(p) for p in PKG.rglob("*.py")}
    graph = import_graph()
    assert set(graph) == files
    assert len(files) > 100                      # the core, not a folder of it
    for sub in ("hapticsdk.runtime.session", "hapticsdk.scene.model", "hapticsdk.cli.core",
                "hapticsdk.testing.conformance", "hapticsdk.interop.hjif_model",
                "hapticsdk.perception.features", "hapticsdk.perception.dimensions",
                "hapticsdk.testing.conformance.runner", "hapticsdk.testing.conformance.actuator_rules"):
        assert sub in graph


def test_no_import_cycle():
    found = cycles(import_graph())
    assert not found, "import cycles: " + "; ".join(" <-> ".join(c) for c in found)


#: the request's path as dependencies: perception (features, dimensions, models,
#: materials, channels: what every later stage speaks in), the devices (actuators, safety,
#: device options: scene, plan and compiler read the device options, the runtime drives the
#: actuators; devices are the request's last stage but import only perception), a scene, the solvers (targets -> features, which
#: the plan's model provenance and the compiler call), the plan (the data the compiler
#: makes), the compiler, the runtime; a stage may import an earlier one, never a later one
STAGES = ("hapticsdk.perception", "hapticsdk.devices", "hapticsdk.scene", "hapticsdk.solvers", "hapticsdk.plan", "hapticsdk.compiler", "hapticsdk.runtime")


def _stage(mod: str) -> int | None:
    for i, st in enumerate(STAGES):
        if mod == st or mod.startswith(st + "."):
            return i
    return None


def test_no_stage_imports_a_later_stage():
    upward = []
    for mod, deps in import_graph().items():
        s = _stage(mod)
        if s is None:
            continue
        upward += [f"{mod} -> {d}" for d in sorted(deps) if (_stage(d) or -1) > s]
    order = " -> ".join(s.removeprefix("hapticsdk.") for s in STAGES)
    assert not upward, f"upward imports along {order}: " + "; ".join(upward)


#: the first-party plugins and the example plugin: they import the core's new places too
PLUGIN_PACKAGES = ("hapticsdk_ga", "hapticsdk_onnx", "hapticsdk_roughness", "hapticsdk_hardness", "hapticsdk_warmth")


def test_the_project_imports_no_deprecated_path():
    """Every module of the core and of the plugins imports under
    ``-W error::DeprecationWarning``: the project's own code uses the new places, never
    a shim (the shims themselves are left out). A plugin module that needs an optional
    library missing here is skipped by its ImportError; only the warning fails."""
    import subprocess
    import sys

    from hapticsdk._deprecation import MOVED_MODULES
    mods = sorted(m for m in import_graph() if m not in MOVED_MODULES and not m.endswith("__main__"))
    code = ("import importlib, pkgutil, sys, warnings\n"
            "warnings.simplefilter('error', DeprecationWarning)\n"
            "bad = []\n"
            "def load(m):\n"
            "    try:\n"
            "        return importlib.import_module(m)\n"
            "    except DeprecationWarning as e:\n"
            "        bad.append(f'{m}: {e}')\n"
            "    except ImportError:\n"
            "        return None\n"
            f"for m in {mods!r}:\n"
            "    load(m)\n"
            f"for top in {PLUGIN_PACKAGES!r}:\n"
            "    pkg = load(top)\n"
            "    for info in pkgutil.walk_packages(getattr(pkg, '__path__', []), top + '.'):\n"
            "        load(info.name)\n"
            "print('\\n'.join(bad)); sys.exit(1 if bad else 0)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=240)
    assert r.returncode == 0, r.stdout + r.stderr[-2000:]


def test_the_checks_catch_a_cycle_and_an_upward_edge():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _stage("hapticsdk.runtime.render") > _stage("hapticsdk.scene.model")
    assert _stage("hapticsdk.scene.model") > _stage("hapticsdk.perception.materials")
    assert _stage("hapticsdk.perception.channels") < _stage("hapticsdk.devices.actuators") < _stage("hapticsdk.scene")


#: where the repository's own code lives besides the core: every file there is read
REPO_CODE = ("hapticsdk", "plugins", "examples", "tests", "bench", "docs", ".ci", "README.md")


def _repo_files() -> list[Path]:
    out: list[Path] = []
    for top in REPO_CODE:
        p = ROOT / top
        files = [p] if p.is_file() else [*p.rglob("*.py"), *p.rglob("*.md")]
        out += [f for f in files if not any(part in (".venv", "build", "node_modules") or part.endswith(".egg-info")
                                            for part in f.relative_to(ROOT).parts)]
    return out


def moved_imports(path: Path, text: str, moved: dict[str, str]) -> list[str]:
    """The imports of a module path in ``moved`` (old -> new) that ``path`` makes: every
    ``import``/``from`` statement of a Python file (relative ones resolved inside the
    core), and of the Python code blocks of a Markdown page."""
    def old(name: str) -> str | None:
        return next((o for o in moved if name == o or name.startswith(o + ".")), None)

    if path.suffix == ".md":
        hits = re.findall(r"^\s*(?:from|import)\s+(hapticsdk(?:\.\w+)+)", text, re.M)
        hits += [f"hapticsdk.{m}" for line in re.findall(r"^\s*from\s+hapticsdk\s+import\s+(.+)$", text, re.M)
                 for m in re.split(r"\s*,\s*", line.strip("() "))]
        return [h for h in hits if old(h)]
    rel = path.relative_to(ROOT)
    mod = _module_name(path) if rel.parts[0] == "hapticsdk" else None
    base = (mod.split(".") if path.name == "__init__.py" else mod.split(".")[:-1]) if mod else []
    out = []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names if old(a.name)]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                if not base:
                    continue
                target = ".".join(base[: len(base) - node.level + 1] + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            names = [target] + [f"{target}.{a.name}" for a in node.names]
            out += [n for n in names if old(n) and (n == target or old(n) == n)]
    return out


def test_no_file_of_the_repository_imports_a_moved_module():
    """Core, plugins, examples, tests, benchmarks, CI scripts and the docs' code use the
    new places; only the shims themselves and the tests of the deprecation (which import
    the old paths by string, on purpose) name the old ones."""
    from hapticsdk._deprecation import MOVED_MODULES
    shims = {ROOT / (old.replace(".", "/") + ".py") for old in MOVED_MODULES}
    on_purpose = {ROOT / "tests" / "core" / "test_deprecated_names.py"}   # imports the old paths to test them
    bad = []
    for f in _repo_files():
        if f in shims | on_purpose:
            continue
        found = moved_imports(f, f.read_text(encoding="utf-8"), MOVED_MODULES)
        bad += [f"{f.relative_to(ROOT)}: {name} (now {MOVED_MODULES[name]})" for name in found]
    assert not bad, "imports of moved modules:\n" + "\n".join(bad)


def test_the_moved_import_scan_sees_every_form():
    moved = {"hapticsdk.features": "hapticsdk.perception.features"}
    core = PKG / "scene" / "model.py"
    py = ("from hapticsdk.features import Feature\nimport hapticsdk.features\n"
          "from hapticsdk import features\nfrom ..features import FeatureSpace\n"
          "from hapticsdk.perception.features import Feature\nfrom hapticsdk import scene\n")
    assert moved_imports(core, py, moved) == ["hapticsdk.features"] * 4
    md = "```python\nfrom hapticsdk.features import Feature\nfrom hapticsdk import scene, features\n```\n"
    assert moved_imports(ROOT / "docs" / "x.md", md, moved) == ["hapticsdk.features"] * 2
