"""Shared fixtures: one generated 23-sample set per session (about 1.5 s)."""

import pytest

from hapticsdk.training import extraction, generator


@pytest.fixture(scope="session")
def gen23():
    return generator.generate(23)


@pytest.fixture(scope="session")
def feats23(gen23):
    return extraction.extract_trials(gen23.trials)


@pytest.fixture(scope="session")
def small_recordings(tmp_path_factory):
    """A written recording set of 3 samples x 2 trials (CSV), for file-level tests."""
    gs = generator.generate(3, n_trials=2, n_raters=3)
    out = tmp_path_factory.mktemp("rec")
    generator.write_recordings(gs, out, fmt="csv")
    return out, gs
