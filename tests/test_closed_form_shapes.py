"""Argument shapes of the closed forms: direction arrays and per-direction values whose leading
shapes do not broadcast are refused with a UsageError naming every argument and its shape (not
NumPy's anonymous message from deep inside); shapes that broadcast give the elementwise values."""

import numpy as np
import pytest

from microsim import analytic as an
from microsim import vectors
from microsim.errors import UsageError

_BECK = an.Beckmann(0.25)
_GGX = an.GGX(0.3)
_LUMPS = an.empirical_lumps(0.3, 20.0, 3.0)
_LUMP = _LUMPS.lumps[0]
_EP = an.EdwardsParams(cd=0.1, f0=0.5, k=0.3, r1=0.5, n1=10.0, r2=1.0, n2=1.0)
_TABLE = an.AlbedoTable(an.Beckmann(0.3), n_theta=10, n_grazing=4)
_KC = an.KullaConty(table=_TABLE)
_EMP = an.Empirical(
    vectors.normalize(
        np.column_stack(
            [np.random.default_rng(3).normal(size=(4000, 2)) * [0.2, 0.4], np.ones(4000)]
        )
    ),
    isotropic=False,
)

# kinds of argument: "d" unit direction (..., 3), "uv" disk point (..., 2), "u" number in [0, 1)
# (name, function, ((argument name, kind), ...)); the arrays are the leading arguments
CASES = [
    # shadowing.py
    ("vgroove_g1", an.vgroove_g1, (("w", "d"), ("h", "d"))),
    ("vgroove_g", an.vgroove_g, (("wi", "d"), ("wo", "d"), ("h", "d"))),
    ("smith_g1", lambda w, h: an.smith_g1(w, h, _BECK), (("w", "d"), ("h", "d"))),
    (
        "smith_g2",
        lambda wi, wo, h: an.smith_g2(wi, wo, h, _BECK),
        (("wi", "d"), ("wo", "d"), ("h", "d")),
    ),
    (
        "shadowing_g",
        lambda wi, wo, h: an.shadowing_g(wi, wo, h, _BECK, "smith-correlated"),
        (("wi", "d"), ("wo", "d"), ("h", "d")),
    ),
    # edwards.py
    ("reflect_halfway", an.reflect_halfway, (("wo", "d"), ("h", "d"))),
    ("scaling_projection", an.scaling_projection, (("wo", "d"), ("h", "d"))),
    ("scaling_projection_inverse", an.scaling_projection_inverse, (("wo", "d"), ("uv", "uv"))),
    ("scaling_jacobian", an.scaling_jacobian, (("wi", "d"), ("wo", "d"))),
    ("orthogonal_projection", an.orthogonal_projection, (("wo", "d"), ("h", "d"))),
    (
        "orthogonal_projection_inverse",
        an.orthogonal_projection_inverse,
        (("wo", "d"), ("uv", "uv")),
    ),
    ("orthogonal_jacobian", an.orthogonal_jacobian, (("wi", "d"), ("wo", "d"))),
    ("disk_projection", an.disk_projection, (("wo", "d"), ("h", "d"))),
    ("disk_projection_inverse", an.disk_projection_inverse, (("wo", "d"), ("uv", "uv"))),
    ("disk_jacobian", an.disk_jacobian, (("wi", "d"), ("wo", "d"))),
    ("incident_to_disk", an.incident_to_disk, (("wi", "d"), ("wo", "d"))),
    ("disk_to_incident", an.disk_to_incident, (("wo", "d"), ("uv", "uv"))),
    ("Lump.pdf", _LUMP.pdf, (("wo", "d"), ("uv", "uv"))),
    ("Lump.sample", _LUMP.sample, (("wo", "d"), ("u1", "u"), ("u2", "u"))),
    ("LumpMixture.pdf", _LUMPS.pdf, (("wo", "d"), ("uv", "uv"))),
    ("LumpMixture.sample", _LUMPS.sample, (("wo", "d"), ("u1", "u"), ("u2", "u"))),
    (
        "edwards_empirical",
        lambda wi, wo: an.edwards_empirical(wi, wo, _LUMPS, "scaling", 0.3, 0.2),
        (("wi", "d"), ("wo", "d")),
    ),
    (
        "brdf_to_disk_density",
        an.brdf_to_disk_density,
        (("wi", "d"), ("wo", "d"), ("rho", "u")),
    ),
    (
        "edwards_fit_brdf",
        lambda wi, wo: an.edwards_fit_brdf(wi, wo, _EP),
        (("wi", "d"), ("wo", "d")),
    ),
    ("pdf_edwards", lambda wi, wo: an.pdf_edwards(wi, wo, _LUMPS), (("wi", "d"), ("wo", "d"))),
    (
        "sample_edwards",
        lambda wo, u1, u2: an.sample_edwards(wo, u1, u2, _LUMPS),
        (("wo", "d"), ("u1", "u"), ("u2", "u")),
    ),
    # low.py
    (
        "rayleigh_rice",
        lambda wi, wo: an.rayleigh_rice(wi, wo, 0.5, 1e-4, 100.0, 1.5, "aluminium"),
        (("wi", "d"), ("wo", "d")),
    ),
    (
        "low_smooth",
        lambda wi, wo: an.low_smooth(wi, wo, 10.0, 100.0, 1.5, 0.01, 1.5, "harvey"),
        (("wi", "d"), ("wo", "d")),
    ),
    (
        "low_microfacet",
        lambda wi, wo: an.low_microfacet(wi, wo, 10.0, 100.0, 1.5, 0.02, "aluminium"),
        (("wi", "d"), ("wo", "d")),
    ),
    ("pdf_low_smooth", lambda wi, wo: an.pdf_low_smooth(wi, wo, 100.0), (("wi", "d"), ("wo", "d"))),
    (
        "sample_low_smooth",
        lambda wo, u1, u2: an.sample_low_smooth(wo, u1, u2, 100.0),
        (("wo", "d"), ("u1", "u"), ("u2", "u")),
    ),
    (
        "pdf_low_microfacet",
        lambda wi, wo: an.pdf_low_microfacet(wi, wo, 100.0, 1.5),
        (("wi", "d"), ("wo", "d")),
    ),
    (
        "sample_low_microfacet",
        lambda wo, u1, u2: an.sample_low_microfacet(wo, u1, u2, 100.0, 1.5),
        (("wo", "d"), ("u1", "u"), ("u2", "u")),
    ),
    # brdf.py
    (
        "torrance_sparrow",
        lambda wi, wo: an.torrance_sparrow(wi, wo, _GGX, "smith", "aluminium"),
        (("wi", "d"), ("wo", "d")),
    ),
    ("pdf_microfacet", lambda wi, wo: an.pdf_microfacet(wi, wo, _BECK), (("wi", "d"), ("wo", "d"))),
    (
        "sample_microfacet",
        lambda wo, u1, u2: an.sample_microfacet(wo, u1, u2, _BECK),
        (("wo", "d"), ("u1", "u"), ("u2", "u")),
    ),
    (
        "mikkelsen_mix",
        lambda wi, wo: an.mikkelsen_mix(wi, wo, _TABLE, 0.5, 0.9),
        (("wi", "d"), ("wo", "d")),
    ),
    # energy_compensation.py
    ("KullaConty.brdf", _KC.brdf, (("wi", "d"), ("wo", "d"))),
    (
        "mikkelsen_diffuse",
        lambda wi, wo: an.mikkelsen_diffuse(wi, wo, _TABLE, 1.2),
        (("wi", "d"), ("wo", "d")),
    ),
    # ndf.py, empirical.py
    ("NDF.sample", _BECK.sample, (("u1", "u"), ("u2", "u"))),
    ("Empirical.sample", _EMP.sample, (("u1", "u"), ("u2", "u"))),
]

# random_walk.sample_visible_normals takes v (N, 3) and u1, u2 (N,) exactly (no broadcasting)
STRICT = [
    (
        "sample_visible_normals",
        lambda v, u1, u2: an.sample_visible_normals(v, _BECK, u1, u2),
        (("v", "d"), ("u1", "u"), ("u2", "u")),
    ),
]


def _arg(kind, lead, rng):
    if kind == "d":  # upper hemisphere, within ~20° of the normal (on every halfway disk)
        xy = rng.normal(size=lead + (2,)) * 0.2
        return vectors.normalize(np.concatenate([xy, np.ones(lead + (1,))], axis=-1))
    if kind == "uv":
        return rng.normal(size=lead + (2,)) * 0.1
    return rng.uniform(0.05, 0.95, size=lead)


def _args(args, leads, seed=0):
    rng = np.random.default_rng(seed)
    return [_arg(kind, lead, rng) for (_, kind), lead in zip(args, leads)]


def _arrays(out):
    return [np.asarray(a, dtype=float) for a in (out if isinstance(out, tuple) else (out,))]


def _check_refused(fn, args, word="broadcast"):
    """The last argument (2,) against the others (3,): the message names every argument."""
    leads = [(3,)] * (len(args) - 1) + [(2,)]
    values = _args(args, leads)
    with pytest.raises(UsageError) as e:
        fn(*values)
    msg = str(e.value)
    assert word in msg, msg
    for (name, _), v in zip(args, values):
        assert f"{name} {np.shape(v)}" in msg, msg


@pytest.mark.parametrize("name, fn, args", CASES, ids=[c[0] for c in CASES])
def test_mismatched_shapes_are_refused(name, fn, args):
    _check_refused(fn, args)
    # the first argument mismatched too (e.g. wi (2, 3) against wo (3, 3))
    if len(args) == 2:
        values = _args(args, [(2,), (3,)])
        with pytest.raises(UsageError) as e:
            fn(*values)
        for (name, _), v in zip(args, values):
            assert f"{name} {np.shape(v)}" in str(e.value), str(e.value)


@pytest.mark.parametrize("name, fn, args", CASES, ids=[c[0] for c in CASES])
def test_broadcast_shapes_give_elementwise_values(name, fn, args):
    """First argument (2, 1, ...), the others (3, ...): the (2, 3) grid of elementwise values."""
    values = _args(args, [(2, 1)] + [(3,)] * (len(args) - 1), seed=1)
    grid = _arrays(fn(*values))
    for i in range(2):
        for j in range(3):
            one = _arrays(fn(values[0][i, 0], *(v[j] for v in values[1:])))
            assert len(one) == len(grid)
            for g, o in zip(grid, one):
                assert g.shape[:2] == (2, 3)
                np.testing.assert_allclose(g[i, j], o, rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("name, fn, args", STRICT, ids=[c[0] for c in STRICT])
def test_strict_shapes(name, fn, args):
    _check_refused(fn, args, word="must have shapes")
    values = _args(args, [(3,)] * len(args), seed=1)
    rows = np.asarray(fn(*values))
    for j in range(3):
        one = np.asarray(fn(*(v[j : j + 1] for v in values)))
        np.testing.assert_allclose(rows[j], one[0], rtol=1e-12, atol=1e-300)
