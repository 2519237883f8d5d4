"""Argument shapes of the closed forms: directions whose leading shapes do not broadcast are
refused with a UsageError naming every argument and its shape (not NumPy's anonymous message
from deep inside); shapes that broadcast give the values of the elementwise calls."""

import numpy as np
import pytest
from test_model_protocol import _BECK, _LUMPS, CASES, IDS

from microsim import analytic as an
from microsim import vectors
from microsim.errors import UsageError

RNG = np.random.default_rng(7)


def _upper(n):
    return vectors.normalize(np.column_stack([RNG.normal(size=(n, 2)) * 0.5, np.ones(n)]))


# (name, function, argument names) of the closed forms taking several directions besides (wi, wo)
WITH_H = [
    ("vgroove_g", lambda wi, wo, h: an.vgroove_g(wi, wo, h), ("wi", "wo", "h")),
    ("smith_g2", lambda wi, wo, h: an.smith_g2(wi, wo, h, _BECK), ("wi", "wo", "h")),
    ("shadowing_g", lambda wi, wo, h: an.shadowing_g(wi, wo, h, _BECK, "smith"), ("wi", "wo", "h")),
]
PAIRS = [
    ("vgroove_g1", lambda w, h: an.vgroove_g1(w, h), ("w", "h")),
    ("smith_g1", lambda w, h: an.smith_g1(w, h, _BECK), ("w", "h")),
    ("scaling_projection", an.scaling_projection, ("wo", "h")),
    ("orthogonal_projection", an.orthogonal_projection, ("wo", "h")),
    ("disk_jacobian", an.disk_jacobian, ("wi", "wo")),
    ("incident_to_disk", an.incident_to_disk, ("wi", "wo")),
    ("pdf_edwards", lambda wi, wo: an.pdf_edwards(wi, wo, _LUMPS), ("wi", "wo")),
    ("pdf_low_smooth", lambda wi, wo: an.pdf_low_smooth(wi, wo, 100.0), ("wi", "wo")),
    ("pdf_low_microfacet", lambda wi, wo: an.pdf_low_microfacet(wi, wo, 100.0, 1.5), ("wi", "wo")),
    ("pdf_microfacet", lambda wi, wo: an.pdf_microfacet(wi, wo, _BECK), ("wi", "wo")),
]
PAIRS += [(i, fn, ("wi", "wo")) for i, (_, fn) in zip(IDS, CASES)]


def _check_refused(fn, names, shapes):
    args = [_upper(s[0]) for s in shapes]
    with pytest.raises(UsageError) as e:
        fn(*args)
    msg = str(e.value)
    for name, shape in zip(names, shapes):
        assert f"{name} {shape}" in msg, msg


def _check_broadcasts(fn, k):
    """First argument (2, 1, 3), the others (3, 3): the (2, 3) grid of elementwise values."""
    a, others = _upper(2), [_upper(3) for _ in range(k - 1)]
    grid = np.asarray(fn(a[:, None, :], *others))
    for i in range(2):
        for j in range(3):
            one = np.asarray(fn(a[i], *(o[j] for o in others)))
            np.testing.assert_allclose(grid[i, j], one, rtol=1e-12, atol=0)


@pytest.mark.parametrize("name, fn, names", PAIRS, ids=[p[0] for p in PAIRS])
def test_two_directions(name, fn, names):
    _check_refused(fn, names, [(2, 3), (3, 3)])
    _check_broadcasts(fn, 2)


@pytest.mark.parametrize("name, fn, names", WITH_H, ids=[p[0] for p in WITH_H])
def test_three_directions(name, fn, names):
    _check_refused(fn, names, [(3, 3), (3, 3), (2, 3)])
    _check_broadcasts(fn, 3)
