"""rays = "auto" (microsim.sim.auto): the run stops at the requested precision, and the error
it then achieves against the exact closed form (V-grooves: Torrance–Sparrow with V-groove G,
Mikkelsen eq. 25, bin-averaged) is what that precision predicts."""

import numpy as np
import pytest
from scipy import stats
from support import flat_verdict

from microsim import analytic as an
from microsim.analysis.verdicts import energy_set
from microsim.analytic.models import TorranceSparrow
from microsim.sim import Bins, simulate
from microsim.sim.auto import _batch_seed, relative_standard_error, simulate_auto
from microsim.sim.predict import Predictor, predict
from microsim.surfaces import vgrooves

ALPHA = 0.01
THETA = [30.0, 70.0]
BINS = Bins(15, 13)


@pytest.fixture(scope="module")
def grooves():
    return vgrooves(1000, an.Beckmann(0.3), seed=0)


def weighted_chi2_bounds(a: np.ndarray, alpha: float):
    """Two-sided (1 − alpha) bounds of Σ a_B z_B², z_B ~ N(0, 1) independent, by Satterthwaite's
    approximation Σ a z² ≈ (Σa) χ²_ν / ν with ν = (Σa)²/Σa² (matching mean and variance)."""
    s1, s2 = a.sum(), np.sum(a * a)
    nu = s1 * s1 / s2
    return (s1 * stats.chi2.ppf(alpha / 2, nu) / nu, s1 * stats.chi2.isf(alpha / 2, nu) / nu)


def test_auto_stops_at_target_and_matches_the_exact_model_at_that_precision(grooves):
    """rel_rms² = Σ_E w ((m − f̂)/f̂)² / Σ_E w with an exact model m is Σ a_B z_B², a_B =
    w_B (se_B/f_B)²/Σw (z_B the bin's standardised error): mean rse², variance 2Σa². The model's
    own errors (quadrature rtol 1e-3, 1000 stratified groove tilts instead of the continuous
    Beckmann NDF: quantile error ≤ 1/2000 per bin) add at most (2e-3)² — included as slack."""
    target = 0.02
    res = simulate_auto(
        grooves, "aluminium", THETA, target=target, bins=BINS, masking="exact", first=8192, seed=1
    )
    model = predict(
        [Predictor("ts", TorranceSparrow(an.Beckmann(0.3), "vgroove", "aluminium"))], THETA, BINS
    )["ts"]
    omega = BINS.projected_solid_angle()
    alpha = 1 - (1 - ALPHA) ** (1 / len(THETA))  # Šidák over the incidences
    for i, info in enumerate(res.meta["auto"]["incidences"]):
        assert info["converged"] and info["rse"] <= target
        # each batch is at most 4x what was done: the last one cannot overshoot by more than 5x
        assert info["rse"] > target / np.sqrt(5) * 0.95
        assert info["rays"] == res.rays[i] and info["seconds"] > 0
        f, se, c = res.brdf[i], res.stderr[i], res.counts[i]
        assert relative_standard_error(f, se, c, omega) == pytest.approx(info["rse"], rel=1e-12)
        used = (c >= 25) & (f > 0)
        w = np.where(used, f * omega, 0.0)
        E = energy_set(w).reshape(f.shape)
        a = w[E] * (se[E] / f[E]) ** 2 / w[E].sum()
        lo, hi = weighted_chi2_bounds(a, alpha)
        v = flat_verdict(f, se, c, model[i], omega, BINS.theta_edges, phi_edges=BINS.phi_edges)
        assert v["energy_bins"] == E.sum()
        assert lo - 4e-6 <= v["rel_rms"] ** 2 <= hi + 4e-6, (THETA[i], v["rel_rms"], lo, hi)


def test_one_batch_run_is_the_plain_simulation(grooves):
    """With a loose target the first batch suffices: its tallies are exactly simulate's."""
    res = simulate_auto(grooves, None, 45.0, target=0.9, bins=BINS, first=3 * 4096, seed=4)
    ref = simulate(grooves, None, 45.0, rays=3 * 4096, bins=BINS, seed=_batch_seed(4, 0, 0))
    assert res.meta["auto"]["incidences"][0]["batches"] == 1
    for name in ("brdf", "stderr", "counts", "sum_w", "sum_w2"):
        assert np.array_equal(getattr(res, name), getattr(ref, name)), name
    for k, v in ref.ledger.items():
        assert res.ledger[k] == pytest.approx(v, rel=1e-12, abs=1e-15), k


def test_batches_are_merged_as_one_larger_run(grooves):
    """Batches pool Σw, Σw² and counts: the merged estimate is the mean of the batch
    estimates weighted by rays, and max_rays caps the run (not converged then)."""
    res = simulate_auto(
        grooves, "aluminium", 30.0, target=1e-4, bins=BINS, first=4096, max_rays=5 * 4096, seed=2
    )
    info = res.meta["auto"]["incidences"][0]
    assert not info["converged"] and info["rays"] == 5 * 4096 and info["batches"] == 2
    parts = [
        simulate(grooves, "aluminium", 30.0, rays=n, bins=BINS, seed=_batch_seed(2, 0, b))
        for b, n in enumerate((4096, 4 * 4096))
    ]
    pooled = sum(p.sum_w for p in parts) / (5 * 4096) / BINS.projected_solid_angle()
    assert np.allclose(res.brdf, pooled, rtol=1e-12, atol=0)
    assert np.array_equal(res.counts, parts[0].counts + parts[1].counts)


@pytest.mark.parametrize(
    "kw", [dict(target=0.0), dict(target=1.5), dict(first=0), dict(max_rays=1), dict(energy=0.0)]
)
def test_bad_arguments_raise(grooves, kw):
    args = dict(target=0.05) | kw
    with pytest.raises(ValueError, match=next(iter(kw))):
        simulate_auto(grooves, None, 30.0, bins=BINS, **args)
