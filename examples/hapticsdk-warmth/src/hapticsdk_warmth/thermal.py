"""Contact temperature of skin touching a material (two semi-infinite bodies).

When two bodies at temperatures ``T_skin`` and ``T_m`` touch, the interface settles at

    T_c = (e_skin * T_skin + e_m * T_m) / (e_skin + e_m)

with ``e = sqrt(k rho c)`` the thermal effusivity (J / (m^2 K s^0.5)). A metal (high
``e``) at room temperature pulls ``T_c`` towards its own temperature and feels cold; a
foam (low ``e``) lets ``T_c`` stay near skin temperature and feels warm. A Peltier
element renders a material by holding its surface at ``T_c`` while touched.
"""

from __future__ import annotations

import numpy as np

#: skin temperature of a fingertip (°C) and its effusivity (J/(m^2 K s^0.5)), textbook values
T_SKIN_C = 33.0
E_SKIN = 1100.0


def contact_temperature(t_surface_c: "float | np.ndarray", effusivity: "float | np.ndarray") -> np.ndarray:
    """``T_c`` (°C) for material surface temperature (°C) and effusivity, vectorised."""
    t = np.asarray(t_surface_c, float)
    e = np.asarray(effusivity, float)
    return (E_SKIN * T_SKIN_C + e * t) / (E_SKIN + e)
