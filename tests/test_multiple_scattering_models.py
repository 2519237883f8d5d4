"""Multiple-scattering models: Heitz et al. 2016's random walk on a Smith
microsurface, Kulla & Conty 2017's energy compensation and Mikkelsen 2009 eq. 28's diffuse term.

Statistical tests compare with closed forms within the run's own standard errors or by Pearson χ²
at a 1e-3 level (Šidák-corrected over the cases of one test)."""

import numpy as np
import pytest
from scipy import stats
from support import pearson_chi2, sidak, walk_on

from microsim import analytic as an
from microsim.analytic import energy_compensation as ec
from microsim.analytic import random_walk as rw
from microsim.errors import UsageError
from microsim.sim import Bins
from microsim.sim.predict import bin_average
from microsim.vectors import spherical, spherical_deg

ALPHA = 1e-3  # family-wise level of each statistical test


@pytest.fixture(scope="module")
def table05():
    """Albedo table of TS with correlated Smith, Beckmann m = 0.5, F = 1 (built once: ~2 s)."""
    return an.AlbedoTable(an.Beckmann(0.5), "smith-correlated")


@pytest.fixture(scope="module")
def ggx_table05():
    return an.AlbedoTable(an.GGX(0.5), "smith-correlated")


# --- visible normals ---------------------------------------------------------------------------
def _vndf_expected(v, ndf, t_edges, p_edges, n_gl=24):
    """∫∫_cell ⟨v, m⟩⁺ D(m) dω_m / A(v) per (θm, φm) cell by tensor Gauss–Legendre."""
    x, w = np.polynomial.legendre.leggauss(n_gl)
    ta, tb = t_edges[:-1, None], t_edges[1:, None]
    th = 0.5 * (ta + tb) + 0.5 * (tb - ta) * x  # (nt, g)
    wt = 0.5 * (tb - ta) * w * np.sin(th)
    pa, pb = p_edges[:-1, None], p_edges[1:, None]
    ph = 0.5 * (pa + pb) + 0.5 * (pb - pa) * x
    wp = 0.5 * (pb - pa) * w
    m = spherical(th[:, :, None, None], ph[None, None, :, :])  # (nt, g, np, g, 3)
    f = np.maximum(m @ v, 0.0) * ndf.D_cos(m[..., 2])
    cell = np.einsum("agbh,ag,bh->ab", f, wt, wp)
    return cell / rw.visible_projected_area(v, ndf)


@pytest.mark.parametrize("ndf", [an.Beckmann(0.5), an.GGX(0.4), an.StudentT(0.4, 3.0)], ids=repr)
def test_visible_normals_follow_the_vndf_above_and_below_the_horizon(ndf):
    """Histogram of sampled normals against ⟨v, m⟩⁺D(m)/A(v) for views above and below the
    horizon (below: what a ray going up after a bounce sees); the cells' quadrature also
    checks the normaliser A(v) = (1 + Λ(v))v_z resp. Λ(−v)|v_z| (sum = 1 to quadrature error)."""
    rng = np.random.default_rng(3)
    t_edges = np.radians(np.linspace(0.0, 90.0, 13))
    p_edges = np.linspace(-np.pi, np.pi, 13)
    cases = [20.0, 75.0, 100.0, 130.0]  # polar angle of v in degrees (> 90: below)
    level = sidak(ALPHA, len(cases))
    n = 100_000
    for theta_v in cases:
        v = spherical_deg(theta_v, 30.0)
        m = rw.sample_visible_normals(np.tile(v, (n, 1)), ndf, 1 - rng.random(n), rng.random(n))
        assert np.all(m @ v >= -1e-12) and np.all(m[:, 2] > 0)
        th = np.arccos(np.clip(m[:, 2], -1, 1))
        ph = np.arctan2(m[:, 1], m[:, 0])
        obs, _, _ = np.histogram2d(th, ph, bins=[t_edges, p_edges])
        p = _vndf_expected(v, ndf, t_edges, p_edges)
        assert abs(p.sum() - 1.0) < 2e-3, (theta_v, p.sum())
        _, _, pval = pearson_chi2(obs, p * n * obs.sum() / n / p.sum())
        assert pval > level, (theta_v, pval)


# --- heights -----------------------------------------------------------------------------------
@pytest.mark.parametrize("heights", rw.HEIGHT_DISTRIBUTIONS)
def test_height_tau_round_trip(heights):
    """Gaussian heights resolve τ at every depth (log-CDF functions); uniform ones only where
    h = 2e^{−τ} − 1 keeps its digits — the reason the walk itself runs in τ."""
    tau = np.array([0.0, 1e-12, 0.3, 2.0, 40.0] if heights == "gaussian" else [0.0, 0.3, 2.0, 9.0])
    h = rw.height_from_tau(tau, heights)
    assert np.all(np.diff(h) < 0)  # deeper = lower
    np.testing.assert_allclose(rw.tau_from_height(h[1:], heights), tau[1:], rtol=1e-9)
    with pytest.raises(UsageError, match="heights"):
        rw.height_from_tau(tau, "laplace")


# --- the walk ----------------------------------------------------------------------------------
BINS = Bins(n_theta=18, n_phi=19, folded=True)


def _walk(theta_i, ndf, material=None, n=200_000, seed=1, orders=4, bins=BINS):
    return walk_on(bins, theta_i, ndf, material, n=n, seed=seed, orders=orders)


def _ts_bins(theta_i, ndf, material=None, bins=BINS):
    wi = spherical_deg(theta_i, 0.0)

    def f(wi, wo):
        return an.torrance_sparrow(wi, wo, ndf, "smith-correlated", material)

    res = bin_average(wi, bins, f, 0.0, 1e-5)
    return res.values


@pytest.mark.parametrize(
    "ndf",
    [an.Beckmann(0.5), an.GGX(0.3), pytest.param(an.StudentT(0.4, 3.0), marks=pytest.mark.slow)],
    ids=repr,
)
def test_order_one_is_torrance_sparrow_with_height_correlated_smith(ndf):
    """Mirror: order-1 exits are multinomial counts over the bins (plus 'not order 1'); their
    expectation is TS with G2 = 1/(1 + Λi + Λo) bin-averaged by quadrature (rtol 1e-5)."""
    cases = [0.0, 45.0, 80.0]
    level = sidak(ALPHA, len(cases))
    n = 200_000
    omega = BINS.projected_solid_angle()
    for th in cases:
        r = _walk(th, ndf, n=n)
        obs = np.append(r.values[0, 0] * omega * n, 0.0)
        obs[-1] = n - obs[:-1].sum()
        exp = np.append(_ts_bins(th, ndf) * omega * n, 0.0)
        exp[-1] = n - exp[:-1].sum()
        np.testing.assert_allclose(obs[:-1], np.round(obs[:-1]), atol=1e-6)  # counts
        _, dof, pval = pearson_chi2(obs, exp)
        assert dof > 20 and pval > level, (th, pval)


def test_order_one_with_fresnel_matches_torrance_sparrow_within_stderr():
    """Aluminium: the order-1 bin averages against TS·F with correlated Smith, z-scores of the
    bins with ≥ 50 expected exits pooled into a χ² with their number of degrees of freedom."""
    ndf = an.Beckmann(0.3)
    n = 200_000
    omega = BINS.projected_solid_angle()
    cases = [30.0, 70.0]
    level = sidak(ALPHA, len(cases))
    for th in cases:
        r = _walk(th, ndf, "aluminium", n=n, seed=7)
        model = _ts_bins(th, ndf, "aluminium")
        use = model * omega * n >= 50
        z = (r.values[0, 0] - model)[use] / r.stderr[0, 0][use]
        assert use.sum() > 20
        assert stats.chi2.sf(np.sum(z * z), use.sum()) > level, (th, np.sum(z * z), use.sum())


@pytest.mark.parametrize("name", ["table05", "ggx_table05"])
def test_mirror_walk_conserves_energy_and_order_one_is_the_albedo(name, request):
    """F = 1: every path leaves (nothing cut at 256 bounces, nothing absorbed), so the orders'
    energies sum to 1; the order-1 energy is the TS albedo E(μ) (AlbedoTable, accuracy 2e-5)
    within 4 standard errors; the bins hold all the escaping energy (folded grid covers the
    hemisphere)."""
    table = request.getfixturevalue(name)
    ndf = table.ndf
    omega = BINS.projected_solid_angle()
    r = _walk([0.0, 60.0, 85.0], ndf, n=60_000, seed=5)
    assert np.all(r.cut == 0) and np.all(r.absorbed == 0)
    np.testing.assert_allclose(r.energy.sum(axis=1), 1.0, rtol=1e-12)
    e1 = table.rho(np.cos(np.radians(r.theta_i)))
    assert np.all(np.abs(r.energy[:, 0] - e1) < 4 * r.energy_stderr[:, 0] + 2e-5)
    np.testing.assert_allclose(
        np.einsum("ikab,ab->ik", r.values, omega), r.energy, rtol=1e-10, atol=1e-15
    )
    np.testing.assert_allclose(r.multiple_energy, r.energy[:, 1:].sum(axis=1), rtol=1e-12)


def test_fresnel_walk_accounts_for_every_path():
    """Aluminium: escaping + absorbed + cut = 1 per path (the ledger closes), absorption > 0."""
    r = _walk([10.0, 80.0], an.GGX(0.6), "aluminium", n=50_000, seed=2)
    np.testing.assert_allclose(r.energy.sum(axis=1) + r.absorbed + r.cut, 1.0, rtol=1e-12)
    assert np.all(r.absorbed > 0.05)


def test_walk_bins_follow_the_simulation_bins():
    """Same projected solid angles as Bins, and the exits land in the bins Bins.locate gives
    (same seed → the same paths), folded and unfolded."""
    ndf = an.GGX(0.4)
    for bins in (Bins(n_theta=9, n_phi=13, folded=True), Bins(n_theta=9, n_phi=12, folded=False)):
        n = 20_000
        r = _walk(35.0, ndf, n=n, seed=11, orders=1, bins=bins)
        np.testing.assert_allclose(r.omega, bins.projected_solid_angle(), rtol=1e-14)
        p = rw.smith_random_walk(
            np.tile(spherical_deg(35.0, 0.0), (n, 1)), ndf, None, np.random.default_rng(11)
        )
        idx = bins.locate(p.wo, 0.0)
        counts = np.bincount(idx[idx >= 0], minlength=bins.n_theta * bins.n_phi)
        np.testing.assert_allclose(
            r.values[0, 0] * r.omega * n, counts.reshape(bins.shape), atol=1e-8
        )


def test_walk_is_reproducible_from_its_seed():
    a = _walk(40.0, an.Beckmann(0.4), n=5_000, seed=3)
    b = _walk(40.0, an.Beckmann(0.4), n=5_000, seed=3)
    c = _walk(40.0, an.Beckmann(0.4), n=5_000, seed=4)
    assert np.array_equal(a.values, b.values) and not np.array_equal(a.values, c.values)


def _band_transfer(ndf, band_in, band_out, dphi_band, n, seed, order=2):
    """Ω_A · E[w 1(order, wo ∈ band_out, |Δφ| ∈ dphi_band)] for wi cosine-distributed over the
    θ band ``band_in`` (all azimuths) = ∫_A ∫_B f μi μo dωi dωo (symmetric if f is reciprocal)."""
    rng = np.random.default_rng(seed)
    s0, s1 = np.sin(np.radians(band_in)) ** 2
    s = s0 + (s1 - s0) * rng.random(n)
    phi = 2 * np.pi * rng.random(n)
    wi = np.stack([np.sqrt(s) * np.cos(phi), np.sqrt(s) * np.sin(phi), np.sqrt(1 - s)], axis=1)
    p = rw.smith_random_walk(wi, ndf, None, rng)
    wo = np.where(np.isnan(p.wo), 0.0, p.wo)
    tho = np.degrees(np.arccos(np.clip(wo[:, 2], -1, 1)))
    dphi = np.abs(np.degrees(np.angle(np.exp(1j * (np.arctan2(wo[:, 1], wo[:, 0]) - phi)))))
    hit = (
        (p.order == order)
        & (tho >= band_out[0])
        & (tho < band_out[1])
        & (dphi >= dphi_band[0])
        & (dphi < dphi_band[1])
    )
    x = np.where(hit, p.weight, 0.0)
    omega_a = np.pi * (s1 - s0)
    return omega_a * x.mean(), omega_a * x.std(ddof=1) / np.sqrt(n)


@pytest.mark.parametrize("ndf", [an.Beckmann(0.5), an.GGX(0.5)], ids=repr)
def test_order_two_is_reciprocal_in_expectation(ndf):
    """∫_A∫_B f₂ μi μo = ∫_B∫_A f₂ μi μo for θ bands A, B and a relative-azimuth band, within
    4.5 combined standard errors (3 cases: family-wise level ≈ 2e-5)."""
    cases = [
        ((15, 30), (60, 75), (150, 180)),
        ((40, 50), (70, 85), (120, 180)),
        ((0, 20), (30, 50), (90, 180)),
    ]
    n = 100_000
    for k, (a, b, dphi) in enumerate(cases):
        tab, sab = _band_transfer(ndf, a, b, dphi, n, 100 + k)
        tba, sba = _band_transfer(ndf, b, a, dphi, n, 200 + k)
        assert tab > 5 * sab and tba > 5 * sba  # the band pair carries order-2 light
        z = (tab - tba) / np.hypot(sab, sba)
        assert abs(z) < 4.5, (a, b, dphi, tab, tba, z)


def test_walk_refuses_bad_input():
    with pytest.raises(UsageError, match="ndf"):
        rw.smith_random_walk(np.array([[0.0, 0.0, 1.0]]), an.BlinnPhong(20.0))
    with pytest.raises(UsageError, match="wi"):
        rw.smith_random_walk(np.array([[0.0, 0.0, -1.0]]), an.GGX(0.3))
    with pytest.raises(UsageError, match="theta_i"):
        _walk(90.0, an.GGX(0.3), n=10)
    with pytest.raises(UsageError, match="orders"):
        _walk(0.0, an.GGX(0.3), n=10, orders=0)


# --- Kulla–Conty -------------------------------------------------------------------------------
def _random_dirs(rng, n):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    return v


@pytest.fixture(scope="module")
def beckmann_kc(table05):
    return ec.KullaConty(table=table05)


def test_kulla_conty_is_reciprocal_and_positive(beckmann_kc):
    rng = np.random.default_rng(0)
    wi, wo = _random_dirs(rng, 10_000), _random_dirs(rng, 10_000)
    f, g = beckmann_kc.brdf(wi, wo), beckmann_kc.brdf(wo, wi)
    assert np.array_equal(f, g) and np.all(f > 0)
    assert np.all(beckmann_kc.brdf(wi, -wo) == 0)


def test_kulla_conty_closes_the_white_furnace_by_quadrature(beckmann_kc):
    """E(μi) + ∫ f_ms μo dωo = 1 with the μo integral done independently (composite
    Gauss–Legendre over μo; f_ms depends on μo only): to the table's quadrature accuracy."""
    x, w = np.polynomial.legendre.leggauss(64)
    edges = np.array([0.0, 0.01, 0.05, 0.2, 0.5, 1.0])
    mu = (0.5 * (edges[:-1, None] + edges[1:, None]) + 0.5 * np.diff(edges)[:, None] * x).ravel()
    wmu = (0.5 * np.diff(edges)[:, None] * w).ravel()
    for th in (0.0, 30.0, 60.0, 80.0, 89.0):
        wi = spherical_deg(th, 0.0)
        wo = spherical(np.arccos(mu), 0.7)
        alb = 2 * np.pi * np.sum(wmu * mu * beckmann_kc.brdf(wi, wo))
        e = beckmann_kc.E(np.cos(np.radians(th)))
        assert abs(alb + e - 1.0) < 1e-6, (th, alb + e)
        assert abs(alb - beckmann_kc.albedo(th)) < 1e-6


def test_kulla_conty_plus_single_scattering_is_white_by_independent_albedo(ggx_table05):
    """TS (correlated Smith, F = 1) + f_ms has albedo 1: checked with the project's randomised
    QMC ``directional_albedo`` (independent of the table's quadrature), within 4 SE + 2e-5."""
    ndf = ggx_table05.ndf
    kc = ec.KullaConty(table=ggx_table05)

    def f(wi, wo):
        return an.torrance_sparrow(wi, wo, ndf, "smith-correlated") + kc.brdf(wi, wo)

    theta = np.array([0.0, 30.0, 60.0, 80.0])
    rho, se = an.directional_albedo(theta, f, n=2**14, ndf=ndf, seed=1)
    assert np.all(np.abs(rho - 1.0) < 4 * se + 2e-5), (rho, se)


def test_kulla_conty_fresnel_factor(table05):
    """F_ms = F_avg² E_avg/(1 − F_avg(1 − E_avg)): 1 for the mirror, < 1 for aluminium, and
    F_avg by quadrature agrees with a Monte Carlo average of F over cosine-weighted μ."""
    table = table05
    white = ec.KullaConty(table=table, fresnel_factor=True)
    assert white.scale == 1.0
    al = ec.KullaConty(table=table, material="aluminium", fresnel_factor=True)
    fa = al.f_avg
    mu = np.sqrt(np.random.default_rng(0).random(400_000))  # cosine-weighted μ
    fmc = an.fresnel(mu, "aluminium")
    assert abs(fa - fmc.mean()) < 5 * fmc.std() / np.sqrt(len(mu))
    e = al.e_avg
    assert al.scale == pytest.approx(fa**2 * e / (1 - fa * (1 - e)), rel=1e-14)
    assert 0 < al.scale < 1
    np.testing.assert_allclose(al.albedo([0, 45]), al.scale * white.albedo([0, 45]), rtol=1e-14)


def test_kulla_conty_refuses_bad_input(beckmann_kc):
    with pytest.raises(UsageError, match="ndf"):
        ec.KullaConty()
    with pytest.raises(UsageError, match="table"):
        ec.KullaConty(table="not a table")
    with pytest.raises(UsageError, match="theta_deg"):
        beckmann_kc.albedo(95.0)


# --- Mikkelsen 2009, eq. 28 --------------------------------------------------------------------
def test_mikkelsen_diffuse_is_reciprocal_and_matches_the_printed_eq28(table05):
    """The term equals mikkelsen_mix (eq. 28) minus its specular part for kd ≤ 1."""
    rng = np.random.default_rng(1)
    wi, wo = _random_dirs(rng, 5_000), _random_dirs(rng, 5_000)
    f = ec.mikkelsen_diffuse(wi, wo, table05, 0.7)
    np.testing.assert_allclose(f, ec.mikkelsen_diffuse(wo, wi, table05, 0.7), rtol=1e-14)
    ts = an.torrance_sparrow(wi, wo, table05.ndf, "smith-correlated")
    np.testing.assert_allclose(f, an.mikkelsen_mix(wi, wo, table05, 0.7) - ts, atol=1e-12)


def test_mikkelsen_kd_matches_energy(table05):
    """kd fitted to target energies: per angle it reproduces them exactly; a single kd fitted
    to energies generated by one kd recovers it; the energy of the fitted term, integrated over
    wo independently, equals kd (1 − ρ(θi))(1 − ρ̄). White case: kd = 1/(1 − ρ̄) turns the term
    into Kulla–Conty's f_ms."""
    theta = np.array([0.0, 30.0, 60.0, 80.0])
    target = np.array([0.05, 0.06, 0.11, 0.07])
    kd = ec.mikkelsen_kd(theta, target, table05, per_angle=True)
    np.testing.assert_allclose(ec.mikkelsen_diffuse_albedo(theta, table05, kd), target, rtol=1e-12)
    gen = ec.mikkelsen_diffuse_albedo(theta, table05, 1.3)
    assert ec.mikkelsen_kd(theta, gen, table05) == pytest.approx(1.3, rel=1e-12)
    s = np.array([0.001, 0.001, 0.002, 0.004])
    kd1 = ec.mikkelsen_kd(theta, target, table05, target_stderr=s)
    a = ec.mikkelsen_diffuse_albedo(theta, table05, 1.0)
    resid = kd1 * a - target  # weighted least squares: residual orthogonal to A/σ²
    assert abs(np.sum(resid * a / s**2)) < 1e-9 * np.sum(a * a / s**2)
    x, w = np.polynomial.legendre.leggauss(64)
    mu = 0.5 + 0.5 * x
    for th in theta:
        wi = spherical_deg(th, 0.0)
        alb = (
            2
            * np.pi
            * np.sum(
                0.5 * w * mu * ec.mikkelsen_diffuse(wi, spherical(np.arccos(mu), 1.0), table05, kd1)
            )
        )
        assert alb == pytest.approx(ec.mikkelsen_diffuse_albedo(th, table05, kd1), rel=1e-5)
    white = 1.0 / (1.0 - table05.rho_bar)
    kc = ec.KullaConty(table=table05)
    rng = np.random.default_rng(2)
    wi, wo = _random_dirs(rng, 1000), _random_dirs(rng, 1000)
    np.testing.assert_allclose(
        ec.mikkelsen_diffuse(wi, wo, table05, white), kc.brdf(wi, wo), rtol=1e-12
    )


def test_mikkelsen_refuses_bad_input(table05):
    with pytest.raises(UsageError, match="kd"):
        ec.mikkelsen_diffuse(np.array([0, 0, 1.0]), np.array([0, 0, 1.0]), table05, -1.0)
    with pytest.raises(UsageError, match="target"):
        ec.mikkelsen_kd([0, 30], [0.1], table05)
    with pytest.raises(UsageError, match="target_stderr"):
        ec.mikkelsen_kd([0, 30], [0.1, 0.1], table05, target_stderr=[0.0, 1.0])


# --- slow: the walk against the energy compensation --------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("m", [0.3, 0.5])
def test_walk_order_one_at_grazing_with_many_paths(m):
    """χ² of order 1 against TS with correlated Smith at θi = 85°, 2e6 paths (finer bins)."""
    ndf = an.Beckmann(m)
    bins = Bins(n_theta=45, n_phi=37)
    n = 2_000_000
    omega = bins.projected_solid_angle()
    r = _walk(85.0, ndf, n=n, bins=bins, seed=21)
    obs = np.append(r.values[0, 0] * omega * n, 0.0)
    obs[-1] = n - obs[:-1].sum()
    exp = np.append(_ts_bins(85.0, ndf, bins=bins) * omega * n, 0.0)
    exp[-1] = n - exp[:-1].sum()
    _, dof, pval = pearson_chi2(obs, exp)
    assert dof > 100 and pval > ALPHA


def test_kulla_conty_bin_averages_match_quadrature_of_the_lobe(beckmann_kc):
    """The band-quadrature bin averages equal the project's adaptive bin_average of f_ms, and
    Σ f̄_B Ω_B is the lobe's albedo."""
    bins = Bins(n_theta=9, n_phi=7)
    for th in (20.0, 75.0):
        ref = bin_average(spherical_deg(th, 0.0), bins, beckmann_kc.brdf, 0.0, 1e-8).values
        got = beckmann_kc.bin_averages(th, bins.theta_edges, bins.n_phi)[0]
        np.testing.assert_allclose(got, ref, rtol=1e-7)
        total = np.sum(got * bins.projected_solid_angle())
        assert total == pytest.approx(beckmann_kc.albedo(th), rel=1e-7)
