"""The simulated Omni's damping measured hands off, shared by the runtime tests.

Importable as ``omni_fits`` through ``tests/conftest.py``."""

from __future__ import annotations

import functools


@functools.lru_cache(maxsize=None)
def measured(damping: float):
    """The fit of a hands-off measurement of the simulated Omni with ``damping`` N s/m (a
    :class:`~hapticsdk.calibration.damping.DampingCalibration`, generated)."""
    from hapticsdk.calibration.damping import DampingCalibration, measure_damping
    from hapticsdk.sim.finger import FingerParams
    from hapticsdk_hardness.omni import OmniVirtual

    free = OmniVirtual(finger=FingerParams(0.0, 0.0, 0.0), damping_ns_per_m=damping)
    fit, _, _ = measure_damping(free)
    return DampingCalibration.from_fit(fit, period_s=1e-3, resolution_mm=free.encoder_resolution_mm,
                                       generated=True, source="test: simulated Omni, hands off")
