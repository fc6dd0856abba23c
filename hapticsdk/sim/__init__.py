"""Simulated device physics: scripted finger trajectories, the exactly integrated arm
axis, and a kinematic virtual probe. Nothing here needs hardware or device libraries."""

from .arm import OMNI_SOURCES, ArmBatch, ArmParams, ArmSim, quantise, transition_matrices
from .finger import (FINGERS, FingerParams, Trajectory, finger, press_slide, quasi_static_press, standard_set, taps,
                     walk, walk_over)

__all__ = ["OMNI_SOURCES", "ArmBatch", "ArmParams", "ArmSim", "quantise", "transition_matrices",
           "FINGERS", "FingerParams", "Trajectory", "finger", "press_slide", "quasi_static_press",
           "standard_set", "taps", "walk", "walk_over"]
