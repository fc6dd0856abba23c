"""A GENERATED perception model of warmth (no human ratings were used).

``warmth = 1 / (1 + exp(-(T_c - T50) / S))`` with ``T_c`` the contact temperature
(:func:`hapticsdk_warmth.thermal.contact_temperature`) of the features ``Tsurf`` (°C) and
``Eff`` (J/(m^2 K s^0.5)). ``T50 = 30.5 °C`` (neither warm nor cool: a little below skin
temperature) and ``S = 2.0 °C`` are ASSUMED parameters chosen so that aluminium at 22 °C
rates about 0.01, wood at 22 °C about 0.3 and foam at 30 °C about 0.75; they are not
fitted to measurements. The model is published under ``hapticsdk.models: warmth`` and
named by ``WarmthDimension.default_model``; the core combines it with the
hardness/roughness model in a :class:`~hapticsdk.perception.models.CompositeModel`.
"""

from __future__ import annotations

import numpy as np

from hapticsdk.perception.features import Feature, FeatureSpace
from hapticsdk.perception.models import PerceptionModel

from .thermal import contact_temperature

#: logistic midpoint (°C) and slope (°C): assumed, see the module docstring
T50_C = 30.5
SLOPE_C = 2.0

FEATURES = (
    Feature("Tsurf", "degC", 15.0, 40.0, "surface temperature of the material before contact"),
    Feature("Eff", "J/(m^2 K s^0.5)", 100.0, 20000.0, "thermal effusivity sqrt(k rho c) of the material"),
)


class WarmthModel(PerceptionModel):
    """Warmth (0..1) from ``[Tsurf, Eff]``, vectorised, analytic Jacobian."""

    hapticsdk_api = ">=1.0,<2"

    def __init__(self) -> None:
        space = FeatureSpace(FEATURES)
        super().__init__(space.names, ("warmth",), feature_space=space, name="warmth", metadata={
            "feature_defaults": {"Tsurf": 24.0, "Eff": 600.0},
            "data_generated": True,
            "source": "GENERATED analytic model (hapticsdk_warmth.model), assumed parameters "
                      f"T50={T50_C} degC, S={SLOPE_C} degC; not fitted to ratings",
        })

    def _predict(self, X: np.ndarray) -> np.ndarray:
        tc = contact_temperature(X[:, 0], X[:, 1])
        return (1.0 / (1.0 + np.exp(-(tc - T50_C) / SLOPE_C)))[:, None]

    def jacobian(self, G: np.ndarray, **_: object) -> np.ndarray:
        from .thermal import E_SKIN, T_SKIN_C
        X = np.atleast_2d(np.asarray(G, float))
        t, e = X[:, 0], X[:, 1]
        y = self._predict(X)[:, 0]
        dy_dtc = y * (1 - y) / SLOPE_C
        dtc_dt = e / (E_SKIN + e)
        dtc_de = E_SKIN * (t - T_SKIN_C) / (E_SKIN + e) ** 2
        return np.stack([dy_dtc * dtc_dt, dy_dtc * dtc_de], axis=1)[:, None, :]


def load_model() -> WarmthModel:
    """Entry point ``hapticsdk.models: warmth`` (zero-argument factory)."""
    return WarmthModel()
