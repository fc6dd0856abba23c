"""Command line ergonomics: help with defaults and an example for every command, one
progress facility that stays quiet off a terminal, and the text defects of issue 17."""

from __future__ import annotations

import argparse
import io
import json
import re

import pytest

from hapticsdk.cli import EXAMPLES, build_parser, example_text, main
from hapticsdk.progress import Progress, shown


def _commands(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _commands(sub, path + (name,))


def _path_of(commands, parser):
    return next(k for k, v in commands.items() if v is parser)


def test_every_flag_has_help_and_every_command_an_example():
    parser = build_parser()
    commands = dict(_commands(parser))
    assert {" ".join(p) for p in commands} == set(EXAMPLES)
    for path, p in commands.items():
        text = p.format_help()
        example = example_text(" ".join(path))
        assert f"Example:\n  {example}" in text, path
        # the example runs this command (or one of its subcommands) with options it has
        words = example.split()
        i = words.index("hapticsdk")
        assert words[i + 1: i + 1 + len(path)] == list(path), (path, example)
        target, rest = parser, words[i + 1:]
        while rest and (" ".join(_path_of(commands, target) + (rest[0],)) in EXAMPLES):
            target = commands[_path_of(commands, target) + (rest[0],)]
            rest = rest[1:]
        options = {o for a in target._actions for o in a.option_strings}
        for w in rest:
            if w.startswith("-"):
                assert w in options, (path, w)
        for a in p._actions:
            if isinstance(a, (argparse._HelpAction, argparse._VersionAction, argparse._SubParsersAction)):
                continue
            assert a.help, (path, a.option_strings or a.dest)
            # a default that is set is stated in the help text
            if a.option_strings and a.default not in (None, False, [], argparse.SUPPRESS):
                assert "default" in p._get_formatter()._get_help_string(a), (path, a.option_strings)


@pytest.mark.parametrize("flag, shown_default", [("--tolerance", "(default: 0.01)"), ("--penalty", "(default: paper)"),
                                                 ("--method", "(default: ga-polish)")])
def test_solve_help_shows_defaults(capsys, flag, shown_default):
    assert main(["solve", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert re.search(re.escape(flag) + r" \S+ .*?" + re.escape(shown_default), text), text


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_draws_only_on_a_terminal_and_not_with_json():
    tty, pipe = _Tty(), io.StringIO()
    assert shown(stream=tty) and not shown(stream=pipe) and not shown(quiet=True, stream=tty)
    with Progress("work", stream=tty) as p:
        for k in range(1, 4):
            p("stage one", k, 3)
    assert "work: stage one" in tty.getvalue() and "/3" in tty.getvalue()
    for stream, quiet in ((pipe, False), (_Tty(), True)):
        with Progress("work", stream=stream, quiet=quiet) as p:
            p("stage one", 1, 3)
            p.note("hello")
        assert stream.getvalue() == ""


def test_dataset_generate_reports_progress_through_the_facility(tmp_path, monkeypatch, capsys):
    seen = []

    class Recorder(Progress):
        def __call__(self, stage, done, total):
            seen.append((stage, done, total))

    monkeypatch.setattr("hapticsdk.progress.Progress", Recorder)
    code = main(["dataset", "generate", str(tmp_path / "g"), "--samples", "2", "--trials", "2",
                 "--raters", "2", "--format", "csv"])
    assert code == 0
    captured = capsys.readouterr()
    assert captured.err == ""  # stderr is not a terminal here: no bar, no ad hoc lines
    stages = [s for s, _, _ in seen]
    assert {"simulating trials", "writing trial files", "extracting features"} <= set(stages)
    assert ("simulating trials", 4, 4) in seen and ("extracting features", 4, 4) in seen


def test_train_json_prints_only_json(tmp_path, capsys):
    from hapticsdk.training.pipeline import shipped_dataset_dir
    code = main(["train", str(shipped_dataset_dir()), "--out", str(tmp_path / "m.onnx"), "--json",
                 "--folds", "0", "--restarts", "1"])
    assert code == 0
    cap = capsys.readouterr()
    json.loads(cap.out)
    assert cap.err == ""


# -- text defects -------------------------------------------------------------------
def test_render_of_intensities_is_not_called_material_material(capsys):
    code = main(["render", "--hardness", "0.8", "--roughness", "0.3", "--seconds", "0.05"])
    out = capsys.readouterr().out
    assert code == 0
    first = out.splitlines()[0]
    assert first.startswith("targets hardness 0.8, roughness 0.3: rendered "), first
    assert "material material" not in out


def test_render_of_a_library_material_names_it(capsys):
    assert main(["render", "S7", "--seconds", "0.05"]) == 0
    assert capsys.readouterr().out.startswith("material S7: rendered ")


def test_unknown_material_is_said_once(capsys):
    assert main(["render", "S99", "--seconds", "0.05"]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("hapticsdk: error: ") and "unknown material 'S99'; known: S1," in err
    assert err.count("unknown material") == 1 and ": material: unknown material" not in err


def test_train_on_a_missing_directory_is_a_prefixed_error(tmp_path, capsys):
    assert main(["train", str(tmp_path / "nope"), "--out", str(tmp_path / "m.onnx")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err and all(line.startswith("hapticsdk: error: ") for line in err), err


def test_render_realtime_flag_paces_on_the_clock(capsys):
    code = main(["render", "S8", "--seconds", "0.05", "--realtime", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    assert out["loop"]["realtime"] is True
    # paced: the run cannot take less wall time than the servo time it rendered
    assert out["wall_s"] >= 0.05 * (1 - 1e-6) - 1e-3
    main(["render", "S8", "--seconds", "0.05", "--json"])
    assert json.loads(capsys.readouterr().out)["loop"]["realtime"] is False
