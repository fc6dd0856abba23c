"""Fit formula (7) of the reference paper to discrimination answers.

:func:`fit_voicecoil` rebuilds a :class:`~hapticsdk.calibration.voicecoil.VoiceCoilCalibration`
from discrimination answers (:mod:`hapticsdk.calibration.discrimination`): one
cumulative Gaussian per frequency level by maximum likelihood, its PSE, then formula
(7)'s quadratic by weighted least squares (weights ``1 / se(PSE)^2``) with confidence
intervals per coefficient.

Imports run one way: ``voicecoil_fit`` -> ``discrimination`` -> ``voicecoil``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from ..errors import CalibrationError
from .discrimination import DiscriminationAnswers, fit_levels
from .voicecoil import VoiceCoilCalibration


@dataclass
class VoiceCoilFit:
    """Result of :func:`fit_voicecoil` (like a scipy ``OptimizeResult``).

    Attributes:
        success: the quadratic was fitted and is increasing over the range.
        message: why not, when ``success`` is False.
        coefficients: (a, b, c) of formula (7), N/mm per Hz^2, per Hz, N/mm.
        stderr: their standard errors.
        confidence_intervals: ``confidence`` intervals per coefficient.
        confidence: the level of the intervals (default 0.95).
        levels: per-level :class:`~hapticsdk.calibration.discrimination.PsychometricFit`.
        chi2_reduced: weighted residual sum of squares / (levels - 3); the intervals are
            widened by ``sqrt(chi2_reduced)`` when it exceeds 1.
        calibration: the :class:`VoiceCoilCalibration` (``None`` when not ``success``).
        generated: the answers were generated, not measured.
    """

    success: bool
    message: str
    coefficients: tuple[float, float, float]
    stderr: tuple[float, float, float]
    confidence_intervals: tuple[tuple[float, float], ...]
    confidence: float
    levels: list[Any]
    chi2_reduced: float
    calibration: VoiceCoilCalibration | None
    generated: bool

    def to_dict(self) -> dict[str, Any]:
        """The fit as a JSON-ready dict: outcome, coefficients with standard errors and
        confidence intervals, reduced chi-square, the per-frequency psychometric fits and
        the resulting calibration.
        """
        return {"success": self.success, "message": self.message, "coefficients": list(self.coefficients),
                "stderr": list(self.stderr), "confidence_intervals": [list(c) for c in self.confidence_intervals],
                "confidence": self.confidence, "chi2_reduced": self.chi2_reduced, "generated": self.generated,
                "levels": [lv.to_dict() for lv in self.levels],
                "calibration": self.calibration.to_dict() if self.calibration else None}


def fit_voicecoil(answers: Any, *, confidence: float = 0.95, frequency_range_hz: tuple[float, float] | None = None,
                  serial: str | None = None, source: str | None = None,
                  amplifier_gain: float | None = None, mounting: str = "") -> VoiceCoilFit:
    """Fit formula (7) to discrimination answers.

    Args:
        answers: a :class:`~hapticsdk.calibration.discrimination.DiscriminationAnswers`
            or the path of its CSV.
        confidence: level of the coefficient intervals.
        frequency_range_hz: validity range; default the lowest..highest level.
        serial, amplifier_gain, mounting: stored in the calibration.

    Per level, a cumulative Gaussian by maximum likelihood gives the PSE and its
    profile-likelihood standard error ``se``; the PSEs over frequency are fitted by
    ``a f^2 + b f + c`` with weights ``1/se^2``. The coefficient covariance is
    ``(X^T W X)^-1``, multiplied by the reduced chi-square when that exceeds 1, and the
    intervals use Student's t with ``levels - 3`` degrees of freedom.
    """
    from scipy import stats

    from .voicecoil import check_amplifier_gain

    check_amplifier_gain(amplifier_gain)  # before the fit: a NaN gain is bad input, not a failed fit
    if not isinstance(answers, DiscriminationAnswers):
        answers = DiscriminationAnswers.from_csv(answers)
    if not 0 < confidence < 1:
        raise CalibrationError(f"confidence must be in (0, 1), got {confidence}")
    levels = fit_levels(answers)
    if len(levels) < 4:
        raise CalibrationError(f"{len(levels)} frequency level(s); at least 4 are needed to fit a quadratic "
                               "with a confidence interval")
    f = np.array([lv.frequency_hz for lv in levels])
    pse = np.array([lv.pse_n_per_mm for lv in levels])
    se = np.array([lv.pse_se for lv in levels])
    X = np.stack([f ** 2, f, np.ones_like(f)], axis=1)
    w = 1.0 / se ** 2
    xtwx = X.T @ (X * w[:, None])
    coef = np.linalg.solve(xtwx, X.T @ (w * pse))
    resid = pse - X @ coef
    dof = len(levels) - 3
    chi2_red = float(np.sum(w * resid ** 2) / dof)
    cov = np.linalg.inv(xtwx) * max(1.0, chi2_red)
    stderr = np.sqrt(np.diag(cov))
    tq = float(stats.t.ppf(0.5 + confidence / 2, dof))
    ci = tuple((float(c - tq * s), float(c + tq * s)) for c, s in zip(coef, stderr))
    rng = frequency_range_hz or (float(f.min()), float(f.max()))
    src = source or (f"fit_voicecoil of {len(answers)} {'GENERATED ' if answers.generated else ''}answers "
                     f"({answers.source})")
    extra = {"levels_hz": f.tolist(), "pse_n_per_mm": pse.tolist(), "pse_se": se.tolist(),
             "chi2_reduced": chi2_red, "n_answers": len(answers), "confidence": confidence}
    cal, ok, msg = None, True, "fitted"
    try:
        cal = VoiceCoilCalibration(coefficients=cast(Any, tuple(float(c) for c in coef)), frequency_range_hz=rng,
                                   source=src, confidence_intervals=ci, extra=extra, serial=serial,
                                   generated=answers.generated, amplifier_gain=amplifier_gain, mounting=mounting)
    except CalibrationError as exc:
        ok, msg = False, f"fitted curve unusable: {exc}"
    return VoiceCoilFit(success=ok, message=msg, coefficients=cast(Any, tuple(float(c) for c in coef)),
                        stderr=cast(Any, tuple(float(s) for s in stderr)), confidence_intervals=ci, confidence=confidence,
                        levels=levels, chi2_reduced=chi2_red, calibration=cal, generated=answers.generated)
