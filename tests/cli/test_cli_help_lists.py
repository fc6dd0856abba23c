"""Help texts built from what is registered and installed (issue 29 items 5 and 6)."""

from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

from hapticsdk.cli import build_parser


def _sub(parser: argparse.ArgumentParser) -> argparse._SubParsersAction:
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return action


def test_bench_help_lists_every_benchmark():
    parser = build_parser()
    bench = _sub(parser).choices["bench"]
    names = list(_sub(bench).choices)
    assert len(names) >= 5
    top = re.sub(r"\s+", " ", parser.format_help())
    line = top[top.index(" bench "):]
    own = re.sub(r"\s+", " ", bench.format_help())
    for name in names:
        assert name in line.split(")")[0], f"`hapticsdk --help` does not list bench {name}: {line[:200]}"
        assert name in own.split("positional arguments")[0], f"`bench --help` description misses {name}"


def test_train_example_names_a_folder_that_exists_from_anywhere(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)              # not the source tree
    train = _sub(build_parser()).choices["train"]
    example = train.format_help().split("Example:")[1].strip().splitlines()[0]
    argv = shlex.split(example)
    assert argv[:2] == ["hapticsdk", "train"]
    folder = Path(argv[2])
    assert (folder / "dataset.json").is_file(), example
