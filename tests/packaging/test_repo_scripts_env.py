"""Loading a repository script for a test leaves the process environment as it was: the
benches set ``OMP_NUM_THREADS=1`` for themselves at import, and a test that loaded one
used to hand that to every later test's subprocesses (a BLAS control case in
tests/runtime/test_session.py then skipped)."""

import os

from repo_scripts import load_script


def test_a_loaded_script_does_not_change_the_environment(monkeypatch):
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    before = dict(os.environ)
    mod = load_script("bench/tick_outputs_digest.py")
    load_script("bench/bench_tick_floor.py")
    assert dict(os.environ) == before
    assert callable(mod.log_backend_commands)   # the script itself was loaded
