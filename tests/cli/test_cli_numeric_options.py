"""Every numeric option of every ``hapticsdk`` subcommand, found by walking the parser
(a new option is covered without being listed), refuses NaN, infinities, a number beyond
the float range, an empty string and text: ``hapticsdk: error: <option>: <reason>``,
exit 2, before any work runs."""

from __future__ import annotations

import argparse

import pytest

from hapticsdk.cli import build_parser, main

#: argparse types that take text, not numbers (paths, serial numbers, figure files)
TEXT_TYPES = {"figure_file", "serial", "Path", "str"}
BAD = ["nan", "NaN", "inf", "-inf", "Infinity", "1e400", "-1e400", "1" + "0" * 400, "", "abc", "1,5"]


def _subcommands(parser, prefix=()):
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            for name, sub in a.choices.items():
                yield from _subcommands(sub, (*prefix, name))
            return
    yield prefix, parser


def _numeric_options():
    out = []
    for prefix, sub in _subcommands(build_parser()):
        positional = [a for a in sub._actions if not a.option_strings and a.dest != "help"]
        for a in sub._actions:
            if a.option_strings and a.nargs != 0 and a.type is not None and \
                    getattr(a.type, "__name__", "") not in TEXT_TYPES:
                out.append((prefix, a, len(positional)))
    return out


OPTIONS = _numeric_options()


def test_the_walk_finds_the_numeric_options():
    names = {(" ".join(p), a.option_strings[-1]) for p, a, _ in OPTIONS}
    assert {("solve", "--tolerance"), ("render", "--seconds"), ("play", "--tick"),
            ("calibrate damping", "--mass")} <= names
    assert len(OPTIONS) >= 40


@pytest.mark.parametrize("prefix, action, _", OPTIONS, ids=[f"{' '.join(p)} {a.option_strings[-1]}"
                                                           for p, a, _ in OPTIONS])
def test_each_bad_number_is_refused_by_the_type(prefix, action, _):
    lists = getattr(action.type, "__name__", "") == "int_list"   # "1,5" is a list of two
    for text in BAD if not lists else [b for b in BAD if b != "1,5"] + ["1,1" + "0" * 400]:
        with pytest.raises((argparse.ArgumentTypeError, ValueError, TypeError)):
            action.type(text)


@pytest.mark.parametrize("prefix, action, npos", OPTIONS, ids=[f"{' '.join(p)} {a.option_strings[-1]}"
                                                              for p, a, _ in OPTIONS])
def test_the_command_line_names_the_option(capsys, prefix, action, npos):
    opt = action.option_strings[-1]
    argv = [*prefix, *(["S7"] * npos), f"{opt}=nan"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err
    assert f"{opt}" in err or action.dest in err, err
