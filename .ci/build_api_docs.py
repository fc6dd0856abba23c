"""Build the API reference (HTML) from the docstrings with pdoc; any warning fails.

    python .ci/build_api_docs.py OUTDIR

Documents the core (``hapticsdk`` and its submodules) and the first-party plugins. pdoc
imports every module it documents: one that fails to import, a docstring it cannot
parse or a reference it cannot resolve is reported as a warning, and any warning is an
error here.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

MODULES = ["hapticsdk", "hapticsdk_ga", "hapticsdk_hardness", "hapticsdk_roughness", "hapticsdk_onnx"]


def modules() -> list[str]:
    """Specs for pdoc covering every public module (no ``_private`` part) of the
    documented packages once: pdoc walks the submodules of a package without ``__all__``
    by itself, so a submodule is added only when no spec covers it yet."""
    import importlib
    import pkgutil

    from pdoc.extract import walk_specs

    from hapticsdk._deprecation import MOVED_MODULES  # shims of moved modules: not documented

    wanted = []
    for top in MODULES:
        pkg = importlib.import_module(top)
        wanted.append(top)
        wanted += [i.name for i in pkgutil.walk_packages(pkg.__path__, prefix=top + ".")
                   if not any(part.startswith("_") for part in i.name.split("."))
                   and i.name not in MOVED_MODULES]
    specs: list[str] = []
    covered: set[str] = set()
    for name in wanted:
        if name not in covered:
            specs.append(name)
            covered = set(walk_specs(specs))
    for name in covered:  # lazy names (module __getattr__) resolved, so pdoc sees them
        mod = importlib.import_module(name)
        if "__getattr__" in vars(mod):
            for attr in getattr(mod, "__all__", []):
                vars(mod).setdefault(attr, getattr(mod, attr))
    return specs


def build(out: Path) -> list[str]:
    import pdoc
    import pdoc.render

    pdoc.render.configure(docformat="restructuredtext", show_source=False,
                          footer_text="hapticsdk API reference (generated from docstrings)")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pdoc.pdoc(*modules(), output_directory=out)
    return [f"{w.category.__name__}: {w.message} ({Path(w.filename).name}:{w.lineno})" for w in caught]


def main() -> int:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("build/api")
    problems = build(out)
    for p in problems:
        print("pdoc:", p, file=sys.stderr)
    pages = sorted(out.rglob("*.html"))
    print(f"pdoc: {len(pages)} pages in {out}, {len(problems)} warnings")
    return 1 if problems or not pages else 0


if __name__ == "__main__":
    sys.exit(main())
