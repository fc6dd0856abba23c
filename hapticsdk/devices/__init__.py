"""Devices: the actuators a plan drives, the safety layer between them and the plan,
and the device options that a configuration names.

* :mod:`~hapticsdk.devices.actuators`: ``Actuator``, ``HapticDevice`` (the base classes
  actuator plugins subclass), ``DeviceState``, ``SensedState``, ``create_actuator``;
* :mod:`~hapticsdk.devices.safety`: ``SafetyLayer``, ``SafetySettings``, the declared
  limits and the stop paths;
* :mod:`~hapticsdk.devices.device_options`: declared device options, the privileged ones
  (options that name code or files) and where their values may come from.

Devices are the last stage of a request (scene -> compile -> plan -> runtime ->
devices), but the first one above :mod:`hapticsdk.perception` in the import order:
scene, plan, compiler and runtime import them, and they import no stage above
perception. The modules were ``hapticsdk.actuators``, ``hapticsdk.safety`` and
``hapticsdk.device_options`` until 0.2; those names still import, with a
``DeprecationWarning``, until 0.3. The logger keeps its 0.1 name, ``hapticsdk.actuators``.
This package imports nothing on its own, so ``import hapticsdk`` stays light.
"""
