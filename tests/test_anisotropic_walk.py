"""Heitz et al. 2016's random walk on anisotropic Smith microsurfaces (``AnisotropicBeckmann``,
``AnisotropicGGX``): order 1 against the closed form, energy, reciprocity of the multiply
scattered light, the isotropic limit, and that the walk tells the anisotropic surface from its
isotropic stand-in.

Every statistical test compares with a closed form or with a second walk within the runs' own
standard errors: z-scores pooled into a χ² whose bound is the χ² quantile at the test's level,
or a single z against the normal quantile. Levels are Šidák-corrected to a family-wise 1e-3 per
test function (``ALPHA``); bins enter a χ² only where they expect ≥ 50 exits, so that the normal
approximation and the estimated standard errors hold."""

import numpy as np
import pytest
from scipy import stats
from support import sidak, walk_on

from microsim import analytic as an
from microsim.analytic import random_walk as rw
from microsim.errors import UsageError
from microsim.sim import Bins
from microsim.sim.predict import bin_average
from microsim.stats import norm_isf
from microsim.testing import assert_sampler_matches
from microsim.vectors import spherical_deg

ALPHA = 1e-3  # family-wise false-alarm rate of each test function
MIN_EVENTS = 50  # expected exits for a bin to enter a χ²
BINS = Bins(n_theta=12, n_phi=16, folded=False)  # full azimuth: no mirror symmetry assumed
AX, AY, ROT = 0.5, 0.1, 30.0  # rough axis at φ = 30°, smooth axis at φ = 120°
FAMILIES = [(an.AnisotropicBeckmann, an.Beckmann), (an.AnisotropicGGX, an.GGX)]
FAMILY_IDS = ["beckmann", "ggx"]


def _walk(ndf, theta_i, phi_i, n, seed, material=None, orders=2, bins=BINS):
    return walk_on(bins, theta_i, ndf, material, n=n, seed=seed, orders=orders, phi_i=phi_i)


def _ts_bins(ndf, theta_i, phi_i, material=None, masking_ndf=None, bins=BINS):
    """Torrance–Sparrow with height-correlated Smith G2 = 1/(1 + Λ(wi) + Λ(wo)) (each Λ at its
    own azimuth) bin-averaged by adaptive quadrature (rtol 1e-5)."""

    def f(wi, wo):
        return an.torrance_sparrow(wi, wo, ndf, "smith-correlated", material, masking_ndf)

    return bin_average(spherical_deg(theta_i, phi_i), bins, f, phi_i, 1e-5).values


def _chi2(values, stderr, model, use):
    """(Σ z², dof) of the walk's bin averages against ``model`` over the bins ``use``."""
    z = (values - model)[use] / stderr[use]
    return float(np.sum(z * z)), int(use.sum())


def _two_walk_chi2(a, b):
    """(Σ z², dof) of two independent walks' bin averages, every order slot, over the bins
    where the two together expect ≥ 2·MIN_EVENTS exits (mirror: values·Ω·n are counts)."""
    counts = (a.values + b.values) * a.omega * a.n_paths
    use = counts >= 2 * MIN_EVENTS
    z = (a.values - b.values)[use] / np.hypot(a.stderr, b.stderr)[use]
    return float(np.sum(z * z)), int(use.sum())


# --- order 1 -----------------------------------------------------------------------------------
ORDER_ONE = [(fam, mat) for fam, _ in FAMILIES for mat in (None, "aluminium")]


@pytest.mark.parametrize(
    "cls, material", ORDER_ONE, ids=[f"{c.__name__}-{m}" for c, m in ORDER_ONE]
)
def test_order_one_is_torrance_sparrow_with_the_anisotropic_smith_g2(cls, material):
    """θi 60°, φi 50° (20° off the rough axis, no mirror symmetry), full-azimuth bins: the
    walk's order-1 bin averages against TS with the anisotropic D and height-correlated G2 of
    the exact per-direction Λ, χ² ≤ its quantile at Šidák(1e-3, 4). The same statistic rejects
    TS whose G2 takes MaterialX's α = √(αx αy) (the comparison can fail)."""
    ndf = cls(AX, AY, ROT)
    theta_i, phi_i, n = 60.0, 50.0, 200_000
    level = sidak(ALPHA, len(ORDER_ONE))
    r = _walk(ndf, theta_i, phi_i, n, seed=11, material=material)
    model = _ts_bins(ndf, theta_i, phi_i, material)
    use = model * r.omega * n >= MIN_EVENTS
    chi2, dof = _chi2(r.values[0, 0], r.stderr[0, 0], model, use)
    bound = stats.chi2.isf(level, dof)
    assert dof > 30
    assert chi2 <= bound, (chi2, dof, bound)
    stand_in = _ts_bins(ndf, theta_i, phi_i, material, ndf.isotropic_equivalent())
    chi2_s, dof_s = _chi2(r.values[0, 0], r.stderr[0, 0], stand_in, use)
    assert chi2_s > stats.chi2.isf(level, dof_s), (chi2_s, dof_s)


# --- energy ------------------------------------------------------------------------------------
@pytest.mark.parametrize("cls", [c for c, _ in FAMILIES], ids=FAMILY_IDS)
def test_mirror_walk_conserves_energy(cls):
    """F = 1, θi 80° along the rough axis and 60° at φi 50°: every path leaves (none cut at
    256 bounces, none absorbed), so the orders' energies sum to 1 and the full-azimuth bins
    hold all of it; the order-1 energy is ∫ f_TS cos θo dωo (quadrature over the same bins,
    rtol 1e-5) within the normal quantile of its standard error, so the multiply scattered
    energy is exactly what single scattering misses, 1 − E_TS."""
    ndf = cls(AX, AY, ROT)
    cases = [(80.0, ROT), (60.0, 50.0)]
    z_max = norm_isf(0.5 * sidak(ALPHA, 2 * len(cases)))
    for k, (theta_i, phi_i) in enumerate(cases):
        r = _walk(ndf, theta_i, phi_i, 100_000, seed=20 + k, orders=3)
        assert r.cut[0] == 0 and r.absorbed[0] == 0
        np.testing.assert_allclose(r.energy[0].sum(), 1.0, rtol=1e-12)
        np.testing.assert_allclose(np.sum(r.values[0] * r.omega), 1.0, rtol=1e-12)
        e_ts = float(np.sum(_ts_bins(ndf, theta_i, phi_i) * r.omega))
        z = (r.energy[0, 0] - e_ts) / np.hypot(r.energy_stderr[0, 0], 1e-5 * e_ts)
        assert abs(z) < z_max, (theta_i, r.energy[0, 0], e_ts, z)
        assert r.multiple_energy[0] > 10 * r.multiple_stderr[0]  # there is multiple scattering


# --- reciprocity -------------------------------------------------------------------------------
def _cell_transfer(ndf, cell_in, cell_out, n, seed):
    """Ω_A E[w 1(order ≥ 2, wo ∈ B)] for wi cosine-distributed over the cell A = (θ band, φ
    band) in the surface frame (degrees): an unbiased estimate of ∫_A ∫_B f_ms μi μo dωi dωo,
    which is symmetric in A, B when f_ms is reciprocal. Returns (estimate, standard error)."""
    rng = np.random.default_rng(seed)
    (t0, t1), (p0, p1) = cell_in
    s0, s1 = np.sin(np.radians([t0, t1])) ** 2
    s = s0 + (s1 - s0) * rng.random(n)
    phi = np.radians(p0 + (p1 - p0) * rng.random(n))
    wi = np.stack([np.sqrt(s) * np.cos(phi), np.sqrt(s) * np.sin(phi), np.sqrt(1 - s)], axis=1)
    p = rw.smith_random_walk(wi, ndf, None, rng)
    wo = np.where(np.isnan(p.wo), 0.0, p.wo)
    tho = np.degrees(np.arccos(np.clip(wo[:, 2], -1.0, 1.0)))
    pho = np.mod(np.degrees(np.arctan2(wo[:, 1], wo[:, 0])), 360.0)
    (u0, u1), (q0, q1) = cell_out
    hit = (p.order >= 2) & (tho >= u0) & (tho < u1) & (pho >= q0) & (pho < q1)
    x = np.where(hit, p.weight, 0.0)
    omega_a = np.radians(p1 - p0) * (s1 - s0) / 2.0
    return omega_a * x.mean(), omega_a * x.std(ddof=1) / np.sqrt(n)


@pytest.mark.parametrize("cls", [c for c, _ in FAMILIES], ids=FAMILY_IDS)
def test_multiple_scattering_is_reciprocal(cls):
    """The walk has no pointwise f, so reciprocity f_ms(wi, wo) = f_ms(wo, wi) is tested on a
    pair of small cells A ∋ wi, B ∋ wo placed off the NDF's axes (A: θ 55–65°, φ 40–70°;
    B: θ 65–80°, φ 200–250°, with the axes at 30°/120°): the transfer A → B equals B → A
    within the normal quantile of the combined standard error (two-sided, Šidák over the two
    families)."""
    ndf = cls(AX, AY, ROT)
    a, b = ((55.0, 65.0), (40.0, 70.0)), ((65.0, 80.0), (200.0, 250.0))
    n = 200_000
    t_ab, s_ab = _cell_transfer(ndf, a, b, n, 101)
    t_ba, s_ba = _cell_transfer(ndf, b, a, n, 202)
    assert t_ab > 10 * s_ab and t_ba > 10 * s_ba  # the pair exchanges multiply scattered light
    z = (t_ab - t_ba) / np.hypot(s_ab, s_ba)
    assert abs(z) < norm_isf(0.5 * sidak(ALPHA, len(FAMILIES))), (t_ab, t_ba, z)


# --- the isotropic limit and the isotropic stand-in --------------------------------------------
@pytest.mark.parametrize("cls, iso", FAMILIES, ids=FAMILY_IDS)
def test_equal_roughness_walks_the_isotropic_surface(cls, iso):
    """AnisotropicX(α, α, rotation) and X(α) (independent seeds, θi 70°, φi 50°): every order
    slot's bin averages agree (two-walk χ² ≤ its quantile), and so do the multiply scattered
    energies (|z| ≤ the normal quantile); Šidák over the 2 × 2 statistics of the two
    families."""
    a = _walk(cls(0.4, 0.4, 25.0), 70.0, 50.0, 150_000, seed=31)
    b = _walk(iso(0.4), 70.0, 50.0, 150_000, seed=32)
    level = sidak(ALPHA, 2 * len(FAMILIES))
    chi2, dof = _two_walk_chi2(a, b)
    assert dof > 40
    assert chi2 <= stats.chi2.isf(level, dof), (chi2, dof)
    z = (a.multiple_energy[0] - b.multiple_energy[0]) / np.hypot(
        a.multiple_stderr[0], b.multiple_stderr[0]
    )
    assert abs(z) < norm_isf(0.5 * level), z


@pytest.mark.parametrize("cls", [c for c, _ in FAMILIES], ids=FAMILY_IDS)
def test_walk_tells_the_anisotropic_surface_from_its_isotropic_stand_in(cls):
    """θi 80° in the plane of the rough axis (φi = rotation, where the direction sees αx): the
    walk on the isotropic equivalent α = √(αx αy) — a wrong NDF — fails the statistic that
    accepts equal surfaces in the test above, in the bins and in the multiply scattered energy.
    The anisotropic walk also depends on φi (rough vs smooth axis), the isotropic one cannot."""
    ndf = cls(AX, AY, ROT)
    level = sidak(ALPHA, 3)
    a = _walk(ndf, 80.0, ROT, 100_000, seed=41)
    b = _walk(ndf.isotropic_equivalent(), 80.0, ROT, 100_000, seed=42)
    chi2, dof = _two_walk_chi2(a, b)
    assert chi2 > stats.chi2.isf(level, dof), (chi2, dof)
    z = (a.multiple_energy[0] - b.multiple_energy[0]) / np.hypot(
        a.multiple_stderr[0], b.multiple_stderr[0]
    )
    assert abs(z) > norm_isf(0.5 * level), z
    c = _walk(ndf, 80.0, ROT + 90.0, 100_000, seed=43)  # along the smooth axis
    z_axes = (a.multiple_energy[0] - c.multiple_energy[0]) / np.hypot(
        a.multiple_stderr[0], c.multiple_stderr[0]
    )
    assert abs(z_axes) > norm_isf(0.5 * level), z_axes


# --- the visible normals the walk draws below the horizon --------------------------------------
@pytest.mark.parametrize("cls", [c for c, _ in FAMILIES], ids=FAMILY_IDS)
def test_anisotropic_visible_normals_below_the_horizon(cls):
    """After a bounce an upward ray sees the surface from below the horizon: the NDF's own
    stretched sampler there against ⟨v, m⟩⁺ D(m) / (Λ(−v)|v_z|) (``visible_projected_area``,
    whose normalisation the Pearson χ² checks too: the probability outside the cells is an
    extra cell), 10⁵ normals at each of two views off the axes, Šidák over 4 cases."""
    ndf = cls(AX, AY, ROT)
    for theta_v, phi_v in ((105.0, 70.0), (125.0, 160.0)):
        v = spherical_deg(theta_v, phi_v)
        area = float(rw.visible_projected_area(v, ndf))

        def sample(u1, u2, v=v):
            return rw.sample_visible_normals(np.tile(v, (len(u1), 1)), ndf, 1.0 - u1, u2)

        def pdf(m, v=v, area=area):
            return np.maximum(m @ v, 0.0) * ndf.D(m) / area

        assert_sampler_matches(sample, pdf, n=100_000, n_tests=4, alpha=ALPHA, order=24)


def test_walk_refuses_other_ndfs_and_a_bad_azimuth():
    with pytest.raises(UsageError, match="ndf must be one of .*AnisotropicGGX"):
        rw.smith_random_walk(np.array([[0.0, 0.0, 1.0]]), an.BlinnPhong(20.0))
    with pytest.raises(UsageError, match="ndf must be one of"):
        rw.walk_bin_averages(30.0, Bins(1, 2), an.BlinnPhong(20.0), n_paths=10)
    with pytest.raises(UsageError, match="phi_i"):
        _walk(an.AnisotropicGGX(AX, AY, ROT), 30.0, float("nan"), 10, seed=0)
    with pytest.raises(UsageError, match="family and alpha"):
        rw.WalkNDF(an.AnisotropicGGX(AX, AY, ROT), "beckmann", None)
    walk = rw.WalkNDF.of(an.AnisotropicBeckmann(AX, AY, ROT))
    assert (walk.family, walk.alpha) == ("beckmann", None) and rw.WalkNDF.of(walk) is walk
