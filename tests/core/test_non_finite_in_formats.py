"""No SDK file format holds a non-finite number (docs/safety.md, "Non-finite numbers").

JSON Schema cannot say "finite": every comparison with NaN is False, so a NaN passes
``minimum`` / ``maximum``, and ``inf`` is a ``number``. Python's ``json`` reads the
literals ``NaN`` / ``Infinity`` (refused by :func:`hapticsdk.schemas_io.read_json`) and
also reads ``1e400`` as ``inf`` and a 1 followed by 400 zeros as an int no float holds,
which the literal check does not see. A dict built in memory (``Scene.from_dict``,
``RenderPlan.from_dict``, a plugin's materials) never went through a reader at all.

The test is a class, not samples: for every schema in ``schemas/`` it takes a valid
instance made by the SDK itself, replaces each number in it (every leaf, each in turn)
by NaN, +-inf and 10**400, and wants a ValidationError whose ``field`` is the JSON path
of that number. The same for files written with a ``1e400`` literal, through each
format's own reader. And the SDK's writers never write what its readers refuse.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest
from json_leaves import dotted, nodes, number_leaves, replaced

from hapticsdk.errors import RecordingError, ValidationError
from hapticsdk.schemas_io import non_finite_at, schema_dir, validate

ROOT = Path(__file__).resolve().parents[2]
BIG = 10 ** 400
BAD = [float("nan"), float("inf"), float("-inf"), BIG, -BIG]


def _materials():
    return json.loads((ROOT / "hapticsdk/data/materials.json").read_text())


def _scene():
    """The desk example (geometry, poses, a seed), with intensities that only the schema's
    0..1 would check (a NaN passes it), inline and overriding a library material's."""
    d = json.loads((ROOT / "examples/scenes/desk-spatial.json").read_text())
    d["objects"][1]["intensities"] = {"hardness": 0.7}
    d["objects"][2]["material"] = {"name": "tile", "intensities": {"hardness": 0.4, "roughness": 0.3}}
    return d


_PLAN: dict = {}


def _plan():
    if not _PLAN:
        from hapticsdk.compiler import compile_scene
        from hapticsdk.scene import Scene
        _PLAN.update(compile_scene(Scene.for_material("S7", solver={"method": "polish"})).to_dict())
    return copy.deepcopy(_PLAN)


def _calibrations():
    from hapticsdk.calibration import PiezoTable, VoiceCoilCalibration
    from hapticsdk.calibration.damping import DampingCalibration
    from hapticsdk.calibration.store import calibration_to_dict
    vc = VoiceCoilCalibration(coefficients=(0.0002, 0.01, -0.3), confidence_intervals=((0.0, 1.0),) * 3,
                              amplifier_gain=2.0)
    pz = PiezoTable(frequencies_hz=[50.0, 100.0], voltages_v=[10.0, 50.0], acceleration=[[1.0, 5.0], [2.0, 10.0]])
    dm = DampingCalibration(trusted_damping_ns_per_m=0.5, damping_ns_per_m=1.0, worst_error_ns_per_m=0.5,
                            mass_kg=0.05, period_s=0.001, resolution_mm=0.01, readings=1000)
    return [calibration_to_dict(c) for c in (vc, pz, dm)]


def _ratings():
    return json.loads((ROOT / "hapticsdk/data/dataset/ratings.json").read_text())


def _manifest():
    return {"schema_version": 1, "format": "hapticsdk-recording", "fs_hz": 1000.0, "accel_unit": "g",
            "lateral_axis": "x", "full_scale": {"force_n": [-10.0, 10.0], "acc": [-16, 16]},
            "trials": [{"sample": "S1", "trial": 1, "file": "S1_1.npz", "fs_hz": 2000}]}


#: (schema, valid instance) for every format validate() checks
INSTANCES = [("materials", _materials), ("scene", _scene), ("plan", _plan),
             *[("calibration", (lambda i: lambda: _calibrations()[i])(i)) for i in range(3)]]
#: the recording formats, validated by hapticsdk.training.recordings.validate_json
RECORDING_INSTANCES = [("ratings.schema.json", _ratings), ("recording.schema.json", _manifest)]


def test_every_schema_is_covered():
    """A new format in schemas/ must join the tables above (hjif has its own parser and test)."""
    covered = {n for n, _ in INSTANCES} | {n.split(".")[0] for n, _ in RECORDING_INSTANCES} | {"hjif"}
    assert {p.name.split(".")[0] for p in schema_dir().glob("*.schema.json")} == covered


@pytest.mark.parametrize("name, make", INSTANCES, ids=[f"{n}{i}" for i, (n, _) in enumerate(INSTANCES)])
def test_a_non_finite_number_anywhere_is_refused_by_its_path(name, make):
    data = make()
    validate(data, name)   # the instance is valid as made
    leaves = list(number_leaves(data))
    assert len(leaves) >= 3
    for path, _ in leaves:
        for bad in BAD:
            with pytest.raises(ValidationError, match="not a finite number") as exc:
                validate(replaced(data, path, bad), name)
            assert exc.value.field == f"{name}{dotted(path)}", (path, bad)


@pytest.mark.parametrize("name, make", RECORDING_INSTANCES, ids=[n for n, _ in RECORDING_INSTANCES])
def test_a_non_finite_number_in_a_recording_format_is_refused(name, make):
    from hapticsdk.training.recordings import validate_json
    data = make()
    validate_json(data, name, source="x")
    leaves = list(number_leaves(data))
    assert len(leaves) >= 3
    for path, _ in leaves:
        for bad in BAD:
            with pytest.raises(RecordingError, match="not a finite number") as exc:
                validate_json(replaced(data, path, bad), name, source="x")
            assert exc.value.field == ".".join(map(str, path)), (path, bad)


def test_numpy_and_in_memory_values_are_seen():
    import numpy as np
    assert non_finite_at({"a": [1, {"b": np.float32("nan")}]}) == (".a[1].b", "nan")
    assert non_finite_at((0.5, np.float64("inf"))) == ("[1]", "inf")
    assert non_finite_at({"a": [1, 2.5, True, None, "NaN", np.int64(3), 2 ** 1000]}) is None


def test_a_scene_dict_with_nan_intensity_is_refused():
    """The reported gap: Scene.from_dict took a NaN intensity (it passes the schema's 0..1)."""
    from hapticsdk.scene import Scene
    with pytest.raises(ValidationError) as exc:
        Scene.from_dict({"objects": [{"material": "S7", "intensities": {"hardness": float("nan")}}]})
    assert exc.value.field == "scene.objects[0].intensities.hardness"


def _file_with_literal(tmp_path, data, path, literal="1e400"):
    """``data`` written as JSON with the number at ``path`` spelled ``literal``."""
    marker = "__HAPTICSDK_TEST_MARKER__"
    text = json.dumps(replaced(data, path, marker)).replace(f'"{marker}"', literal)
    p = tmp_path / "f.json"
    p.write_text(text)
    return p


def _readers():
    from hapticsdk.calibration.store import read_calibration
    from hapticsdk.perception.materials import load_library
    from hapticsdk.plan import RenderPlan
    from hapticsdk.scene import Scene
    from hapticsdk.training.recordings import load_manifest, load_ratings
    return [("materials", _materials, load_library, "materials"), ("scene", _scene, Scene.load, "scene"),
            ("plan", _plan, RenderPlan.load, "plan"),
            ("calibration", lambda: _calibrations()[0], read_calibration, "calibration"),
            ("ratings", _ratings, load_ratings, ""), ("recording", _manifest, load_manifest, "")]


@pytest.mark.parametrize("i", range(6), ids=["materials", "scene", "plan", "calibration", "ratings", "recording"])
@pytest.mark.parametrize("literal", ["1e400", "-1e999", "1" + "0" * 400])
def test_a_file_with_an_overflowing_literal_is_refused(tmp_path, i, literal):
    """``json`` reads 1e400 as inf: not a NaN/Infinity literal, so only the finite check sees it."""
    name, make, read, prefix = _readers()[i]
    data = make()
    for path, _ in number_leaves(data):
        p = _file_with_literal(tmp_path, data, path, literal)
        with pytest.raises(ValidationError) as exc:   # a named error, by the field
            read(p)
        want = f"{prefix}{dotted(path)}" if prefix else ".".join(map(str, path))
        assert exc.value.field is not None and exc.value.field.endswith(want), (exc.value.field, want)


def test_a_plan_with_a_nan_is_not_written(tmp_path):
    """RenderPlan.to_json / save wrote NaN (json.dumps allows it by default), which
    RenderPlan.load then refused: the writer refuses it by path instead."""
    from hapticsdk.plan import RenderPlan
    plan = RenderPlan.from_dict(_plan())
    mp = next(iter(plan.materials.values()))
    mp.solve["error"] = float("nan")
    with pytest.raises(ValidationError) as exc:
        plan.save(tmp_path / "p.json")
    assert exc.value.field == f"plan.materials.{mp.name}.solve.error"
    assert not (tmp_path / "p.json").exists()


def test_the_ratings_writer_refuses_nan(tmp_path):
    from hapticsdk.training.recordings import load_ratings, write_ratings
    ratings = load_ratings(ROOT / "hapticsdk/data/dataset/ratings.json")
    sample = next(iter(ratings.values))
    dim = next(iter(ratings.values[sample]))
    ratings.values[sample][dim][0] = float("nan")
    with pytest.raises(RecordingError, match="not a finite number"):
        write_ratings(tmp_path / "ratings.json", ratings)
    assert not (tmp_path / "ratings.json").exists()


@pytest.mark.parametrize("name, make", INSTANCES, ids=[f"{n}{i}" for i, (n, _) in enumerate(INSTANCES)])
def test_a_key_that_is_not_a_string_is_refused_by_its_path(name, make):
    """JSON keys are strings; a dict built in code may hold None, 1 or NaN as a key (a
    scene's ``devices`` then named a role ``None`` that compiled and was ignored)."""
    data = make()
    objects = [p for p, v in nodes(data) if isinstance(v, dict)]
    assert objects
    for path in objects:
        for key in (None, 1):
            grown = {**_at(data, path), key: 0.5}
            d = replaced(data, path, grown) if path else grown
            with pytest.raises(ValidationError, match="is not a string") as exc:
                validate(d, name)
            assert exc.value.field == f"{name}{dotted(path)}", (path, key)


def _at(data, path):
    for k in path:
        data = data[k]
    return data
