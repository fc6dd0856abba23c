"""hapticsdk-hardness: the hardness dimension of the reference paper (features GS, W;
constraint (4); rendering (7)-(8)), a simulated PHANTOM Omni (``omni-virtual``), a
simulated voice-coil tactor (``voicecoil-virtual``) and, in
:mod:`hapticsdk_hardness.openhaptics`, the OpenHaptics backend of a real Omni."""

__version__ = "0.2.0"
#: plugin API range this distribution was built for (checked when a plugin is loaded)
hapticsdk_api = ">=1.0,<2"
