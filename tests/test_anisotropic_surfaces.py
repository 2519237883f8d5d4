"""Anisotropic Gaussian heightfields (``gaussian(..., corr_len_y=…, rotation=…)``): the facets'
realised roughness along the ensemble NDF's axes is the generator's prediction — exactly for
exact-amplitude synthesis (Parseval over the mesh's two triangle types), within the
realisation scatter for plain noise — and the prediction is the continuum 2σ/ℓ up to the
mesh's finite-difference bias; isotropic fields are unchanged."""

import numpy as np
import pytest

from microsim.analytic import AnisotropicBeckmann, Beckmann
from microsim.errors import UsageError
from microsim.surfaces import gaussian
from microsim.surfaces.heightfields import gaussian_anisotropic_psd, psd_grid, spectrum_moments


@pytest.mark.parametrize("rotation", [0.0, 30.0, -70.0, 90.0])
def test_realised_roughness_is_the_prediction_exactly(rotation):
    s = gaussian(128, 1.0, 1.0, 12.0, corr_len_y=40.0, rotation=rotation, seed=3)
    st = s.stats()
    assert isinstance(s.ensemble_ndf, AnisotropicBeckmann)
    assert s.ensemble_ndf.rotation == rotation
    for axis in ("x", "y"):
        assert st[f"alpha_{axis}_realised"] == pytest.approx(st[f"predicted_alpha_{axis}"],
                                                               rel=1e-9)  # fmt: skip


def test_axis_aligned_prediction_is_the_mesh_formula_per_axis():
    """Along the grid axes the facet slope variance of a Gaussian field is 2σ²(1 − e^{−u})/dx²,
    u = (dx/ℓ)², per axis (the isotropic formula with that axis's ℓ); the continuum 2σ/ℓ is
    its dx → 0 limit."""
    sigma, lx, ly, dx = 1.0, 8.0, 24.0, 1.0
    s = gaussian(192, dx, sigma, lx, corr_len_y=ly)
    p = s.predicted
    for alpha, ell in ((p.alpha_x, lx), (p.alpha_y, ly)):
        mesh = 2 * sigma**2 * -np.expm1(-((dx / ell) ** 2)) / dx**2
        assert alpha**2 / 2 == pytest.approx(mesh, rel=1e-4)
        assert alpha == pytest.approx(2 * sigma / ell, rel=(dx / ell) ** 2)
    assert s.nominal["alpha_x"] == 2 * sigma / lx and s.nominal["alpha_y"] == 2 * sigma / ly


def test_plain_noise_realisations_scatter_about_the_prediction():
    """Eight plain-noise tiles: the mean realised αx² lies within 4 standard errors of the
    predicted one, the standard error from the spectrum (every mode's power ~ Exp(1):
    ``spectrum_moments``' relative sd)."""
    sigma, lx, ly, dx, n = 1.0, 8.0, 20.0, 1.0, 128
    tiles = [gaussian(n, dx, sigma, lx, corr_len_y=ly, seed=k, exact_amplitude=False)
             for k in range(8)]  # fmt: skip
    pred = tiles[0].predicted.alpha_x ** 2
    real = np.array([t.stats()["alpha_x_realised"] ** 2 for t in tiles])
    FX, FY = np.meshgrid(np.fft.fftfreq(n, dx), np.fft.fftfreq(n, dx))
    S = gaussian_anisotropic_psd(FX, FY, sigma, lx, ly, 0.0)
    S[0, 0] = 0.0
    rel_sd = spectrum_moments(S, FX, FY, dx).slope_var_x_rel_sd
    assert abs(real.mean() / pred - 1) < 4 * rel_sd / np.sqrt(len(tiles))


def test_isotropic_fields_are_unchanged_and_equal_lengths_are_isotropic_in_law():
    a = gaussian(64, 1.0, 1.0, 8.0, seed=2)
    assert isinstance(a.ensemble_ndf, Beckmann) and "corr_len_y" not in a.nominal
    S, FX, FY = psd_grid(
        lambda f: np.pi * 8.0**2 * np.exp(-((np.pi * 8.0 * f) ** 2)), (64, 64), 1.0
    )
    from microsim.surfaces.heightfields import gaussian_anisotropic_psd

    S2 = gaussian_anisotropic_psd(FX, FY, 1.0, 8.0, 8.0, 37.0)
    S2[0, 0] = 0.0
    np.testing.assert_allclose(S2, S, rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize(
    "kw, name",
    [(dict(corr_len_y=0.5), "corr_len_y"), (dict(corr_len_y=-2.0), "corr_len_y"),
     (dict(corr_len_y=8.0, rotation=float("inf")), "rotation")],
)  # fmt: skip
def test_bad_anisotropy_names_its_parameter(kw, name):
    with pytest.raises(UsageError, match=name):
        gaussian(32, 1.0, 0.5, 8.0, **kw)
