"""Importance models: does rendering a dimension change what a person feels?

An :class:`ImportanceModel` predicts, from a material's features, the loss of realism
(percent of the realism rated with every dimension rendered) that leaving one dimension
out would cause. Models are plugins of the entry-point group ``hapticsdk.importance``;
the core registers ``paper`` (:class:`PaperRegressionImportance`).

What is judged (:func:`judge_material`): the material itself, not one member of the
perception model's inverse. The inverse has a whole family of feature vectors for a
target, spread far wider than any one material (the family places the library's S16 at
Fpeak 190 Hz where its recorded features say 79 Hz), so a decision on the family, or on
whichever member a solver returned, judges an accident of the search. The feature points
judged are

* ``recorded``: the material's recorded features, where the library has them (and the
  scene did not change its intensities);
* ``recorded, solved onto the target``: those features moved onto the target by the
  perception model's minimum-norm Gauss-Newton steps (the member of the family nearest to
  the material's own features; deterministic);
* ``solved``: for a material without recorded features, the compile's solved features
  (what is rendered).

The uncertainty is the importance model's own (:meth:`ImportanceModel.loss_draws`):
for ``paper``, a deterministic parametric bootstrap of the Tables 5-6 regressions
(:class:`PaperRegressionImportance`). A dimension is left out only when its whole 80 %
loss interval (10th percentile of the lowest point to 90th percentile of the highest)
lies below the threshold; when the interval straddles the threshold the dimension is
kept, and the plan says so with the interval. A negative predicted loss (the regression
extrapolating) counts as 0 % and is flagged.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar, Mapping, Sequence

import numpy as np

from ..errors import ValidationError
from ..quantiles import median, percentile


class ImportanceModel(ABC):
    """Predicts the realism loss of leaving a dimension out.

    Subclasses set ``name`` and implement :meth:`_predict_loss`; they may override
    :meth:`replacement` to render something simpler in a dropped dimension's place.
    """

    name: ClassVar[str] = ""
    #: ``hapticsdk_api`` range of the plugin API this model was written for.
    hapticsdk_api: ClassVar[str] = ">=1.0,<2"
    #: True when the predictions refer to removing ONE dimension with all the others
    #: rendered: then at most one judged dimension is dropped per material (the one
    #: with the lowest predicted loss).
    single_removal: ClassVar[bool] = False

    def features_needed(self, dimension: str, present: Sequence[str]) -> tuple[str, ...]:
        """Feature names the prediction for ``dimension`` reads (default: none)."""
        return ()

    def judges(self, dimension: str, present: Sequence[str]) -> bool:
        """Whether this model predicts the loss of ``dimension`` when the material renders
        the dimensions ``present`` (which include ``dimension``)."""
        return False

    def predict_loss(self, dimension: str, features: Mapping[str, Any],
                     present: Sequence[str]) -> np.ndarray:
        """Predicted realism loss (%) per row of ``features`` (name -> array of shape
        ``(m,)`` or scalar) when ``dimension`` is left out of ``present``.

        Raises :class:`ValidationError` when a needed feature is missing or not finite, or
        when the model does not judge this dimension in this context."""
        present = list(present)
        if dimension not in present:
            raise ValidationError(f"{dimension!r} is not among the rendered dimensions {present}",
                                  field="dimension")
        if not self.judges(dimension, present):
            raise ValidationError(f"importance model {self.name!r} does not judge {dimension!r} "
                                  f"with {present}", field="dimension")
        cols: dict[str, np.ndarray] = {}
        for f in self.features_needed(dimension, present):
            if f not in features:
                raise ValidationError(f"importance model {self.name!r} needs feature {f!r}",
                                      field=f"features.{f}")
            a = np.atleast_1d(np.asarray(features[f], dtype=float))
            if not np.isfinite(a).all():
                raise ValidationError("NaN or infinite feature", field=f"features.{f}")
            cols[f] = a
        m = max((len(a) for a in cols.values()), default=1)
        cols = {k: np.broadcast_to(v, (m,)) for k, v in cols.items()}
        out = np.asarray(self._predict_loss(dimension, cols, present), dtype=float).reshape(-1)
        if out.shape != (m,):
            out = np.broadcast_to(out, (m,)).copy()
        return out

    @abstractmethod
    def _predict_loss(self, dimension: str, cols: Mapping[str, np.ndarray],
                      present: Sequence[str]) -> np.ndarray:
        """Backend: loss (%) per row of the validated columns."""

    def loss_draws(self, dimension: str, features: Mapping[str, Any],
                   present: Sequence[str]) -> np.ndarray:
        """Draws of the predicted loss (%) from the model's own uncertainty, shape
        ``(n_draws, m)`` for ``m`` rows of ``features``: what the model's fit allows.

        The default is the point prediction as one draw (a model that states no
        uncertainty); :class:`PaperRegressionImportance` bootstraps its regressions.
        Validation as :meth:`predict_loss`."""
        return self.predict_loss(dimension, features, present)[None, :]

    def replacement(self, dimension: str) -> dict[str, Any] | None:
        """What to render instead of a dropped ``dimension`` (``None``: nothing)."""
        return None

    def describe(self) -> dict[str, Any]:
        """Name and one-line description of this importance model."""
        from ..perception.dimensions import first_line
        return {"name": self.name, "doc": first_line(self.__doc__)}


class PaperRegressionImportance(ImportanceModel):
    """The multiple regressions of Tables 5 and 6 of the reference paper.

    Loss of realism (% of the realism with hardness and roughness rendered) when one is
    removed, from the GA features GS (N/mm), Fpeak (Hz) and AFpeak (in g, see below):

    * removing roughness: ``35.009 - 0.075 GS - 0.232 Fpeak + 15.966 AFpeak`` (R^2 0.842)
    * removing hardness:  ``3.804 + 8.168 GS + 0.060 Fpeak - 9.138 AFpeak``  (R^2 0.952)

    The regressions were measured on materials rendered with both hardness and
    roughness, so this model judges a dimension only while both are rendered (once one
    is dropped, the other is kept). A dropped hardness is replaced by a constant normal
    force of 1 N while in contact (the paper's "No Hardness" condition).

    Units of AFpeak: the paper gives none. Its accelerometer (ADXL345) reports in g, and
    only g makes the regressions agree with the paper's own averages: with Fpeak about
    100 Hz and GS about 2 N/mm, the mean losses it reports (hardness 29 %, roughness 18 %:
    realism 70.86 -> 50.23 and 57.81) need AFpeak about 0.2-0.4, i.e. 2-4 m/s^2 expressed
    in g; read as m/s^2 the hardness regression would call nearly every material "soft".
    The SDK's AFpeak is in m/s^2, so it is divided by ``G0`` before the regression
    (``AFPEAK_PER_UNIT``; set it to 1.0 in a subclass to apply the coefficients to m/s^2).
    """

    name: ClassVar[str] = "paper"
    single_removal: ClassVar[bool] = True
    PAIR: ClassVar[tuple[str, str]] = ("hardness", "roughness")
    #: intercept, GS, Fpeak, AFpeak coefficients per removed dimension
    COEFFICIENTS: ClassVar[dict[str, tuple[float, float, float, float]]] = {
        "roughness": (35.009, -0.075, -0.232, 15.966),
        "hardness": (3.804, 8.168, 0.060, -9.138),
    }
    #: factor turning the SDK's AFpeak (m/s^2) into the regression's unit (g)
    AFPEAK_PER_UNIT: ClassVar[float] = 1.0 / 9.80665
    #: normal force (N) rendered in place of a dropped hardness
    NO_HARDNESS_FORCE_N: ClassVar[float] = 1.0

    def features_needed(self, dimension: str, present: Sequence[str]) -> tuple[str, ...]:
        return ("GS", "Fpeak", "AFpeak")

    def judges(self, dimension: str, present: Sequence[str]) -> bool:
        return dimension in self.COEFFICIENTS and all(d in present for d in self.PAIR)

    #: standard errors of the coefficients (Tables 5 and 6, column "SE"), same order
    STANDARD_ERRORS: ClassVar[dict[str, tuple[float, float, float, float]]] = {
        "roughness": (8.671, 1.259, 0.064, 5.512),
        "hardness": (6.873, 0.998, 0.051, 4.369),
    }
    #: the regressions' data: 8 evaluated samples, 4 coefficients -> 4 residual degrees of freedom
    N_SAMPLES: ClassVar[int] = 8
    N_COEFFICIENTS: ClassVar[int] = 4
    #: means of the predictors (GS N/mm, Fpeak Hz, AFpeak g) over the paper's 8 evaluated
    #: samples S1 S2 S7 S12 S13 S14 S16 S20. The paper does not publish them; these are the
    #: means of the shipped library's recorded features of those samples, which are
    #: GENERATED data (anchored to the paper's orderings), not measurements
    #: (``tests/scene/test_leave_out_basis.py`` keeps them equal to the library's).
    PREDICTOR_MEANS: ClassVar[tuple[float, float, float]] = (1.774675, 109.415, 0.235105)
    #: bootstrap: number of draws and the fixed seed (deterministic: the same draws in
    #: every process, so the same decisions). 4000 draws put the Monte Carlo error of the
    #: interval's 90 % point at 0.040 of the t interval's scale (``sqrt(.09/n)/pdf_t4(1.533)``;
    #: 0.14-0.27 loss points for the library); a decision within ~0.5 points of the
    #: threshold still follows the draw. The seed's value (the issue's number) carries no
    #: meaning; what another seed changes: docs/solvers.md, "How many draws, which seed").
    BOOTSTRAP_DRAWS: ClassVar[int] = 4000
    BOOTSTRAP_SEED: ClassVar[int] = 26

    def _predict_loss(self, dimension: str, cols: Mapping[str, np.ndarray],
                      present: Sequence[str]) -> np.ndarray:
        b0, bgs, bf, ba = self.COEFFICIENTS[dimension]
        return b0 + bgs * cols["GS"] + bf * cols["Fpeak"] + ba * self.AFPEAK_PER_UNIT * cols["AFpeak"]

    def coefficient_draws(self, dimension: str) -> np.ndarray:
        """``(BOOTSTRAP_DRAWS, 4)`` coefficient vectors (intercept, GS, Fpeak, AFpeak): a
        parametric bootstrap of the regression of ``dimension`` from its table.

        The table gives each coefficient's estimate B and standard error SE, the
        standardised coefficients beta and R^2 for n = 8 samples. Those imply the variance
        inflation factor of each predictor, ``VIF_j = (SE_j sqrt(n-1) (beta_j/B_j) /
        sqrt((1-R^2)(n-1)/(n-p)))^2``, which is 1.00-1.03 for every predictor of both
        tables: the predictors were (nearly) uncorrelated over the 8 samples, so the slopes'
        sampling errors are independent with the tabled SEs. The intercept is
        ``ybar - sum_j b_j xbar_j``: its error is the mean response's (variance
        ``SE_0^2 - sum_j xbar_j^2 SE_j^2``, independent of the slopes) minus the slopes'
        errors times the predictor means (:attr:`PREDICTOR_MEANS`). Errors are
        Student-t with n - p = 4 degrees of freedom (a shared chi-square scale, as the
        residual variance is estimated once). The draws are cached per class; the seed is
        fixed (:attr:`BOOTSTRAP_SEED`), so they are the same in every process.
        """
        cache = _DRAWS
        key = (type(self), dimension, self.COEFFICIENTS[dimension], self.STANDARD_ERRORS.get(dimension),
               self.PREDICTOR_MEANS, self.BOOTSTRAP_DRAWS, self.BOOTSTRAP_SEED)
        hit = cache.get(key)
        if hit is not None:
            return hit
        B = np.asarray(self.COEFFICIENTS[dimension], dtype=float)
        se = self.STANDARD_ERRORS.get(dimension)
        if se is None:   # a subclass with coefficients but no errors: no uncertainty known
            out = B[None, :].copy()
            cache[key] = out
            return out
        SE = np.asarray(se, dtype=float)
        xbar = np.asarray(self.PREDICTOR_MEANS, dtype=float)
        var_mean = SE[0] ** 2 - float(np.sum(xbar ** 2 * SE[1:] ** 2))
        if var_mean <= 0:
            raise ValidationError(f"importance model {self.name!r}: the intercept's standard error "
                                  f"is smaller than the predictor means allow", field="PREDICTOR_MEANS")
        df = self.N_SAMPLES - self.N_COEFFICIENTS
        rng = np.random.default_rng(self.BOOTSTRAP_SEED)
        n = self.BOOTSTRAP_DRAWS
        z = rng.standard_normal((n, 4))
        scale = np.sqrt(df / rng.chisquare(df, size=n))[:, None]
        z = z * scale
        slopes = B[1:] + z[:, 1:] * SE[1:]
        b0 = B[0] + z[:, 0] * np.sqrt(var_mean) - (slopes - B[1:]) @ xbar
        out = np.column_stack([b0, slopes])
        out.setflags(write=False)
        cache[key] = out
        return out

    def loss_draws(self, dimension: str, features: Mapping[str, Any],
                   present: Sequence[str]) -> np.ndarray:
        self.predict_loss(dimension, features, present)     # validation
        C = self.coefficient_draws(dimension)
        cols = {f: np.atleast_1d(np.asarray(features[f], dtype=float)) for f in ("GS", "Fpeak", "AFpeak")}
        m = max(len(v) for v in cols.values())
        X = np.column_stack([np.ones(m)] + [np.broadcast_to(cols[f], (m,)) for f in ("GS", "Fpeak")]
                            + [np.broadcast_to(cols["AFpeak"], (m,)) * self.AFPEAK_PER_UNIT])
        return C @ X.T

    def replacement(self, dimension: str) -> dict[str, Any] | None:
        if dimension == "hardness":
            return {"renderer": "constant-force", "role": "force",
                    "force_n": self.NO_HARDNESS_FORCE_N,
                    "note": "the paper's 'No Hardness' condition: constant 1 N normal force in contact"}
        return None


#: coefficient draws per (model class, dimension, table, seed): computed once per process
_DRAWS: dict[Any, np.ndarray] = {}

#: importance models of the core (also published as entry points of the core distribution)
BUILTIN: dict[str, type[ImportanceModel]] = {"paper": PaperRegressionImportance}


def load_importance(name: str | ImportanceModel = "paper") -> ImportanceModel:
    """An importance model by entry-point name (group ``hapticsdk.importance``) or as given."""
    if isinstance(name, ImportanceModel):
        return name
    from ..plugins import registry
    reg = registry("importance")
    if name not in reg and name in BUILTIN:
        # the core's own model, when the core's entry points are not installed (source tree)
        obj: Any = BUILTIN[name]
    else:
        obj = reg.load(name)
    model = obj() if callable(obj) else obj
    if not isinstance(model, ImportanceModel):
        raise ValidationError(f"importance plugin {name!r} did not give an ImportanceModel "
                              f"(got {type(model).__name__})", field="settings.importance.model")
    return model


def decide_drops(model: ImportanceModel, dimensions: Sequence[str],
                 features: Mapping[str, np.ndarray], thresholds: Mapping[str, float],
                 default_threshold: float) -> list[list[tuple[str, float, float]]]:
    """For each material (row of ``features``) the dimensions to drop, as
    ``(dimension, predicted_loss_percent, threshold_percent)``.

    Rule: every dimension the model judges (with all of ``dimensions`` rendered, the
    condition its predictions refer to) is dropped when its predicted loss is below its
    threshold (``thresholds[dim]``, else ``default_threshold``); decisions are independent,
    one vectorised prediction per dimension for all materials. A model whose predictions
    refer to single removals (``single_removal``) drops at most one dimension per
    material: the one with the lowest predicted loss. If the rule would leave a
    material with nothing rendered at all (no kept dimension and no replacement), the
    dropped dimension with the highest predicted loss is kept.
    """
    dims = list(dimensions)
    m = len(next(iter(features.values()))) if features else 1
    losses: dict[str, np.ndarray] = {}
    for d in dims:
        if not model.judges(d, dims):
            continue
        if any(f not in features for f in model.features_needed(d, dims)):
            continue
        losses[d] = model.predict_loss(d, features, dims)
    out: list[list[tuple[str, float, float]]] = []
    for i in range(m):
        drops = []
        for d in dims:
            if d in losses:
                thr = float(thresholds.get(d, default_threshold))
                if losses[d][i] < thr:
                    drops.append((d, float(losses[d][i]), thr))
        if model.single_removal and len(drops) > 1:
            drops = [min(drops, key=lambda t: t[1])]
        if drops and len(drops) == len(dims) and not any(model.replacement(d) for d, _, _ in drops):
            keep = max(drops, key=lambda t: t[1])
            drops.remove(keep)
        out.append(drops)
    return out


@dataclass
class LossEstimate:
    """Predicted realism loss of leaving one dimension out, over a material's solutions.

    Attributes:
        dimension: the dimension left out.
        median_percent: median predicted loss (%), negative predictions counted as 0.
        low_percent, high_percent: 10th and 90th percentile (%), likewise.
        threshold_percent: the threshold it is compared with (%).
        p_below: share of the solutions whose predicted loss is below the threshold.
        n_solutions: number of feature vectors the estimate is taken over.
        extrapolated_fraction: share of the solutions whose raw prediction was negative
            (the regression outside the range it was fitted on).
        reached: False when no feature vector reaches the target (the estimate is then
            taken over the nearest feasible ones).
        drop: the decision.
        basis: the feature points judged (:func:`judge_material`), each
            ``{"source", "features", "median_percent", "interval_percent"}``; empty for
            an estimate over a solution set (:func:`estimate_losses`).
        method: how the uncertainty was obtained, in words.

    From :func:`judge_material`: ``median_percent`` is the highest point's median,
    ``low_percent``/``high_percent`` span every point's 80 % interval, ``p_below`` is the
    share of the importance model's draws in which every point is below the threshold,
    ``n_solutions`` is the number of feature points, and ``drop`` is
    ``high_percent < threshold_percent`` (the whole interval below the threshold).
    """

    dimension: str
    median_percent: float
    low_percent: float
    high_percent: float
    threshold_percent: float
    p_below: float
    n_solutions: int
    extrapolated_fraction: float
    reached: bool
    drop: bool
    basis: list[dict[str, Any]] = field(default_factory=list)
    method: str = ""

    @property
    def confidence(self) -> float:
        """Share of the solutions on the side of the threshold the decision took."""
        return self.p_below if self.drop else 1.0 - self.p_below

    def to_dict(self) -> dict[str, Any]:
        """The estimate as a JSON-ready dict: median and 80 % interval of the predicted
        realism loss (%), threshold, confidence, number of solutions, extrapolated share,
        and the decision (``"drop"`` or ``"keep"``).
        """
        return {"dimension": self.dimension, "median_percent": self.median_percent,
                "interval_percent": [self.low_percent, self.high_percent], "interval_level": 0.8,
                "threshold_percent": self.threshold_percent, "p_below": self.p_below,
                "confidence": self.confidence, "n_solutions": self.n_solutions,
                "extrapolated_fraction": self.extrapolated_fraction, "reached": self.reached,
                "decision": "drop" if self.drop else "keep",
                **({"basis": [dict(b) for b in self.basis]} if self.basis else {}),
                **({"method": self.method} if self.method else {})}

    @property
    def straddles(self) -> bool:
        """True when the threshold lies inside the 80 % interval (the dimension is kept
        because the importance model cannot tell)."""
        return self.low_percent < self.threshold_percent <= self.high_percent


def estimate_losses(model: ImportanceModel, dimensions: Sequence[str], sets: Sequence[Any],
                    thresholds: Mapping[str, float], default_threshold: float,
                    fixed: Mapping[str, float] | None = None) -> list[dict[str, LossEstimate]]:
    """For each material (one :class:`~hapticsdk.compiler.solution_set.SolutionSet` per
    material) the :class:`LossEstimate` of every dimension the model judges, over the
    members of the model's inverse (the median decides).

    Not what :func:`~hapticsdk.compiler.compile_scene` decides on any more: the family's
    spread is the search's, not the material's (see the module docstring and
    :func:`judge_material`). Kept for callers who want the spread over the family.

    ``fixed``: features pinned in the solve (not in the sets' columns)."""
    dims = list(dimensions)
    out: list[dict[str, LossEstimate]] = []
    for sset in sets:
        est: dict[str, LossEstimate] = {}
        if len(sset) == 0:
            out.append(est)
            continue
        cols = sset.columns(dict(fixed or {}))
        for d in dims:
            if not model.judges(d, dims) or any(f not in cols for f in model.features_needed(d, dims)):
                continue
            raw = model.predict_loss(d, cols, dims)
            loss = np.maximum(raw, 0.0)
            thr = float(thresholds.get(d, default_threshold))
            med = median(loss)
            lo, hi = percentile(loss, [10.0, 90.0])
            est[d] = LossEstimate(dimension=d, median_percent=round(med, 6), low_percent=round(lo, 6),
                                  high_percent=round(hi, 6), threshold_percent=thr,
                                  p_below=round(float(np.mean(loss < thr)), 6), n_solutions=len(sset),
                                  extrapolated_fraction=round(float(np.mean(raw < 0.0)), 6),
                                  reached=bool(sset.reached), drop=med < thr)
        out.append(est)
    return out


def decide_from_estimates(model: ImportanceModel, dimensions: Sequence[str],
                          estimates: Sequence[Mapping[str, LossEstimate]]) -> list[list[LossEstimate]]:
    """The dimensions to drop per material, from :func:`estimate_losses`: every estimate
    whose decision is ``drop``; with a ``single_removal`` model at most one (the lowest
    median); never every dimension when none has a replacement (then the one with the
    highest median is kept)."""
    dims = list(dimensions)
    out: list[list[LossEstimate]] = []
    for est in estimates:
        drops = [est[d] for d in dims if d in est and est[d].drop]
        if model.single_removal and len(drops) > 1:
            drops = [min(drops, key=lambda e: e.median_percent)]
        if drops and len(drops) == len(dims) and not any(model.replacement(e.dimension) for e in drops):
            drops.remove(max(drops, key=lambda e: e.median_percent))
        out.append(drops)
    return out


#: names of the feature points :func:`judge_material` judges
RECORDED = "recorded"
RECORDED_SOLVED = "recorded, solved onto the target"
SOLVED = "solved"


_SOURCE_WORDS = {RECORDED: "its recorded features", RECORDED_SOLVED: "those features solved onto the target",
                 SOLVED: "its solved features"}


def basis_words(basis: Sequence[Mapping[str, Any]], n_solutions: int = 0) -> str:
    """Where a loss estimate was judged, in words: ``at its recorded features and at those
    features solved onto the target``; for an estimate without a basis (over a solution
    set, :func:`estimate_losses`), ``over n feature vectors``."""
    if not basis:
        return f"over {n_solutions} feature vector{'s' if n_solutions != 1 else ''}"
    return "at " + " and at ".join(_SOURCE_WORDS.get(b["source"], str(b["source"])) for b in basis)


def describe_uncertainty(model: ImportanceModel) -> str:
    """One line on where ``model``'s loss interval comes from."""
    if isinstance(model, PaperRegressionImportance):
        return (f"parametric bootstrap of the paper's Tables 5-6 regressions ({model.BOOTSTRAP_DRAWS} draws, "
                f"seed {model.BOOTSTRAP_SEED}, t with {model.N_SAMPLES - model.N_COEFFICIENTS} df)")
    return f"importance model {model.name!r}: its own loss draws"


def judge_material(model: ImportanceModel, dimensions: Sequence[str],
                   points: Sequence[tuple[str, Mapping[str, float]]], thresholds: Mapping[str, float],
                   default_threshold: float, level: float = 0.8) -> dict[str, LossEstimate]:
    """The :class:`LossEstimate` of every dimension ``model`` judges, for one material
    given as feature points ``[(source, {feature: value}), ...]`` (see the module
    docstring for the sources).

    For each point the model's loss draws (:meth:`ImportanceModel.loss_draws`; negative
    losses count as 0) give a median and a ``level`` interval; the estimate spans every
    point. The dimension is dropped only when the whole interval lies below its threshold
    (``thresholds[dim]``, else ``default_threshold``). Nothing here depends on a solver's
    seed or on a search design: only on the points and the model.
    """
    dims = list(dimensions)
    if not points:
        return {}
    q = [50.0 * (1.0 - level), 50.0 * (1.0 + level)]
    out: dict[str, LossEstimate] = {}
    for d in dims:
        if not model.judges(d, dims):
            continue
        need = model.features_needed(d, dims)
        use = [(src, f) for src, f in points if all(k in f for k in need)]
        if not use:
            continue
        cols = {k: np.array([float(f[k]) for _, f in use]) for k in need}
        raw = np.asarray(model.loss_draws(d, cols, dims), dtype=float)   # (n_draws, n_points)
        loss = np.maximum(raw, 0.0)
        thr = float(thresholds.get(d, default_threshold))
        # per point (column), as np.median / np.percentile(axis=0) compute them, bit for
        # bit, without their import of numpy.ma (~6 ms of `render`'s start-up)
        med = np.array([median(loss[:, j]) for j in range(loss.shape[1])])
        lo, hi = np.array([percentile(loss[:, j], q) for j in range(loss.shape[1])]).reshape(-1, 2).T
        basis = [{"source": src, "features": {k: float(f[k]) for k in need},
                  "median_percent": round(float(med[j]), 6),
                  "interval_percent": [round(float(lo[j]), 6), round(float(hi[j]), 6)]}
                 for j, (src, f) in enumerate(use)]
        low, high = round(float(lo.min()), 6), round(float(hi.max()), 6)
        out[d] = LossEstimate(dimension=d, median_percent=round(float(med.max()), 6), low_percent=low,
                              high_percent=high, threshold_percent=thr,
                              p_below=round(float(np.mean((loss < thr).all(axis=1))), 6),
                              n_solutions=len(use), extrapolated_fraction=round(float(np.mean(raw < 0.0)), 6),
                              reached=True, drop=high < thr, basis=basis, method=describe_uncertainty(model))
    return out
