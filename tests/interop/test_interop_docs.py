"""The round-trip example of docs/interop.md runs and prints what the page says."""

from __future__ import annotations

import re
from pathlib import Path

DOC = Path(__file__).resolve().parents[2] / "docs" / "interop.md"


def test_round_trip_example_runs(capsys):
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)
    assert len(blocks) == 1
    exec(compile(blocks[0], "docs/interop.md", "exec"), {"__name__": "interop_doc"})
    assert capsys.readouterr().out.strip() == "['coil', 'stiffness', 'texture']"
