"""The model objects of ``analytic.models`` / ``analytic.masking``: each is its wrapped function
bitwise, satisfies the protocol, is frozen and hashable, samples with its own pdf, and is listed
in the catalogue; a model object predicts like the function-based predictors."""

import dataclasses

import numpy as np
import pytest

from microsim import analytic as an
from microsim import vectors
from microsim.analytic import masking as masking_module
from microsim.analytic import models as models_module
from microsim.analytic.catalogue import MODELS
from microsim.bins import Bins
from microsim.errors import UsageError
from microsim.sim.predict import FunctionBRDF, Predictor, predict
from microsim.testing import assert_sampler_matches

_TABLE = an.AlbedoTable(an.Beckmann(0.3), n_theta=10, n_grazing=4)
_GGX = an.GGX(0.3)
_BECK = an.Beckmann(0.25)
_LUMPS = an.empirical_lumps(0.3, 20.0, 3.0)
_EP = an.EdwardsParams(cd=0.1, f0=0.5, k=0.3, r1=0.5, n1=10.0, r2=1.0, n2=1.0)
_KC = an.KullaConty(table=_TABLE)

# (model object, the wrapped function of (wi, wo) it must equal bitwise)
CASES = [
    (an.TorranceSparrow(_GGX), lambda wi, wo: an.torrance_sparrow(wi, wo, _GGX, "vgroove")),
    (
        an.TorranceSparrow(_GGX, an.Smith(), "aluminium"),
        lambda wi, wo: an.torrance_sparrow(wi, wo, _GGX, "smith", "aluminium"),
    ),
    (
        an.TorranceSparrow(_BECK, an.Smith(_BECK, correlated=True), 1.5),
        lambda wi, wo: an.torrance_sparrow(wi, wo, _BECK, "smith-correlated", 1.5),
    ),
    (
        an.TorranceSparrow(_BECK, an.NoMasking()),
        lambda wi, wo: an.torrance_sparrow(wi, wo, _BECK, "none"),
    ),
    (
        an.CookTorrance(_BECK, 1.5, ks=0.8, kd=0.1),
        lambda wi, wo: 0.1 / np.pi + 0.8 * an.torrance_sparrow(wi, wo, _BECK, "vgroove", 1.5),
    ),
    (
        an.LowSmooth(10.0, 100.0, 1.5, 0.01, 1.5, "harvey"),
        lambda wi, wo: an.low_smooth(wi, wo, 10.0, 100.0, 1.5, 0.01, 1.5, "harvey"),
    ),
    (
        an.LowMicrofacet(10.0, 100.0, 1.5, 0.02, "aluminium"),
        lambda wi, wo: an.low_microfacet(wi, wo, 10.0, 100.0, 1.5, 0.02, "aluminium"),
    ),
    (
        an.RayleighRice(0.5, 1e-4, 100.0, 1.5, "aluminium"),
        lambda wi, wo: an.rayleigh_rice(wi, wo, 0.5, 1e-4, 100.0, 1.5, "aluminium"),
    ),
    (
        an.EdwardsEmpirical(_LUMPS, "scaling", 0.3, 0.2),
        lambda wi, wo: an.edwards_empirical(wi, wo, _LUMPS, "scaling", 0.3, 0.2),
    ),
    (an.EdwardsFit(_EP), lambda wi, wo: an.edwards_fit_brdf(wi, wo, _EP, "orthogonal")),
    (
        an.MikkelsenMix(_TABLE, 0.5, 0.9),
        lambda wi, wo: an.mikkelsen_mix(wi, wo, _TABLE, 0.5, 0.9),
    ),
    (
        an.MikkelsenDiffuse(_TABLE, 1.2),
        lambda wi, wo: an.mikkelsen_diffuse(wi, wo, _TABLE, 1.2),
    ),
    (an.KullaContyLobe(_KC), _KC.brdf),
]
IDS = [type(m).__name__ + str(k) for k, (m, _) in enumerate(CASES)]
SAMPLEABLE = [m for m, _ in CASES if isinstance(m, an.SampleableBRDF)]


def _upper(rng, n):
    return vectors.spherical(np.arccos(rng.random(n)), 2 * np.pi * rng.random(n))


def test_every_model_class_is_covered_and_exported():
    classes = {
        v
        for v in vars(models_module).values()
        if isinstance(v, type)
        and issubclass(v, models_module.ModelBase)
        and v is not models_module.ModelBase
        and hasattr(v, "source")
        and dataclasses.is_dataclass(v)
    }
    assert classes == set(models_module.MODEL_CLASSES)
    assert {type(m) for m, _ in CASES} == classes
    assert all(getattr(an, c.__name__) is c for c in classes)


@pytest.mark.parametrize("model, fn", CASES, ids=IDS)
def test_f_is_the_wrapped_function_bitwise(model, fn):
    rng = np.random.default_rng(1)
    wi, wo = _upper(rng, 500), _upper(rng, 500)
    np.testing.assert_array_equal(model.f(wi, wo), fn(wi, wo))
    np.testing.assert_array_equal(model.f(wi[0], wo[0]), fn(wi[0], wo[0]))


@pytest.mark.parametrize("model, fn", CASES, ids=IDS)
def test_protocol_frozen_hashable(model, fn):
    assert isinstance(model, an.BRDFModel)
    assert isinstance(model, an.SampleableBRDF) == hasattr(type(model), "sample")
    assert isinstance(model.source, str) and model.source
    params = model.params()
    assert list(params) == [f.name for f in dataclasses.fields(model)]
    field = dataclasses.fields(model)[0].name
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(model, field, None)
    assert hash(model) == hash(dataclasses.replace(model))
    assert model == dataclasses.replace(model)


def test_models_without_a_sampler_have_no_sample_or_pdf():
    for model in (CASES[7][0], CASES[11][0], CASES[12][0]):
        assert not isinstance(model, an.SampleableBRDF)
        assert not hasattr(model, "sample") and not hasattr(model, "pdf")


@pytest.mark.parametrize("model", SAMPLEABLE, ids=[type(m).__name__ for m in SAMPLEABLE])
def test_sample_pdf_equals_pdf_at_the_drawn_direction(model):
    rng = np.random.default_rng(2)
    n = 4000
    wo = _upper(rng, n)
    wo[:, 2] = np.maximum(wo[:, 2], 0.05)
    wo = vectors.normalize(wo)
    s = model.sample(wo, rng.random(n), rng.random(n))
    assert s._fields[:2] == ("wi", "pdf")
    ok = np.isfinite(s.pdf) & (s.pdf > 0)
    assert ok.mean() > 0.5
    wi = vectors.normalize(s.wi[ok])
    np.testing.assert_allclose(model.pdf(wi, wo[ok]), s.pdf[ok], rtol=1e-9)


@pytest.mark.parametrize(
    "model",
    [an.TorranceSparrow(_GGX, an.Smith(correlated=True)), an.LowMicrofacet(10.0, 50.0, 2.0)],
    ids=["ts-ggx", "low-microfacet"],
)
def test_sampler_matches_pdf_chi2(model):
    wo = vectors.spherical_deg(40.0, 30.0)

    def sample(u1, u2):  # below-horizon draws rejected (NaN): keeps wi = −wo out of the cells
        s = model.sample(np.broadcast_to(wo, (len(u1), 3)), u1, u2)
        wi = vectors.normalize(s.wi)
        return np.where((wi[:, 2] > 0)[:, None], wi, np.nan), s.pdf

    def pdf(w):
        return np.where(w[:, 2] > 0, model.pdf(w, np.broadcast_to(wo, w.shape)), 0.0)

    assert_sampler_matches(sample, pdf, n=100_000, n_tests=2)


def test_torrance_sparrow_masking_forms():
    assert an.TorranceSparrow(_GGX, "smith-correlated") == an.TorranceSparrow(
        _GGX, an.Smith(correlated=True)
    )
    assert an.TorranceSparrow(_GGX).shadowing == "vgroove"
    assert an.TorranceSparrow(_GGX, an.Smith()).masking == an.Smith(_GGX)
    # a Smith of another NDF: G from its Λ, D from the model's (a renderer's stand-in)
    from microsim.vectors import half_vector, spherical_deg

    stand_in = an.TorranceSparrow(_GGX, an.Smith(_BECK))
    own = an.TorranceSparrow(_GGX, an.Smith())
    assert stand_in.masking_ndf == _BECK and own.masking_ndf is None
    wi, wo = spherical_deg(70, 0), spherical_deg(60, 180)
    h = half_vector(wi, wo)
    ratio = stand_in.f(wi, wo) / own.f(wi, wo)
    assert ratio == pytest.approx(an.smith_g2(wi, wo, h, _BECK) / an.smith_g2(wi, wo, h, _GGX))
    with pytest.raises(UsageError, match="masking"):
        an.TorranceSparrow(_GGX, 3)
    with pytest.raises(UsageError):
        an.TorranceSparrow(_GGX, material="unobtainium")
    with pytest.raises(UsageError):
        an.LowSmooth(1.0, -1.0, 1.0)


def test_masking_objects_are_the_shadowing_functions():
    rng = np.random.default_rng(3)
    wi, wo, h = _upper(rng, 300), _upper(rng, 300), _upper(rng, 300)
    eq = np.testing.assert_array_equal
    eq(an.VGroove().g1(wi, h), an.vgroove_g1(wi, h))
    eq(an.VGroove().g2(wi, wo, h), an.vgroove_g(wi, wo, h))
    eq(an.Smith(_GGX).g1(wi, h), an.smith_g1(wi, h, _GGX))
    eq(an.Smith(_GGX, True).g2(wi, wo, h), an.smith_g2(wi, wo, h, _GGX, correlated=True))
    eq(an.NoMasking().g2(wi, wo, h), an.shadowing_g(wi, wo, h, None, "none"))
    eq(an.NoMasking().g1(wi, h), (np.sum(wi * h, -1) > 0).astype(float))
    for m in (an.VGroove(), an.Smith(_GGX), an.NoMasking()):
        assert isinstance(m, an.Masking) and m.kind in an.SHADOWING_KINDS
        eq(m.g2(wi, wo, h), an.shadowing_g(wi, wo, h, _GGX, m.kind))
    with pytest.raises(UsageError, match="needs an ndf"):
        an.Smith().g1(wi, h)


@pytest.mark.parametrize("shadowing", ["vgroove", "smith-correlated"])
def test_ts_model_predicts_bitwise_as_its_function(shadowing):
    bins = Bins(9, 10)
    model = an.TorranceSparrow(_BECK, shadowing, "aluminium")
    spec = Predictor("obj", model)

    def fn(wi, wo):
        return an.torrance_sparrow(wi, wo, _BECK, shadowing, "aluminium")

    ref = Predictor("fn", FunctionBRDF(fn, symmetric=True))
    out = predict([spec, ref], [0.0, 50.0], bins)
    np.testing.assert_array_equal(out["obj"], out["fn"])


def test_other_models_predict_with_f():
    bins = Bins(9, 10)
    model = an.LowMicrofacet(10.0, 50.0, 2.0)
    spec = Predictor("low", model)
    ref = Predictor("ref", FunctionBRDF(model.f, symmetric=True))
    out = predict([spec, ref], [30.0], bins)
    np.testing.assert_array_equal(out["low"], out["ref"])
    with pytest.raises(UsageError, match="BRDFModel"):
        Predictor("x", lambda wi, wo: 1.0)


def test_catalogue_lists_every_model_and_masking_class():
    names = {m.name for m in MODELS}
    for cls in models_module.MODEL_CLASSES + masking_module.MASKING_CLASSES:
        entry = next(m for m in MODELS if m.name == cls.name)
        assert entry.source == cls.source and entry.params == cls.params_doc
        if hasattr(cls, "sample"):
            assert f"{cls.name}.sample" in names
