"""Every numeric, flag and choice option of the first-party solvers is checked by name
before it is used: a string that reads as a number ("0.5"), a bool, NaN, an int beyond the
float range, or a value scipy would take without a word (recombination=nan, tol=-1,
polish="no") raises ValidationError with field ``options.<name>``."""

import math

import pytest

import hapticsdk as hs
from hapticsdk.errors import ValidationError

SMALL = {"ga": {"population": 6, "generations": 2}, "de": {"population": 6, "generations": 2},
         "de-scipy": {"popsize": 2, "maxiter": 2}, "polish": {}, "ga-polish": {}, "amortised": {}}

NUMBERS = ["0.5", True, math.nan, 10 ** 400, [0.5]]
CASES = [(m, k, v) for m, keys in {
    "ga": ["crossover_fraction", "mutation_rate", "target_error", "time_budget_s"],
    "de": ["mutation", "recombination", "target_error", "time_budget_s"],
    "de-scipy": ["mutation", "recombination", "tol", "target_error", "time_budget_s"],
    "polish": ["target_error", "ftol", "damping", "constraint_margin", "constraint_weight", "time_budget_s"],
    "ga-polish": ["target_error", "ftol", "damping", "constraint_margin", "constraint_weight"],
}.items() for k in keys for v in NUMBERS if not (k == "time_budget_s" and v == 10 ** 400)]
CASES += [
    ("de-scipy", "recombination", -1.0), ("de-scipy", "recombination", math.inf),
    ("de-scipy", "tol", -1.0), ("de-scipy", "tol", math.nan),
    ("de-scipy", "polish", "no"), ("de-scipy", "polish", 1), ("de-scipy", "polish", None),
    ("de-scipy", "strategy", "nope"), ("de-scipy", "strategy", 5),
    ("de", "mutation", (0.5, "1")), ("de", "mutation", (0.5, True)), ("de-scipy", "mutation", (0.5,)),
    ("polish", "damping", 0.0), ("ga-polish", "damping", 0.0),
    ("polish", "ga_options", True), ("polish", "ga_options", [1]), ("ga-polish", "ga_options", "x"),
    ("amortised", "cache", "no"), ("amortised", "cache", None), ("amortised", "cache_dir", 5),
]


@pytest.mark.parametrize("method, key, value", CASES)
def test_bad_option_value_is_named(method, key, value):
    with pytest.raises(ValidationError) as exc:
        hs.solve({"hardness": 0.5}, method=method, seed=0, options={**SMALL[method], key: value})
    assert exc.value.field is not None and exc.value.field.startswith(f"options.{key}"), exc.value


@pytest.mark.parametrize("method, opts", [
    ("de-scipy", {"mutation": 0.7, "recombination": 1, "tol": 0, "polish": False, "strategy": "rand1exp"}),
    ("de", {"mutation": [0.5, 1], "recombination": 0}),
    ("ga", {"crossover_fraction": 1, "time_budget_s": math.inf, "target_error": 0}),
    ("polish", {"damping": 1e-12, "ga_options": {}, "time_budget_s": 10 ** 400}),
])
def test_good_option_values_still_solve(method, opts):
    res = hs.solve({"hardness": 0.5}, method=method, seed=0, options={**SMALL[method], **opts})
    assert math.isfinite(res.error)
