"""Random damage to documents of every .hjif release shape and to AHAP patterns: the
readers either accept the document or raise a FormatError naming a field, never another
exception, and what they accept synthesises (seeded random cells; the shapes come from test_hjif_versions and test_ahap)."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import test_ahap as ta
import test_hjif_versions as tv

from hapticsdk.errors import ValidationError
from hapticsdk.interop.ahap import parse_ahap, to_haptic_file
from hapticsdk.interop.hjif_model import parse_hjif
from hapticsdk.interop.hjif_synth import file_duration_s, synthesize

JUNK = [None, True, -1, 65535, 0.0, 1e308, "", "Wave", [], {}, [{}], {"x": 1},
        float("nan"), float("inf"), 10 ** 400, -10 ** 400, 2 ** 63]


def _nodes(obj, out, parent=None, key=None):
    out.append((parent, key))
    if isinstance(obj, dict):
        for k, v in obj.items():
            _nodes(v, out, obj, k)
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            _nodes(v, out, obj, i)
    return out


def _damage(doc, rng):
    d = copy.deepcopy(doc)
    for _ in range(int(rng.integers(1, 4))):
        nodes = [n for n in _nodes(d, []) if n[0] is not None]
        parent, key = nodes[int(rng.integers(len(nodes)))]
        if rng.random() < 0.3 and isinstance(parent, dict):
            del parent[key]
        else:
            parent[key] = copy.deepcopy(JUNK[int(rng.integers(len(JUNK)))])
    return d


BUILDERS = [tv.crm0, tv.crm2, tv.crm3, tv.crm32, tv.current]


@pytest.mark.parametrize("seed", range(300))
def test_damaged_hjif_of_any_release_is_read_or_named(seed):
    rng = np.random.default_rng(seed)
    doc = _damage(BUILDERS[seed % len(BUILDERS)](), rng)
    try:
        h = parse_hjif(doc)
        synthesize(h, fs=2000.0, seconds=min(2.0, file_duration_s(h)))
    except ValidationError as exc:  # FormatError and ContentBudgetError are ValidationErrors
        assert exc.field


AHAP = ta.ahap(ta.event(0.0, kind="HapticTransient", intensity=0.8, sharpness=0.4),
               ta.event(0.015, dur=0.25, intensity=0.8, sharpness=0.4),
               ta.curve("HapticIntensityControl", 0.015, [(0, 1), (0.1, 0.5), (0.25, 0.0)]),
               {"Parameter": {"ParameterID": "HapticSharpnessControl", "Time": 0.1, "ParameterValue": 0.2}})


@pytest.mark.parametrize("seed", range(300))
def test_damaged_ahap_is_read_or_named(seed):
    doc = _damage(AHAP, np.random.default_rng(seed))
    try:
        h = to_haptic_file(parse_ahap(doc))
        synthesize(h, fs=2000.0, seconds=min(2.0, file_duration_s(h)))
    except ValidationError as exc:
        assert exc.field
