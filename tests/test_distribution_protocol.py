"""Every microfacet distribution satisfies the ``analytic.ndf.NDF`` protocol — D, Smith Λ, G1,
G2 (separable and height-correlated), visible normals, ``isotropic``, ``params()``, ``name`` —
or declares what it lacks (``has_closed_smith``, ``has_visible_sampler``); scene names come from
the classes; and nothing in microsim probes a distribution with getattr/hasattr."""

import re
from pathlib import Path

import numpy as np
import pytest

from microsim import analytic as an
from microsim import vectors
from microsim.analytic.anisotropic import AnisotropicNDF
from microsim.analytic.ndf import NDF
from microsim.app.scene import make_ndf
from microsim.errors import UsageError

_RNG = np.random.default_rng(7)
_TILTS = np.column_stack([_RNG.normal(0, 0.2, 4000), _RNG.normal(0, 0.4, 4000), np.ones(4000)])
DISTRIBUTIONS = [
    an.Beckmann(0.3),
    an.GGX(0.2),
    an.BlinnPhong(20.0),
    an.VonMisesFisher(17.0),
    an.ABC(100.0, 2.0),
    an.AnisotropicBeckmann(0.1, 0.3, 20.0),
    an.AnisotropicGGX(0.3, 0.1, -35.0),
    an.StudentT(0.3, 3.0),
    an.AnisotropicStudentT(0.2, 0.4, 4.0, 30.0),
    an.Empirical(vectors.normalize(_TILTS)),
    an.Empirical(vectors.normalize(_TILTS), isotropic=False),
]
_IDS = [f"{type(d).__name__}-{'iso' if d.isotropic else 'aniso'}" for d in DISTRIBUTIONS]
# (views, half vectors): pairs on both sides of h = n, one view near grazing
_W = vectors.spherical_deg(np.array([0.0, 30.0, 60.0, 85.0]), np.array([0.0, 40.0, 135.0, 250.0]))
_H = vectors.spherical_deg(np.array([5.0, 10.0, 25.0, 40.0]), np.array([10.0, 200.0, 90.0, 300.0]))


def _microsim_subclasses(cls) -> set:
    """Every subclass of ``cls`` defined in microsim, but the stretched family's shared base."""
    out = set()
    for sub in cls.__subclasses__():
        out |= _microsim_subclasses(sub)
        if sub.__module__.startswith("microsim.") and sub is not AnisotropicNDF:
            out.add(sub)
    return out


def test_the_cases_cover_every_distribution_class():
    assert {type(d) for d in DISTRIBUTIONS} == _microsim_subclasses(NDF)


@pytest.mark.parametrize("ndf", DISTRIBUTIONS, ids=_IDS)
def test_every_distribution_answers_the_protocol(ndf):
    assert isinstance(ndf.name, str) and ndf.name
    assert isinstance(ndf.isotropic, bool)
    assert isinstance(ndf.params(), dict)
    d = ndf.D(_H)
    assert d.shape == (4,) and np.all(np.isfinite(d)) and np.all(d >= 0)
    assert np.all(ndf.D(-_H) == 0.0)  # nothing below the horizon
    lam = ndf.smith_lambda(_W)
    assert lam.shape == (4,) and np.all(lam >= 0) and lam[0] == pytest.approx(0.0, abs=1e-9)
    g1 = ndf.G1(_W, _H)
    np.testing.assert_array_equal(g1, np.where(np.sum(_W * _H, -1) > 0, 1 / (1 + lam), 0.0))
    wo = _W[::-1]
    lam_o = ndf.smith_lambda(wo)
    np.testing.assert_allclose(ndf.G2(_W, wo, _H), g1 * ndf.G1(wo, _H), rtol=1e-15)
    ok = (np.sum(_W * _H, -1) > 0) & (np.sum(wo * _H, -1) > 0)
    np.testing.assert_allclose(
        ndf.G2(_W, wo, _H, correlated=True), np.where(ok, 1 / (1 + lam + lam_o), 0.0), rtol=1e-15
    )
    # the visible-normal density integrates to 1 over the facets (projected-area identity)
    h = ndf.sample(_RNG.random(40000), _RNG.random(40000))
    v = np.broadcast_to(_W[1], h.shape)
    # E_pdf[D_v / pdf] = ∫ D_v dm = 1
    ratio = ndf.pdf_visible(h, v) / ndf.pdf(h)
    assert np.mean(ratio) == pytest.approx(1.0, rel=0.05)


@pytest.mark.parametrize("ndf", DISTRIBUTIONS, ids=_IDS)
def test_what_a_distribution_lacks_is_declared(ndf):
    w = _W[:3]
    if ndf.has_visible_sampler:
        m = ndf.sample_visible(w, np.full(3, 0.3), np.full(3, 0.6))
        np.testing.assert_allclose(np.linalg.norm(m, axis=-1), 1.0, rtol=1e-12)
        assert np.all(np.sum(m * w, -1) > 0)
    else:
        with pytest.raises(UsageError, match="has no visible-normal sampler"):
            ndf.sample_visible(w, np.full(3, 0.3), np.full(3, 0.6))
    if ndf.has_closed_smith:
        np.testing.assert_array_equal(ndf.smith_lambda(w, "closed"), ndf.smith_lambda(w))
    else:
        with pytest.raises(UsageError, match="closed-form Smith"):
            ndf.smith_lambda(w, "closed")


@pytest.mark.parametrize(
    "aniso, iso",
    [
        (an.AnisotropicBeckmann(0.3, 0.3, 40.0), an.Beckmann(0.3)),
        (an.AnisotropicGGX(0.2, 0.2), an.GGX(0.2)),
        (an.AnisotropicStudentT(0.2, 0.2, 3.0, 10.0), an.StudentT(0.2, 3.0)),
        (an.StudentT(0.2, 2.0), an.GGX(0.2)),
    ],
)
def test_equal_roughness_makes_the_anisotropic_family_its_isotropic_member(aniso, iso):
    np.testing.assert_allclose(aniso.D(_H), iso.D(_H), rtol=1e-12)
    np.testing.assert_allclose(aniso.D_cos(_H[:, 2]), iso.D_cos(_H[:, 2]), rtol=1e-12)
    np.testing.assert_allclose(aniso.smith_lambda(_W), iso.smith_lambda(_W), rtol=1e-12)
    u = np.array([0.1, 0.5, 0.9])
    np.testing.assert_allclose(aniso.tilt_quantile_rad(u), iso.tilt_quantile_rad(u), rtol=1e-9)


def test_scene_names_are_the_classes_names():
    names = an.scene_distributions()
    assert names == ("beckmann", "ggx", "blinn-phong", "vmf", "abc", "student-t")
    for name in names:
        cls = an.scene_distribution(name)
        assert cls.name == name
        params = {k: min(lo + 0.5, hi) for k, (lo, hi) in cls.scene_params.items()}
        ndf = make_ndf(name, params)
        assert type(ndf) is cls and ndf.name == name and ndf.params() == params
    assert an.scene_distribution("phong") is an.BlinnPhong
    assert an.scene_distribution("von-mises-fisher") is an.VonMisesFisher
    with pytest.raises(UsageError, match="ndf must be one of beckmann, ggx, blinn-phong"):
        an.scene_distribution("cauchy")


def test_no_module_probes_a_distribution():
    probe = re.compile(r"(getattr|hasattr)\([^,)]*(ndf|distribution)\b")
    root = Path(an.__file__).resolve().parents[1]
    found = [
        f"{p.relative_to(root)}:{i}"
        for p in sorted(root.rglob("*.py"))
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
        if probe.search(line)
    ]
    assert found == []
