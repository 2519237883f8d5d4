"""Realisations drawn one per stratum of the ensemble (the Student-t mixture's Beckmann patches)
are judged with the stratified variance of their mean (``stats.stratified_mean``, Cochran
1977), not the i.i.d. one: its formulas, its calibration (a t test on it keeps its level where
the stratum means vary smoothly) and its use in the verdicts of a mixture run."""

import numpy as np
import pytest
from scipy import stats

from microsim.analysis.verdicts import realisation_strata, verdicts_for_result
from microsim.errors import UsageError
from microsim.sim import Bins, simulate
from microsim.sim.compare import attach_models, default_models
from microsim.stats import stratified_mean
from microsim.surfaces import student_t_mixture


def test_one_per_stratum_collapses_neighbouring_pairs():
    x = np.array([1.0, 2.0, 4.0, 7.0])
    st = stratified_mean(x, [0, 1, 2, 3])
    assert st.mean == pytest.approx(3.5)
    assert st.var == pytest.approx(((1 - 2) ** 2 + (4 - 7) ** 2) / 16)
    assert st.dof == 2
    odd = stratified_mean(np.array([1.0, 2.0, 4.0, 7.0, 8.0]), [0, 1, 2, 3, 4])
    triple = np.array([4.0, 7.0, 8.0])  # the last group is a triple when K is odd
    assert odd.var == pytest.approx(((1 - 2) ** 2 + 1.5 * np.sum((triple - 19 / 3) ** 2)) / 25)
    assert odd.dof == 3


def test_several_per_stratum_use_the_within_stratum_variance():
    rng = np.random.default_rng(1)
    x = rng.normal(size=12) + np.repeat([0.0, 10.0, 20.0], 4)
    strata = np.repeat([0, 1, 2], 4)
    st = stratified_mean(x, strata)
    groups = x.reshape(3, 4)
    assert st.mean == pytest.approx(groups.mean())
    assert st.var == pytest.approx(np.sum(groups.var(axis=1, ddof=1) / 4) / 9)
    assert 1 <= st.dof <= 9


@pytest.mark.parametrize("strata", [[0], [0, 0, 1]])
def test_bad_strata_name_themselves(strata):
    with pytest.raises(UsageError, match="strata"):
        stratified_mean(np.zeros(2), strata)


def test_a_t_test_on_it_keeps_its_level_where_strata_means_vary_smoothly():
    """16 strata with means rising along a smooth curve (as a BRDF over the Gamma strata of
    roughness), one noisy draw each: the t test of the true mean on the collapsed-strata error
    rejects at most at its nominal 5 % (binomial bound at 1e-3), while the i.i.d. error — which
    counts the spread of the strata as noise — would be several times larger."""
    rng = np.random.default_rng(7)
    K, trials = 16, 2000
    centres = np.tanh(np.linspace(-2.0, 2.0, K))  # stratum means, their average is the truth
    x = centres + 0.05 * rng.standard_normal((trials, K))
    strata = np.arange(K)
    st = stratified_mean(x.T, strata)
    t = (st.mean - centres.mean()) / np.sqrt(st.var)
    rejected = np.sum(np.abs(t) > stats.t.isf(0.025, st.dof))
    assert rejected <= stats.binom.isf(1e-3, trials, 0.05)
    iid = x.std(axis=1, ddof=1) / np.sqrt(K)
    assert np.median(np.sqrt(st.var) / iid) < 0.5


def test_a_mixture_run_is_judged_with_the_stratified_error():
    patches = [student_t_mixture(64, 1.0, 0.3, 2.0, 8.0, seed=s, patches=4) for s in range(4)]
    res = simulate(None, None, [30.0], rays=80_000, bins=Bins(9, 7), realisations=patches)
    assert list(realisation_strata(res)) == [0, 1, 2, 3]
    res = attach_models(res, [m for m in default_models(patches, None) if "nominal" in m.name])
    (v, *_) = verdicts_for_result(res)
    # two collapsed pairs of strata: 2 dof (i.i.d. realisations would have R − 1 = 3)
    assert v["reference"] == "realisations" and v["realisation_dof"] == 2
