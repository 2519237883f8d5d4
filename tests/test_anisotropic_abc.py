"""Anisotropic ABC heightfields (``abc(..., B_y=…, rotation=…)``): the elliptical PSD
A/(1 + B² f'x² + B_y² f'y²)^((C+1)/2) along axes rotated counter-clockwise by ``rotation``,
A = σ² B B_y (C − 1)/(2π).

Facts checked: the synthesised spectrum is that formula (periodogram of an exact-amplitude
tile, to rounding); the facets' realised roughness along the PSD's axes is the generator's
prediction — exactly for exact-amplitude synthesis (Parseval over the mesh's two triangle
types), within the realisation scatter for plain noise — and along the grid axes it lies
between sinc²(π f_max dx) × and 1 × the continuum (2π f'x)² moment of the same lattice
spectrum (the finite-difference response); the normalisation makes the whole lattice sum σ²
(Poisson summation, below); B_y = B is the isotropic spectrum; B_y = None is the isotropic
generator unchanged, bit for bit."""

import warnings

import numpy as np
import pytest
from scipy import special

from microsim.analytic import AnisotropicBeckmann, Beckmann, abc_psd_church
from microsim.errors import UsageError
from microsim.surfaces import abc
from microsim.surfaces import heightfields as hf

SIGMA, B, B_Y, C = 1.0, 8.0, 32.0, 3.5


def _tile(rotation=0.0, **kw):
    return abc(128, 1.0, SIGMA, B, C, seed=3, band_limit=2, B_y=B_Y, rotation=rotation, **kw)


def _formula(FX, FY, A, b, b_y, c, rotation):
    """The elliptical ABC PSD written out here (not the package's function)."""
    t = np.radians(rotation)
    u = np.cos(t) * FX + np.sin(t) * FY
    v = -np.sin(t) * FX + np.cos(t) * FY
    return A / (1.0 + (b * u) ** 2 + (b_y * v) ** 2) ** ((c + 1.0) / 2.0)


@pytest.mark.parametrize("rotation", [0.0, 30.0, -70.0, 90.0])
def test_realised_roughness_is_the_prediction_exactly(rotation):
    s = _tile(rotation)
    st = s.stats()
    assert isinstance(s.ensemble_ndf, AnisotropicBeckmann)
    assert s.ensemble_ndf.rotation == rotation
    for axis in ("x", "y"):
        assert st[f"alpha_{axis}_realised"] == pytest.approx(st[f"predicted_alpha_{axis}"],
                                                               rel=1e-9)  # fmt: skip
    # the scene's path to the NDF (without building the surface) gives the same object
    ndf = hf.abc_ensemble_ndf(128, 1.0, SIGMA, B, C, 2, B_Y, rotation)
    assert ndf == s.ensemble_ndf
    assert (ndf.alpha_x, ndf.alpha_y) == (s.predicted.alpha_x, s.predicted.alpha_y)
    assert s.nominal["B_y"] == B_Y and s.nominal["rotation"] == rotation
    # the smaller B is the shorter correlation length: the x' axis is the rough one
    assert ndf.alpha_x > 2 * ndf.alpha_y


def test_spectrum_is_the_rotated_elliptical_formula():
    """Periodogram |FFT h|² dx²/N of an exact-amplitude tile at rotation 30° against the
    formula (rounding: 1e-8), zero outside the radial band; along the direction at +30° from x
    the spectrum is the isotropic profile with B, at +120° the one with B_y."""
    rotation, n, dx, k = 30.0, 128, 1.0, 2
    s = _tile(rotation)
    A = SIGMA**2 * B * B_Y * (C - 1) / (2 * np.pi)
    assert s.nominal["A"] == pytest.approx(A, rel=1e-15)
    FX, FY = np.meshgrid(np.fft.fftfreq(n, dx), np.fft.fftfreq(n, dx))
    inside = (np.hypot(FX, FY) > 0) & (np.hypot(FX, FY) <= 1 / (2 * k * dx))
    P = np.abs(np.fft.fft2(s.heights)) ** 2 * dx * dx / s.heights.size
    S = _formula(FX, FY, A, B, B_Y, C, rotation)
    np.testing.assert_allclose(P[inside], S[inside], rtol=1e-8)
    assert P[~inside].max() < 1e-20 * S.max()
    t = np.linspace(0.0, 0.25, 7)
    for angle, b in ((rotation, B), (rotation + 90.0, B_Y)):
        fx, fy = t * np.cos(np.radians(angle)), t * np.sin(np.radians(angle))
        got = hf.abc_anisotropic_psd(fx, fy, A, B, B_Y, C, rotation)
        np.testing.assert_allclose(got, abc_psd_church(t, A, b, C), rtol=1e-13)


@pytest.mark.parametrize("rotation", [0.0, 90.0])
def test_axis_prediction_is_bounded_by_the_finite_difference_response(rotation):
    """Along a grid axis the mesh slope variance is Σ S (2 sin(π f dx)/dx)² df² and the
    continuum one Σ S (2π f)² df² on the same lattice; the response ratio sinc²(π f dx) lies in
    [sinc²(π f_max dx), 1] for |f| ≤ f_max, so αx²/2 (x' = grid x at 0°, grid y at 90°) lies
    between those multiples of the continuum moment."""
    n, dx, k = 128, 1.0, 2
    s = _tile(rotation)
    A = SIGMA**2 * B * B_Y * (C - 1) / (2 * np.pi)
    FX, FY = np.meshgrid(np.fft.fftfreq(n, dx), np.fft.fftfreq(n, dx))
    f_max = 1 / (2 * k * dx)
    inside = (np.hypot(FX, FY) > 0) & (np.hypot(FX, FY) <= f_max)
    S = np.where(inside, _formula(FX, FY, A, B, B_Y, C, rotation), 0.0)
    along_x = FX if rotation == 0.0 else FY
    along_y = FY if rotation == 0.0 else FX
    df2 = 1 / (n * dx) ** 2
    lo = np.sinc(f_max * dx) ** 2  # numpy sinc(x) = sin(πx)/(πx)
    for alpha, fr in ((s.predicted.alpha_x, along_x), (s.predicted.alpha_y, along_y)):
        cont = np.sum(S * (2 * np.pi * fr) ** 2) * df2
        assert lo * cont <= alpha**2 / 2 <= cont


def test_plain_noise_realisations_scatter_about_the_prediction():
    """Eight plain-noise tiles at rotation 0 (αx²/2 is the grid-x slope variance): the mean
    realised αx² within 4 standard errors of the prediction, the standard error from the
    spectrum (every mode's power ~ Exp(1): ``spectrum_moments``' relative sd)."""
    tiles = [abc(128, 1.0, SIGMA, B, C, seed=k, band_limit=2, B_y=B_Y, exact_amplitude=False)
             for k in range(8)]  # fmt: skip
    pred = tiles[0].predicted.alpha_x ** 2
    real = np.array([t.stats()["alpha_x_realised"] ** 2 for t in tiles])
    *_, S, FX, FY = hf.abc_spectrum(128, 1.0, SIGMA, B, C, 2, B_Y, 0.0)
    rel_sd = hf.spectrum_moments(S, FX, FY, 1.0).slope_var_x_rel_sd
    assert abs(real.mean() / pred - 1) < 4 * rel_sd / np.sqrt(len(tiles))


def test_height_variance_is_sigma_squared_by_poisson_summation():
    """Poisson summation on the frequency lattice df = 1/L: Σ_{all k} S(k df) df² = Σ_m R(m L),
    R the continuum autocorrelation, here Matérn: R/σ² = r̃^ν K_ν(r̃)/(2^{ν−1} Γ(ν)), ν = (C−1)/2,
    r̃ = 2π √((x'/B)² + (y'/B_y)²). So the tile's discrete height variance (the in-band lattice
    sum, = the realised variance exactly), plus the missing f = 0 cell A df², plus the lattice
    sum outside the band up to |f| = R, equals σ² Σ_m R(mL)/σ² up to the lattice tail beyond R,
    which is below (B_y/B)(1 + B²R²)^{−(C−1)/2} σ² (BB_y/b(θ)² ≤ B_y/B, b(θ) ≥ B). A wrong A
    (e.g. the isotropic σ²B²(C−1)/(2π)) would miss by a factor."""
    n, dx, k, c, b, b_y, rot = 128, 1.0, 2, 5.0, 8.0, 24.0, 30.0
    s = abc(n, dx, SIGMA, b, c, seed=1, band_limit=k, B_y=b_y, rotation=rot)
    L, A, f_max = n * dx, s.nominal["A"], s.nominal["f_max"]
    disc = s.predicted.rms_height**2
    assert np.mean(s.heights**2) == pytest.approx(disc, rel=1e-9)  # Parseval, exact amplitude
    R = 4.0
    M = int(np.ceil(R * L))
    kk = np.arange(-M, M + 1) / L
    FX, FY = np.meshgrid(kk, kk)
    f = np.hypot(FX, FY)
    outside = np.sum(np.where((f > f_max) & (f <= R), _formula(FX, FY, A, b, b_y, c, rot), 0.0))
    nu = (c - 1) / 2
    m = np.arange(-3, 4)
    MX, MY = np.meshgrid(m * L, m * L)
    t = np.radians(rot)
    rt = 2 * np.pi * np.hypot((np.cos(t) * MX + np.sin(t) * MY) / b,
                              (-np.sin(t) * MX + np.cos(t) * MY) / b_y)  # fmt: skip
    with np.errstate(invalid="ignore"):
        rho = np.where(rt > 0, rt**nu * special.kv(nu, rt) / (2 ** (nu - 1) * special.gamma(nu)), 1)
    total = disc + (A + outside) / L**2
    tail = (b_y / b) * (1 + (b * R) ** 2) ** (-(c - 1) / 2) * SIGMA**2
    assert abs(total - SIGMA**2 * rho.sum()) <= tail
    assert tail < 1e-5 and abs(rho.sum() - 1) < 1e-9


def test_kept_fraction_warning_states_the_discrete_variance():
    """As for the isotropic field: the tile and band keep mom.height_var of σ², stated in the
    warning when below 90 % (a 24² tile, 1 × the long correlation scale B_y); a 128² tile with
    C > 3 keeps more and warns of nothing."""
    with pytest.warns(UserWarning, match="keep only") as rec:
        s = abc(24, 1.0, SIGMA, 8.0, 5.0, band_limit=2, B_y=24.0, rotation=30.0)
    kept = s.predicted.rms_height**2 / SIGMA**2
    assert kept < 0.9
    assert f"{100 * kept:.1f} %" in str(rec[0].message)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        big = abc(128, 1.0, SIGMA, 8.0, 5.0, band_limit=2, B_y=24.0, rotation=30.0)
    assert big.warnings == () and big.predicted.rms_height**2 >= 0.9 * SIGMA**2


def test_isotropic_limit_is_the_isotropic_spectrum():
    """B_y = B: the same A and spectrum as the isotropic generator (to rounding) at any
    rotation, heights equal to rounding for the same seed, the continuum slope variance equal
    to quadrature accuracy, and at rotation 0 αx = αy = the isotropic Beckmann m (the square
    grid's two axes are equivalent)."""
    n, dx, sigma, b, c, k = 96, 1.0, 0.7, 12.0, 2.5, 4
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        iso = abc(n, dx, sigma, b, c, seed=5, band_limit=k)
        for rot in (0.0, 37.0):
            an = abc(n, dx, sigma, b, c, seed=5, band_limit=k, B_y=b, rotation=rot)
            A1, _, S1, *_ = hf.abc_spectrum(n, dx, sigma, b, c, k)
            A2, _, S2, *_ = hf.abc_spectrum(n, dx, sigma, b, c, k, b, rot)
            assert A2 == pytest.approx(A1, rel=1e-15)
            np.testing.assert_allclose(S2, S1, rtol=1e-12, atol=0)
            np.testing.assert_allclose(an.heights, iso.heights, rtol=0,
                                       atol=1e-12 * np.abs(iso.heights).max())  # fmt: skip
            assert an.predicted.continuum_slope_var == pytest.approx(
                iso.predicted.continuum_slope_var, rel=1e-7
            )
            if rot == 0.0:
                m = iso.ensemble_ndf.m
                assert an.ensemble_ndf.alpha_x == pytest.approx(m, rel=1e-12)
                assert an.ensemble_ndf.alpha_y == pytest.approx(m, rel=1e-12)


@pytest.mark.filterwarnings("ignore:abc.*keep only:UserWarning")
def test_isotropic_path_is_unchanged():
    """B_y = None is the isotropic generator: the heights are bit for bit the synthesis of the
    isotropic ABC spectrum (``psd_grid`` of ``abc_psd_church``) with the seed's noise, equal to
    passing nothing, and the ensemble NDF is Beckmann, equal to ``abc_ensemble_ndf``'s."""
    n, dx, sigma, b, c, k, seed = 64, 1.0, 0.5, 8.0, 4.0, 4, 2
    plain = abc(n, dx, sigma, b, c, seed=seed, band_limit=k)
    given = abc(n, dx, sigma, b, c, seed=seed, band_limit=k, B_y=None, rotation=0.0)
    A = sigma**2 * b**2 * (c - 1) / (2 * np.pi)
    S, *_ = hf.psd_grid(lambda f: abc_psd_church(f, A, b, c), (n, n), dx, 1 / (2 * k * dx))
    ref = hf.synthesize(S, dx, np.random.default_rng(seed))
    assert np.array_equal(plain.heights, ref) and np.array_equal(given.heights, ref)
    assert np.array_equal(plain.vertices, given.vertices)
    assert type(plain.ensemble_ndf) is Beckmann
    assert plain.ensemble_ndf == hf.abc_ensemble_ndf(n, dx, sigma, b, c, k)
    assert "B_y" not in plain.nominal and "rotation" not in plain.nominal
    assert plain.predicted.alpha_x is None and "alpha_x_realised" not in plain.stats()


@pytest.mark.parametrize(
    "kw, name",
    [(dict(B_y=0.0), "B_y"), (dict(B_y=-8.0), "B_y"), (dict(B_y=float("inf")), "B_y"),
     (dict(B_y=float("nan")), "B_y"), (dict(B_y="8"), "B_y"),
     (dict(B_y=8.0, rotation=float("inf")), "rotation"),
     (dict(B_y=8.0, rotation=float("nan")), "rotation"), (dict(rotation="30"), "rotation")],
)  # fmt: skip
def test_bad_anisotropy_names_its_parameter(kw, name):
    with pytest.raises(UsageError, match=name):
        abc(32, 1.0, 0.5, 8.0, 4.0, **kw)
    if "B_y" in kw:
        with pytest.raises(UsageError, match=name):
            hf.abc_ensemble_ndf(32, 1.0, 0.5, 8.0, 4.0, 4, kw["B_y"], kw.get("rotation", 0.0))
