"""Feature extraction from exploration trials (the paper's section 2.1).

Per trial:

* force and displacement: Butterworth low-pass, 10 Hz, order 4, zero-phase
  (``filtfilt``); acceleration: Butterworth high-pass, 20 Hz, order 4, zero-phase.
* **GS** (N/mm): least-squares slope of force over displacement on the loading part
  of the press (start of the press phase up to the peak displacement), using the
  samples with displacement between 10 % and 90 % of the peak (contact onset and
  turnaround are left out).
* **W** (mJ = N*mm): work of pressing, trapezoidal ``integral F dx`` over the loading
  part where the displacement is >= 0 (after contact).
* **P** ((m/s^2)^2): mean square of the high-passed lateral acceleration in the slide
  phase, with :data:`SLIDE_TRIM_S` trimmed at both ends (filter edges, start/stop).
* **Fpeak** (Hz), **AFpeak** (m/s^2): frequency and one-sided amplitude of the largest
  peak (above the 20 Hz cut-off) of the FFT of that same segment, with an amplitude-
  calibrated flat-top window (amplitude exact to ~0.1 % between bins, so AFpeak does
  not depend on where the frequency falls relative to the bins). ``df = fs/N``
  (Hz) is the frequency resolution, N the segment length; a segment of >= 2 s gives
  df <= 0.5 Hz, which makes ``P >= AFpeak^2 df`` hold (the peak alone contributes
  ``AFpeak^2/2`` to P).

Per sample: mean and standard deviation over its trials.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Iterable, Sequence, Sized

import numpy as np
from scipy import signal

from ..errors import RecordingError
from .recordings import RecordingSet, Trial, validate_trial

FEATURE_NAMES: tuple[str, ...] = ("GS", "W", "Fpeak", "AFpeak", "P")
FEATURE_UNITS: dict[str, str] = {"GS": "N/mm", "W": "mJ", "Fpeak": "Hz", "AFpeak": "m/s^2",
                                 "P": "(m/s^2)^2"}
FEATURE_DESCRIPTIONS: dict[str, str] = {
    "GS": "global stiffness while pressing", "W": "work of pressing",
    "Fpeak": "frequency of the largest FFT peak of lateral acceleration",
    "AFpeak": "one-sided amplitude of that peak",
    "P": "lateral vibration power (mean square of the high-passed acceleration)"}
LP_HZ = 10.0
HP_HZ = 20.0
FILTER_ORDER = 4
SLIDE_TRIM_S = 0.1
FIT_RANGE = (0.1, 0.9)


@dataclass(frozen=True)
class TrialFeatures:
    """Features of one trial (units in :data:`FEATURE_UNITS`) plus ``df_hz`` and slide speed."""

    sample: str
    trial: int
    GS: float
    W: float
    Fpeak: float
    AFpeak: float
    P: float
    df_hz: float
    v_mm_s: float

    def vector(self) -> np.ndarray:
        """The features as ``[GS, W, Fpeak, AFpeak, P]`` (N/mm, mJ, Hz, m/s^2, (m/s^2)^2).
        """
        return np.array([self.GS, self.W, self.Fpeak, self.AFpeak, self.P])


@lru_cache(maxsize=8)
def _filters(fs: float) -> tuple[Any, Any]:
    lp = signal.butter(FILTER_ORDER, LP_HZ, btype="lowpass", fs=fs, output="sos")
    hp = signal.butter(FILTER_ORDER, HP_HZ, btype="highpass", fs=fs, output="sos")
    return lp, hp


def extract_trial(tr: Trial, *, expected_fs_hz: float | None = 500.0) -> TrialFeatures:
    """Validate one trial and compute its features; broken trials raise RecordingError."""
    validate_trial(tr, expected_fs_hz=expected_fs_hz)
    w = tr.where
    fs = tr.fs_hz
    lp, hp = _filters(fs)
    press = np.flatnonzero(tr.phase == "press")
    slide = np.flatnonzero(tr.phase == "slide")
    # -- press: GS and W ----------------------------------------------------
    F = signal.sosfiltfilt(lp, tr.force_n)[press]
    X = signal.sosfiltfilt(lp, tr.displacement_mm)[press]
    k_peak = int(np.argmax(X))
    x_max = X[k_peak]
    if x_max <= 0:
        raise RecordingError(f"{w}: no indentation in the press phase (peak displacement "
                             f"{x_max:.3g} mm)", field="displacement_mm")
    Fl, Xl = F[: k_peak + 1], X[: k_peak + 1]
    sel = (Xl >= FIT_RANGE[0] * x_max) & (Xl <= FIT_RANGE[1] * x_max)
    if np.count_nonzero(sel) < 10:
        raise RecordingError(f"{w}: loading part too short for the stiffness fit "
                             f"({int(np.count_nonzero(sel))} samples in 10..90 % of the peak "
                             f"displacement)", field="displacement_mm")
    xs, fsel = Xl[sel], Fl[sel]
    xc = xs - xs.mean()
    gs = float(np.dot(xc, fsel - fsel.mean()) / np.dot(xc, xc))
    contact = Xl >= 0
    xw, fw = Xl[contact], np.maximum(Fl[contact], 0.0)
    work = float(np.sum(0.5 * (fw[1:] + fw[:-1]) * np.diff(xw)))
    if not (gs > 0 and work > 0):
        raise RecordingError(f"{w}: force does not rise with displacement (GS={gs:.3g} N/mm, "
                             f"W={work:.3g} mJ)", field="force_n")
    # -- slide: P, Fpeak, AFpeak ---------------------------------------------
    a = signal.sosfiltfilt(hp, tr.acc[:, tr.lateral])[slide]
    trim = int(round(SLIDE_TRIM_S * fs))
    seg = a[trim: len(a) - trim]
    n = len(seg)
    power = float(np.mean(seg ** 2))
    win = signal.windows.flattop(n, sym=False)
    spec = np.abs(np.fft.rfft(seg * win)) * 2.0 / np.sum(win)
    freqs = np.fft.rfftfreq(n, 1.0 / fs)
    band = freqs >= HP_HZ
    k = int(np.flatnonzero(band)[np.argmax(spec[band])])
    v = float(np.mean(tr.velocity_mm_s[slide][trim: len(slide) - trim]))
    return TrialFeatures(sample=tr.sample, trial=tr.trial, GS=gs, W=work, Fpeak=float(freqs[k]),
                         AFpeak=float(spec[k]), P=power, df_hz=float(fs / n), v_mm_s=v)


@dataclass
class FeatureTable:
    """Per-trial features of a data set: ``X (n, 5)`` in :data:`FEATURE_NAMES` order."""

    samples: list[str]
    trials: list[int]
    X: np.ndarray
    df_hz: np.ndarray

    @property
    def sample_names(self) -> list[str]:
        """Unique sample names in first-seen order."""
        return list(dict.fromkeys(self.samples))

    def summary(self) -> dict[str, dict[str, tuple[float, float]]]:
        """Per sample: feature -> (mean, std over trials, ddof=1 when >1 trial)."""
        out = {}
        s = np.array(self.samples)
        for name in self.sample_names:
            rows = self.X[s == name]
            sd = rows.std(axis=0, ddof=1) if len(rows) > 1 else np.zeros(rows.shape[1])
            out[name] = {f: (float(m), float(d)) for f, m, d in zip(FEATURE_NAMES, rows.mean(0), sd)}
        return out

    def sample_means(self) -> np.ndarray:
        """Mean feature vector of each sample, ``(samples, 5)``, in :attr:`sample_names`
        order.
        """
        s = np.array(self.samples)
        return np.array([self.X[s == n].mean(axis=0) for n in self.sample_names])

    @property
    def dataset_df_hz(self) -> float:
        """Coarsest FFT resolution over the trials (Hz): conservative for ``P >= AFpeak^2 df``."""
        return float(np.max(self.df_hz))


def extract_trials(trials: Iterable[Trial], *, expected_fs_hz: float | None = 500.0,
                   progress: Any = None) -> FeatureTable:
    """Extract features of many trials (each validated; the first broken one raises);
    ``progress(stage, done, total)`` is called after each trial (total -1 when unknown)."""
    from ..progress import report

    total = len(trials) if isinstance(trials, Sized) else -1
    feats = []
    for t in trials:
        feats.append(extract_trial(t, expected_fs_hz=expected_fs_hz))
        report(progress, "extracting features", len(feats), total)
    if not feats:
        raise RecordingError("no trials to extract", field="trials")
    return FeatureTable(samples=[f.sample for f in feats], trials=[f.trial for f in feats],
                        X=np.array([f.vector() for f in feats]),
                        df_hz=np.array([f.df_hz for f in feats]))


def extract_set(rs: RecordingSet, *, expected_fs_hz: float | None = None) -> FeatureTable:
    """Extract a whole recording set; the expected rate defaults to the manifest's ``fs_hz``."""
    exp = rs.fs_hz if expected_fs_hz is None else expected_fs_hz
    return extract_trials(rs.iter_trials(), expected_fs_hz=exp)


def constraint_margins(X: np.ndarray, df_hz: float, mf_n: float = 3.3) -> tuple[np.ndarray, np.ndarray]:
    """Per row ``W - MF^2/(2 GS)`` (mJ) and ``P - AFpeak^2 df`` ((m/s^2)^2); >= 0 when met."""
    X = np.atleast_2d(X)
    return X[:, 1] - mf_n ** 2 / (2 * X[:, 0]), X[:, 4] - X[:, 3] ** 2 * df_hz


def column_names(names: Sequence[str] = FEATURE_NAMES) -> list[str]:
    """The feature table's column names, in order."""
    return list(names)
