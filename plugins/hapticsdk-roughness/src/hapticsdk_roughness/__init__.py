"""hapticsdk-roughness: the roughness perception dimension and DRV2667 piezo actuators.

Entry points (see ``docs/architecture.md``):

* ``hapticsdk.dimensions``: ``roughness`` -> :class:`~hapticsdk_roughness.dimension.RoughnessDimension`
* ``hapticsdk.actuators``: ``piezo-virtual`` (simulated DRV2667 + piezo, default),
  ``piezo-serial`` (DRV2667 behind a serial I2C bridge), ``piezo-mcp2221`` (DRV2667 behind
  an MCP2221A USB-I2C bridge).

This module imports nothing: a scene that only uses the dimension or the virtual actuator
never imports ``serial`` or ``usb`` (the hardware transports import them inside their
``open``/``check_available``).
"""

__version__ = "0.2.0"
#: plugin API range this distribution was built for (checked when a plugin is loaded)
hapticsdk_api = ">=1.0,<2"
