"""Bin-averaged model predictions (microsim/sim/predict.py).

Facts checked: exactness on models with closed-form bin integrals; the adaptive quadrature's
accuracy on sharp lobes against a much tighter reference; honesty of its ``converged`` flag;
agreement of the quasi-Monte Carlo and facet-sum paths with the quadrature within their own
(or theory-derived) standard errors; energy bookkeeping of the facet sum.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats
from support import sidak

from microsim import vectors
from microsim.analytic.brdf import torrance_sparrow
from microsim.analytic.empirical import Empirical
from microsim.analytic.fresnel import fresnel
from microsim.analytic.masking import masking_from_kind, vgroove_g
from microsim.analytic.models import TorranceSparrow
from microsim.analytic.ndf import Beckmann, VonMisesFisher
from microsim.analytic.shadowing import smith_g2
from microsim.bins import Bins
from microsim.sim.facet_sum_kernels import G_NONE, G_VGROOVE, local_terms
from microsim.sim.fresnel_kernels import fresnel_material
from microsim.sim.predict import (
    QMC,
    FunctionBRDF,
    Predictor,
    _reflection_terms,
    _rotate_z,
    bin_average,
    bin_average_facets,
    bin_average_ts,
    predict,
)

ALPHA = 0.01


def ts_fn(ndf, shadowing="vgroove", ior=None):
    return lambda wi, wo: torrance_sparrow(wi, wo, ndf, shadowing=shadowing, material=ior)


def facet_weight(wi, h, G, ior=None):
    """x(h) = F(wi·h) G (wi·h)/(cos θi h_z): one half vector's share of ∫_B f cos θo dω_o."""
    wih = np.clip(h @ wi, 0.0, 1.0)
    return fresnel(wih, ior) * G * wih / (wi[2] * h[..., 2])


def sample_fraction(ndf, wi, bins):
    """P(wo(h) ∈ B) for h ~ D(h) h_z: ∫_B D h_z /(4 wo·h) dω_o (Mikkelsen 2009, eq. 15), by
    quadrature."""

    def density(wi, wo):  # per unit cos θo dω_o, as bin_average expects
        h = vectors.half_vector(wi, wo)
        return ndf.D(h) * h[..., 2] / (4.0 * np.sum(wo * h, -1) * wo[..., 2])

    return bin_average(wi, bins, density, rtol=1e-6).values * bins.projected_solid_angle()


def relative_azimuth(wo, phi_i_deg):
    return np.arctan2(wo[..., 1], wo[..., 0]) - np.radians(phi_i_deg)


# --- exact cases ---------------------------------------------------------------------------------
@pytest.mark.parametrize("bins", [Bins(45, 72), Bins(9, 8, folded=False), Bins(1, 2)])
def test_lambertian_is_exact_and_conserves_energy(bins):
    wi = vectors.spherical_deg(40.0, 25.0)
    res = bin_average(wi, bins, lambda wi, wo: np.full(wo.shape[:-1], 1.0 / np.pi))
    assert res.converged.all()
    np.testing.assert_allclose(res.values, 1.0 / np.pi, rtol=1e-12)
    assert abs(np.sum(res.values * bins.projected_solid_angle()) - 1.0) < 1e-12


@pytest.mark.parametrize(
    "bins,symmetric",
    [(Bins(18, 19), True), (Bins(18, 19), False), (Bins(18, 36, folded=False), False)],
)
def test_separable_model_matches_closed_form(bins, symmetric):
    """f = cos³θo (1 + ½ cos Δφ + s sin Δφ): ∫ cos³θ cosθ sinθ dθ = [−cos⁵θ/5],
    ∫ (1 + ½ cos + s sin) dφ = Δφ + ½[sin φ] − s[cos φ]; folded bins add the mirror half, where
    the odd sin term cancels (it is included only when the model is declared non-symmetric)."""
    phi_i = 30.0
    s = 0.0 if symmetric else 0.4

    def f(wi, wo):
        d = relative_azimuth(wo, phi_i)
        return wo[..., 2] ** 3 * (1.0 + 0.5 * np.cos(d) + s * np.sin(d))

    res = bin_average(
        vectors.spherical_deg(20.0, phi_i), bins, f, phi_i=phi_i, rtol=1e-9, symmetric=symmetric
    )
    t, p = np.radians(bins.theta_edges), np.radians(bins.phi_edges)
    theta_part = (np.cos(t[:-1]) ** 5 - np.cos(t[1:]) ** 5) / 5.0
    phi_part = np.diff(p) + 0.5 * np.diff(np.sin(p)) - s * np.diff(np.cos(p))
    if bins.folded:
        phi_part = 2.0 * (np.diff(p) + 0.5 * np.diff(np.sin(p)))
    exact = np.outer(theta_part, phi_part) / bins.projected_solid_angle()
    assert res.converged.all()
    np.testing.assert_allclose(res.values, exact, rtol=1e-6, atol=0)


# --- adaptive quadrature on sharp lobes ----------------------------------------------------------
@pytest.mark.parametrize(
    "ndf", [VonMisesFisher(1024.0), Beckmann(0.05)], ids=["vmf1024", "beck005"]
)
@pytest.mark.parametrize("theta_i", [0.0, 30.0, 60.0, 80.0])
def test_sharp_lobe_reaches_rtol(ndf, theta_i):
    bins = Bins(45, 91)  # 2° bins
    wi = vectors.spherical_deg(theta_i, 0.0)
    fn = ts_fn(ndf, "vgroove", "aluminium")
    res = bin_average(wi, bins, fn, rtol=1e-3)
    ref = bin_average(wi, bins, fn, rtol=1e-7, order=(8, 16), max_depth=10)
    assert res.converged.all() and ref.converged.all()
    diff = np.abs(res.values - ref.values)
    big = ref.values >= 1e-6 * ref.values.max()
    assert np.all(diff[big] <= 1e-3 * ref.values[big])
    # the reported error bounds the actual one (it is the low-order rule's error)
    assert np.all(diff <= res.error + ref.error + 1e-12 * ref.values.max())


def test_refinement_is_needed_and_converged_flag_is_honest():
    """A lobe ~0.4° wide on 10° bins: unrefined (max_depth=0) some bins must be flagged; every bin
    flagged converged — refined or not — is within its tolerance of a tight reference."""
    bins, rtol, floor = Bins(9, 19), 1e-3, 1e-6
    fn = ts_fn(VonMisesFisher(1e5))
    wi = vectors.spherical_deg(30.0, 0.0)
    ref = bin_average(wi, bins, fn, rtol=1e-8, order=(8, 16), max_depth=14)
    assert ref.converged.all()
    tol = np.maximum(rtol * ref.values, rtol * floor * ref.values.max()) * (1 + 1e-6)
    coarse = bin_average(wi, bins, fn, rtol=rtol, floor=floor, max_depth=0)
    fine = bin_average(wi, bins, fn, rtol=rtol, floor=floor)
    assert not coarse.converged.all()
    assert fine.converged.all()
    for res in (coarse, fine):
        ok = res.converged
        assert np.all(np.abs(res.values - ref.values)[ok] <= tol[ok])


# --- quasi-Monte Carlo path ----------------------------------------------------------------------
QMC_ANGLES = [0.0, 60.0, 80.0]


@pytest.mark.parametrize("theta_i", QMC_ANGLES)
def test_qmc_agrees_with_quadrature_within_its_error(theta_i):
    """Each bin's RQMC mean over R scramblings minus the exact value, over its replicate standard
    error, is Student-t with R − 1 dof; all bins of all angles form one Šidák family. Bins are
    kept where every replicate expects ≥ 50 samples (the t approximation needs them)."""
    ndf, bins, n, R = Beckmann(0.3), Bins(30, 31), 2**20, 16
    wi = vectors.spherical_deg(theta_i, 0.0)
    ref = bin_average(wi, bins, ts_fn(ndf, "vgroove", 1.329), rtol=1e-6)
    est = bin_average_ts(wi, bins, ndf, "vgroove", 1.329, n=n, replicates=R)
    keep = sample_fraction(ndf, wi, bins) * (n // R) >= 50
    assert keep.sum() > 50
    t = (est.values - ref.values)[keep] / est.stderr[keep]
    crit = stats.t.isf(0.5 * sidak(ALPHA, keep.sum() * len(QMC_ANGLES)), R - 1)
    assert np.abs(t).max() < crit


# --- facet path ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def beckmann_facets():
    rng = np.random.default_rng(12345)
    ndf = Beckmann(0.3)
    return ndf, ndf.sample(*rng.random((2, 10**6)))


FACET_ANGLES = [30.0, 70.0]


@pytest.mark.parametrize("theta_i", FACET_ANGLES)
def test_facets_agree_with_quadrature_within_mc_error(beckmann_facets, theta_i):
    """1e6 i.i.d. normals from Beckmann 0.3, V-groove G, F = 1. Per bin, I_B = (1/N) Σ_k x_k 1_B
    with Var = (E[x² 1_B] − I_B²)/N; E[x² 1_B] = ∫_B x(h(wo)) f cos θo dω_o and the expected
    count N P_B (``sample_fraction``) are computed by quadrature. Over bins with
    N P_B ≥ 25, Σ z² (theory variance) and Σ z² (the returned stderr) are χ²_K two-sided."""
    ndf, normals = beckmann_facets
    N, bins = len(normals), Bins(30, 31)
    wi = vectors.spherical_deg(theta_i, 0.0)
    omega = bins.projected_solid_angle()
    f = ts_fn(ndf, "vgroove")

    def x_times_f(wi, wo):
        h = vectors.half_vector(wi, wo)
        return facet_weight(wi, h, vgroove_g(wi, wo, h)) * f(wi, wo)

    ref = bin_average(wi, bins, f, rtol=1e-6).values * omega
    second = bin_average(wi, bins, x_times_f, rtol=1e-6).values * omega
    count = N * sample_fraction(ndf, wi, bins)
    est = bin_average_facets(wi, bins, normals, None, shadowing="vgroove")
    keep = count >= 25
    K = int(keep.sum())
    assert K > 100
    diff = (est.values * omega - ref)[keep]
    chi_theory = np.sum(diff**2 / ((second - ref**2)[keep] / N))
    chi_est = np.sum((diff / (est.stderr * omega)[keep]) ** 2)
    a = sidak(ALPHA, 2 * len(FACET_ANGLES))
    lo, hi = stats.chi2.ppf(0.5 * a, K), stats.chi2.isf(0.5 * a, K)
    assert lo < chi_theory < hi
    assert lo < chi_est < hi


@pytest.mark.parametrize("theta_i", [0.0, 45.0, 85.0])
def test_facet_energy_equals_direct_albedo(beckmann_facets, theta_i):
    """Σ_B f̄_B Ω_B = Σ_k a_k F G (wi·n_k)/(cos θi n_kz) over upward wo_k: no facet lost or
    double-counted by the binning."""
    _, normals = beckmann_facets
    normals = normals[:200_000]
    rng = np.random.default_rng(7)
    weights = rng.uniform(0.5, 1.5, len(normals))
    bins = Bins(45, 72, folded=False)
    wi = vectors.spherical_deg(theta_i, 10.0)
    est = bin_average_facets(wi, bins, normals, weights, material="aluminium", shadowing="vgroove")
    wo = 2.0 * (normals @ wi)[:, None] * normals - wi
    x = facet_weight(wi, normals, vgroove_g(wi, vectors.normalize(wo), normals), 0.769 + 6.08j)
    albedo = np.sum((weights / weights.sum() * x)[wo[:, 2] > 0])
    total = np.sum(est.values * bins.projected_solid_angle())
    assert abs(total - albedo) <= 1e-12 * albedo


def test_facets_smith_agree_with_quadrature(beckmann_facets):
    """Smith G from the facets' own Empirical Λ: the quadrature model with the same Λ and the
    parent Beckmann D differs from the facet sum only by facet sampling (χ², returned stderr)."""
    ndf, normals = beckmann_facets
    emp = Empirical(normals)
    bins, wi = Bins(30, 31), vectors.spherical_deg(60.0, 0.0)

    def f(wi, wo):
        h = vectors.half_vector(wi, wo)
        g = smith_g2(np.broadcast_to(wi, wo.shape), wo, h, emp)
        return ndf.D(h) * g / (4.0 * wi[2] * wo[..., 2])

    ref = bin_average(wi, bins, f, rtol=1e-6).values
    est = bin_average_facets(wi, bins, normals, None, shadowing="smith", smith_ndf=emp)
    keep = sample_fraction(ndf, wi, bins) * len(normals) >= 25
    K = int(keep.sum())
    chi = np.sum(((est.values - ref)[keep] / est.stderr[keep]) ** 2)
    assert stats.chi2.ppf(0.5 * ALPHA, K) < chi < stats.chi2.isf(0.5 * ALPHA, K)


def test_vgroove_azimuth_average_matches_isotropic_ts():
    """Grooves along y with i.i.d. Beckmann 0.3 tilts (both faces of each groove, normals in the
    xz plane, equal weights), averaged over the groove azimuth, give the isotropic V-cavity:
    Torrance–Sparrow with Beckmann D and V-groove G (Mikkelsen 2009, eq. 25; docs/design.md)."""
    ndf = Beckmann(0.3)
    rng = np.random.default_rng(99)
    theta = ndf.tilt_quantile_rad(rng.random(3000))
    faces = np.concatenate([vectors.spherical(theta, 0.0), vectors.spherical(theta, np.pi)])
    bins, wi = Bins(18, 19), vectors.spherical_deg(50.0, 0.0)
    est = bin_average_facets(wi, bins, faces, None, shadowing="vgroove", azimuths=512)
    ref = bin_average(wi, bins, ts_fn(ndf), rtol=1e-6).values
    keep = sample_fraction(ndf, wi, bins) * len(theta) >= 25
    K = int(keep.sum())
    chi = np.sum(((est.values - ref)[keep] / est.stderr[keep]) ** 2)
    assert stats.chi2.ppf(0.5 * ALPHA, K) < chi < stats.chi2.isf(0.5 * ALPHA, K)


@pytest.mark.parametrize("kind", ["vgroove", "none"])
@pytest.mark.parametrize("copies", [1, 7])
def test_compiled_facet_terms_are_the_numpy_terms(kind, copies):
    """The compiled (facet, azimuth) terms of a local G (``facet_sum_kernels.local_terms``)
    are the NumPy terms of every other G (``_reflection_terms`` and ``Bins.locate`` of the same
    rotated normals) to rounding, in the same bins."""
    rng = np.random.default_rng(5)
    normals = Beckmann(0.4).sample(rng.random(3000), rng.random(3000))
    u, eta, phi_i = rng.random(len(normals)), 0.769 + 6.08j, 20.0
    wi, bins = vectors.spherical_deg(50.0, phi_i), Bins(30, 24, folded=False)
    x, idx = np.empty(len(normals) * copies), np.empty(len(normals) * copies, dtype=np.int64)
    mode = G_VGROOVE if kind == "vgroove" else G_NONE
    grid = bins.kernel_grid(phi_i)
    local_terms(normals, u, copies, wi, fresnel_material(eta), mode, grid, x, idx)
    h = normals
    if copies > 1:
        psi = 2.0 * np.pi * (np.arange(copies)[None, :] + u[:, None]) / copies
        h = _rotate_z(normals, psi).reshape(-1, 3)
    wo, expected = _reflection_terms(wi, h, wi[2], eta, masking_from_kind(kind))
    assert np.count_nonzero(expected) > len(expected) // 2
    np.testing.assert_allclose(x, expected, rtol=1e-12, atol=1e-12 * expected.max())
    np.testing.assert_array_equal(idx, bins.locate(wo, phi_i))


# --- predict -------------------------------------------------------------------------------------
def test_predict_runs_every_kind_and_matches_direct_calls(beckmann_facets):
    ndf, normals = beckmann_facets
    bins, angles = Bins(9, 10), [0.0, 45.0]
    models = [
        Predictor("lambert", FunctionBRDF(lambda wi, wo: np.full(wo.shape[:-1], 1 / np.pi))),
        Predictor("ts", TorranceSparrow(ndf, "smith", "methanol")),
        Predictor("ts-qmc", TorranceSparrow(ndf, "smith", "methanol"), QMC(2**14)),
        Predictor.facets("facets", normals[:10_000], masking="vgroove"),
    ]
    out = predict(models, angles, bins)
    assert set(out) == {m.name for m in models}
    for name, arr in out.items():
        assert arr.shape == (len(angles),) + bins.shape and np.all(np.isfinite(arr))
    np.testing.assert_allclose(out["lambert"], 1 / np.pi, rtol=1e-12)
    wi = vectors.spherical_deg(45.0, 0.0)
    direct = bin_average(wi, bins, ts_fn(ndf, "smith", "methanol")).values
    np.testing.assert_array_equal(out["ts"][1], direct)
    with pytest.raises(ValueError, match="unique"):
        predict(models[:1] * 2, angles, bins)
    with pytest.raises(ValueError, match="rule must be"):
        Predictor("x", TorranceSparrow(ndf), "nonsense")
    with pytest.raises(ValueError, match="TorranceSparrow for QMC"):
        Predictor("x", FunctionBRDF(np.add), QMC(2**14))


# --- edge cases ----------------------------------------------------------------------------------
@settings(max_examples=15, deadline=None)
@given(theta_i=st.one_of(st.just(0.0), st.just(89.999), st.floats(0.0, 89.999)))
def test_finite_nonnegative_for_every_incidence(theta_i):
    ndf, bins = Beckmann(0.3), Bins(9, 10)
    wi = vectors.spherical_deg(theta_i, 0.0)
    for res in (
        bin_average(wi, bins, ts_fn(ndf, "smith"), rtol=1e-2, max_depth=3).values,
        bin_average_ts(wi, bins, ndf, "vgroove", n=2**10, replicates=4).values,
        bin_average_facets(
            wi,
            bins,
            ndf.sample(*np.random.default_rng(0).random((2, 1000))),
            None,
            shadowing="smith",
        ).values,
    ):
        assert np.all(np.isfinite(res)) and np.all(res >= 0)


def test_invalid_arguments_raise():
    bins, wi = Bins(9, 10), vectors.spherical_deg(30.0, 0.0)
    lam = lambda wi, wo: np.full(wo.shape[:-1], 1 / np.pi)  # noqa: E731
    with pytest.raises(ValueError, match="horizon"):
        bin_average(vectors.spherical_deg(90.0, 0.0), bins, lam)
    with pytest.raises(ValueError, match="rtol"):
        bin_average(wi, bins, lam, rtol=0.0)
    with pytest.raises(ValueError, match="order"):
        bin_average(wi, bins, lam, order=(8, 4))
    with pytest.raises(ValueError, match="finite"):
        bin_average(wi, bins, lambda wi, wo: np.full(wo.shape[:-1], np.nan))
    with pytest.raises(ValueError, match="power of 2"):
        bin_average_ts(wi, bins, Beckmann(0.3), n=1000)
    with pytest.raises(ValueError, match="shadowing"):
        bin_average_facets(wi, bins, np.array([[0.0, 0.0, 1.0]]), None, shadowing="blinn")
    with pytest.raises(ValueError, match="weights"):
        bin_average_facets(wi, bins, np.array([[0.0, 0.0, 1.0]]), [-1.0])
