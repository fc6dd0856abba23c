"""Stimulus features and the bounded spaces they span.

A *feature* is one physical quantity of the stimulus (for example global stiffness
``GS`` in N/mm); a :class:`FeatureSpace` is an ordered tuple of features with bounds,
so that a feature vector is a plain ``(n, d)`` numpy array whose columns have names,
units and bounds. The space a scene solves in is assembled from the features that
its perception dimensions contribute (:meth:`FeatureSpace.union`).

A feature is identified by its name AND its unit: two dimensions may share a feature
(the same physical quantity, e.g. a plugin reading the paper's ``GS``) only when they
declare the same unit; a union of spaces that name one feature in two units raises
:class:`~hapticsdk.errors.FeatureConflictError` naming both owners. Naming rule for
plugin authors (docs/plugin-authors.md): the paper's features keep their short names
(``GS``, ``W``, ``Fpeak``, ``AFpeak``, ``P``); a feature of your own is prefixed with
your dimension's name and a dot (``stickiness.mu``), so it cannot collide with anyone
else's.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Iterable, Mapping, Sequence

import numpy as np
import numpy.typing as npt

from ..errors import FeatureConflictError, ValidationError


def same_unit(a: str, b: str) -> bool:
    """Whether two unit strings name the same unit, parsed (:mod:`hapticsdk.units`:
    ``newton`` = ``N``, ``N / mm`` = ``N/mm``, ``N/mm`` and ``N/m`` differ)."""
    from ..units import same_unit as _same
    return _same(a, b)


@dataclass(frozen=True)
class Feature:
    """One physical stimulus feature.

    Attributes:
        name: short identifier, unique within a space (``"GS"``).
        unit: physical unit of values (``"N/mm"``).
        lower, upper: inclusive bounds in ``unit``; ``lower == upper`` is a degenerate
            (fixed) feature and is allowed.
        description: one line for docs and CLI output.
        owner: who declares it (``"dimension hardness"``, ``"model default"``), for
            conflict messages; not part of the feature's identity.
    """

    name: str
    unit: str
    lower: float
    upper: float
    description: str = ""
    owner: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if not self.name or not isinstance(self.name, str):
            raise ValidationError("feature name must be a non-empty string", field="feature.name")
        from ..argcheck import number   # "1", True, None and 10**400 are no bound
        lo = number(self.lower, f"feature.{self.name}.lower")
        hi = number(self.upper, f"feature.{self.name}.upper")
        if lo > hi:
            raise ValidationError(f"lower bound {lo} > upper bound {hi}", field=f"feature.{self.name}")
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)

    @property
    def span(self) -> float:
        """``upper - lower``, in the feature's unit."""
        return self.upper - self.lower

    def owned_by(self, owner: str) -> "Feature":
        """Copy labelled with its declarer (for conflict messages)."""
        return replace(self, owner=owner)

    def with_bounds(self, lower: float, upper: float) -> "Feature":
        """A copy with other bounds (same name, unit, description)."""
        return replace(self, lower=lower, upper=upper)

    def to_dict(self) -> dict:
        """The feature as a JSON-ready dict (name, unit, lower, upper, description)."""
        return {"name": self.name, "unit": self.unit, "lower": self.lower,
                "upper": self.upper, "description": self.description}


@dataclass(frozen=True)
class FeatureSpace:
    """An ordered, named, bounded feature space."""

    features: tuple[Feature, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        feats = tuple(self.features)
        names = [f.name for f in feats]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValidationError(f"duplicate feature names {sorted(dup)}", field="features")
        object.__setattr__(self, "features", feats)

    # -- basic access ------------------------------------------------------
    def __len__(self) -> int:
        return len(self.features)

    def __iter__(self):
        return iter(self.features)

    def __contains__(self, name: object) -> bool:
        return any(f.name == name for f in self.features)

    def __getitem__(self, name: str) -> Feature:
        for f in self.features:
            if f.name == name:
                return f
        raise ValidationError(f"unknown feature {name!r}; valid: {list(self.names)}", field="feature")

    @property
    def names(self) -> tuple[str, ...]:
        """Feature names, in column order."""
        return tuple(f.name for f in self.features)

    @property
    def units(self) -> tuple[str, ...]:
        """Feature units, in column order."""
        return tuple(f.unit for f in self.features)

    @property
    def lower(self) -> np.ndarray:
        """Lower bounds ``(d,)``, physical units."""
        return np.array([f.lower for f in self.features], dtype=float)

    @property
    def upper(self) -> np.ndarray:
        """Upper bounds ``(d,)``, physical units."""
        return np.array([f.upper for f in self.features], dtype=float)

    def index(self, name: str) -> int:
        """Column of feature ``name``; raises :class:`~hapticsdk.errors.ValidationError` for
        an unknown name.
        """
        for i, f in enumerate(self.features):
            if f.name == name:
                return i
        raise ValidationError(f"unknown feature {name!r}; valid: {list(self.names)}", field="feature")

    # -- algebra -----------------------------------------------------------
    def union(self, other: "FeatureSpace | Iterable[Feature]") -> "FeatureSpace":
        """Features of ``self`` then those of ``other`` not already present (by name).

        Raises :class:`~hapticsdk.errors.FeatureConflictError` when ``other`` names a
        feature of ``self`` in another unit (naming both owners)."""
        feats = list(self.features)
        seen = {f.name: f for f in self.features}
        for f in other:
            mine = seen.get(f.name)
            if mine is None:
                feats.append(f)
                seen[f.name] = f
            elif not same_unit(mine.unit, f.unit):
                raise FeatureConflictError(
                    f"feature {f.name!r} is declared in {mine.unit!r} by {mine.owner or 'one plugin'} and in "
                    f"{f.unit!r} by {f.owner or 'another'}; a feature is one physical quantity in one unit: "
                    f"rename one (plugin features take the prefix '<dimension>.', e.g. 'stickiness.{f.name}')",
                    field=f"features.{f.name}")
        return FeatureSpace(tuple(feats))

    def subset(self, names: Sequence[str]) -> "FeatureSpace":
        """The space of the features ``names``, in that order."""
        return FeatureSpace(tuple(self[n] for n in names))

    def with_bounds(self, bounds: Mapping[str, tuple[float, float]]) -> "FeatureSpace":
        """Copy with the bounds of the named features replaced."""
        return FeatureSpace(tuple(
            f.with_bounds(*bounds[f.name]) if f.name in bounds else f for f in self.features))

    # -- arrays ------------------------------------------------------------
    def validate(self, X: npt.ArrayLike, *, field: str = "features", check_bounds: bool = False,
                 rtol: float = 1e-9) -> np.ndarray:
        """Return ``X`` as a float ``(n, d)`` array; raise on wrong shape, NaN or Inf.

        A 1-D input of length ``d`` is taken as one row. With ``check_bounds`` a value
        outside ``[lower, upper]`` (relative slack ``rtol`` of the span) raises too.
        """
        arr = np.asarray(X, dtype=float)
        if arr.ndim == 1:
            arr = arr[None, :]
        if arr.ndim != 2 or arr.shape[1] != len(self):
            raise ValidationError(
                f"expected shape (n, {len(self)}) for features {list(self.names)}, got {arr.shape}",
                field=field)
        bad = ~np.isfinite(arr)
        if bad.any():
            col = int(np.argwhere(bad)[0][1])
            raise ValidationError("NaN or infinite value", field=f"{field}.{self.names[col]}")
        if check_bounds:
            slack = rtol * np.maximum(self.upper - self.lower, 1.0)
            low = arr < self.lower - slack
            high = arr > self.upper + slack
            if (low | high).any():
                r, c = np.argwhere(low | high)[0]
                f = self.features[c]
                raise ValidationError(
                    f"value {arr[r, c]:g} {f.unit} outside [{f.lower:g}, {f.upper:g}]",
                    field=f"{field}.{f.name}")
        return arr

    def clip(self, X: np.ndarray) -> np.ndarray:
        """``X`` clipped into the bounds, column by column."""
        return np.clip(X, self.lower, self.upper)

    def contains(self, X: np.ndarray, rtol: float = 1e-9) -> np.ndarray:
        """Boolean per row: inside the bounds (with relative slack)."""
        X = np.atleast_2d(X)
        slack = rtol * np.maximum(self.upper - self.lower, 1.0)
        return np.all((X >= self.lower - slack) & (X <= self.upper + slack), axis=-1)

    def to_unit(self, X: np.ndarray) -> np.ndarray:
        """Map physical values to [0, 1] per feature (degenerate features map to 0)."""
        span = self.upper - self.lower
        safe = np.where(span > 0, span, 1.0)
        return np.where(span > 0, (np.asarray(X, float) - self.lower) / safe, 0.0)

    def from_unit(self, U: np.ndarray) -> np.ndarray:
        """Map ``U`` in the unit box ``[0, 1]^d`` to physical units (``lower + U * span``).
        """
        return self.lower + np.asarray(U, float) * (self.upper - self.lower)

    def random(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` feature vectors drawn uniformly in the box, ``(n, d)``, physical units."""
        return self.from_unit(rng.random((n, len(self))))

    def vector(self, values: Mapping[str, float], *, field: str = "features") -> np.ndarray:
        """Build a ``(d,)`` vector from a name -> value mapping (all names required)."""
        missing = [n for n in self.names if n not in values]
        if missing:
            raise ValidationError(f"missing features {missing}", field=field)
        extra = [k for k in values if k not in self]
        if extra:
            raise ValidationError(f"unknown features {extra}; valid: {list(self.names)}", field=field)
        return self.validate([float(values[n]) for n in self.names], field=field)[0]

    def as_dict(self, x: np.ndarray) -> dict[str, float]:
        """One feature vector ``(d,)`` as ``{name: value}``."""
        x = np.asarray(x, float).reshape(-1)
        return {n: float(v) for n, v in zip(self.names, x)}

    def to_dict(self) -> list[dict]:
        """The features as a list of JSON-ready dicts (see :meth:`Feature.to_dict`)."""
        return [f.to_dict() for f in self.features]

    @classmethod
    def from_dicts(cls, items: Iterable[Mapping]) -> "FeatureSpace":
        """Build a space from dicts with ``name``, ``lower``, ``upper`` (``unit`` and
        ``description`` optional).
        """
        return cls(tuple(Feature(name=i["name"], unit=i.get("unit", ""), lower=i["lower"],
                                 upper=i["upper"], description=i.get("description", ""))
                         for i in items))
