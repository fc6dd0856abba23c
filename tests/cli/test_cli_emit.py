"""``hapticsdk.cli.emit``: ``--json`` output is written as it is encoded, the same text as
``json.dumps(obj, indent=2)`` and a newline, so a large result (``bench stability --random
N --json``: about 4.6 kB of text per cell) is never held whole in memory beside itself."""

from __future__ import annotations

import io
import json

import numpy as np

from hapticsdk.cli import emit


class _Sink(io.TextIOBase):
    """A stdout stand-in that keeps the text and the largest single write."""

    def __init__(self) -> None:
        self.parts: list[str] = []
        self.largest = 0

    def write(self, s: str) -> int:
        self.parts.append(s)
        self.largest = max(self.largest, len(s))
        return len(s)


def _result(cells: int) -> dict:
    return {"mode": "random", "seed": np.int64(1), "summary": {"ok": np.bool_(True), "median": np.float64(0.25)},
            "cells": [{"i": i, "x": np.arange(3, dtype=float) * i, "name": f"cell {i}"} for i in range(cells)]}


def test_the_json_text_is_that_of_dumps_with_a_newline(monkeypatch):
    sink = _Sink()
    monkeypatch.setattr("sys.stdout", sink)
    obj = _result(5)
    emit(obj, True)
    from hapticsdk.cli import _json_default
    assert "".join(sink.parts) == json.dumps(obj, indent=2, default=_json_default) + "\n"


def test_a_large_result_is_written_in_pieces(monkeypatch):
    # 2000 cells of 6 values each: one write per encoded token or line, so no write comes
    # near the whole text (the old emit wrote it in one piece)
    sink = _Sink()
    monkeypatch.setattr("sys.stdout", sink)
    emit(_result(2000), True)
    total = sum(len(p) for p in sink.parts)
    assert total > 100_000
    assert sink.largest < total / 1000, (sink.largest, total)


def test_text_mode_prints_the_text(monkeypatch, capsys):
    emit({"a": 1}, False, "hello")
    assert capsys.readouterr().out == "hello\n"
