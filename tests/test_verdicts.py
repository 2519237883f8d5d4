"""Verdict statistics (calibration, localisation, exact definitions, schema) and the known
physics (V-groove G exact on V-grooves; Smith vs V-groove G on a Gaussian surface)."""

import json

import numpy as np
import pytest
from scipy import stats
from support import flat_verdict

from microsim import analytic as an
from microsim import surfaces as sf
from microsim.analysis import verdicts as V
from microsim.analysis.verdict_record import validate_verdict
from microsim.analytic.models import TorranceSparrow
from microsim.sim import Bins, simulate
from microsim.sim.predict import Predictor, predict

BINS = Bins(30, 19)
OMEGA = BINS.projected_solid_angle()


def _lobe():
    """A smooth positive 'BRDF' over the bins (sr⁻¹): a lobe at θo = 40°, Δφ = 180° on a floor."""
    t = BINS.theta_centers[:, None]
    p = BINS.phi_centers[None, :]
    return 0.2 + 5.0 * np.exp(-(((t - 40.0) / 12.0) ** 2) - ((p - 180.0) / 40.0) ** 2)


def _verdict(sim, se, model, **kw):
    counts = np.full(sim.shape, 1000)
    return flat_verdict(
        sim, se, counts, model, OMEGA, BINS.theta_edges, phi_edges=BINS.phi_edges, **kw
    )


# --- calibration ------------------------------------------------------------------------------
def test_false_alarm_rate_is_alpha_and_p_values_uniform():
    """Sim = model + Gaussian noise of known σ (model_rtol = 0: σ is exact). The verdict is two
    tests at Šidák(α, 2), so P(agrees = False) = α for independent tests and ≤ α otherwise:
    binomial test (two-sided, 0.01) of the rejection count; the χ² p-values are uniform (KS)."""
    rng = np.random.default_rng(1)
    truth = _lobe()
    se = 0.02 * truth + 0.01
    alpha, n_rep = 0.1, 1000
    rejected, pvals = 0, []
    for _ in range(n_rep):
        sim = truth + se * rng.standard_normal(truth.shape)
        v = _verdict(sim, se, truth, model_rtol=0.0, alpha=alpha)
        rejected += not v["agrees"]
        pvals.append(v["p_value"])
    assert stats.binomtest(rejected, n_rep, alpha).pvalue > V.sidak(0.01, 2)
    assert stats.kstest(pvals, "uniform").pvalue > V.sidak(0.01, 2)


def test_n_tests_applies_sidak_to_the_family():
    truth = _lobe()
    v = _verdict(truth, 0.01 * truth, truth, alpha=0.05, n_tests=8)
    assert v["alpha_eff"] == pytest.approx(1.0 - 0.95 ** (1 / 8), rel=1e-12)
    assert v["p_threshold"] == pytest.approx(1.0 - (1.0 - v["alpha_eff"]) ** 0.5, rel=1e-12)
    a_bin = 1.0 - (1.0 - v["p_threshold"]) ** (1.0 / v["n_bins"])
    assert v["z_threshold"] == pytest.approx(stats.norm.isf(a_bin / 2), rel=1e-12)


# --- localisation and exact definitions ---------------------------------------------------------
def test_model_off_by_ten_percent_in_a_theta_range_is_located_exactly():
    """model = truth·1.1 for θo ∈ [30°, 45°) at every Δφ, noise 1 %: there z ≈ 10 ± 1 > 5 and the
    relative error 10 % > 5 %; elsewhere z ~ N(0, 1) never reaches 5 (P ≈ 3e-7 per bin)."""
    rng = np.random.default_rng(2)
    truth = _lobe()
    se = 0.01 * truth
    sim = truth + se * rng.standard_normal(truth.shape)
    region = (BINS.theta_centers >= 30.0) & (BINS.theta_centers < 45.0)
    model = truth * np.where(region[:, None], 1.1, 1.0)
    v = _verdict(sim, se, model)
    assert v["agrees"] is False
    assert v["deviations"] == [[30.0, 45.0]]
    assert 30.0 <= v["worst_bin"][0] <= 45.0
    assert v["max_rel_dev"] == pytest.approx(-0.1, abs=0.05)  # sim − model: the model is brighter
    assert _verdict(sim, se, truth)["deviations"] == []


@pytest.mark.parametrize("eps", [0.12, -0.07, 0.0])
def test_rel_rms_of_a_uniform_relative_error_is_exactly_eps(eps):
    sim = _lobe()
    v = _verdict(sim, 0.01 * sim, sim * (1.0 + eps))
    assert v["rel_rms"] == pytest.approx(abs(eps), rel=1e-12, abs=1e-15)


def test_energy_set_is_the_smallest_set_reaching_the_fraction():
    rng = np.random.default_rng(3)
    e = rng.exponential(size=500)
    mask = V.energy_set(e, 0.9)
    assert e[mask].sum() >= 0.9 * e.sum() * (1 - 1e-12)
    assert e[mask].min() >= e[~mask].max()
    assert e[mask].sum() - e[mask].min() < 0.9 * e.sum()  # minimal


def test_bins_below_min_events_are_ignored():
    truth = _lobe()
    counts = np.full(truth.shape, 1000)
    counts[:10] = 24
    model = truth * np.where(np.arange(BINS.n_theta)[:, None] < 10, 2.0, 1.0)
    v = flat_verdict(truth, 0.01 * truth, counts, model, OMEGA, BINS.theta_edges, min_events=25)
    assert v["n_bins"] == (BINS.n_theta - 10) * BINS.n_phi
    assert v["agrees"] and v["deviations"] == []


def test_fitted_parameters_reduce_dof():
    truth = _lobe()
    v = _verdict(truth, 0.01 * truth, truth, fitted=True, n_params=3, params={"m": 0.3})
    assert v["dof"] == v["n_bins"] - 3 and v["fitted"] and v["params"] == {"m": 0.3}


# --- schema -----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def small_vgroove_result():
    surface = sf.vgrooves(1000, an.Beckmann(0.3))
    res = simulate(surface, "aluminium", [0.0, 60.0], rays=100_000, bins=BINS)
    res = res.with_models(
        predict(
            [Predictor("ts_vgroove", TorranceSparrow(an.Beckmann(0.3), "vgroove", "aluminium"))],
            res.theta_i,
            BINS,
        )
    )
    return res


def test_schema_accepts_real_output_and_json_round_trip(small_vgroove_result):
    vs = V.verdicts_for_result(small_vgroove_result, params={"ts_vgroove": {"m": 0.3}})
    assert len(vs) == 2 and all(v["n_tests"] == 2 for v in vs)
    for v in vs:
        V.validate_verdict(json.loads(json.dumps(v, allow_nan=False)))
    assert set(V.summary_row(vs)) == {"ts_vgroove"}


def test_schema_rejects_missing_keys_and_wrong_types():
    truth = _lobe()
    v = _verdict(truth, 0.01 * truth, truth)
    V.validate_verdict(v)
    for key in ("chi2", "agrees", "deviations"):
        bad = dict(v)
        del bad[key]
        with pytest.raises(ValueError, match=key):
            V.validate_verdict(bad)
    with pytest.raises(ValueError, match="agrees"):
        V.validate_verdict({**v, "agrees": "yes"})
    with pytest.raises(ValueError, match="n_bins"):
        V.validate_verdict({**v, "n_bins": 3.0})
    with pytest.raises(ValueError, match="unknown"):
        V.validate_verdict({**v, "extra": 1})


def test_summary_row_wording():
    truth = _lobe()
    good = _verdict(truth, 0.01 * truth, truth, name="a", theta_i=30.0)
    bad = _verdict(truth, 0.01 * truth, truth * 1.2, name="b", theta_i=80.0)
    rows = V.summary_row([good, bad])
    assert rows["a"] == "agrees"
    assert rows["b"].startswith("deviates at θi=80°") and "rel RMS 20% at θi=80°" in rows["b"]
    assert "worst -20%" in rows["b"]  # sim − model: the model is too bright


def test_invalid_arguments_raise():
    truth = _lobe()
    with pytest.raises(ValueError, match="alpha"):
        _verdict(truth, truth, truth, alpha=0.0)
    with pytest.raises(ValueError, match="shape"):
        flat_verdict(truth, truth, truth, truth[:3], OMEGA, BINS.theta_edges)
    with pytest.raises(ValueError, match="min_events"):
        _verdict(truth, truth, truth, min_events=0)


# --- known physics --------------------------------------------------------------------------------
def _vgroove_verdicts(rays, n_grooves=4000, masking="traced"):
    """TS with Blinn's V-groove G is exact for single scattering on V-grooves (Mikkelsen 2009,
    eq. 25; docs/design.md)."""
    surface = sf.vgrooves(n_grooves, an.Beckmann(0.3))
    res = simulate(
        surface, "aluminium", [0.0, 30.0, 60.0, 80.0], rays=rays, bins=BINS, masking=masking
    )
    res = res.with_models(
        predict(
            [Predictor("ts_vgroove", TorranceSparrow(an.Beckmann(0.3), "vgroove", "aluminium"))],
            res.theta_i,
            BINS,
        )
    )
    return V.verdicts_for_result(res)


def _assert_vgroove_agrees(vs):
    for v in vs:
        V.validate_verdict(v)
        assert v["agrees"], v
        assert v["deviations"] == []


def test_vgroove_g_agrees_on_vgrooves():
    _assert_vgroove_agrees(_vgroove_verdicts(1_000_000))


@pytest.mark.slow
def test_vgroove_g_agrees_on_vgrooves_slow():
    """At 8e6 rays the run resolves what 1e6 cannot: the discreteness of 4000 stratified groove
    tilts (~1 tilt in ~100 per bin, χ²/dof ≈ 1.5 at θi = 0°) and the traced-masking offset bias
    near the horizon. A surface model with no more detail than the question needs then has
    40000 grooves and the exact float64 masking test."""
    _assert_vgroove_agrees(_vgroove_verdicts(8_000_000, 40_000, "exact"))


def _gaussian_comparison(rays, seeds):
    """Gaussian heightfield m = 2σ/ℓ = 0.5 at θi ∈ {60°, 80°} against TS with Beckmann at the
    realised m and V-groove G, height-correlated Smith G2 or separable Smith G2."""
    surfaces = [sf.gaussian(512, 1.0, 2.0, 8.0, seed=s) for s in seeds]
    m = float(np.mean([s.stats()["m_realised"] for s in surfaces]))
    res = simulate(
        surfaces[0],
        "aluminium",
        [60.0, 80.0],
        rays=rays,
        bins=BINS,
        realisations=surfaces if len(surfaces) > 1 else None,
    )
    ndf = an.Beckmann(m)
    res = res.with_models(
        predict(
            [
                Predictor("vgroove", TorranceSparrow(ndf, "vgroove", "aluminium")),
                Predictor("smith", TorranceSparrow(ndf, "smith-correlated", "aluminium")),
                Predictor("smith-separable", TorranceSparrow(ndf, "smith", "aluminium")),
            ],
            res.theta_i,
            BINS,
        )
    )
    return res


def _peak_ratio(res, name, t, brdf=None):
    """Σ model Ω / Σ sim Ω over the in-plane forward bins within 4° of the mirror direction
    (``brdf``: one realisation's (T, Θ, Φ) estimate instead of the pooled one)."""
    f = BINS.forward_index
    near = np.abs(BINS.theta_centers - res.theta_i[t]) < 4.0
    om = OMEGA[near, f]
    sim = res.brdf if brdf is None else brdf
    return np.sum(res.models[name][t, near, f] * om) / np.sum(sim[t, near, f] * om)


def _print_peak_errors(res, t):
    """docs/verdicts.md's Smith-at-80° figures: model/sim − 1 at the forward peak, mean ± standard
    error over the realisations (their scatter includes the ray noise)."""
    if res.brdf_realisations is None:
        return
    parts = []
    for name in ("smith", "smith-separable", "vgroove"):
        r = np.array([_peak_ratio(res, name, t, b) for b in res.brdf_realisations]) - 1.0
        parts.append(
            f"{name} {100 * r.mean():+.1f} % ± {100 * r.std(ddof=1) / np.sqrt(len(r)):.1f} %"
        )
    print(
        f"\nforward peak at θi = {res.theta_i[t]:g}° ({len(res.brdf_realisations)} realisations,"
        f" {int(res.rays[t]):,} rays): " + ", ".join(parts)
    )


def _assert_gaussian_physics(res):
    vs = {(v["model"], v["theta_i"]): v for v in V.verdicts_for_result(res)}
    t80 = int(np.flatnonzero(res.theta_i == 80.0)[0])
    vg_peak, sm_peak = _peak_ratio(res, "vgroove", t80), _peak_ratio(res, "smith", t80)
    _print_peak_errors(res, t80)
    # V-groove G: the m = 0.5 specular peak far too bright at 80° (docs/design.md: ~2×).
    assert vg_peak > 1.4
    # Height-correlated Smith: much closer at the peak (docs/verdicts.md gives the measured figure,
    # from the slow variant of this test run with -s; docs/design.md's 0.2 % is about G1
    # masking, not about the G2 of forward scattering).
    assert abs(sm_peak - 1.0) < 0.5 * (vg_peak - 1.0)
    assert not vs[("vgroove", 80.0)]["agrees"]
    assert vs[("smith", 80.0)]["rel_rms"] < vs[("vgroove", 80.0)]["rel_rms"] / 3.0
    assert vs[("smith", 60.0)]["rel_rms"] < vs[("vgroove", 60.0)]["rel_rms"]


def test_smith_beats_vgroove_g_on_a_gaussian_surface():
    _assert_gaussian_physics(_gaussian_comparison(1_000_000, [0]))


@pytest.mark.slow
def test_smith_beats_vgroove_g_on_a_gaussian_surface_slow():
    _assert_gaussian_physics(_gaussian_comparison(4_000_000, [0, 1, 2, 3]))


# --- ts-facets: the model of the facets that were traced --------------------------------------
def _random_grooves(seed, n=200, realisations=2):
    return [
        sf.vgrooves(n, an.Beckmann(0.3), seed=1000 * seed + r, sampling="random")
        for r in range(realisations)
    ]


def test_facet_model_of_other_surfaces_is_refused():
    """Random tilts: each realisation has its own tilts, so ts-facets of the first tile is not
    the model of the mean over two tiles (its χ² would measure the tile scatter).
    attach_models must refuse it; stratified tiles share their tilt set but not their mesh."""
    from microsim.errors import UsageError
    from microsim.sim.compare import attach_models, default_models

    surfs = _random_grooves(0)
    res = simulate(None, "aluminium", [30.0], rays=20_000, bins=Bins(8, 5), realisations=surfs)
    with pytest.raises(UsageError, match="realisation"):
        attach_models(res, default_models(surfs[0], "aluminium", azimuths=16))
    attach_models(res, default_models(surfs, "aluminium", azimuths=16))  # the pool: accepted


def test_facet_model_agrees_on_random_tilts_over_realisations():
    """ts-facets built from the traced realisations is exact whatever the tilt sampling: its
    χ² p-value and max-|z| pass at the run's own level (default azimuth copies, whose noise is
    kept below the ray noise by ``VGROOVE_PAIRS``)."""
    from microsim.sim.compare import attach_models, default_models

    surfs = _random_grooves(3, n=300, realisations=3)
    res = simulate(
        None, "aluminium", [0.0, 60.0], rays=150_000, bins=Bins(12, 7), realisations=surfs, seed=2
    )
    specs = [m for m in default_models(surfs, "aluminium") if m.name == "ts-facets"]
    res = attach_models(res, specs)
    for v in V.verdicts_for_result(res):
        assert v["agrees"], v


# --- ensemble models: the "realisations" and "one-tile" references ----------------------------
def _tiles(rng, truth, R, scatter=0.05, ray=0.005):
    """R synthetic tile BRDFs: each tile's lobe is brighter/wider as a whole (coherent across
    bins: a_r, b_r ~ N(0, scatter)) plus independent ray noise of relative σ ``ray``."""
    t = BINS.theta_centers[:, None] - 40.0
    out = []
    for _ in range(R):
        a, b = rng.normal(0.0, scatter, 2)
        tile = truth * (1.0 + a + b * (t / 20.0) ** 2)
        out.append(tile + rng.normal(0.0, ray, truth.shape) * truth)
    return np.array(out)


def _ensemble_verdict(F, model, ray=0.005, **kw):
    sim = F.mean(axis=0)
    se = ray * sim / np.sqrt(len(F))
    return _verdict(sim, se, model, ensemble=True, realisations=F, model_rtol=0.0, **kw)


@pytest.mark.parametrize("R", [2, 3, 8])
def test_realisation_tests_are_calibrated_under_coherent_tile_scatter(R):
    """Model = ensemble truth, tiles scatter coherently (5 % ≫ ray noise): the fraction of
    "deviates" is within the binomial bound of α (the per-bin z with the R-tile variance would
    reject far more often: asserted too, so the test shows what it guards against)."""
    rng = np.random.default_rng(R)
    truth, n, alpha = _lobe(), 300, 0.05
    vs = [_ensemble_verdict(_tiles(rng, truth, R), truth, alpha=alpha) for _ in range(n)]
    assert all(v["reference"] == "realisations" and v["conclusive"] for v in vs)
    rejected = sum(not v["agrees"] for v in vs)
    assert rejected <= stats.binom.isf(1e-3, n, alpha), rejected
    naive = 0
    for _ in range(100):
        F = _tiles(rng, truth, R)
        se = np.std(F, axis=0, ddof=1) / np.sqrt(R)
        naive += not _verdict(F.mean(axis=0), se, truth, alpha=alpha)["agrees"]
    assert naive > stats.binom.isf(1e-3, 100, alpha), naive


def test_realisation_energy_test_has_power():
    """A model 5 % too bright against 8 tiles scattering by 1 % in energy: flagged always."""
    rng = np.random.default_rng(7)
    truth = _lobe()
    vs = [_ensemble_verdict(_tiles(rng, truth, 8, scatter=0.01), 1.05 * truth) for _ in range(20)]
    assert not any(v["agrees"] for v in vs)
    assert all(abs(v["energy_dev"] + 0.05 / 1.05) < 5 * v["energy_dev_se"] for v in vs)


def test_one_tile_rejection_is_inconclusive_and_summarised_so():
    """An ensemble model with one realisation: agreement within ray noise is conclusive, a
    rejection is not (tile scatter and model error cannot be separated)."""
    rng = np.random.default_rng(3)
    truth = _lobe()
    F = _tiles(rng, truth, 1, scatter=0.2)
    bad = _verdict(F[0], 0.005 * F[0], truth, ensemble=True, realisations=F, theta_i=10.0)
    good = _verdict(truth, 0.01 * truth, truth, ensemble=True, theta_i=20.0)
    assert bad["reference"] == good["reference"] == "one-tile"
    assert not bad["conclusive"] and not bad["agrees"]
    assert good["conclusive"] and good["agrees"]
    for v in (bad, good):
        V.validate_verdict(json.loads(json.dumps(v)))
    row = V.summary_row([good, bad])["model"]
    assert row.startswith("inconclusive at θi=10°") and "deviates" not in row
    with pytest.raises(ValueError, match="conclusive"):
        V.validate_verdict({**bad, "agrees": True})


def test_one_tile_departure_decides_between_deviates_and_inconclusive():
    """One tile with a computed departure δ from its ensemble: a deviation the departure
    explains stays "inconclusive" (and says how large the departure is); one beyond it by many
    σ is a resolved "deviates"; within ray noise it agrees."""
    rng = np.random.default_rng(11)
    truth = _lobe()
    tile = truth * (1.0 + 0.03 * np.sign(rng.normal(size=truth.shape)))  # the tile departs ±3 %
    se = 0.002 * tile
    sim = tile + rng.normal(size=truth.shape) * se
    departure = np.abs(tile - truth)
    explained = _verdict(sim, se, truth, ensemble=True, departure=departure)
    assert explained["reference"] == "one-tile" and not explained["conclusive"]
    assert explained["tile_departure"] == pytest.approx(0.03, rel=1e-9)
    assert V.verdict_kind(explained) == "inconclusive"
    beyond = _verdict(sim, se, 1.2 * truth, ensemble=True, departure=1.2 * departure)
    assert V.verdict_kind(beyond) == "deviates" and beyond["rel_rms"] > 0.15
    assert beyond["departure_max_abs_z"] > beyond["z_threshold"]
    within = _verdict(
        truth + rng.normal(size=truth.shape) * se, se, truth, ensemble=True, departure=departure
    )
    assert V.verdict_kind(within) == "agrees"
    for v in (explained, beyond, within):
        V.validate_verdict(json.loads(json.dumps(v)))
    with pytest.raises(ValueError, match="departure"):
        _verdict(sim, se, truth, ensemble=True, departure=-departure)


def test_excess_over_departure_is_conservative():
    """Model = ensemble, the tile departs from it by a random δ per bin and the sim adds ray
    noise: beyond-departure rejections ("deviates") occur in at most α of the cases (here
    none need occur: the excess is bounded by the noise's |z|)."""
    rng = np.random.default_rng(5)
    truth, n, alpha = _lobe(), 300, 0.05
    n_dev = 0
    for _ in range(n):
        tile = truth * (1.0 + rng.normal(0.0, 0.02, truth.shape))
        se = 0.005 * tile
        sim = tile + rng.normal(size=truth.shape) * se
        v = _verdict(sim, se, truth, ensemble=True, departure=np.abs(tile - truth), alpha=alpha)
        n_dev += V.verdict_kind(v) == "deviates"
    assert n_dev <= stats.binom.isf(1e-3, n, alpha), n_dev


def test_a_standard_error_of_few_degrees_of_freedom_is_judged_as_student_t():
    """Exact model, f̄ = m + σ·N(0, 1), and a reported se² = σ² χ²_ν/ν (an unbiased error of ν
    dof, as paired strata give a bin with ν discordant pairs): with ``dof`` = ν the verdicts
    say "deviates" at most at their rate α (binomial bound at 1 − 1e-3 over the trials);
    taking the same errors as exact (normal z) raises far more false alarms, as a max-|z|
    over 400 bins of Student t on 8 dof crosses the normal Šidák threshold most of the time."""
    rng = np.random.default_rng(7)
    shape, nu, alpha, trials = (20, 20), 8.0, 0.05, 200
    theta_edges = np.linspace(0.0, 90.0, shape[0] + 1)
    model, sigma = np.full(shape, 0.2), np.full(shape, 0.002)
    alarms = {"dof": 0, "exact": 0}
    for _ in range(trials):
        sim = model + sigma * rng.standard_normal(shape)
        se = sigma * np.sqrt(rng.chisquare(nu, shape) / nu)
        for kind in alarms:
            m = V.Measured(
                sim, se, np.full(shape, 1000.0), np.full(shape, 0.01), theta_edges,
                dof=np.full(shape, nu) if kind == "dof" else None,
            )  # fmt: skip
            v = V.verdict(m, V.Prediction(model), V.Significance(model_rtol=0.0, alpha=alpha))
            alarms[kind] += not v["agrees"]
    assert alarms["dof"] <= stats.binom.isf(1e-3, trials, alpha), alarms
    assert alarms["exact"] > 0.5 * trials, alarms


@pytest.mark.parametrize("realisations", [None, 4])
def test_a_verdict_without_a_bin_to_test_is_inconclusive(realisations):
    """When no bin holds ``min_events`` events (a faint or narrow lobe for the rays traced)
    nothing is tested: the verdict is inconclusive ("?"), says why, and never "deviates" —
    with ray noise as with realisations."""
    bins = Bins(6, 5)
    omega = bins.projected_solid_angle()
    sim = np.full(bins.shape, 0.1)
    model = np.full(bins.shape, 0.2)  # far off: only the missing evidence keeps it from ✗
    counts = np.full(bins.shape, 3)
    per_real = None if realisations is None else np.tile(sim, (realisations, 1, 1))
    v = flat_verdict(
        sim, 0.01 * sim, counts, model, omega, bins.theta_edges, realisations=per_real,
        ensemble=realisations is not None, min_events=10,
    )  # fmt: skip
    assert v.n_bins == 0 and V.verdict_kind(v) == "inconclusive"
    assert V.verdict_symbol(v) == "?" and "no bin holds 10 events" in V.inconclusive_reason(v)
    assert validate_verdict(json.loads(json.dumps(v))) == json.loads(json.dumps(v))  # writable


def test_a_fit_with_no_more_bins_than_parameters_is_inconclusive_and_says_so():
    """Two testable bins against three fitted parameters leave no degree of freedom."""
    bins = Bins(6, 5)
    omega = bins.projected_solid_angle()
    sim, counts = np.full(bins.shape, 0.1), np.full(bins.shape, 3)
    counts[0, :2] = 100
    v = flat_verdict(
        sim, 0.01 * sim, counts, 2 * sim, omega, bins.theta_edges, fitted=True, n_params=3,
        min_events=10,
    )  # fmt: skip
    assert (v.n_bins, v.dof) == (2, -1) and V.verdict_kind(v) == "inconclusive"
    assert "2 bins hold 10 events, no more than the 3 fitted parameters" in (
        V.inconclusive_reason(v)
    )
