"""A figure path the plotting backend cannot write fails before a benchmark runs
(``bench solvers`` takes minutes, ``bench stability`` tens of seconds): review G found
the format checked only when the figure was saved, after the run."""

from __future__ import annotations

import pytest

from hapticsdk.cli import main


@pytest.mark.parametrize("argv, module, fn", [
    (["bench", "solvers", "--quick"], "hapticsdk.benchmarks.solvers", "run"),
    (["bench", "stability", "--quick"], "hapticsdk.benchmarks.stability", "run_matrix"),
    (["plan", "examples/scenes/library.json"], "hapticsdk.compiler", "compile_scene"),
])
def test_unwritable_figure_format_fails_before_the_benchmark(tmp_path, monkeypatch, capsys, argv, module, fn):
    import importlib
    ran = []
    monkeypatch.setattr(importlib.import_module(module), fn, lambda *a, **k: ran.append(1) or {})
    try:
        code = main([*argv, "--plot", str(tmp_path / "fig.exe")])
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    assert "--plot" in capsys.readouterr().err and not ran
