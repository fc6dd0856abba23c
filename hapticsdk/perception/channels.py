"""The command channels an actuator can take (a leaf module: dimensions, actuators and
the safety layer all read it)."""

#: channels an actuator declares (``Actuator.channels``) and a role asks for
CHANNELS = ("force", "vibration", "thermal", "friction", "other")
