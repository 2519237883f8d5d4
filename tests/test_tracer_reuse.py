"""Tracer reuse: repeated ``simulate`` calls on one surface build its Embree scene
once; a changed mesh, another masking mode or a released surface never gets a stale tracer, and
reuse changes no result."""

import gc

import numpy as np
from support import heightfield_surface, random_heights

from microsim.sim import Bins, simulate
from microsim.sim.paths import tracer_for


def _surface(seed=3):
    return heightfield_surface(random_heights(sigma=0.02, seed=seed), 1 / 32)


def test_same_surface_same_tracer_changed_mesh_new_tracer():
    s = _surface()
    a = tracer_for(s, "traced", s.fingerprint())
    assert tracer_for(s, "traced", s.fingerprint()) is a
    assert tracer_for(s, "traced") is not a  # no fingerprint: no reuse
    s.vertices[:, 2] *= 1.5  # mutated in place: another mesh
    b = tracer_for(s, "traced", s.fingerprint())
    assert b is not a and b[0].zmax != a[0].zmax


def test_reuse_is_released_with_the_surface():
    s = _surface()
    tracer = tracer_for(s, "traced", s.fingerprint())[0]
    import weakref

    ref = weakref.ref(tracer)
    del s, tracer
    gc.collect()
    _surface(4)  # other work
    assert ref() is None


def test_reused_tracer_gives_bitwise_the_same_result():
    s = _surface()
    kw = dict(rays=20_000, bins=Bins(10, 7), seed=2)
    first = simulate(s, "aluminium", [20.0, 70.0], **kw)
    again = simulate(s, "aluminium", [20.0, 70.0], **kw)  # reused tracer
    fresh = simulate(_surface(), "aluminium", [20.0, 70.0], **kw)  # same mesh, new object
    for other in (again, fresh):
        for name in ("brdf", "stderr", "counts", "sum_w", "sum_w2"):
            assert np.array_equal(getattr(first, name), getattr(other, name), equal_nan=True)
