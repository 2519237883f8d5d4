"""Tracer reuse: repeated ``simulate`` calls on one surface build its Embree scene
once; a changed mesh, another masking mode or a released surface never gets a stale tracer, and
reuse changes no result."""

import gc

import numpy as np
from support import heightfield_surface, random_heights

from microsim.sim import Bins, simulate
from microsim.sim.tracer_cache import tracer_for


def _surface(seed=3):
    return heightfield_surface(random_heights(sigma=0.02, seed=seed), 1 / 32)


def test_same_surface_same_tracer_changed_mesh_new_tracer():
    """A surface's mesh is read-only (its fingerprint is computed once); a changed mesh is a
    new surface, which gets a new tracer — also where the arrays are not the surface's own
    (a view), whose fingerprint is then computed on every call."""
    import dataclasses

    import pytest

    s = _surface()
    a = tracer_for(s, "traced", s.fingerprint())
    assert tracer_for(s, "traced", s.fingerprint()) is a
    assert tracer_for(s, "traced") is not a  # no fingerprint: no reuse
    with pytest.raises(ValueError):
        s.vertices[:, 2] *= 1.5
    changed = s.vertices.copy()
    changed[:, 2] *= 1.5
    t = dataclasses.replace(s, vertices=changed)
    b = tracer_for(t, "traced", t.fingerprint())
    assert b is not a and b[0].zmax != a[0].zmax
    shared = np.array(s.vertices)  # writable, and viewed by the surface below
    u = dataclasses.replace(s, vertices=shared[:])
    before = u.fingerprint()
    shared[:, 2] *= 1.5  # through the base the view still sees
    assert u.fingerprint() != before and u.fingerprint() == t.fingerprint()


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


def test_facet_tables_are_kept_per_incidence_read_only_and_bounded():
    """A tracer hands out the same facet table for the same incidence, material, bins and
    azimuth (read-only, so a kept table cannot be altered), builds a new one when any of them
    changes, keeps at most ``TABLES_KEPT``, and a run on kept tables equals a fresh one."""
    import pytest

    from microsim.analytic.fresnel import resolve_material
    from microsim.sim import facet_tables
    from microsim.vectors import spherical_deg

    s = _surface()
    tr = tracer_for(s, "traced", s.fingerprint())[0]
    al, bins = resolve_material("aluminium"), Bins(9, 7)
    a = facet_tables.facet_table(tr, spherical_deg(30.0, 0.0), al, bins, 0.0)
    assert facet_tables.facet_table(tr, spherical_deg(30.0, 0.0), al, bins, 0.0) is a
    with pytest.raises(ValueError):
        a.weight[0] = 1.0
    others = [
        facet_tables.facet_table(tr, spherical_deg(31.0, 0.0), al, bins, 0.0),
        facet_tables.facet_table(
            tr, spherical_deg(30.0, 0.0), resolve_material("methanol"), bins, 0.0
        ),
        facet_tables.facet_table(tr, spherical_deg(30.0, 0.0), al, Bins(9, 9), 0.0),
        facet_tables.facet_table(tr, spherical_deg(30.0, 0.0), al, bins, 10.0),
    ]
    assert all(t is not a for t in others)
    assert len(tr.facet_tables) == facet_tables.TABLES_KEPT
    assert facet_tables.facet_table(tr, spherical_deg(30.0, 0.0), al, bins, 0.0) is not a  # dropped
    kw = dict(rays=20_000, bins=Bins(9, 7), seed=4)
    first, again = simulate(s, "aluminium", 30.0, **kw), simulate(s, "aluminium", 30.0, **kw)
    fresh = simulate(_surface(), "aluminium", 30.0, **kw)
    for r in (again, fresh):
        assert np.array_equal(first.brdf, r.brdf) and np.array_equal(first.stderr, r.stderr)


def test_older_facet_tables_are_kept_only_within_their_byte_budget(monkeypatch):
    """Beside the newest table a tracer keeps older ones only while their arrays add up to
    ``TABLES_KEPT_BYTES``: with room for one, the newest two are kept, and a table asked for
    again after being dropped is built anew (the same values)."""
    from microsim.analytic.fresnel import resolve_material
    from microsim.sim import facet_tables
    from microsim.vectors import spherical_deg

    s = _surface()
    tr = tracer_for(s, "traced", s.fingerprint())[0]
    al, bins = resolve_material("aluminium"), Bins(9, 7)

    def table(theta):
        return facet_tables.facet_table(tr, spherical_deg(theta, 0.0), al, bins, 0.0)

    first = table(10.0)
    arrays = (first.code, first.weight, first.bin, first.wo32, first.clear, first.ahead)
    size = sum(a.nbytes for a in arrays)
    monkeypatch.setattr(facet_tables, "TABLES_KEPT_BYTES", size)  # room for one older table
    for theta in (20.0, 30.0):
        table(theta)
    assert len(tr.facet_tables) == 2  # 30° (the newest) and 20°
    assert table(20.0) is table(20.0)
    again = table(10.0)  # dropped: built anew
    assert again is not first and np.array_equal(again.weight, first.weight)


def test_a_mesh_beyond_the_tabled_size_is_traced_ray_by_ray(monkeypatch):
    """Above ``TABLED_FACETS_MAX`` facets no facet table is built, however many rays: the
    run is traced per ray and agrees with the tabled one (Fresnel weights to rounding)."""
    from microsim.sim import facet_tables

    s = _surface()
    kw = dict(rays=8 * len(s.faces), bins=Bins(9, 7), seed=5, threads=1)
    tabled = simulate(s, "aluminium", 40.0, **kw)
    tr = tracer_for(s, "traced", s.fingerprint())[0]
    assert len(tr.facet_tables) == 1
    monkeypatch.setattr(facet_tables, "TABLED_FACETS_MAX", len(s.faces) - 1)
    tr.facet_tables.clear()
    per_ray = simulate(s, "aluminium", 40.0, **kw)
    assert len(tr.facet_tables) == 0
    assert np.array_equal(per_ray.counts, tabled.counts)
    assert np.allclose(per_ray.brdf, tabled.brdf, rtol=1e-12, atol=0, equal_nan=True)
