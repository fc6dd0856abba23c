"""Stiffness-discrimination answers for the voice-coil calibration, and their
psychometric analysis.

The paper calibrates formula (7) with a discrimination experiment: at each voice-coil
drive frequency (30..120 Hz, 10 Hz steps) a person presses the vibrating stimulus and a
reference spring of Table 4 (0.08, 0.3, 0.5, 0.8, 1.5, 2.1, 4.5 N/mm) and answers
whether the spring felt stiffer. 10 people x 70 pairs (10 levels x 7 springs) = 700
answers. For each frequency level the proportion of "spring stiffer" over spring
stiffness is fitted with a cumulative Gaussian; its 50 % point is the point of
subjective equality (PSE), the stiffness the vibration feels like.

This module holds the answer table (:class:`DiscriminationAnswers`, CSV columns
``person, frequency_hz, spring_n_per_mm, spring_stiffer``), a documented generator of
**GENERATED** answers (:func:`generate_answers`; the paper published none) and the
maximum-likelihood psychometric fit (:func:`fit_psychometric`).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..errors import CalibrationError, ValidationError
from .voicecoil import VoiceCoilCalibration

#: Table 4 of the paper: reference springs (N/mm)
TABLE4_SPRINGS_N_PER_MM = (0.08, 0.3, 0.5, 0.8, 1.5, 2.1, 4.5)
#: drive-frequency levels of the paper's experiment (Hz)
PAPER_LEVELS_HZ = tuple(float(f) for f in range(30, 121, 10))

CSV_COLUMNS = ("person", "frequency_hz", "spring_n_per_mm", "spring_stiffer")


def read_commented_csv(path: str | Path, what: str) -> tuple[Path, list[str], list[list[str]]]:
    """``(path, comments, rows)`` of a CSV file whose ``#`` lines are comments (their text
    without ``#``; blank lines skipped, ``rows[0]`` is the header). A missing file raises
    :class:`CalibrationError` "<what> file not found"."""
    from ..schemas_io import read_csv_rows

    from ..argcheck import file_path
    try:
        p = file_path(path, what)
    except ValidationError as exc:
        raise CalibrationError(f"{what}: {exc.reason}") from None
    if not p.exists():
        raise CalibrationError(f"{what} file not found: {p}")
    try:  # the shared reader: regular UTF-8 file of bounded size, well-formed CSV
        comments, rows = read_csv_rows(p, field=what, comments=True)
    except ValidationError as exc:
        raise CalibrationError(str(exc)) from None
    return p, comments, rows


#: the largest whole number a column of answers holds: the float64 a CSV cell is read
#: as holds every integer up to 2**53 exactly
_MAX_WHOLE = 2.0 ** 53


def _whole_numbers(values: Any, name: str) -> np.ndarray:
    """``values`` as int64, each one a whole number as it was given: a fraction, a NaN,
    an infinity or more than 2**53 raises :class:`CalibrationError` naming ``name``
    (``astype(int)`` truncated 0.5 to 0 and turned NaN into -2**63)."""
    a = np.asarray(values)
    if a.dtype.kind in "biu":
        return a.astype(np.int64).reshape(-1)
    try:
        f = np.asarray(a, float).reshape(-1)
    except (TypeError, ValueError):
        raise CalibrationError(f"answers: {name} must hold whole numbers, got {a.dtype} values") from None
    bad = ~(np.isfinite(f) & (np.abs(f) <= _MAX_WHOLE))
    bad[~bad] = f[~bad] != np.round(f[~bad])
    if bad.any():
        i = int(np.argmax(bad))
        raise CalibrationError(f"answers: {name} must hold whole numbers, got {f[i]!r} in row {i + 1}")
    return f.astype(np.int64)


@dataclass
class DiscriminationAnswers:
    """One row per answer.

    Attributes:
        person: (n,) participant id (int).
        frequency_hz: (n,) voice-coil drive frequency of the trial (Hz).
        spring_n_per_mm: (n,) stiffness of the reference spring (N/mm).
        spring_stiffer: (n,) 1 when the person judged the spring stiffer, else 0.
        generated: True for answers made by :func:`generate_answers`.
        source: provenance text.
    """

    person: np.ndarray
    frequency_hz: np.ndarray
    spring_n_per_mm: np.ndarray
    spring_stiffer: np.ndarray
    generated: bool = False
    source: str = ""

    def __post_init__(self) -> None:
        self.person = _whole_numbers(self.person, "person")
        self.frequency_hz = np.asarray(self.frequency_hz, float).reshape(-1)
        self.spring_n_per_mm = np.asarray(self.spring_n_per_mm, float).reshape(-1)
        self.spring_stiffer = _whole_numbers(self.spring_stiffer, "spring_stiffer")
        n = self.person.size
        for name in ("frequency_hz", "spring_n_per_mm", "spring_stiffer"):
            if getattr(self, name).size != n:
                raise CalibrationError(f"answers: column {name} has {getattr(self, name).size} rows, "
                                       f"person has {n}")
        if n == 0:
            raise CalibrationError("answers: no rows")
        if not (np.isfinite(self.frequency_hz).all() and np.isfinite(self.spring_n_per_mm).all()):
            raise CalibrationError("answers: frequency_hz and spring_n_per_mm must be finite")
        if np.any(self.frequency_hz <= 0) or np.any(self.spring_n_per_mm <= 0):
            raise CalibrationError("answers: frequency_hz and spring_n_per_mm must be > 0")
        from .voicecoil import MAX_FREQUENCY_HZ
        if np.any(self.frequency_hz > MAX_FREQUENCY_HZ):
            raise CalibrationError(f"answers: frequency_hz {self.frequency_hz.max():g} Hz is above "
                                   f"{MAX_FREQUENCY_HZ:g} Hz (not a vibrotactile drive frequency)")
        if not np.isin(self.spring_stiffer, (0, 1)).all():
            raise CalibrationError("answers: spring_stiffer must be 0 or 1")

    def __len__(self) -> int:
        return int(self.person.size)

    @property
    def levels_hz(self) -> np.ndarray:
        """The distinct voice-coil frequencies tested (Hz), sorted."""
        return np.unique(self.frequency_hz)

    def to_csv(self, path: str | Path) -> Path:
        """Write the CSV (a ``# GENERATED`` comment line first for generated answers)."""
        from ..fileio import atomic_writer
        p = Path(path)
        # temp file + rename: never half a CSV; read back by from_csv before the rename
        with atomic_writer(p, "w", newline="", verify=type(self).from_csv) as fh:
            if self.generated or self.source:
                head = f"{'GENERATED, not measured: ' if self.generated else ''}{self.source}"
                for line in head.splitlines() or [""]:  # a line break in source stays a comment
                    fh.write(f"# {line}\n")
            w = csv.writer(fh)
            w.writerow(CSV_COLUMNS)
            for row in zip(self.person, self.frequency_hz, self.spring_n_per_mm, self.spring_stiffer):
                w.writerow([int(row[0]), f"{row[1]:g}", f"{row[2]:g}", int(row[3])])
        return p

    @classmethod
    def from_csv(cls, path: str | Path) -> "DiscriminationAnswers":
        """Read answers from CSV (columns :data:`CSV_COLUMNS`; ``#`` lines are comments;
        a comment containing ``GENERATED`` marks the answers as generated)."""
        p, comments, rows = read_commented_csv(path, "answers")
        if not rows:
            raise CalibrationError(f"{p}: empty answers file")
        from ..schemas_io import csv_header
        try:
            header = csv_header(rows[0], p, field="answers")
        except ValidationError as exc:
            raise CalibrationError(exc.reason) from None
        missing = [c for c in CSV_COLUMNS if c not in header]
        if missing:
            raise CalibrationError(f"{p}: missing column(s) {missing}; expected {list(CSV_COLUMNS)}")
        idx = [header.index(c) for c in CSV_COLUMNS]
        cols: list[list[float]] = [[] for _ in CSV_COLUMNS]
        for i, r in enumerate(rows[1:], start=2):
            try:
                for j, k in enumerate(idx):
                    cols[j].append(float(r[k]))
            except (ValueError, IndexError):
                raise CalibrationError(f"{p}: line {i}: bad row {r!r}") from None
        return cls(person=np.asarray(cols[0]), frequency_hz=np.asarray(cols[1]),  # whole numbers checked there
                   spring_n_per_mm=np.asarray(cols[2]),
                   spring_stiffer=np.asarray(cols[3]),
                   generated=any("GENERATED" in c for c in comments), source="; ".join(comments) or str(p))


def generate_answers(pse_n_per_mm: Callable[[np.ndarray], np.ndarray] | None = None, *,
                     people: int = 10, levels_hz: Sequence[float] = PAPER_LEVELS_HZ,
                     springs_n_per_mm: Sequence[float] = TABLE4_SPRINGS_N_PER_MM, repeats: int = 1,
                     weber_fraction: float = 0.2, noise_floor_n_per_mm: float = 0.05,
                     person_sd: float = 0.05, lapse_rate: float = 0.0,
                     seed: int | None = 0) -> DiscriminationAnswers:
    """**GENERATED** discrimination answers from a simulated observer (the paper
    published none). Default design = the paper's: 10 people x (10 levels x 7 springs)
    = 700 answers.

    Observer model (assumptions, stated so they can be replaced by real answers):
    person ``p`` at level ``f`` perceives the vibration as a spring of stiffness
    ``PSE(f) * (1 + e_p)`` with ``e_p ~ N(0, person_sd)`` (fixed per person), compares
    it with the reference spring ``k`` under Gaussian noise of standard deviation
    ``sigma(f) = weber_fraction * PSE(f) + noise_floor_n_per_mm`` (N/mm), and answers
    "spring stiffer" when ``k + noise > perceived``. With probability ``lapse_rate`` the
    answer is a coin flip.

    Args:
        pse_n_per_mm: true PSE curve ``f (Hz) -> N/mm``; default formula (7) with the
            paper's coefficients.
        repeats: pairs per (person, level, spring).
        seed: random seed (``None``: fresh entropy).
    """
    if pse_n_per_mm is None:
        pse_n_per_mm = VoiceCoilCalibration.paper().gs_coil
    if people < 1 or repeats < 1:
        raise CalibrationError("people and repeats must be >= 1")
    rng = np.random.default_rng(seed)
    f = np.asarray(levels_hz, float)
    k = np.asarray(springs_n_per_mm, float)
    pp, ff, kk = np.meshgrid(np.arange(people), f, k, indexing="ij")
    pp, ff, kk = (np.repeat(a.reshape(-1), repeats) for a in (pp, ff, kk))
    order = np.lexsort((rng.random(pp.size), pp))  # each person's pairs in random order
    pp, ff, kk = pp[order], ff[order], kk[order]
    pse = np.asarray(pse_n_per_mm(ff), float)
    bias = 1.0 + person_sd * rng.standard_normal(people)
    perceived = pse * bias[pp]
    sigma = weber_fraction * np.abs(pse) + noise_floor_n_per_mm
    answer = (kk + sigma * rng.standard_normal(pp.size) > perceived).astype(int)
    lapse = rng.random(pp.size) < lapse_rate
    answer[lapse] = rng.integers(0, 2, int(lapse.sum()))
    src = (f"hapticsdk.calibration.discrimination.generate_answers(people={people}, repeats={repeats}, "
           f"weber_fraction={weber_fraction}, noise_floor_n_per_mm={noise_floor_n_per_mm}, "
           f"person_sd={person_sd}, lapse_rate={lapse_rate}, seed={seed})")
    return DiscriminationAnswers(person=pp, frequency_hz=ff, spring_n_per_mm=kk, spring_stiffer=answer,
                                 generated=True, source=src)


@dataclass
class PsychometricFit:
    """Cumulative-Gaussian fit of one frequency level.

    ``P(spring stiffer | k) = Phi((k - pse) / sigma)``.

    Attributes:
        frequency_hz: the level (Hz).
        pse_n_per_mm: point of subjective equality (N/mm), maximum likelihood; where the
            likelihood is flat (perfectly separated answers) the centre of the maximal set.
        sigma_n_per_mm: spread of the cumulative Gaussian (N/mm).
        pse_ci: 95 % profile-likelihood interval of the PSE (N/mm).
        pse_se: its half width / 1.96 (N/mm), the PSE uncertainty used as weight.
        censored: True when the interval reaches the search range (PSE outside the springs).
        n_answers: answers at this level.
        springs, n_trials, n_stiffer: per-spring counts.
    """

    frequency_hz: float
    pse_n_per_mm: float
    sigma_n_per_mm: float
    pse_ci: tuple[float, float]
    pse_se: float
    censored: bool
    n_answers: int
    springs: np.ndarray = field(repr=False)
    n_trials: np.ndarray = field(repr=False)
    n_stiffer: np.ndarray = field(repr=False)
    log_likelihood: float = 0.0

    def proportion(self, k: Any) -> np.ndarray:
        """Fitted P(spring stiffer) at spring stiffness ``k`` (N/mm)."""
        from scipy import special
        return special.ndtr((np.asarray(k, float) - self.pse_n_per_mm) / self.sigma_n_per_mm)

    def to_dict(self) -> dict[str, Any]:
        """The fit as a JSON-ready dict: PSE and sigma (N/mm), the PSE's confidence interval
        and standard error, whether it was censored, and the per-spring trial counts.
        """
        return {"frequency_hz": self.frequency_hz, "pse_n_per_mm": self.pse_n_per_mm,
                "sigma_n_per_mm": self.sigma_n_per_mm, "pse_ci": list(self.pse_ci), "pse_se": self.pse_se,
                "censored": self.censored, "n_answers": self.n_answers,
                "springs_n_per_mm": self.springs.tolist(), "n_trials": self.n_trials.tolist(),
                "n_stiffer": self.n_stiffer.tolist()}


_SIGMA_GRID = np.geomspace(0.01, 5.0, 36)
_CHI2_95_HALF = 1.9207294103470618  # 0.5 * chi2.ppf(0.95, df=1)


def _loglik(mu: np.ndarray, sigma: np.ndarray, k: np.ndarray, n: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Binomial log-likelihood summed over springs; broadcasts ``mu``/``sigma`` grids."""
    from scipy import special
    # springs near the float range overflow here (inf, then 0 x inf = NaN): the caller
    # names a likelihood that is not finite anywhere, so numpy's warnings add nothing
    with np.errstate(over="ignore", invalid="ignore"):
        z = (k - mu[..., None]) / sigma[..., None]
        lp = special.log_ndtr(z)
        lq = special.log_ndtr(-z)
        return np.sum(y * lp + (n - y) * lq, axis=-1)


def fit_psychometric(springs_n_per_mm: Any, stiffer: Any, *, frequency_hz: float = float("nan"),
                     pse_range: tuple[float, float] | None = None) -> PsychometricFit:
    """Maximum-likelihood cumulative-Gaussian fit of one level's answers.

    Args:
        springs_n_per_mm: (n,) reference stiffness of each answer (N/mm).
        stiffer: (n,) 1 = spring judged stiffer.
        pse_range: where the PSE is searched (N/mm); default ``[0, 1.5 * max spring]``.

    The likelihood is evaluated on a (PSE, sigma) grid (vectorised), refined by a local
    optimiser; the PSE interval is the profile-likelihood 95 % interval
    (log-likelihood within 1.92 of the maximum).
    """
    from scipy import optimize

    k_all = np.asarray(springs_n_per_mm, float)
    a_all = np.asarray(stiffer, float)
    k, inv = np.unique(k_all, return_inverse=True)
    if k.size < 2:
        raise CalibrationError(f"level {frequency_hz:g} Hz: answers at >= 2 different springs needed, "
                               f"got {k.size}")
    n = np.bincount(inv, minlength=k.size).astype(float)
    y = np.bincount(inv, weights=a_all, minlength=k.size)
    lo, hi = pse_range if pse_range is not None else (0.0, 1.5 * float(k.max()))
    try:
        ok = bool(np.isfinite(lo) and np.isfinite(hi) and float(hi) > float(lo))
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:   # a NaN or infinite bound: a NaN grid, then an IndexError
        raise CalibrationError(f"level {frequency_hz:g} Hz: the PSE search range {lo!r:.30}..{hi!r:.30} N/mm "
                               f"is not a finite interval (springs {float(k.min()):g}..{float(k.max()):g} N/mm)")
    mu_grid = np.linspace(lo, hi, 541)
    ll = _loglik(mu_grid[:, None], _SIGMA_GRID[None, :], k, n, y)  # (n_mu, n_sigma)
    prof = ll.max(axis=1)
    best = float(prof.max())
    if not np.isfinite(best):   # springs so large (1e308 N/mm) that the likelihood overflows
        raise CalibrationError(f"level {frequency_hz:g} Hz: the answers' likelihood is not finite anywhere in "
                               f"the PSE range {lo:g}..{hi:g} N/mm (springs {float(k.min()):g}.."
                               f"{float(k.max()):g} N/mm)")
    # local refinement from the grid optimum (PSE kept inside the search range)
    i, j = np.unravel_index(int(np.argmax(ll)), ll.shape)

    def nll(p: np.ndarray) -> float:
        return -float(_loglik(np.array(p[0]), np.array(np.exp(p[1])), k, n, y))

    res = optimize.minimize(nll, x0=[mu_grid[i], np.log(_SIGMA_GRID[j])], method="L-BFGS-B",
                            bounds=[(lo, hi), (np.log(_SIGMA_GRID[0]), np.log(_SIGMA_GRID[-1]))])
    mu_hat, sig_hat, ll_hat = mu_grid[i], _SIGMA_GRID[j], best
    if res.success and -res.fun >= best - 1e-9:
        mu_hat, sig_hat, ll_hat = float(res.x[0]), float(np.exp(res.x[1])), float(-res.fun)
    # flat maximum (perfect separation): take the centre of the maximal set
    top = mu_grid[prof >= best - 1e-3]
    if top[-1] - top[0] > 2 * (mu_grid[1] - mu_grid[0]):
        mu_hat = float(0.5 * (top[0] + top[-1]))
        sig_hat = float(_SIGMA_GRID[int(np.argmax(ll[np.argmin(np.abs(mu_grid - mu_hat))]))])
    inside = mu_grid[prof >= max(best, ll_hat) - _CHI2_95_HALF]
    ci = (float(inside[0]), float(inside[-1])) if inside.size else (float(mu_hat), float(mu_hat))
    step = mu_grid[1] - mu_grid[0]
    censored = bool(ci[0] <= lo + step / 2 and lo > 0) or bool(ci[1] >= hi - step / 2)
    se = max((ci[1] - ci[0]) / (2 * 1.959964), step)
    return PsychometricFit(frequency_hz=float(frequency_hz), pse_n_per_mm=float(mu_hat),
                           sigma_n_per_mm=float(sig_hat), pse_ci=ci, pse_se=float(se), censored=censored,
                           n_answers=int(k_all.size), springs=k, n_trials=n.astype(int),
                           n_stiffer=y.astype(int), log_likelihood=float(ll_hat))


def fit_levels(answers: DiscriminationAnswers) -> list[PsychometricFit]:
    """:func:`fit_psychometric` for every frequency level of ``answers``."""
    return [fit_psychometric(answers.spring_n_per_mm[answers.frequency_hz == f],
                             answers.spring_stiffer[answers.frequency_hz == f], frequency_hz=float(f))
            for f in answers.levels_hz]
