"""A feature data set (``dataset.json`` + ``trial_features.csv``) holds no non-finite
number: ``df_hz`` (the spectrum's resolution, which bounds the roughness constraint
``P >= AFpeak^2 df`` and goes into the trained model file) must be a finite number > 0
in every row, and ``dataset.json`` -- no schema checks it -- refuses a ``1e400`` (read as
inf) by its path. A NaN ``df_hz`` was trained into the model: its constraint bound was
NaN, which reads as met everywhere."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from hapticsdk.errors import RecordingError
from hapticsdk.training.pipeline import load_table

DATA = Path(__file__).resolve().parents[2] / "hapticsdk/data/dataset"


@pytest.fixture
def dataset(tmp_path):
    d = tmp_path / "ds"
    shutil.copytree(DATA, d)
    return d


def test_the_shipped_data_set_loads(dataset):
    assert load_table(dataset).features.X.shape[1] == 5


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e400", "0", "-0.4"])
def test_df_hz_must_be_finite_and_positive(dataset, value):
    p = dataset / "trial_features.csv"
    lines = p.read_text().splitlines()
    head = lines[0].split(",")
    row = lines[2].split(",")
    row[head.index("df_hz")] = value
    lines[2] = ",".join(row)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match="row 2") as exc:
        load_table(dataset)
    assert exc.value.field == "df_hz"


@pytest.mark.parametrize("literal", ["1e400", "-1e999", "1" + "0" * 400])
def test_dataset_index_refuses_overflowing_numbers(dataset, literal):
    p = dataset / "dataset.json"
    doc = json.loads(p.read_text())
    doc["fs_hz"] = "__MARK__"
    p.write_text(json.dumps(doc).replace('"__MARK__"', literal))
    with pytest.raises(RecordingError, match="not a finite number") as exc:
        load_table(dataset)
    assert exc.value.field == "fs_hz"
