"""Models are the implementation: ``TorranceSparrow`` and the masking objects compute f and G
themselves and the free functions are thin wrappers over them (bitwise the same numbers); one
place parses a shadowing name; predictions are (model, integration rule) pairs (no ``ModelSpec``);
measured tables answer the model protocol's ``f``."""

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from microsim import analytic as an
from microsim import vectors
from microsim.analytic.protocol import BRDFModel
from microsim.errors import UsageError
from microsim.measured import BRDFTable
from microsim.measured.merl import read_merl, write_merl
from microsim.measured.rgl import RGLResolution, read_rgl, write_rgl
from microsim.sim import Bins
from microsim.sim.predict import (
    Facets,
    FunctionBRDF,
    Predictor,
    bin_average_facets,
    bin_average_ts,
    predict,
)

PACKAGE = Path(an.__file__).resolve().parents[1]
KIND_MESSAGE = "shadowing must be one of"
NDFS = {
    "beckmann": an.Beckmann(0.3),
    "ggx": an.GGX(0.2),
    "anisotropic": an.AnisotropicGGX(0.3, 0.1, 20.0),
    "vmf": an.VonMisesFisher(30.0),
}


def _sources():
    return sorted(PACKAGE.rglob("*.py"))


def _directions(rng, n):
    z = rng.uniform(-0.2, 1.0, n)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=-1)


@pytest.fixture(scope="module")
def directions():
    rng = np.random.default_rng(7)
    wi, wo = _directions(rng, 3000), _directions(rng, 3000)
    h = vectors.normalize(_directions(rng, 3000) * [1.0, 1.0, 0.0] + [0.0, 0.0, 1.2])
    return wi, wo, h


# --- one parser, one V-groove G -------------------------------------------------------------------
def test_the_shadowing_kind_message_is_written_once_in_the_package():
    hits = [p for p in _sources() for _ in re.finditer(KIND_MESSAGE, p.read_text())]
    assert len(hits) == 1, hits
    assert hits[0].name == "masking.py"


@pytest.mark.parametrize(
    "call",
    [
        lambda: an.torrance_sparrow([0, 0, 1], [0, 0, 1], an.Beckmann(0.3), "cook"),
        lambda: an.shadowing_g([0, 0, 1], [0, 0, 1], [0, 0, 1], None, "cook"),
        lambda: an.TorranceSparrow(an.Beckmann(0.3), "cook"),
        lambda: an.AlbedoTable(an.Beckmann(0.3), "cook"),
        lambda: an.masking_from_kind("cook"),
        lambda: bin_average_ts([0, 0, 1], Bins(3, 3), an.Beckmann(0.3), "cook"),
        lambda: bin_average_facets([0, 0, 1], Bins(3, 3), [[0, 0, 1]], shadowing="cook"),
    ],
)
def test_every_entry_point_refuses_an_unknown_kind_with_that_message(call):
    with pytest.raises(UsageError, match=f"{KIND_MESSAGE} 'vgroove', 'smith'"):
        call()


def test_the_vgroove_ratio_is_written_once_in_the_package():
    """2(n·h)(n·w)/(w·h) of Mikkelsen 2009, eq. 25: one expression in the whole package."""
    pattern = re.compile(r"2\.0 \* \w+ \* (?:np\.minimum\([\w, ]*\)|\w+) / \w+")
    hits = [(p.name, m.group(0)) for p in _sources() for m in pattern.finditer(p.read_text())]
    assert hits == [("masking.py", "2.0 * cos_h * cos_w / w_dot_h")], hits


# --- the free functions are wrappers: bitwise the objects' numbers --------------------------------
@pytest.mark.parametrize("ndf", list(NDFS), ids=list(NDFS))
@pytest.mark.parametrize("kind", an.SHADOWING_KINDS)
def test_torrance_sparrow_is_bitwise_the_model(directions, ndf, kind):
    wi, wo, h = directions
    d = NDFS[ndf]
    for material in (None, "aluminium", 1.5):
        model = an.TorranceSparrow(d, an.masking_from_kind(kind), material)
        np.testing.assert_array_equal(
            an.torrance_sparrow(wi, wo, d, kind, material), model.f(wi, wo)
        )
    masking = an.masking_from_kind(kind, d)
    np.testing.assert_array_equal(an.shadowing_g(wi, wo, h, d, kind), masking.g2(wi, wo, h))


def test_the_stand_in_masking_ndf_is_bitwise_the_model(directions):
    wi, wo, _ = directions
    aniso = NDFS["anisotropic"]
    stand_in = aniso.isotropic_equivalent()
    model = an.TorranceSparrow(aniso, an.Smith(stand_in, correlated=True), "aluminium")
    fn = an.torrance_sparrow(wi, wo, aniso, "smith-correlated", "aluminium", masking_ndf=stand_in)
    np.testing.assert_array_equal(fn, model.f(wi, wo))


def test_vgroove_functions_and_cook_torrance_are_bitwise_the_objects(directions):
    wi, wo, h = directions
    np.testing.assert_array_equal(an.vgroove_g(wi, wo, h), an.VGroove().g2(wi, wo, h))
    np.testing.assert_array_equal(an.vgroove_g1(wi, h), an.VGroove().g1(wi, h))
    d = NDFS["beckmann"]
    ct = an.CookTorrance(d, "aluminium", ks=0.7, kd=0.2)
    up = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    ts = an.torrance_sparrow(wi, wo, d, "vgroove", "aluminium")
    np.testing.assert_array_equal(ct.f(wi, wo), np.where(up, 0.2 / np.pi + 0.7 * ts, 0.0))


def _upper(w):
    return np.where(w[:, 2:3] > 0.05, w, np.array([0.0, 0.0, 1.0]))


PAPER_MODELS = [
    (an.LowSmooth(1.0, 20.0, 1.5, 0.1, "aluminium", "harvey"), an.low_smooth),
    (an.LowMicrofacet(1.0, 20.0, 1.5, 0.0, 1.5, "none"), an.low_microfacet),
    (an.RayleighRice(0.5, 1e-3, 100.0, 1.7, 1.5, "ss", B_y=30.0, rotation=20.0), an.rayleigh_rice),
    (an.EdwardsEmpirical(an.Lump(20.0), "scaling", 0.5, 0.2), an.edwards_empirical),
    (an.EdwardsFit(an.EdwardsParams(cd=0.2, n1=30.0, n2=3.0)), an.edwards_fit_brdf),
]


@pytest.mark.parametrize("model, function", PAPER_MODELS, ids=lambda v: type(v).__name__)
def test_the_paper_functions_are_bitwise_their_models(directions, model, function):
    wi, wo, _ = directions
    wo = _upper(wo)
    np.testing.assert_array_equal(function(wi, wo, *model.params().values()), model.f(wi, wo))


# --- (model, rule) replaces ModelSpec -----------------------------------------------------------
def test_model_spec_is_gone():
    users = [p.relative_to(PACKAGE).as_posix() for p in _sources() if "ModelSpec" in p.read_text()]
    assert users == [], users
    import microsim.sim.predict as predict_module

    assert not hasattr(predict_module, "ModelSpec")


def test_a_rule_needs_a_model_that_can_follow_it():
    with pytest.raises(UsageError, match="TorranceSparrow for Facets"):
        Predictor("x", an.LowSmooth(1.0, 10.0, 1.5), Facets([[0.0, 0.0, 1.0]]))
    with pytest.raises(UsageError, match="rule must be"):
        Predictor("x", an.TorranceSparrow(an.Beckmann(0.3)), "quadrature")


# --- measured tables answer f -------------------------------------------------------------------
@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    d = tmp_path_factory.mktemp("tables")
    model = an.TorranceSparrow(an.GGX(0.3), an.Smith(correlated=True), "aluminium")
    write_merl(d / "ggx.binary", model.f)
    write_rgl(
        d / "ggx.bsdf",
        model.f,
        an.GGX(0.3),
        resolution=RGLResolution(theta_i=8, vndf=(16, 16), samples=16, ndf=64),
    )
    table = BRDFTable.from_function(model.f, [0.0, 30.0, 60.0], Bins(9, 7), "ggx")
    return {"table": table, "merl": read_merl(d / "ggx.binary"), "rgl": read_rgl(d / "ggx.bsdf")}


@pytest.mark.parametrize("kind", ["table", "merl", "rgl"])
def test_measured_tables_answer_the_model_protocol(tables, directions, kind):
    t = tables[kind]
    wi, wo, _ = directions
    assert isinstance(t, BRDFModel) and isinstance(t.params(), dict) and t.symmetric
    f = t.f(wi, wo)
    assert f.shape == wi.shape[:-1] and np.all(f >= 0) and np.any(f > 0)
    np.testing.assert_array_equal(f, t.evaluate(wi, wo))
    bins = Bins(6, 5)
    out = predict(
        {"model": t, "function": FunctionBRDF(t.evaluate, symmetric=True)}, [20.0], bins, rtol=1e-2
    )
    np.testing.assert_array_equal(out["model"], out["function"])


# --- microsim.analytic's public names -----------------------------------------------------------
def test_the_documented_analytic_names_resolve_and_the_left_out_helpers_warn():
    root = PACKAGE.parent
    docs = ("README.md", "docs/python.md", "docs/testing.md")
    text = "".join((root / f).read_text() for f in docs)
    used = set(re.findall(r"\ban\.([A-Za-z]\w*)", text))
    for block in re.findall(r"from microsim\.analytic import (\([^)]*\)|[\w ,]+)", text):
        used |= set(re.findall(r"\w+", block))
    assert used and used <= set(an.__all__), used - set(an.__all__)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        assert all(getattr(an, n) is not None for n in an.__all__)
    with pytest.warns(DeprecationWarning, match="microsim.analytic.random_walk"):
        an.WalkNDF
    with pytest.raises(AttributeError):
        an.no_such_name
