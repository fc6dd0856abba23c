"""Build every distribution of this repository (wheel and sdist) with the build backend
installed in this environment (no build isolation) and check what a user gets:

* the wheel holds ``py.typed`` next to the package and the LICENSE in its metadata;
* its METADATA has ``License-Expression: MIT``, a summary, a README (description),
  classifiers and project URLs; a first-party plugin requires a bounded ``hapticsdk``;
* the sdist holds README.md and LICENSE.

    python .ci/check_dists.py OUTDIR
"""

from __future__ import annotations

import email
import shutil
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DISTS = {
    ".": "hapticsdk",
    "plugins/hapticsdk-onnx": "hapticsdk_onnx",
    "plugins/hapticsdk-ga": "hapticsdk_ga",
    "plugins/hapticsdk-hardness": "hapticsdk_hardness",
    "plugins/hapticsdk-roughness": "hapticsdk_roughness",
    "examples/hapticsdk-warmth": "hapticsdk_warmth",
}


def _copy(src: str, out: Path) -> Path:
    """A copy of one distribution's source to build from (builds leave build/ and
    egg-info directories behind; the working tree stays clean)."""
    skip = shutil.ignore_patterns(".git", "build", "dist", "*.egg-info", "__pycache__", ".venv",
                                  *(["plugins", "examples", "tests", "docs", "bench"] if src == "." else []))
    dest = out / "src" / (Path(src).name if src != "." else "hapticsdk")
    shutil.copytree(ROOT / src, dest, ignore=skip)
    return dest


def check(src: str, pkg: str, out: Path) -> list[str]:
    dest = out / pkg
    dest.mkdir(parents=True)
    tree = _copy(src, out)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation",
                    "--wheel-dir", str(dest), str(tree)], check=True)
    # sdist through the PEP 517 hook of the same backend
    code = ("import os, sys; from setuptools import build_meta as b; os.chdir(sys.argv[1]); "
            "print(b.build_sdist(sys.argv[2]))")
    subprocess.run([sys.executable, "-c", code, str(tree), str(dest)], check=True,
                   capture_output=True)
    errs: list[str] = []
    (whl,) = dest.glob("*.whl")
    (sdist,) = dest.glob("*.tar.gz")
    with zipfile.ZipFile(whl) as z:
        names = z.namelist()
        if f"{pkg}/py.typed" not in names:
            errs.append(f"{whl.name}: no {pkg}/py.typed")
        if not any(n.endswith(".dist-info/licenses/LICENSE") for n in names):
            errs.append(f"{whl.name}: no LICENSE in .dist-info/licenses")
        meta = email.message_from_bytes(z.read(next(n for n in names if n.endswith(".dist-info/METADATA"))))
    if meta.get("License-Expression") != "MIT":
        errs.append(f"{whl.name}: License-Expression is {meta.get('License-Expression')!r}")
    if meta.get("License"):
        errs.append(f"{whl.name}: deprecated License field present")
    for field in ("Summary", "Author", "Classifier", "Project-URL"):
        if not meta.get_all(field):
            errs.append(f"{whl.name}: no {field}")
    if len(meta.get_payload() or "") < 200:
        errs.append(f"{whl.name}: no README in the long description")
    if pkg != "hapticsdk":
        core = [r for r in meta.get_all("Requires-Dist") or [] if r.split()[0].rstrip("<>=,") == "hapticsdk"
                or r.startswith("hapticsdk<") or r.startswith("hapticsdk>")]
        if not core or "<" not in core[0] or ">=" not in core[0]:
            errs.append(f"{whl.name}: requires an unbounded hapticsdk ({core})")
    with tarfile.open(sdist) as t:
        base = {Path(n).relative_to(Path(n).parts[0]).as_posix() for n in t.getnames() if len(Path(n).parts) > 1}
    for need in ("README.md", "LICENSE", "pyproject.toml"):
        if need not in base:
            errs.append(f"{sdist.name}: no {need}")
    return errs


def main() -> int:
    out = Path(sys.argv[1])
    errs: list[str] = []
    for src, pkg in DISTS.items():
        errs.extend(check(src, pkg, out))
    for e in errs:
        print("dists:", e, file=sys.stderr)
    if not errs:
        import setuptools
        print(f"dists: {len(DISTS)} wheels and sdists built with setuptools {setuptools.__version__}: "
              "py.typed, LICENSE, License-Expression, README, classifiers, URLs, hapticsdk range")
    return 1 if errs else 0


if __name__ == "__main__":
    sys.exit(main())
