"""Importance models: does rendering a dimension change what a person feels?

An :class:`ImportanceModel` predicts, from a material's solved features, the loss of
realism (percent of the realism rated with every dimension rendered) that leaving one
dimension out would cause. A scene drops a dimension whose predicted loss is below its
threshold (``settings.importance.threshold_percent``). Models are plugins of the
entry-point group ``hapticsdk.importance``; the core registers ``paper``
(:class:`PaperRegressionImportance`).

Predictions are vectorised: :meth:`ImportanceModel.predict_loss` takes feature columns
(arrays, one entry per material) and returns one loss per material.

Scenes decide on the distribution of the predicted loss over every feature vector
that reaches the material's target (:func:`estimate_losses` over the target's
:class:`~hapticsdk.compiler.solution_set.SolutionSet`), not on the one vector a
randomised solver returned, so the decision does not change with the solver's seed:
a dimension is dropped when the median predicted loss is below the threshold, and the
plan reports the 10-90 % interval and the share of solutions on the decided side
(the decision's confidence). A negative predicted loss (the regression extrapolating
outside the materials it was fitted on) counts as 0 % and is flagged.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
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

    def replacement(self, dimension: str) -> dict[str, Any] | None:
        """What to render instead of a dropped ``dimension`` (``None``: nothing)."""
        return None

    def describe(self) -> dict[str, Any]:
        """Name and one-line description of this importance model."""
        from ..dimensions import first_line
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

    def _predict_loss(self, dimension: str, cols: Mapping[str, np.ndarray],
                      present: Sequence[str]) -> np.ndarray:
        b0, bgs, bf, ba = self.COEFFICIENTS[dimension]
        return b0 + bgs * cols["GS"] + bf * cols["Fpeak"] + ba * self.AFPEAK_PER_UNIT * cols["AFpeak"]

    def replacement(self, dimension: str) -> dict[str, Any] | None:
        if dimension == "hardness":
            return {"renderer": "constant-force", "role": "force",
                    "force_n": self.NO_HARDNESS_FORCE_N,
                    "note": "the paper's 'No Hardness' condition: constant 1 N normal force in contact"}
        return None


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
        drop: the decision: ``median_percent < threshold_percent``.
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
                "decision": "drop" if self.drop else "keep"}


def estimate_losses(model: ImportanceModel, dimensions: Sequence[str], sets: Sequence[Any],
                    thresholds: Mapping[str, float], default_threshold: float,
                    fixed: Mapping[str, float] | None = None) -> list[dict[str, LossEstimate]]:
    """For each material (one :class:`~hapticsdk.compiler.solution_set.SolutionSet` per
    material) the :class:`LossEstimate` of every dimension the model judges.

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
