"""Calibration of actuators: the perceptual mapping of the voice coil (formula (7))
and the piezo's voltage table ``Tab`` (formula (9))."""

from .piezo import PiezoTable
from .voicecoil import VoiceCoilCalibration

__all__ = ["PiezoTable", "VoiceCoilCalibration"]
