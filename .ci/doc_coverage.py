"""Count public names without a docstring.

    python .ci/doc_coverage.py [--list] [PACKAGE ...]   (default: hapticsdk and the plugins)

A public name is a module, or a class / function / method / property defined in a public
module (no ``_private`` part in its dotted path) whose name does not start with ``_``;
inherited members and re-exports are counted where they are defined. Exit status 1 when
any has no docstring (an inherited docstring counts for an overriding method).
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import sys

DEFAULT = ["hapticsdk", "hapticsdk_ga", "hapticsdk_hardness", "hapticsdk_roughness", "hapticsdk_onnx"]


def _modules(top: str) -> list:
    pkg = importlib.import_module(top)
    mods = [pkg]
    for info in pkgutil.walk_packages(pkg.__path__, prefix=top + "."):
        if not any(p.startswith("_") for p in info.name.split(".")):
            mods.append(importlib.import_module(info.name))
    return mods


def _inherited_doc(cls: type, name: str) -> bool:
    for base in cls.__mro__[1:]:
        member = base.__dict__.get(name)
        if member is not None and inspect.getdoc(member):
            return True
    return False


def public_names(top: str) -> list[tuple[str, bool]]:
    """(dotted name, has a docstring) for every public name of package ``top``."""
    out = []
    for mod in _modules(top):
        out.append((mod.__name__, bool(mod.__doc__ and mod.__doc__.strip())))
        for name, obj in vars(mod).items():
            if name.startswith("_") or getattr(obj, "__module__", None) != mod.__name__:
                continue
            if not (inspect.isclass(obj) or inspect.isfunction(obj)):
                continue
            out.append((f"{mod.__name__}.{name}", bool(obj.__doc__ and obj.__doc__.strip())))
            if inspect.isclass(obj):
                for mname, member in vars(obj).items():
                    if mname.startswith("_"):
                        continue
                    func = member.fget if isinstance(member, property) else getattr(member, "__func__", member)
                    if not (inspect.isfunction(func) or isinstance(member, property)):
                        continue
                    doc = bool(func.__doc__ and func.__doc__.strip()) or _inherited_doc(obj, mname)
                    out.append((f"{mod.__name__}.{name}.{mname}", doc))
    return out


def main(argv: list[str]) -> int:
    show = "--list" in argv
    tops = [a for a in argv if not a.startswith("-")] or DEFAULT
    missing_total = 0
    for top in tops:
        names = public_names(top)
        missing = [n for n, ok in names if not ok]
        missing_total += len(missing)
        print(f"{top}: {len(missing)} of {len(names)} public names without a docstring")
        if show:
            for n in missing:
                print("   ", n)
    return 1 if missing_total else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
