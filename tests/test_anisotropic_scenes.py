"""Anisotropic fields reach scenes and the wave verdicts: an ABC scene with ``B_y`` is an
anisotropic scene (full-azimuth bins, the anisotropic Beckmann of its mesh as ensemble NDF),
and the wave closed forms evaluate an anisotropic field's PSD at the scattering frequency
(fx, fy), not at |f| — checked against Rayleigh–Rice written directly with the elliptical PSD
(``analytic.rayleigh_rice(..., B_y, rotation)``), an independent code path."""

from __future__ import annotations

import numpy as np
import pytest

from microsim import vectors
from microsim.analysis.wave_verdicts import WAVE_MODELS, closed_form, surface_spectrum
from microsim.analytic import AnisotropicBeckmann, church_to_condensed, rayleigh_rice
from microsim.app.scene import CATALOGUE, load_scene
from microsim.errors import UsageError
from microsim.surfaces import abc, gaussian
from microsim.surfaces.heightfields import gaussian_anisotropic_psd

SCENE = """\
name = "abc-aniso"
[surface]
kind = "abc"
n = 128
sigma = 0.5
B = 20.0
B_y = 60.0
C = 3.5
rotation = 30
[material]
ior = "aluminium"
[simulation]
theta_i = [30]
phi_bins = 24
"""


def _directions(rng, n=500):
    wi = vectors.spherical_deg(rng.uniform(0, 80, n), rng.uniform(-180, 180, n))
    wo = vectors.spherical_deg(rng.uniform(0, 85, n), rng.uniform(-180, 180, n))
    return wi, wo


def test_an_abc_scene_with_b_y_is_anisotropic(tmp_path):
    p = tmp_path / "abc-aniso.toml"
    p.write_text(SCENE)
    scene = load_scene(p)
    assert scene.anisotropic and scene.full_azimuth
    surface = scene.build_surface()
    ndf = scene.ndf()
    assert isinstance(ndf, AnisotropicBeckmann) and ndf == surface.ensemble_ndf
    assert ndf.rotation == 30.0 and ndf.alpha_x > ndf.alpha_y  # B < B_y: rougher along x'
    iso = load_scene_text(tmp_path, SCENE.replace("B_y = 60.0\n", ""))
    assert not iso.anisotropic and not iso.full_azimuth


def load_scene_text(tmp, text):
    p = tmp / "scene.toml"
    p.write_text(text)
    return load_scene(p)


def test_rayleigh_rice_on_an_anisotropic_abc_spectrum_is_the_elliptical_psd():
    """The wave verdicts' Rayleigh–Rice on the tile's spectrum equals ``rayleigh_rice`` with
    Löw's condensed (A, B², B_y², (C + 1)/2) and the rotation, to rounding, inside the band."""
    surface = abc(128, 1.0, 0.5, 20.0, 3.5, seed=1, B_y=60.0, rotation=30.0)
    nom, lam = surface.nominal, 4.0
    spec = surface_spectrum(surface)
    assert not spec.isotropic
    fn = closed_form("rayleigh-rice", spec, lam, "aluminium")
    wi, wo = _directions(np.random.default_rng(2))
    A, B, C = church_to_condensed(nom["A"], nom["B"], nom["C"])
    B_y = church_to_condensed(nom["A"], nom["B_y"], nom["C"])[1]
    direct = rayleigh_rice(wi, wo, lam, A, B, C, "aluminium", B_y=B_y, rotation=30.0)
    inside = np.hypot(*((wi + wo)[:, :2] / lam).T) <= nom["f_max"]
    assert inside.sum() > 100
    np.testing.assert_allclose(fn(wi, wo)[inside], direct[inside], rtol=1e-10)
    assert np.all(fn(wi, wo)[~inside] == 0.0)
    # the isotropic spectrum with the same A and B differs by far more than rounding
    iso = closed_form("rayleigh-rice", surface_spectrum(_isotropic(surface)), lam, "aluminium")
    assert np.max(np.abs(iso(wi, wo)[inside] / direct[inside] - 1.0)) > 0.5


def _isotropic(surface):
    nom = surface.nominal
    return abc(128, 1.0, nom["sigma"], nom["B"], nom["C"], seed=1)


def test_gaussian_anisotropic_spectrum_and_low_smooth_is_left_out():
    surface = gaussian(64, 1.0, 0.3, 8.0, seed=0, corr_len_y=24.0, rotation=-20.0)
    spec = surface_spectrum(surface)
    wi, wo = _directions(np.random.default_rng(3))
    lam = 2.0
    d = (wi + wo)[:, :2] / lam
    want = gaussian_anisotropic_psd(d[:, 0], d[:, 1], 0.3, 8.0, 24.0, -20.0)
    np.testing.assert_allclose(spec.at_pair(wi, wo, lam), want, rtol=1e-12)
    with pytest.raises(UsageError, match="anisotropic"):
        spec(np.array([0.1]))
    aniso_abc = surface_spectrum(abc(128, 1.0, 0.5, 20.0, 3.5, B_y=60.0))
    assert "low-smooth" in WAVE_MODELS
    with pytest.raises(UsageError, match="isotropic ABC"):
        closed_form("low-smooth", aniso_abc, lam, "aluminium")


@pytest.mark.slow  # 12–15 s end to end; the default run keeps the elliptical-PSD check above
@pytest.mark.integration
def test_the_anisotropic_wave_scene_judges_the_elliptical_rayleigh_rice(tmp_path):
    """The catalogue's anisotropic smooth ABC scene end to end (``--quick``): the Kirchhoff
    solver runs at the scene's φi = 30° on full-azimuth bins, and Rayleigh–Rice with the
    elliptical PSD is not found to differ from it at θi 30° and 60° (σ/λ = 1/77, where the
    isotropic scene's Rayleigh–Rice agrees too; g/2 ≤ 1 % there)."""
    import json

    from microsim.app.cli import main
    from microsim.sim import Result

    out = tmp_path / "run"
    scene = str(CATALOGUE / "abc-aniso-smooth-wave.toml")
    assert main(["run", scene, "--quick", "--out", str(out), "--no-progress"]) == 0
    k = Result.load(out / "kirchhoff")
    assert set(k.phi_i.tolist()) == {30.0} and not k.bins.folded
    wave = json.loads((out / "verdicts.json").read_text())["wave"]["verdicts"]
    rr = {v["theta_i"]: v for v in wave if v["model"] == "rayleigh-rice"}
    assert rr[30.0]["status"] != "differs" and rr[60.0]["status"] != "differs", rr
    assert not any(v["model"] == "low-smooth" for v in wave)  # isotropic spectra only
