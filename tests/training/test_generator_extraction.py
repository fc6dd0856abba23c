"""Generated data set: extraction recovers the generating parameters; physical plausibility."""

import numpy as np

from hapticsdk.training import extraction, generator


def test_recovers_generating_parameters_for_all_23(gen23, feats23):
    specs = gen23.specs
    assert [s.name for s in specs] == [f"S{i}" for i in range(1, 24)]
    truth = gen23.truth
    X, df = feats23.X, feats23.df_hz
    # per trial: dominant frequency within one FFT bin of v/lambda of that trial
    f_true = np.array([t["Fpeak"] for t in truth])
    assert np.all(np.abs(X[:, 2] - f_true) <= df)
    means = feats23.sample_means()
    gs = np.array([s.gs_n_mm for s in specs])
    amp = np.array([s.amplitude_m_s2 for s in specs])
    # per sample: stiffness within 5 %, amplitude within 10 %
    assert np.all(np.abs(means[:, 0] / gs - 1) < 0.05), np.abs(means[:, 0] / gs - 1).max()
    assert np.all(np.abs(means[:, 3] / amp - 1) < 0.10), np.abs(means[:, 3] / amp - 1).max()
    # work of pressing against the spring-damper integral
    w_true = np.array([t["W"] for t in truth])
    assert np.all(np.abs(X[:, 1] / w_true - 1) < 0.05)


def test_feature_ranges_physically_plausible_and_constraints_hold(gen23, feats23):
    X = feats23.X
    assert feats23.dataset_df_hz == 0.4
    gs = np.array([s.gs_n_mm for s in gen23.specs])
    assert gs.min() <= 0.11 and gs.max() >= 4.4 and gs.max() <= 4.6
    assert X[:, 2].max() < 220.0 and X[:, 2].min() > 30.0
    peak_f = np.array([t["peak_force_n"] for t in gen23.truth])
    assert peak_f.min() > 3.3 * 1.2 and peak_f.max() < 6.5
    mw, mp = extraction.constraint_margins(X, feats23.dataset_df_hz)
    assert np.all(mw > 0), mw.min()  # W >= MF^2/(2 GS), formula (4)
    assert np.all(mp > 0), mp.min()  # P >= AFpeak^2 df, formula (5)
    sd = feats23.summary()
    assert all(v["GS"][1] > 0 for v in sd.values())


def test_ratings_follow_the_psychophysics(gen23):
    names = [s.name for s in gen23.specs]
    Y = gen23.ratings.mean_normalised(names)
    assert np.all((Y >= 0) & (Y <= 1))
    gs = np.array([s.gs_n_mm for s in gen23.specs])
    # hardness grows with stiffness (power law), roughness varies across samples
    assert np.corrcoef(np.log(gs), np.log(Y[:, 0]))[0, 1] > 0.95
    assert Y[:, 1].max() - Y[:, 1].min() > 0.3
    labels = {s.label for s in gen23.specs}
    assert {"leather on sponge", "fabric on rubber"} <= labels
    for s in gen23.specs:
        assert s.substrate in s.label and s.texture in s.label


def test_generator_is_deterministic_and_seeded():
    a = generator.generate(2, n_trials=1, n_raters=2)
    b = generator.generate(2, n_trials=1, n_raters=2)
    c = generator.generate(2, seed=5, n_trials=1, n_raters=2)
    np.testing.assert_array_equal(a.trials[1].acc, b.trials[1].acc)
    assert a.ratings.values == b.ratings.values
    assert not np.array_equal(a.trials[1].acc, c.trials[1].acc)


def test_larger_sets_fill_the_same_ranges():
    specs = generator.make_samples(92)
    assert len({s.name for s in specs}) == 92
    gs = np.array([s.gs_n_mm for s in specs])
    assert gs.min() >= 0.1 - 1e-12 and gs.max() <= 4.5 + 1e-12
    assert {s.substrate for s in specs} == set(generator.SUBSTRATES)
