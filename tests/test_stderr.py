"""Standard error of stratified ray tracing (collapsed strata, ``tallies.bin_estimate``).

Calibration: K independent seeds of one configuration give K independent estimates per bin;
their scatter is the true ray noise, against which the reported ``stderr`` is judged.

Derived acceptance interval. Per bin B, s²_B (sample variance over K seeds, K − 1 dof) has
(K − 1) s²_B / σ²_B ~ χ²_{K−1}. The reported se²_B is conservative: E[se²_B] = σ²_B / c_B
with c_B ≤ 1 (E(x_2k − x_2k+1)² = σ²_2k + σ²_2k+1 + (μ_2k − μ_2k+1)²). The collapse bias
is largest for an integrand with a step edge across the sweep direction: edge at a uniform
position in a pair of strata of unit width gives E[pair] = ∫₀¹ b db = 1/2 against the true
∫₀¹ b(1 − b) db = 1/6 per edge, c = 1/3; an edge along the sweep, or a feature smaller than a
stratum, gives c ≈ 1 — so c_B ∈ [1/3, 1] for the piecewise-constant integrands of
facet-hit indicators. The mean over M bins of r_B = s²_B / mean_K(se²_B) is then
mean(c_B X_B) with X_B ~ χ²_{K−1}/(K−1) independent (bins are disjoint events: their
correlation −μ_Bμ_B' is negligible), so (1/3)·q_lo ≤ r̄ ≤ q_hi with q the two-sided
quantiles of χ²_{M(K−1)}/(M(K−1)) (noise of the mean se² over K runs neglected: its relative
variance is O(1/(K·events))). The same holds for the pooled χ²/dof of seed-vs-seed
differences, z = (f_a − f_b)/√(se_a² + se_b²) over K/2 disjoint seed pairs (M·K/2 dof).
α = 0.01 with Šidák correction over the 4 interval checks (2 surfaces × 2 statistics).
"""

import warnings

import numpy as np
import pytest
from scipy import stats
from support import sidak

from microsim import analytic as an
from microsim.checkpoints import interrupt_at
from microsim.sim import BLOCK, LEDGER, Bins, Result, ray_events, simulate
from microsim.sim.tallies import bin_estimate
from microsim.surfaces import flat, gaussian, vgrooves

K, RAYS, THETA, BINS = 16, 200_000, [30.0, 70.0], Bins(9, 7)
MIN_EVENTS = 100
ALPHA = sidak(0.01, 4)
C_MIN = 1.0 / 3.0  # worst collapse bias (step edge, module docstring)


def chi2_interval(dof: int) -> tuple[float, float]:
    """Two-sided (1 − ALPHA) interval of χ²_dof / dof."""
    return stats.chi2.ppf(ALPHA / 2, dof) / dof, stats.chi2.isf(ALPHA / 2, dof) / dof


def per_ray_stderr(res: Result, i: int) -> np.ndarray:
    """The old i.i.d. formula √((Σw²/N − (Σw/N)²)/(N − 1))/Ω, flat."""
    omega = res.bins.projected_solid_angle().ravel()
    return bin_estimate(res.sum_w[i].ravel(), res.sum_w2[i].ravel(), int(res.rays[i]), omega)[1]


def calibration(surface):
    """(mean ratio new, mean ratio old, pooled χ²/dof new, M bins) over the incidences."""
    runs = [
        simulate(surface, "aluminium", THETA, rays=RAYS, bins=BINS, seed=1000 + k) for k in range(K)
    ]
    assert all(r.meta["stderr_method"] == "pairs" for r in runs)
    r_new, r_old, chi2, dof = [], [], 0.0, 0
    for i in range(len(THETA)):
        f = np.array([r.brdf[i].ravel() for r in runs])
        se = np.array([r.stderr[i].ravel() for r in runs])
        old = np.array([per_ray_stderr(r, i) for r in runs])
        used = np.array([r.counts[i].ravel() for r in runs]).min(axis=0) >= MIN_EVENTS
        s2 = np.var(f[:, used], axis=0, ddof=1)
        r_new.append(s2 / np.mean(se[:, used] ** 2, axis=0))
        r_old.append(s2 / np.mean(old[:, used] ** 2, axis=0))
        a, b = f[0::2, used], f[1::2, used]
        sa, sb = se[0::2, used], se[1::2, used]
        chi2 += float(np.sum((a - b) ** 2 / (sa**2 + sb**2)))
        dof += a.size
    r_new, r_old = np.concatenate(r_new), np.concatenate(r_old)
    return float(r_new.mean()), float(r_old.mean()), chi2 / dof, r_new.size, dof


@pytest.fixture(scope="module")
def heightfield():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return gaussian(128, 1.0, 1.2, 8.0, seed=0)


@pytest.fixture(scope="module")
def grooves():
    return vgrooves(1000, an.Beckmann(0.3), seed=0)


@pytest.mark.parametrize("name", ["heightfield", "grooves"])
def test_pair_stderr_matches_the_scatter_between_seeds(request, name):
    ratio, ratio_old, chi2_dof, m, dof = calibration(request.getfixturevalue(name))
    lo, hi = chi2_interval(m * (K - 1))
    print(
        f"{name}: M = {m}, ratio new {ratio:.3f}, old {ratio_old:.3f}, chi2/dof {chi2_dof:.3f}, "
        f"interval [{C_MIN * lo:.3f}, {hi:.3f}]"
    )
    assert m >= 30
    assert C_MIN * lo <= ratio <= hi
    lo2, hi2 = chi2_interval(dof)
    assert C_MIN * lo2 <= chi2_dof <= hi2
    if name == "heightfield":  # the per-ray formula ignores the stratification
        assert ratio_old < C_MIN * lo


# --- the pair tally itself ---------------------------------------------------------------------
def test_sum_pair_is_the_sum_over_adjacent_ray_pairs_in_one_bin(heightfield):
    """Σ_k w_2k w_2k+1 over pairs in the same bin, from the per-ray events of the same stream
    (odd ray count: the last ray has no partner). Weights agree to rounding (the facet table
    evaluates Fresnel per facet), so the comparison is relative 1e-12."""
    n, bins = 5 * BLOCK + 7, Bins(9, 7)
    res = simulate(heightfield, "aluminium", 40.0, rays=n, bins=bins, seed=3)
    ev = ray_events(heightfield, "aluminium", 40.0, rays=n, seed=3)
    where = np.where(
        ev.status == LEDGER.index("single"), bins.locate(np.nan_to_num(ev.wo), 0.0), -1
    )
    x = np.zeros((n, bins.shape[0] * bins.shape[1]))
    ok = where >= 0
    x[np.flatnonzero(ok), where[ok]] = ev.weight[ok]
    want = np.sum(x[0 : n - 1 : 2] * x[1:n:2], axis=0)
    got = res.tallies["sum_pair"][0, 0]
    assert np.any(want > 0)
    assert np.allclose(got, want, rtol=1e-12, atol=0)
    # Σx² − 2Σpair = Σ_k (x_2k − x_2k+1)² + x_last²: the variance estimate is a sum of squares
    sq = np.sum((x[0 : n - 1 : 2] - x[1:n:2]) ** 2, axis=0) + x[-1] ** 2
    assert np.allclose(res.tallies["sum_w2"][0, 0] - 2 * got, sq, rtol=1e-9, atol=1e-12)


def test_sum_pair_is_bitwise_independent_of_threads_and_chunk(grooves):
    kw = dict(rays=6 * BLOCK + 11, bins=Bins(9, 7), seed=2)
    a = simulate(grooves, "aluminium", [20.0, 60.0], threads=1, chunk=BLOCK, **kw)
    b = simulate(grooves, "aluminium", [20.0, 60.0], threads=2, chunk=4 * BLOCK, **kw)
    assert np.array_equal(a.tallies["sum_pair"], b.tallies["sum_pair"])
    assert np.array_equal(a.stderr, b.stderr, equal_nan=True)


def test_save_load_keeps_the_pair_tally(tmp_path, grooves):
    res = simulate(grooves, None, 30.0, rays=2 * BLOCK, bins=Bins(9, 7), seed=1)
    res.save(tmp_path)
    back = Result.load(tmp_path)
    assert np.array_equal(back.tallies["sum_pair"], res.tallies["sum_pair"])
    with np.load(tmp_path / "brdf.npz") as z:
        assert "tally_sum_pair" in z.files


def test_independent_origins_keep_the_per_ray_formula(grooves):
    res = simulate(
        grooves, "aluminium", 30.0, rays=3 * BLOCK, bins=Bins(9, 7), origins="independent"
    )
    assert res.meta["stderr_method"] == "per-ray"
    assert np.array_equal(res.stderr[0].ravel(), per_ray_stderr(res, 0), equal_nan=True)


def test_pair_rule_falls_back_to_per_ray_where_the_pair_estimate_is_zero():
    """A flat mirror puts every ray, with one weight, in one bin: all pairs are equal, the pair
    variance is 0 up to rounding and so is the per-ray one — the estimate has no noise."""
    res = simulate(flat(), "aluminium", 30.0, rays=2 * BLOCK, bins=Bins(9, 7))
    assert np.count_nonzero(res.counts) == 1
    assert np.all(res.stderr <= 1e-7 * res.brdf.max())
    # pair estimate 0 but per-ray > 0 (constructed): the per-ray value is used
    omega = np.ones(2)
    f, se = bin_estimate(
        np.array([2.0, 1.0]), np.array([2.0, 1.0]), 10, omega, sum_pair=np.array([1.0, 0.0])
    )
    per = bin_estimate(np.array([2.0, 1.0]), np.array([2.0, 1.0]), 10, omega)[1]
    assert se[0] == per[0] > 0 and se[1] == pytest.approx(0.1)  # √(1 − 0)/10


# --- isotropic (per-block incidence-azimuth rotation) ------------------------------------------
def test_isotropic_is_part_of_the_resume_configuration(heightfield):
    kw = dict(rays=6 * BLOCK, bins=Bins(9, 7), seed=5, threads=1, chunk=BLOCK)
    with interrupt_at("simulation", after=1):  # after two of the six blocks
        part = simulate(heightfield, "aluminium", 50.0, isotropic=True, **kw)
    assert part.is_partial and part.meta["isotropic"] and part.meta["stderr_method"] == "per-ray"
    with pytest.raises(ValueError, match="isotropic"):
        simulate(heightfield, "aluminium", 50.0, isotropic=False, resume=part, **kw)
    full = simulate(heightfield, "aluminium", 50.0, isotropic=True, **kw)
    resumed = simulate(heightfield, "aluminium", 50.0, isotropic=True, resume=part, **kw)
    for k in full.tallies:
        assert np.array_equal(full.tallies[k], resumed.tallies[k]), k
    plain = simulate(heightfield, "aluminium", 50.0, **kw)
    assert not np.array_equal(plain.sum_w, full.sum_w)  # the rotation acts


def test_isotropic_rejects_non_booleans(grooves):
    with pytest.raises(ValueError, match="isotropic"):
        simulate(grooves, None, 30.0, rays=BLOCK, isotropic="yes")


# --- runner: rays = "auto" -----------------------------------------------------------------------
AUTO_SCENE = """\
name = "tiny-auto"
description = "tiny auto scene"
[surface]
kind = "vgrooves"
n_grooves = 400
ndf = "beckmann"
m = 0.3
[material]
ior = "aluminium"
[simulation]
theta_i = [30]
rays = "auto"
theta_bins = 9
phi_bins = 10
realisations = {realisations}
seed = 3
"""


def test_runner_traces_an_auto_scene_to_the_target(tmp_path):
    from microsim.app import runner

    scene = tmp_path / "auto.toml"
    scene.write_text(AUTO_SCENE.format(realisations=1))
    plan = runner.plan_run(scene, out=tmp_path / "run", quick=True)
    assert plan.auto and plan.rays == min(runner.AUTO_MAX_RAYS, runner.QUICK.max_rays)
    res = runner.tracing.simulate_auto_scene(plan, None)
    info = runner.tracing.auto_summary(res)["incidences"][0]
    assert info["rays"] == int(res.rays[0]) <= plan.rays and info["seconds"] > 0
    assert info["converged"] == (info["rse"] <= runner.AUTO_TARGET)
    assert info["converged"] or info["rays"] == plan.rays
    meta = runner.tracing.run_meta(plan)
    assert meta["rays"] == "auto" and meta["max_rays"] == plan.rays
    fixed = runner.plan_run(scene, out=tmp_path / "run2", quick=True, rays=5000)
    assert not fixed.auto and fixed.rays == 5000  # --rays overrides


def test_runner_refuses_auto_with_several_realisations(tmp_path):
    from microsim.app import runner

    scene = tmp_path / "auto.toml"
    scene.write_text(AUTO_SCENE.format(realisations=2))
    with pytest.raises(ValueError, match="auto"):
        runner.plan_run(scene, out=tmp_path / "run", quick=True)
