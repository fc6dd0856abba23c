"""Start-up import structure of ``hapticsdk render`` (issue 16, item 6), without timing.

scipy costs 200-500 ms of import time (``scipy.linalg``, ``scipy.special``,
``scipy.interpolate`` and through them ``scipy.optimize`` and ``numpy.f2py``); the modules
the render path uses have numpy replacements (``hapticsdk.linalg.expm``,
``hapticsdk.special.gammainc2``, ``hapticsdk.interpolate``). These tests run the path in a
fresh interpreter and check which modules ended up imported. Timings are in
docs/runtime.md ("Start-up"), measured by hand.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

#: never imported by the render path (each is 20-300 ms of import time)
HEAVY = ("scipy", "numpy.f2py")

PROBE = r"""
import json, sys
{body}
heavy = sorted(m for m in sys.modules if m in {heavy!r} or any(m.startswith(h + ".") for h in {heavy!r}))
print(json.dumps(heavy))
"""


def _imported(body: str, heavy: tuple[str, ...] = HEAVY) -> list[str]:
    code = PROBE.format(body=body, heavy=heavy)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_passivity_simulated_arm_and_piezo_table_do_not_import_scipy():
    """Importing and using (expm, P(2, x), the piezo table's PCHIP, spline and inversion)
    the modules that used scipy on the render path."""
    body = """
import hapticsdk.passivity as p, hapticsdk.sim.arm as arm
from hapticsdk.sim import ArmParams, ArmSim
from hapticsdk.sim.finger import FINGERS
from hapticsdk.calibration import PiezoTable
from hapticsdk_roughness.table import generated_table
p.spectral_radius(1.0, 0.045, 0.5, 1e-3)
p.mass_correction(0.5, 1e-3, 0, 0.045)
ArmSim(ArmParams(), FINGERS["medium"]).step(1e-3, 0.5, 0.0, 0.0)
arm.dissipation_gramians(1e-3, [ArmParams()], [FINGERS["medium"]])
t = generated_table()
t.voltage_for(123.0, 5.0); t.acceleration_at(80.0, 33.3)
"""
    assert _imported(body) == []


def test_render_of_a_library_material_does_not_import_scipy():
    """The whole ``hapticsdk render S7`` (compile, solve, importance, renderers, servo
    loop; a short duration keeps the test fast, the imports do not depend on it)."""
    body = """
import contextlib, io
from hapticsdk.cli import main
with contextlib.redirect_stdout(io.StringIO()) as buf:
    code = main(["render", "S7", "--seconds", "0.05"])
assert code in (0, 1), code
assert "servo loop:" in buf.getvalue()
"""
    assert _imported(body) == []


def test_render_of_a_library_material_does_not_import_numpy_ma():
    """numpy's median and percentile import ``numpy.ma`` (~6-10 ms of start-up); the
    render path computes them with :mod:`hapticsdk.quantiles` (the same numbers, bit for
    bit), the importance estimate included (issue 30). numpy before 1.25 imports
    ``numpy.ma`` itself in ``import numpy`` (the oldest numpy the project allows is
    1.24): there the check has nothing to measure, and says so."""
    if _imported("import numpy", ("numpy.ma",)):
        pytest.skip("this numpy imports numpy.ma in `import numpy` itself (numpy < 1.25)")
    body = """
import contextlib, io
from hapticsdk.cli import main
with contextlib.redirect_stdout(io.StringIO()) as buf:
    code = main(["render", "S7", "--seconds", "0.05"])
assert code in (0, 1), code
"""
    assert _imported(body, ("numpy.ma",)) == []
