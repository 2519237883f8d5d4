"""Student-t (GGX) heightfields (``microsim.surfaces.student_t``): the realised facet-slope law
of the transform and mixture constructions against the STD by Kolmogorov–Smirnov over the
tile's independent cells (a wrong target fails the same test), the slope azimuth, the
anisotropic axes, the tail masses, and the scene kinds through ``microsim surface``."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from scipy.special import gammainc, ndtr
from support import refused

from microsim.analytic import GGX, Beckmann, StudentT
from microsim.app.cli import main
from microsim.surfaces import student_t_mixture, student_t_transform
from microsim.surfaces.student_t import (
    SlopeLaw,
    gamma_weight,
    height_transform,
    mixture_patch_m,
    slope_law_stats,
)
from microsim.surfaces.surface import facet_slopes

ALPHA = 0.3
CORR = 7.0  # cells
PATCHES = 16


@lru_cache(maxsize=None)
def transform(gamma: float, **aniso):
    return student_t_transform(512, 1.0, ALPHA, gamma, CORR, seed=5, **aniso)


@lru_cache(maxsize=None)
def mixture(gamma: float):
    return [student_t_mixture(160, 1.0, ALPHA, gamma, CORR, s, PATCHES) for s in range(PATCHES)]


def ks(surfaces, *ndfs, stretch=(1.0, 1.0), rotation=0.0):
    """(KS distance, critical value) of the surfaces' |slope| against the blend of ``ndfs``."""
    st = slope_law_stats(surfaces, SlopeLaw(tuple(ndfs), CORR * CORR, stretch, rotation))
    return st["slope_ks"], st["slope_ks_critical"]


@pytest.mark.parametrize("gamma", [2.0, 3.0])
def test_transform_is_the_stated_height_map(gamma):
    """w(g) is the Gamma(γ − 1) variable of Φ(g); the tabulated T has T′ = scale √((γ−1)/2w)."""
    g = np.linspace(-6.0, 6.0, 1001)
    w = gamma_weight(g, gamma)
    assert np.allclose(gammainc(gamma - 1.0, w), ndtr(g), rtol=1e-10, atol=1e-15)
    T = height_transform(gamma, 2.0)
    exact = 2.0 * np.sqrt((gamma - 1.0) / (2.0 * w))
    assert np.max(np.abs(T.derivative()(g) / exact - 1.0)) < 1e-6
    assert T(0.0) == 0.0


@pytest.mark.parametrize("gamma", [2.0, 3.0])
def test_transform_slopes_follow_the_student_t_law(gamma):
    surf = transform(gamma)
    st = surf.stats()
    assert surf.ensemble_ndf == (GGX(ALPHA) if gamma == 2.0 else StudentT(ALPHA, gamma))
    assert surf.nominal["construction"] == "transform"
    assert st["independent_cells"] == int(512 * 512 / CORR**2)
    assert st["slope_ks"] < st["slope_ks_critical"]
    assert st["azimuth_ks"] < st["slope_ks_critical"]
    # the same test rejects Beckmann and the other γ at this α
    for wrong in (Beckmann(ALPHA), StudentT(ALPHA, 5.0 - gamma)):
        d, crit = ks([surf], wrong)
        assert d > 2 * crit, (wrong, d, crit)
    # valleys are the rough parts: heights and |slope| anti-correlated by construction; the
    # heavy tail digs pits far deeper than the flat top rises
    assert st["height_slope_rank_corr"] < -0.3
    assert surf.z_range[1] < abs(surf.z_range[0]) / 3.0


def test_anisotropic_transform_realises_alpha_along_the_rotated_axes():
    surf = transform(3.0, alpha_y=2 * ALPHA, rotation=30.0)
    st = surf.stats()
    assert surf.anisotropy is not None
    assert st["alpha_x_realised"] == pytest.approx(ALPHA, rel=0.03)
    assert st["alpha_y_realised"] == pytest.approx(2 * ALPHA, rel=0.03)
    assert st["slope_ks"] < st["slope_ks_critical"]
    assert st["azimuth_ks"] < st["slope_ks_critical"]
    d, crit = ks([surf], StudentT(1.0, 3.0), stretch=(ALPHA, 2 * ALPHA), rotation=120.0)
    assert d > 2 * crit  # the axes swapped


@pytest.mark.parametrize("gamma", [2.0, pytest.param(3.0, marks=pytest.mark.slow)])
def test_mixture_patches_cover_the_strata_and_blend_to_the_law(gamma):
    patches = mixture(gamma)
    for seed, patch in enumerate(patches):  # w of patch k lies in the k-th stratum
        w = (gamma - 1.0) * (ALPHA / patch.nominal["m_patch"]) ** 2
        assert seed / PATCHES <= gammainc(gamma - 1.0, w) < (seed + 1) / PATCHES
        assert patch.ensemble_ndf == (GGX(ALPHA) if gamma == 2.0 else StudentT(ALPHA, gamma))
    # the stratum's midpoint, the same for every seed of that stratum
    assert mixture_patch_m(ALPHA, gamma, PATCHES, PATCHES) == patches[0].nominal["m_patch"]
    ms = [p.nominal["m_patch"] for p in patches]
    blend = SlopeLaw(tuple(Beckmann(m) for m in ms), CORR**2)
    union = slope_law_stats(patches, blend)
    crit = union["slope_ks_critical"]
    assert union["slope_ks"] < crit  # every patch realises its Beckmann law
    # Gaussian patches: height and |slope| uncorrelated (4 standard errors of the mean)
    assert abs(union["height_slope_rank_corr"]) < 4.0 / np.sqrt(union["independent_cells"])
    # the midpoint rule puts the blend within 0.12/patches of the law (its documented bound) …
    r = np.geomspace(1e-4, 1e4, 100_001)
    strata = np.max(np.abs(blend.cdf(r) - SlopeLaw((StudentT(ALPHA, gamma),), 1.0).cdf(r)))
    assert strata <= 0.12 / PATCHES
    # … so the union of patches passes the KS test against the Student-t law itself, and
    # Beckmann(α) fails it
    assert ks(patches, StudentT(ALPHA, gamma))[0] < crit
    assert ks(patches, Beckmann(ALPHA))[0] > 2.0 * crit


def test_tail_masses_equal_their_formulas():
    surf = transform(2.0)
    r_max = np.max(np.hypot(*facet_slopes(surf.facet_normals())))
    assert surf.stats()["tail_mass_truncated"] == pytest.approx(
        ALPHA**2 / (ALPHA**2 + r_max**2), rel=1e-6
    )  # GGX: P(|s| > r) = α²/(α² + r²)
    # a rough mixture: the lowest stratum's m is capped where a Gaussian scene stops, 2σ/ℓ = 10
    alpha = 3.0
    patch = student_t_mixture(64, 1.0, alpha, 2.0, CORR, seed=0, patches=PATCHES)
    m_cap = patch.nominal["m_patch"]
    assert 2 * patch.nominal["sigma"] / CORR == pytest.approx(10.0, rel=1e-12)
    assert patch.nominal["capped_tail_mass"] == pytest.approx(-np.expm1(-((alpha / m_cap) ** 2)))
    assert patch.nominal["capped_tail_mass"] > 1.0 / PATCHES  # the whole stratum is capped


def test_generators_refuse_bad_values():
    refused(lambda: student_t_transform(64, 1.0, ALPHA, 1.5, CORR), "gamma")
    refused(lambda: student_t_transform(64, 1.0, ALPHA, 2.0, 0.5), "corr_len", "dx")
    refused(lambda: student_t_transform(64, 1.0, ALPHA, 2.0, 2.0, alpha_y=1.0), "alpha_y")
    refused(lambda: student_t_mixture(64, 1.0, ALPHA, np.inf, CORR), "gamma")
    refused(lambda: student_t_mixture(64, 1.0, ALPHA, 2.0, CORR, patches=0), "patches")


SCENE = """\
[surface]
kind = "{kind}"
n = 64
alpha = 0.3
gamma = 2
corr_len = 7
{extra}
[simulation]
realisations = {realisations}
"""


def write_scene(tmp_path, kind, extra="", realisations=1):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.format(kind=kind, extra=extra, realisations=realisations))
    return str(path)


def run_cli(capsys, *args):
    status = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return status, out, err


@pytest.mark.parametrize(
    "kind, extra, realisations, key",
    [
        ("student-t-transform", "", 1, None),
        ("student-t-transform", "gamma = 1.5", 1, "surface.gamma"),
        ("student-t-transform", "gamma = inf", 1, "surface.gamma"),
        ("student-t-transform", "corr_len = 0.5", 1, "surface.corr_len"),
        ("student-t-transform", "alpha_y = 3.0", 1, "surface.alpha_y"),
        ("student-t-mixture", "patches = 4", 8, None),
        ("student-t-mixture", "patches = 0", 1, "surface.patches"),
        ("student-t-mixture", "patches = 4", 6, "simulation.realisations"),
        ("student-t-mixture", "patches = 4", '"auto"', "simulation.realisations"),
    ],
)
def test_scene_kinds_one_line_errors(tmp_path, capsys, kind, extra, realisations, key):
    text = SCENE.format(kind=kind, extra="", realisations=realisations)
    if extra:  # the given key replaces the default one
        name = extra.split(" = ")[0]
        lines = [ln for ln in text.splitlines() if not ln.startswith(f"{name} =")]
        text = "\n".join(lines).replace("[simulation]", f"{extra}\n[simulation]") + "\n"
    path = tmp_path / "scene.toml"
    path.write_text(text)
    status, out, err = run_cli(capsys, "surface", path)
    if key is None:
        assert status == 0, err
        return
    assert status == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert key in err and str(path) in err, err


@pytest.mark.parametrize("kind", ["student-t-transform", "student-t-mixture"])
def test_cli_surface_prints_the_slope_law_statistics(tmp_path, capsys, kind):
    extra = "patches = 2" if kind == "student-t-mixture" else ""
    path = write_scene(tmp_path, kind, extra, realisations=2)
    status, out, err = run_cli(capsys, "surface", path)
    assert status == 0, err
    from microsim.app.scene import load_scene

    st = load_scene(path).build_surface().stats()
    rows = {ln.split("  ")[0]: ln.split() for ln in out.splitlines()}
    *_, measured, critical, _ = rows["|slope| KS distance to its law"]
    assert float(measured) == pytest.approx(st["slope_ks"], rel=1e-5)
    assert float(critical) == pytest.approx(st["slope_ks_critical"], rel=1e-5)
    assert int(rows["independent cells"][-3]) == st["independent_cells"]
    assert "height-|slope| rank correlation" in rows


def test_vgrooves_with_student_t_tilts_describe(tmp_path, capsys):
    path = tmp_path / "vg.toml"
    path.write_text(
        '[surface]\nkind = "vgrooves"\nn_grooves = 400\nndf = "student-t"\nalpha = 0.3\ngamma = 3\n'
    )
    status, out, err = run_cli(capsys, "surface", path)
    assert status == 0, err
    assert "ndf = student-t" in out and "tilt CDF distance to NDF" in out
