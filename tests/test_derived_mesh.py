"""Heightfields that store no mesh: the generators' surfaces keep only their heights; their
mesh, fingerprint and tracer are those of the same heights with the mesh stored, bit for
bit, and a run on them holds no more than the issue's 64 bytes per grid point."""

import dataclasses
import tracemalloc

import numpy as np
import pytest

from microsim import surfaces
from microsim.errors import UsageError
from microsim.sim import Bins, simulate
from microsim.sim.tracer import Tracer
from microsim.surfaces import surface as surface_module
from microsim.surfaces.surface import Surface, heightfield_mesh


def _pair(shape=(33, 17), dx=0.05, seed=4):
    """The same periodic heights as a surface that stores no mesh and as one that does."""
    h = np.random.default_rng(seed).normal(0.0, 0.02, shape)
    ny, nx = shape
    tile = (nx * dx, ny * dx)
    derived = Surface("gaussian", None, None, tile, True, {}, heights=h, dx=dx)
    stored = Surface("gaussian", *heightfield_mesh(h, dx), tile, True, {}, heights=h, dx=dx)
    return derived, stored


def test_a_derived_mesh_is_the_stored_one_and_so_is_its_fingerprint(monkeypatch):
    """Vertices, faces, facet count, z range and fingerprint (hashed in blocks that do not
    split the grid's rows evenly) equal those of the stored mesh; the derived arrays are
    read-only and not kept; ``replaced`` keeps the mesh derived."""
    derived, stored = _pair()
    assert derived.stores_mesh is False and stored.stores_mesh is True
    assert np.array_equal(derived.vertices, stored.vertices)
    assert np.array_equal(derived.faces, stored.faces) and derived.faces.dtype == np.int32
    assert derived.vertices is not derived.vertices  # derived on each access
    with pytest.raises(ValueError):
        derived.vertices[0, 2] = 1.0
    assert derived.facet_count == stored.facet_count == len(stored.faces)
    assert derived.z_range == stored.z_range
    monkeypatch.setattr(surface_module, "FINGERPRINT_ROWS", 7 * 18 + 5)
    assert derived.fingerprint() == stored.fingerprint()
    assert derived.replaced(warnings=("w",)).stores_mesh is False
    assert dataclasses.replace(derived, warnings=("w",)).stores_mesh is True  # read, stored


def test_the_generators_store_no_mesh_and_a_surface_needs_one_or_heights():
    g = surfaces.gaussian(32, 1.0, 1.0, 8.0, seed=2)
    assert g.stores_mesh is False and g.heights.flags.writeable is False
    with pytest.raises(UsageError, match="vertices and faces"):
        Surface("gaussian", None, None, (1.0, 1.0), True, {})


def test_a_tracer_of_the_heights_alone_is_the_tracer_of_the_mesh():
    """Facets, bounds, horizon grid, eps and wrap cap are the same bits; so is a run, through
    the facet table and ray by ray, one bounce and all; and a tile that does not match its
    heights is refused."""
    derived, stored = _pair()
    a, b = Tracer(derived, grid=True), Tracer(stored, grid=True)
    assert (a.eps, a.zmin, a.zmax, a.max_wraps, a.rise_bound) == (
        b.eps,
        b.zmin,
        b.zmax,
        b.max_wraps,
        b.rise_bound,
    )
    assert np.array_equal(a.normals, b.normals)
    assert np.array_equal(a.horizon.cmax, b.horizon.cmax)
    assert np.array_equal(a.horizon.cslope, b.horizon.cslope)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    for rays, bounces in ((2**13, 1), (2**8, 1), (2**10, "all")):
        runs = [
            simulate(s, "aluminium", [30.0, 75.0], rays=rays, bins=Bins(9, 6), bounces=bounces)
            for s in (derived, stored)
        ]
        assert np.array_equal(runs[0].brdf, runs[1].brdf)
        assert np.array_equal(runs[0].stderr, runs[1].stderr)
    bad = dataclasses.replace(derived, tile_size=(1.0, 1.0), vertices=None, faces=None)
    with pytest.raises(UsageError, match="tile_size"):
        Tracer(bad)


def test_a_run_on_a_heightfield_holds_at_most_64_bytes_per_grid_point():
    """The memory target for measured-scan sizes: the tracer's set-up and a run ray by ray
    (fewer rays than facets: no facet table) allocate, besides the heights the surface
    already holds (8 bytes per point), at most 56 bytes per grid point at their peak (NumPy's
    allocations, as tracemalloc sees them)."""
    n = 1024
    s = surfaces.gaussian(n, 1.0, 1.2, 8.0, seed=1)
    simulate(surfaces.gaussian(64, 1.0, 1.2, 8.0, seed=1), "aluminium", 30.0, rays=2**12)
    tracemalloc.start()
    try:
        simulate(s, "aluminium", 30.0, rays=2**16, threads=1)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak <= 56 * n * n, f"{peak / n / n:.1f} bytes per grid point"
