"""``main`` builds only the parser of the command it runs (issue 30, round 7: the other
~30 parsers cost 10-15 ms of a ``hapticsdk render S7``); what that parser accepts, prints
and returns is what the full parser does."""

from __future__ import annotations

import argparse
import contextlib
import io

import pytest

from hapticsdk import cli
from hapticsdk.cli import build_parser, command_word


def _sub(parser: argparse.ArgumentParser) -> argparse._SubParsersAction | None:
    found = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return found[0] if found else None


def _tree(parser: argparse.ArgumentParser) -> dict[str, object]:
    """Help text, defaults and sub-commands of a parser, recursively."""
    sub = _sub(parser)
    return {"help": parser.format_help(), "defaults": sorted(parser._defaults),
            "children": {n: _tree(p) for n, p in sub.choices.items()} if sub else {}}


def _commands() -> list[str]:
    return list(_sub(build_parser()).choices)


def test_every_command_has_the_same_parser_when_built_alone(monkeypatch):
    monkeypatch.setenv("COLUMNS", "100")
    full = _tree(build_parser())["children"]
    assert len(full) >= 15
    for name in full:
        alone = _tree(build_parser(name))
        assert list(alone["children"]) == [name], name     # only that command was built
        assert alone["children"][name] == full[name], name  # and it is the same one


@pytest.mark.parametrize("name", [None, "no-such-command"])
def test_no_command_or_an_unknown_one_gets_the_full_parser(name, monkeypatch):
    monkeypatch.setenv("COLUMNS", "100")
    assert _tree(build_parser(name)) == _tree(build_parser())


@pytest.mark.parametrize("argv, word", [
    (["render", "S7"], "render"), (["-v", "render"], "render"), (["--verbose", "bench", "timing"], "bench"),
    (["--help"], None), (["--version"], None), (["--verb", "render"], None), ([], None), (["-v"], None)])
def test_command_word(argv, word):
    assert command_word(argv) == word


def test_main_builds_only_the_parser_it_needs(monkeypatch):
    made: list[str] = []
    real = argparse.ArgumentParser.__init__

    def counting(self, *args, **kwargs):
        made.append(kwargs.get("prog") or "?")
        real(self, *args, **kwargs)
    monkeypatch.setattr(argparse.ArgumentParser, "__init__", counting)
    with contextlib.redirect_stdout(io.StringIO()) as out:
        code = cli.main(["render", "S7", "--seconds", "0.05"])
    assert code in (0, 1)
    assert "servo loop:" in out.getvalue()
    assert len(made) == 2, made          # the top level and `render`


@pytest.mark.parametrize("argv", [["rendr"], ["render", "--seconds"], ["bench"], []])
def test_usage_errors_read_as_with_the_full_parser(argv, monkeypatch, capsys):
    monkeypatch.setenv("COLUMNS", "100")
    code = cli.main(argv)
    got = capsys.readouterr()
    monkeypatch.setattr(cli, "command_word", lambda argv: None)   # the full parser
    assert cli.main(argv) == code
    assert capsys.readouterr() == got
