"""A CSV header that names one column twice is refused by every CSV reader of the SDK,
naming the column -- the CSV form of a JSON key given twice (test_duplicate_json_keys).

Each reader looked a column up by name, some by the first of two equal names
(``header.index``: piezo measurements, discrimination answers, damping runs and
excitations, trial feature tables) and one by the last (a dict built column by column:
trial recordings), so which of two columns of numbers became the calibration or the
recording depended on the reader, silently. For each reader: the file it reads, then the
same file with each needed column written twice (the copy holding other numbers) ->
a named error whose message names the column."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hapticsdk.errors import HapticSDKError

ROOT = Path(__file__).resolve().parents[2]


def _piezo(tmp):
    from hapticsdk.calibration import read_measurements_csv
    rows = [["frequency_hz", "voltage_v", "acceleration_m_s2"], ["100", "10", "1"], ["100", "50", "5"],
            ["200", "10", "2"], ["200", "50", "10"]]
    return rows, read_measurements_csv


def _run(tmp):
    from hapticsdk.calibration.damping import read_run_csv
    return [["position_mm", "force_n"]] + [[f"{0.01 * i:.3f}", f"{0.1 * (-1) ** i:.2f}"] for i in range(20)], read_run_csv


def _excitation(tmp):
    from hapticsdk.calibration.damping import read_excitation_csv
    return [["force_n"]] + [[f"{0.1 * (-1) ** i:.2f}"] for i in range(20)], read_excitation_csv


def _answers(tmp):
    from hapticsdk.calibration.discrimination import DiscriminationAnswers, generate_answers
    text = generate_answers(people=1).to_csv(tmp / "a.csv").read_text()
    rows = [ln.split(",") for ln in text.splitlines() if not ln.startswith("#")]
    return rows, DiscriminationAnswers.from_csv


def _trial_features(tmp):
    from hapticsdk.training.pipeline import _read_trial_features
    text = (ROOT / "hapticsdk/data/dataset/trial_features.csv").read_text()
    return [ln.split(",") for ln in text.splitlines()[:6]], _read_trial_features


def _trial(tmp):
    from hapticsdk.training.recordings import COLUMNS, read_trial_file, write_trial_file
    cols = {c: np.linspace(0.0, 1.0, 8) for c in COLUMNS}
    write_trial_file(tmp / "t.csv", cols)
    return [ln.split(",") for ln in (tmp / "t.csv").read_text().splitlines()], read_trial_file


READERS = {"piezo": _piezo, "run": _run, "excitation": _excitation, "answers": _answers,
           "trial_features": _trial_features, "trial": _trial}


def _write(path, rows):
    path.write_text("\n".join(",".join(r) for r in rows) + "\n")
    return path


@pytest.mark.parametrize("name", sorted(READERS))
def test_a_column_named_twice_is_refused_by_name(tmp_path, name):
    rows, read = READERS[name](tmp_path)
    p = _write(tmp_path / "x.csv", rows)
    read(p)  # as written, it reads
    for j, col in enumerate(rows[0]):
        col = col.strip()
        twice = [r + [(("9" if r[j].strip()[:1] != "9" else "8") + r[j]) if i else r[j]] for i, r in enumerate(rows)]
        _write(p, twice)
        with pytest.raises(HapticSDKError, match=f"'{col}'"):
            read(p)
