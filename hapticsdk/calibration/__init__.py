"""Calibration of actuators: the perceptual mapping of the voice coil (formula (7))
and the piezo's voltage table ``Tab`` (formula (9)), their fits from experiment data,
the force arm's damping measured hands off (:mod:`.damping`), and calibration files per
device serial number (``docs/calibration.md``)."""

from .damping import DampingCalibration, DampingFit, excitation, fit_damping
from .discrimination import (TABLE4_SPRINGS_N_PER_MM, DiscriminationAnswers, PsychometricFit,
                             fit_psychometric, generate_answers)
from .piezo import PiezoTable, read_measurements_csv, table_from_measurements
from .store import (LoadedCalibration, calibration_dir, calibrations_in_use, list_calibrations,
                    load_calibration, read_calibration, save_calibration)
from .voicecoil import VoiceCoilCalibration
from .voicecoil_fit import VoiceCoilFit, fit_voicecoil

__all__ = ["PiezoTable", "VoiceCoilCalibration", "VoiceCoilFit", "fit_voicecoil", "DiscriminationAnswers",
           "PsychometricFit", "fit_psychometric", "generate_answers", "TABLE4_SPRINGS_N_PER_MM",
           "table_from_measurements", "read_measurements_csv", "LoadedCalibration", "calibration_dir",
           "calibrations_in_use", "list_calibrations", "load_calibration", "read_calibration",
           "save_calibration", "DampingCalibration", "DampingFit", "excitation", "fit_damping"]
