"""The ``hapticsdk`` command holds the BLAS / OpenMP thread pools to one thread unless the
user's environment sizes them (hapticsdk.threadpools.default_one_thread, called by
hapticsdk.cli.run before any command imports numpy)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

import hapticsdk.cli as cli
from hapticsdk.threadpools import POOL_ENV, default_one_thread


def test_with_nothing_set_every_pool_variable_becomes_one():
    env: dict[str, str] = {"PATH": "/bin"}
    assert default_one_thread(env) is True
    assert {k: env[k] for k in POOL_ENV} == {k: "1" for k in POOL_ENV}
    assert env["PATH"] == "/bin"


@pytest.mark.parametrize("name", POOL_ENV)
def test_a_pool_variable_the_user_set_leaves_all_of_them_alone(name):
    """A user who sized one pool (say OMP_NUM_THREADS=4) meant it: setting
    OPENBLAS_NUM_THREADS=1 beside it would override it, since OpenBLAS reads its own
    variable first."""
    env = {name: "4"}
    assert default_one_thread(env) is False
    assert env == {name: "4"}


def _run_capturing_environment(monkeypatch, env):
    """cli.run() with ``env`` as the process environment (a copy: what run() sets must not
    reach the other tests' subprocesses)."""
    monkeypatch.setattr(os, "environ", env)
    seen: dict[str, str | None] = {}

    def fake_main(argv=None):
        seen.update({k: os.environ.get(k) for k in POOL_ENV})
        return 0

    monkeypatch.setattr(cli, "main", fake_main)
    with pytest.raises(SystemExit) as ex:
        cli.run()
    assert ex.value.code == 0
    return seen


def _environment_without_pools() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k not in POOL_ENV}


def test_the_command_sets_the_pools_before_it_runs(monkeypatch):
    assert _run_capturing_environment(monkeypatch, _environment_without_pools()) == {k: "1" for k in POOL_ENV}


def test_the_command_keeps_a_users_pool_size(monkeypatch):
    env = {**_environment_without_pools(), "OMP_NUM_THREADS": "3"}
    seen = _run_capturing_environment(monkeypatch, env)
    assert seen == {k: ("3" if k == "OMP_NUM_THREADS" else None) for k in POOL_ENV}


def test_running_the_command_in_a_test_leaves_this_process_environment_alone(monkeypatch):
    before = {k: os.environ.get(k) for k in POOL_ENV}
    _run_capturing_environment(monkeypatch, _environment_without_pools())
    monkeypatch.undo()
    assert {k: os.environ.get(k) for k in POOL_ENV} == before


# the command as a user runs it; at exit (after the command has loaded numpy and solved)
# the process's thread count goes to stderr
_PROBE = r"""
import atexit, os, sys
atexit.register(lambda: print("threads", len(os.listdir("/proc/self/task")), file=sys.stderr))
sys.argv = ["hapticsdk", "solve", "--hardness", "0.5", "--roughness", "0.5", "--seed", "1"]
from hapticsdk.cli import run
run()
"""


def _threads(extra_env: dict[str, str]) -> int:
    env = {**_environment_without_pools(), **extra_env}
    out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, env=env, timeout=300,
                         check=False)
    assert out.returncode == 0, out.stderr[-2000:]
    line = [ln for ln in out.stderr.splitlines() if ln.startswith("threads ")][-1]
    return int(line.split()[1])


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="thread counts from /proc (Linux)")
@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="a one-CPU machine starts no BLAS worker either way")
def test_the_command_runs_without_a_blas_worker_thread():
    """With two or more CPUs, numpy's OpenBLAS starts a worker per extra CPU when it loads
    (up to the pool size its environment gives). The same command with the pool sized 2
    by the user has one thread more than with nothing set: so nothing set means the
    command's own one-thread default was in force when numpy loaded. (A first run may load
    onnxruntime, whose thread would count too, while the SDK's cache is cold: it runs once
    before the two that are compared.)"""
    _threads({})
    default = _threads({})
    user_two = _threads({"OPENBLAS_NUM_THREADS": "2"})
    assert default < user_two, (default, user_two)
