"""Every catalogue scene (microsim/scenes/*.toml) renders headless in every ``microsim view --what``
view through the command line, with the fewest rays and a small image (the whole grid with
``-m slow``; by default the normals view of every scene and every view of the anisotropic
ones); and the anisotropic
NDFs answer the tilt-distribution interface the normals view compares the facets with."""

from pathlib import Path

import numpy as np
import pytest
from test_view import _image, opengl  # noqa: F401  (the off-screen OpenGL probe fixture)

from microsim import analytic as an
from microsim.app.cli import main
from microsim.app.scene import CATALOGUE
from microsim.app.view import VIEWS

ROOT = Path(__file__).resolve().parents[1]
SCENES = sorted(CATALOGUE.glob("*.toml"))
RAYS = {"rays": 50, "lobe": 2000, "disk": 2000}
"""The fewest rays each tracing view is given: enough for a drawing, not for a judgement."""
ANISOTROPIC_SCENES = {"abc-aniso-smooth-wave", "gaussian-aniso-4", "vgroove-oriented-0.3"}
"""Scenes whose surface is anisotropic: every view of them runs in the default test run, as
does the normals view (the one that draws the distribution) of every scene; the rest of the
grid is marked slow (``pytest -m slow tests/test_view_grid.py`` renders it all)."""


def _case(scene: Path, what: str):
    default = what == "normals" or scene.stem in ANISOTROPIC_SCENES
    marks = () if default else (pytest.mark.slow,)
    return pytest.param(scene, what, id=f"{scene.stem}-{what}", marks=marks)


GRID = [_case(scene, what) for scene in SCENES for what in VIEWS]


@pytest.fixture
def headless_env(monkeypatch):
    """No display, as on a CI machine: the views render with VTK's EGL window."""
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setenv("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


@pytest.mark.integration
@pytest.mark.parametrize("scene, what", GRID)
def test_every_catalogue_scene_renders_in_every_view(
    opengl,  # noqa: F811
    headless_env,
    tmp_path,
    capsys,
    scene,
    what,
):
    out = tmp_path / f"{scene.stem}-{what}.png"
    args = ["view", str(scene), "--what", what, "--screenshot", str(out), "--size", "240x160"]
    if what in RAYS:
        args += ["--rays", str(RAYS[what])]
    status = main(args)
    assert status == 0, capsys.readouterr().err
    assert out.stat().st_size > 0
    colours = np.unique(_image(out).reshape(-1, 3), axis=0)
    assert len(colours) > 1


ANISOTROPIC = [
    an.AnisotropicBeckmann(0.3, 0.075),
    an.AnisotropicBeckmann(0.011, 0.0045, 30.0),
    an.AnisotropicGGX(0.4, 0.1, -60.0),
]


@pytest.mark.parametrize("ndf", ANISOTROPIC, ids=repr)
def test_anisotropic_tilt_distribution_is_that_of_its_samples(ndf):
    """cdf_theta_rad is the tilt CDF of the sampler's half vectors (Kolmogorov–Smirnov at
    α = 1e-3) and reaches 1 at the horizon; tilt_pdf_rad is its derivative."""
    from scipy import stats

    rng = np.random.default_rng(5)
    h = ndf.sample(rng.random(20_000), rng.random(20_000))
    tilts = np.arccos(np.clip(h[:, 2], -1.0, 1.0))
    assert stats.kstest(tilts, ndf.cdf_theta_rad).pvalue > 1e-3
    assert ndf.cdf_theta_rad(0.5 * np.pi) == pytest.approx(1.0, abs=1e-12)
    t = np.linspace(0.0, 0.5 * np.pi, 20_001)
    slope = np.gradient(ndf.cdf_theta_rad(t), t)[1:-1]  # central differences
    pdf = ndf.tilt_pdf_rad(t)[1:-1]
    assert np.max(np.abs(slope - pdf)) < 1e-3 * np.max(pdf)


@pytest.mark.parametrize(
    "aniso, iso",
    [
        (an.AnisotropicBeckmann(0.3, 0.3, 20.0), an.Beckmann(0.3)),
        (an.AnisotropicGGX(0.2, 0.2), an.GGX(0.2)),
    ],
)
def test_equal_roughness_has_the_isotropic_tilt_distribution(aniso, iso):
    t = np.linspace(0.0, 0.5 * np.pi, 91)
    assert aniso.cdf_theta_rad(t) == pytest.approx(iso.cdf_theta_rad(t), abs=1e-12)
    assert aniso.tilt_pdf_rad(t) == pytest.approx(iso.tilt_pdf_rad(t), rel=1e-12, abs=1e-12)


def test_anisotropic_ggx_tilt_cdf_has_its_closed_form():
    """P(θh ≤ θ) = T / √((T + αx²)(T + αy²)), T = tan²θ: the azimuth average of T/(T + α(φ)²)."""
    ndf = an.AnisotropicGGX(0.1, 0.8, 30.0)
    t = np.linspace(0.0, 1.5, 40)
    T = np.tan(t) ** 2
    expected = T / np.sqrt((T + 0.1**2) * (T + 0.8**2))
    assert ndf.cdf_theta_rad(t) == pytest.approx(expected, abs=1e-12)
