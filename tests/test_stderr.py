"""Standard error of stratified ray tracing (paired strata, ``tallies.bin_estimate``).

Calibration: K independent seeds of one configuration give K independent estimates per bin;
their scatter is the true ray noise, against which the reported ``stderr`` is judged.

Rays 2k and 2k + 1 are two independent samples of one stratum, so the reported se²_B is an
unbiased estimate of the estimator's variance σ²_B: E[(x_2k − x_2k+1)²] = 2σ²_k per stratum
(Cochran, Sampling Techniques, §5.5). Per bin B, r_B = s²_B / mean_K(se²_B) (s²_B the sample
variance over the K seeds) then has expectation 1 up to O(1/events) (the Jensen term of the
noisy denominator, small for bins with ≥ ``ENOUGH`` events in every run). The test takes
the mean r̄ over the bins (every order slot, for bounce chains) and its standard error from
the run itself — the jackknife over seeds, which carries whatever correlation the bins share
— and asserts (a) |r̄ − 1| ≤ z·se_jack, z the two-sided normal quantile at α = 0.01 Šidák-
corrected over the trace paths, and (b) r̄ in [0.8, 1.25]: error bars within ±12 % in σ of
the noise they describe, on every trace path (heightfield, V-grooves traced/exact/analytic,
bounce chains, and ``isotropic`` runs, whose blocks are independent replicates and whose
error comes from the scatter between blocks, B/(B − 1)-corrected: unbiased too; the
denominator's Jensen term is larger there, 1/(B − 1) with B ≈ 49 blocks per run, and
averaged over K runs).
"""

import warnings

import numpy as np
import pytest
from support import sidak

from microsim import analytic as an
from microsim.checkpoints import interrupt_at
from microsim.sim import BLOCK, LEDGER, Bins, Result, ray_events, simulate
from microsim.sim.tallies import MIN_DISCORDANT, PairSums, bin_estimate, stderr_dof
from microsim.stats import MIN_EVENTS, norm_isf  # MIN_EVENTS: the pair rule's threshold
from microsim.surfaces import flat, gaussian, vgrooves

K, RAYS, THETA, BINS = 16, 200_000, [30.0, 70.0], Bins(9, 7)
ENOUGH = 100  # events a bin needs in every run to enter the calibration
PATHS = {  # trace path → (surface fixture, simulate keywords)
    "heightfield": ("heightfield", {}),
    "heightfield-bounces": ("heightfield", {"bounces": 3}),
    "grooves-traced": ("grooves", {"masking": "traced"}),
    "grooves-exact": ("grooves", {"masking": "exact"}),
    "grooves-analytic": ("grooves", {"masking": "analytic"}),
    "heightfield-isotropic": ("heightfield", {"isotropic": True}),
}
METHOD = {"heightfield-isotropic": "blocks"}  # the others: paired strata
Z = norm_isf(sidak(0.01, len(PATHS)) / 2)
BAND = (0.8, 1.25)


def per_ray_stderr(res: Result, i: int) -> np.ndarray:
    """The i.i.d. formula √((Σw²/N − (Σw/N)²)/(N − 1))/Ω, flat."""
    omega = res.bins.projected_solid_angle().ravel()
    return bin_estimate(res.sum_w[i].ravel(), res.sum_w2[i].ravel(), int(res.rays[i]), omega)[1]


def slots(res: Result):
    """(estimates, standard errors, events) per (incidence, order slot × bin), order slots
    for bounce chains (``brdf_orders``), else the single-bounce bins."""
    if res.brdf_orders is None:
        return res.brdf.reshape(len(THETA), -1), res.stderr.reshape(len(THETA), -1), res.counts
    f = np.moveaxis(res.brdf_orders, 0, 1).reshape(len(THETA), -1)
    se = np.moveaxis(res.stderr_orders, 0, 1).reshape(len(THETA), -1)
    return f, se, res.tallies["count"].sum(axis=0)


def ratios(runs) -> np.ndarray:
    """r_B = s²_B / mean(se²_B) over the bins with ≥ ENOUGH events in every run, for each
    leave-one-out subset too: (K + 1, M), row 0 from all runs."""
    f, se, n = (np.array(a) for a in zip(*map(slots, runs)))
    used = n.reshape(len(runs), -1).min(axis=0) >= ENOUGH
    f, se2 = f.reshape(len(runs), -1)[:, used], se.reshape(len(runs), -1)[:, used] ** 2
    keep = [np.ones(len(runs), bool)] + [np.arange(len(runs)) != k for k in range(len(runs))]
    return np.array([np.var(f[m], axis=0, ddof=1) / se2[m].mean(axis=0) for m in keep])


@pytest.fixture(scope="module")
def heightfield():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return gaussian(128, 1.0, 1.2, 8.0, seed=0)


@pytest.fixture(scope="module")
def grooves():
    return vgrooves(1000, an.Beckmann(0.3), seed=0)


@pytest.mark.parametrize("path", PATHS)
def test_stderr_matches_the_scatter_between_seeds(request, path):
    fixture, kw = PATHS[path]
    seed = 1000 + 100 * list(PATHS).index(path)  # independent streams for each path
    surface = request.getfixturevalue(fixture)
    runs = [
        simulate(surface, "aluminium", THETA, rays=RAYS, bins=BINS, seed=seed + k, **kw)
        for k in range(K)
    ]
    assert all(r.meta["stderr_method"] == METHOD.get(path, "pairs") for r in runs)
    r = ratios(runs).mean(axis=1)
    ratio, loo = r[0], r[1:]
    se_jack = np.sqrt((K - 1) / K * np.sum((loo - loo.mean()) ** 2))
    m = ratios(runs).shape[1]
    print(f"{path}: M = {m}, variance ratio {ratio:.3f} ± {se_jack:.3f} (jackknife)")
    assert m >= 30
    assert abs(ratio - 1) <= Z * se_jack
    assert BAND[0] <= ratio <= BAND[1]
    if path == "heightfield":  # the i.i.d. formula ignores the stratification: outside the band
        f = np.array([run.brdf.reshape(len(THETA), -1) for run in runs])
        old = np.array([[per_ray_stderr(run, i) for i in range(len(THETA))] for run in runs])
        used = np.array([run.counts.reshape(len(THETA), -1) for run in runs]).min(0) >= ENOUGH
        old_ratio = np.mean(np.var(f, axis=0, ddof=1)[used] / np.mean(old**2, axis=0)[used])
        print(f"  per-ray formula: variance ratio {old_ratio:.3f}")
        assert old_ratio < BAND[0]


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
    omega, many = np.ones(2), np.full(2, MIN_EVENTS)
    w, w2 = np.array([2.0, 1.0]), np.array([2.0, 1.0])
    f, se = bin_estimate(w, w2, 10, omega, PairSums(np.array([1.0, 0.0]), many))
    per = bin_estimate(w, w2, 10, omega)[1]
    assert se[0] == per[0] > 0 and se[1] == pytest.approx(0.1)  # √(1 − 0)/10


def test_pair_rule_falls_back_to_per_ray_below_the_events_and_pairs_a_test_needs():
    """Pairs of a rare bin landing in it together with near-equal weights make a pair estimate
    of ~0 on almost no degrees of freedom: below ``MIN_EVENTS`` events, or below
    ``MIN_DISCORDANT`` discordant pairs (N·(Σx² − 2Σ pairs)/Σx²), the per-ray formula (never
    below the stratified variance in expectation) is used, at and above both the pair
    estimate."""
    omega, w, w2 = np.ones(1), np.array([2.0]), np.array([2.0])
    per = bin_estimate(w, w2, 1000, omega)[1]

    def pair_se(sum_pair, events):
        return bin_estimate(w, w2, 1000, omega, PairSums(np.array([sum_pair]), np.array([events])))[
            1
        ]

    # 2 − 2·0.5 = 1 of Σx² = 2 is discordant: MIN_EVENTS/2 discordant pairs
    assert pair_se(0.5, MIN_EVENTS - 1)[0] == per[0]
    assert pair_se(0.5, MIN_EVENTS)[0] == pytest.approx(1.0 / 1000)
    assert 1.0 / 1000 < per[0]
    # 2 − 2·0.999 = 0.002: 0.025 discordant pairs among MIN_EVENTS events, a collapsed error
    assert MIN_EVENTS * 0.002 / 2.0 < MIN_DISCORDANT
    assert pair_se(0.999, MIN_EVENTS)[0] == per[0]


# --- isotropic (per-block incidence-azimuth rotation) ------------------------------------------
def test_isotropic_is_part_of_the_resume_configuration(heightfield):
    kw = dict(rays=6 * BLOCK, bins=Bins(9, 7), seed=5, threads=1, chunk=BLOCK)
    with interrupt_at("simulation", after=1):  # after two of the six blocks
        part = simulate(heightfield, "aluminium", 50.0, isotropic=True, **kw)
    assert part.is_partial and part.meta["isotropic"] and part.meta["stderr_method"] == "blocks"
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


def test_the_pair_error_has_the_discordant_pairs_as_degrees_of_freedom(grooves):
    """``stderr_dof``: with equal weights in a bin, Σ_k (x_2k − x_2k+1)² has one non-zero term
    per discordant pair (one ray of the pair in the bin), so ν is their count. Counted from the
    per-ray events of the same stream; Fresnel weights differ a little within a bin (concordant
    pairs of unequal weights add small terms), so per bin within 10 %."""
    n, bins = 20 * BLOCK, Bins(9, 7)
    res = simulate(grooves, "aluminium", 80.0, rays=n, bins=bins, seed=3)
    ev = ray_events(grooves, "aluminium", 80.0, rays=n, seed=3)
    where = np.where(
        ev.status == LEDGER.index("single"), bins.locate(np.nan_to_num(ev.wo), 0.0), -1
    )
    a, b = where[0:n:2], where[1:n:2]
    nbin = bins.shape[0] * bins.shape[1]
    events = np.bincount(where[where >= 0], minlength=nbin)
    discordant = events - 2 * np.bincount(a[(a == b) & (a >= 0)], minlength=nbin)
    nu = stderr_dof(res)[0].ravel()
    use = events >= MIN_EVENTS
    assert use.sum() >= 10
    assert np.allclose(nu[use], discordant[use], rtol=0.1), (nu[use], discordant[use])
