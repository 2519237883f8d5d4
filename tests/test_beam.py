"""Masking decided per facet on heightfield grids (``engine.beam``): a facet whose whole beam
of masking rays is cleared never has a ray blocked, and clearing changes no tally."""

import dataclasses

import numpy as np
import pytest

from microsim.analytic.fresnel import resolve_material
from microsim.sim import Bins, Tracer, facet_tables, paths, ray_columns
from microsim.sim.tracer import ESCAPED, HIT
from microsim.surfaces import abc, gaussian
from microsim.vectors import spherical_deg

SURFACES = {
    "gaussian, rms slope 0.35": lambda: gaussian(128, 1.0, 2.0, 8.0, seed=7),
    "ABC fractal": lambda: abc(128, 1.0, 1.0, 10.0, 2.5, seed=3),
}


def _tables(tracer, wi):
    """(facet table with beams cleared, the same table with only the steepness test)."""
    table = facet_tables.facet_table(tracer, wi, resolve_material("aluminium"), Bins(30, 19), 0.0)
    wo = table.wo32.astype(np.float64)
    steep = (table.code == paths.SINGLE) & tracer.surely_escapes(wo[:, 0], wo[:, 1], wo[:, 2])
    steep.flags.writeable = False  # as a kept table's: the kernels compiled once
    return table, dataclasses.replace(table, clear=steep)


def _points_on(tracer, facets, per_facet, rng):
    """``per_facet`` points on each of ``facets``: its three vertices, then uniform points."""
    v = tracer.vertices[tracer.faces[facets]]  # (k, 3, 3)
    w = rng.dirichlet(np.ones(3), (len(facets), per_facet))
    w[:, :3] = np.eye(3)
    return np.einsum("kpa,kad->kpd", w, v).reshape(-1, 3), np.repeat(facets, per_facet)


@pytest.mark.parametrize("name", SURFACES)
@pytest.mark.parametrize("theta", [20.0, 55.0, 80.0])
def test_every_ray_of_a_cleared_beam_escapes_when_traced(name, theta):
    """Rays from the vertices and from random points of the cleared facets (beyond the rise
    bound's steep ones), traced along their mirror direction, all escape; the beam test
    clears most such facets, and among the facets it leaves, rays are blocked (the geometry
    does mask)."""
    tr = Tracer(SURFACES[name](), grid=True)
    wi = spherical_deg(theta, 35.0)
    table, steep = _tables(tr, wi)
    by_beam = table.clear & ~steep.clear
    left = (table.code == paths.SINGLE) & ~table.clear
    assert by_beam.sum() > 0.5 * (by_beam.sum() + left.sum())
    rng = np.random.default_rng(int(theta))
    facets = rng.choice(np.flatnonzero(by_beam), min(4000, by_beam.sum()), replace=False)
    p, f = _points_on(tr, facets, 8, rng)
    status = tr.escapes(p, tr.facets.normals(f), table.wo32[f].astype(np.float64))
    assert np.all(status == ESCAPED)
    others = rng.choice(np.flatnonzero(left), min(4000, left.sum()), replace=False)
    p, f = _points_on(tr, others, 8, rng)
    assert np.any(tr.escapes(p, tr.facets.normals(f), table.wo32[f].astype(np.float64)) == HIT)


@pytest.mark.parametrize("theta", [0.0, 40.0, 75.0])
def test_clearing_beams_changes_no_tally(theta):
    """The tabled trace of the same rays with beams cleared and without is bitwise the same
    (status, weight, bin of every ray), and traces far fewer masking rays."""
    tr = Tracer(SURFACES["gaussian, rms slope 0.35"](), grid=True)
    wi = spherical_deg(theta, 10.0)
    table, steep = _tables(tr, wi)
    rng = np.random.default_rng(5)
    n, (lx, ly) = 200_000, tr.tile
    x = [rng.uniform(-lx / 2, lx / 2, n), rng.uniform(-ly / 2, ly / 2, n)]
    x.append(np.full(n, tr.zmax + tr.top_margin))
    fast = [a.copy() for a in ray_columns.trace_tabled(tr, table, wi, x)]
    slow = [a.copy() for a in ray_columns.trace_tabled(tr, steep, wi, x)]
    for a, b in zip(fast, slow):
        np.testing.assert_array_equal(a, b)
    m_fast = ray_columns.tabled_masking_rays(tr, table, wi, x).m
    m_slow = ray_columns.tabled_masking_rays(tr, steep, wi, x).m
    assert m_fast < 0.5 * m_slow


def test_beams_on_every_heightfield_grid_and_only_there():
    """The beam test needs the mesh to be a heightfield grid, not the grid walk: a tracer that
    casts its primary rays with Embree clears the same beams; the same mesh given as a custom
    surface (not known to be a heightfield) clears none beyond the steepness test."""
    from microsim.surfaces.surface import Surface

    s = SURFACES["gaussian, rms slope 0.35"]()
    wi = spherical_deg(40.0, 0.0)
    walked, _ = _tables(Tracer(s, grid=True), wi)
    embree = Tracer(s)
    assert embree.grid is None and embree.beam is not None
    np.testing.assert_array_equal(_tables(embree, wi)[0].clear, walked.clear)
    custom = Surface(
        kind="custom", vertices=s.vertices, faces=s.faces, tile_size=s.tile_size,
        periodic=True, nominal={},
    )  # fmt: skip
    tr = Tracer(custom)
    assert tr.beam is None
    table, steep = _tables(tr, wi)
    np.testing.assert_array_equal(table.clear, steep.clear)
