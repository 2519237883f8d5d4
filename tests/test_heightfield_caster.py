"""The heightfield grid walk (microsim.sim.heightfield_caster) against Embree.

The walk finds the first root of the ray's height above the surface, exactly in float64 on the
float64 heights; Embree intersects the float32 mesh. So both must name the same facet except
for rays within float32 rounding of an edge (ties, bounded at 1e-4 of the rays as in
test_packets.py), and the walk's hit must lie on its facet's plane, inside its footprint and
on the ray to float64 rounding. Rays aimed exactly at grid lines, diagonals and vertices must
never pass through (watertightness).
"""

import numpy as np
import pytest
from support import heightfield_surface, random_heights, vgroove_surface

from microsim import surfaces as sf
from microsim.sim import (
    BLOCK,
    Bins,
    Tracer,
    facet_tables,
    masking_rays,
    paths,
    ray_columns,
    simulate,
    tracer_cache,
)
from microsim.sim.tracer import HIT
from microsim.vectors import spherical_deg

TIES = 1e-4  # allowed fraction of edge/vertex ties


def _rough(seed=4, n=64, sigma=0.03):
    """A 64² heightfield on a unit tile, slopes up to ~1 (rms 0.4)."""
    return heightfield_surface(random_heights(n=n, sigma=sigma, seed=seed), 1 / n)


def _starts(tracer, n, seed):
    rng = np.random.default_rng(seed)
    lx, ly = tracer.tile
    x = rng.uniform(-lx / 2, lx / 2, n)
    y = rng.uniform(-ly / 2, ly / 2, n)
    return [x, y, np.full(n, tracer.zmax + tracer.top_margin)]


def _on_facet(tracer, prim, point, down, starts):
    """Largest plane residual, footprint excess (negative barycentric) and distance from the
    ray of the hits, relative to the tile size."""
    v = tracer.vertices[tracer.faces[prim]]  # (N, 3, 3)
    p = np.stack(point, axis=1)
    n = tracer.normals[prim]
    plane = np.abs(np.einsum("ij,ij->i", p - v[:, 0], n))
    # barycentrics of the footprint (x, y)
    a, b, c = v[:, 0, :2], v[:, 1, :2], v[:, 2, :2]
    q = p[:, :2]

    def cross(u, w):
        return u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]

    area = cross(b - a, c - a)
    bary = np.stack([cross(b - q, c - q), cross(c - q, a - q), cross(a - q, b - q)], 1)
    outside = np.max(-bary / area[:, None], axis=1)
    # the ray, unwrapped: the hit minus whole tiles must lie on start + t·down
    o = np.stack(starts, axis=1)
    rel = p - o
    lx, ly = tracer.tile
    d = np.asarray(down)
    t = -rel[:, 2] / -d[2]
    off = o + t[:, None] * d - p  # a whole number of tiles in x, y; 0 in z
    off[:, 0] -= np.round(off[:, 0] / lx) * lx
    off[:, 1] -= np.round(off[:, 1] / ly) * ly
    scale = max(lx, ly)
    return plane.max() / scale, outside.max(), np.abs(off).max() / scale


@pytest.mark.parametrize("theta", [0.0, 25.0, 55.0, 75.0])
def test_grid_walk_names_embrees_facet_and_hits_it_exactly(theta):
    s = _rough()
    walk, ref = Tracer(s, grid=True), Tracer(s, backend="embreex")
    assert walk.grid is not None and ref.grid is None
    n = 40_000
    x = _starts(walk, n, seed=int(theta))
    for phi in (0.0, 33.0, 90.0, 217.0):
        down = [float(-c) for c in spherical_deg(theta, phi)]
        cast = walk.cast_falling(x, down)
        assert cast is not None
        status, prim, point = cast[0].copy(), cast[1].copy(), [c.copy() for c in cast[2]]
        assert np.all(status == HIT)
        hs, rprim, _ = ref.trace_columns(x, down, np.array([down], dtype=np.float32))
        assert np.all(hs == HIT)
        assert np.sum(prim != rprim) <= TIES * n, (theta, phi)
        plane, outside, off_ray = _on_facet(walk, prim, point, down, x)
        assert plane < 1e-13 and outside < 1e-9 and off_ray < 1e-12, (plane, outside, off_ray)


def test_grid_walk_is_watertight_on_grid_lines_diagonals_and_vertices():
    """Starts exactly above vertices, on cell walls and on diagonals, falling straight down
    and along the grid's axes and diagonals: every ray hits a facet whose footprint holds the
    hit (no ray slips between two triangles)."""
    s = _rough(seed=7, n=32)
    walk = Tracer(s, grid=True)
    c = walk.grid.cell
    k = np.arange(-16, 16)
    gx, gy = np.meshgrid(k * c, k * c)
    lines = [
        (gx.ravel(), gy.ravel()),  # vertices
        ((gx + 0.5 * c).ravel(), gy.ravel()),  # x walls' midpoints
        (gx.ravel(), (gy + 0.25 * c).ravel()),  # y walls
        ((gx + 0.375 * c).ravel(), (gy + 0.375 * c).ravel()),  # diagonals
    ]
    x = [np.concatenate([a for a, _ in lines]), np.concatenate([b for _, b in lines])]
    x.append(np.full(len(x[0]), walk.zmax + walk.top_margin))
    for theta, phi in [(0.0, 0.0), (40.0, 0.0), (40.0, 90.0), (40.0, 45.0), (60.0, 225.0)]:
        down = [float(-c) for c in spherical_deg(theta, phi)]
        if theta == 0.0:
            down = [0.0, 0.0, -1.0]
        status, prim, point = walk.cast_falling(x, down)
        assert np.all(status == HIT)
        _, outside, off_ray = _on_facet(walk, prim.copy(), [p.copy() for p in point], down, x)
        assert outside < 1e-9 and off_ray < 1e-12


def test_grid_is_found_only_for_heightfield_grids():
    s = _rough()
    assert Tracer(s, grid=True).grid is not None
    assert Tracer(sf.gaussian(32, 1.0, 0.5, 8.0, seed=1), grid=True).grid is not None
    with pytest.warns(UserWarning):  # a small tile of a fractal surface: warned, still a grid
        abc = sf.abc(32, 1.0, 0.5, 40.0, 1.5, seed=1)
    assert Tracer(abc, grid=True).grid is not None
    assert Tracer(vgroove_surface([30.0, -40.0]), grid=True).grid is None
    assert Tracer(sf.flat(), grid=True).grid is None
    v = s.vertices.copy()
    v[5, 2] += 1e-9  # no longer the mesh of its heights
    moved = type(s)("gaussian", v, s.faces, s.tile_size, True, {}, heights=s.heights, dx=s.dx)
    assert Tracer(moved, grid=True).grid is None


def test_a_mesh_is_known_as_its_heights_grid_only_when_it_is_exactly_that_grid():
    """``is_heightfield_mesh`` against ``heightfield_mesh`` itself: true for its output
    (square and oblong tiles), false after any one change of a coordinate or a face."""
    from microsim.surfaces.surface import heightfield_mesh, is_heightfield_mesh

    rng = np.random.default_rng(2)
    for shape in ((8, 8), (5, 9)):
        h = rng.normal(size=shape)
        v, f = heightfield_mesh(h, 0.25)
        assert is_heightfield_mesh(h, 0.25, v, f)
        assert not is_heightfield_mesh(h, 0.5, v, f)
        for k in range(3):  # a coordinate moved: the last vertex (a wrapped copy) or one inside
            for row in (len(v) - 1, shape[1] + 2):
                w = v.copy()
                w[row, k] += 1e-12
                assert not is_heightfield_mesh(h, 0.25, w, f), (k, row)
        for row in (0, len(f) - 1):  # a face's corners turned
            g = f.copy()
            g[row] = g[row, [1, 2, 0]]
            assert not is_heightfield_mesh(h, 0.25, v, g)
        assert not is_heightfield_mesh(h, 0.25, v, f[::-1])


def test_the_fused_primary_walk_takes_only_falling_rays_from_above_the_relief():
    s = _rough()
    walk = Tracer(s, grid=True)
    x = _starts(walk, 100, seed=1)
    assert walk.cast_falling(x, [float(-c) for c in spherical_deg(89.0, 10.0)]) is not None
    assert walk.cast_falling(x, [0.0, 0.0, 1.0]) is None  # rising
    low = [x[0], x[1], np.zeros(100)]  # below zmax: not a primary start
    assert walk.cast_falling(low, [0.0, 0.0, -1.0]) is None


def _leaving_rays(tracer, n, seed, below=False):
    """Rays leaving random points of the surface along random directions on one side of
    their facet (above it, or below it for a medium's inside), started ``eps`` off its plane
    as the tracer's secondary rays are: (starts, directions) as columns."""
    rng = np.random.default_rng(seed)
    lx, ly = tracer.tile
    x = np.stack([rng.uniform(-lx / 2, lx / 2, n), rng.uniform(-ly / 2, ly / 2, n)], 1)
    hits = tracer.first_hit(np.c_[x, np.full(n, tracer.zmax + 1.0)], np.array([0.0, 0.0, -1.0]))
    nrm = hits.normal
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    sign = -1.0 if below else 1.0
    d *= np.where(np.sum(d * nrm, axis=1) * sign < 0, -1.0, 1.0)[:, None]
    start = tracer.on_plane(hits.prim, hits.point, sign * tracer.eps)
    return [np.ascontiguousarray(start[:, k]) for k in range(3)], [d[:, k].copy() for k in range(3)]


@pytest.mark.parametrize("below", [False, True])
def test_walk_columns_on_the_grid_is_embrees_walk_from_either_side(below):
    """Secondary rays (masking and bounce rays above the surface, a medium's rays below it)
    through ``Tracer.trace_columns``/``escape_columns``: the grid's answers are Embree's
    status and facet but for ties, the hit on its facet's plane and on the ray."""
    s = _rough(n=48)
    walk, ref = Tracer(s, grid=True), Tracer(s, backend="embreex")
    n = 30_000
    x, d = _leaving_rays(walk, n, seed=11 + below, below=below)
    d32 = np.stack(d, 1).astype(np.float32)
    hs, prim, point = (np.copy(a) if a is not None else a for a in walk.trace_columns(x, d, d32))
    rs, rprim, _ = ref.trace_columns(x, d, d32)
    assert np.sum(hs != rs) <= TIES * n + 1
    both = (hs == HIT) & (rs == HIT)
    assert both.mean() > 0.1 and np.mean(hs == HIT) < 0.9  # hits and escapes both tested
    assert np.sum(prim[both] != rprim[both]) <= TIES * n + 1
    p = np.stack(point, 1)[both]
    nrm, v0 = walk.normals[prim[both]], walk.vertices[walk.faces[prim[both], 0]]
    assert np.abs(np.einsum("ij,ij->i", p - v0, nrm)).max() < 1e-12
    esc = walk.escape_columns(x, d, d32)
    assert np.array_equal(esc, hs)  # occlusion queries: the same statuses


def test_a_heightfield_run_never_builds_the_embree_scene():
    """Primary, masking and bounce rays of opaque and dielectric runs all walk the grid, at
    grazing incidence too; a tracer without the grid builds its scene on its first ray."""
    s = _rough(n=32)
    for options in (dict(), dict(bounces="all"), dict(bounces="all", transmission=True)):
        tracer_cache._REUSED.clear()
        r = simulate(s, 1.5 if options.get("transmission") else "aluminium", [0.0, 80.0],
                     rays=BLOCK, bins=Bins(18, 13), **options)  # fmt: skip
        assert r.meta["surface"]["grid_walk"]
        prepared = tracer_cache.tracer_for(s, "traced", s.fingerprint())
        assert prepared.tracer._scene is None, options
    embree = Tracer(s, grid=False)
    assert embree._scene is None
    top = embree.zmax + embree.top_margin
    hits = embree.first_hit(np.array([[0.1, 0.2, top]]), np.array([[0.0, 0.0, -1.0]]))
    assert embree._scene is not None and hits.prim[0] >= 0


def test_simulate_with_the_grid_walk_equals_embree_and_is_reproducible(monkeypatch):
    """Whole runs with and without the walk: ledgers and bins equal up to edge ties; with
    the walk, bitwise identical for 1/2 threads and chunk sizes."""
    rough = _rough()
    kw = dict(rays=4 * BLOCK + 77, bins=Bins(18, 13), seed=3)
    angles = [0.0, 25.0, 70.0]
    a = simulate(rough, "aluminium", angles, threads=1, chunk=BLOCK, **kw)
    b = simulate(rough, "aluminium", angles, threads=2, chunk=2 * BLOCK, **kw)
    for name in ("sum_w", "sum_w2", "counts", "brdf"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert all(np.array_equal(a.ledger[k], b.ledger[k]) for k in a.ledger)
    monkeypatch.setattr(tracer_cache, "GRID_CASTER", False)
    c = simulate(rough, "aluminium", angles, threads=2, chunk=BLOCK, **kw)
    rays = kw["rays"]
    for k in ("single", "masked", "downward", "unresolved", "missed"):
        assert np.all(np.abs(a.ledger[k] - c.ledger[k]) * rays <= TIES * rays + 1), k
    moved = np.abs(a.counts.astype(np.int64) - c.counts.astype(np.int64)).sum(axis=(1, 2)) / 2
    assert np.all(moved <= TIES * rays + 1)
    assert a.meta["surface"]["grid_walk"] and not c.meta["surface"]["grid_walk"]


@pytest.mark.parametrize("theta, phi", [(0.0, 0.0), (30.0, 0.0), (55.0, 37.0), (70.0, 200.0)])
def test_fused_walk_and_lookups_give_the_bits_of_walk_then_lookups(theta, phi):
    """``primary.cast_tabled_primary`` (grid walk tile by tile, then the facet table's
    look-ups and the masking rays' setup) writes exactly what the walk into whole columns
    followed by ``primary.tabled_primary`` writes: every ledger entry and every masking ray."""
    from microsim.analytic.fresnel import resolve_material
    from microsim.sim.engine import primary, segments

    tracer = Tracer(_rough(seed=7), grid=True)
    wi = spherical_deg(theta, phi)
    table = facet_tables.facet_table(tracer, wi, resolve_material("aluminium"), Bins(18, 12), phi)
    x = _starts(tracer, 3 * 1024 + 17, seed=3)  # several tiles and a short last one
    down = [float(-c) for c in wi]
    assert tracer.grid_walk(x, down) is not None
    fused = ray_columns.tabled_masking_rays(tracer, table, wi, x)
    fused = [a.copy() for a in fused.outcome], _masking_rays(fused.mask, fused.m)
    hs, prim, p = tracer.cast_falling(x, down)
    n = len(x[0])
    out = np.empty(n, np.int8), np.empty(n), np.empty(n, np.int64)
    mask = masking_rays.MaskingRays.work(n)
    m = primary.tabled_primary(
        segments.WalkResult(hs, prim, *p),
        primary.FacetColumns(
            table.code, table.weight, table.facets, table.wo32, table.bin, table.clear,
        ),
        tracer.horizon,
        masking_rays.segment_geometry(tracer),
        primary.PrimaryLedger(*out),
        mask.kernel_args(),
    )  # fmt: skip
    for a, b in zip(fused[0], out):
        np.testing.assert_array_equal(a, b)
    assert m == len(fused[1][0]) and m > 0
    for a, b in zip(fused[1], _masking_rays(mask, m)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("theta, phi, first", [(30.0, 0.0, 3), (55.0, 37.0, 0), (70.0, 200.0, 1)])
def test_origins_drawn_in_the_walks_pass_give_the_bits_of_drawn_columns(theta, phi, first):
    """``ray_columns.drawn_masking_rays`` (a chunk's stratified origins drawn block by block in
    the walk's own pass) writes exactly what ``streams.chunk_origins`` followed by
    ``tabled_masking_rays`` writes, on chunks of whole blocks and on a run's short last block;
    a draw with a start outside the tile is refused (None)."""
    from microsim.analytic.fresnel import resolve_material
    from microsim.sim import streams

    tracer = Tracer(_rough(seed=7), grid=True)
    wi = spherical_deg(theta, phi)
    table = facet_tables.facet_table(tracer, wi, resolve_material("aluminium"), Bins(18, 12), phi)
    rays, key = 5 * BLOCK + 1234, (3, 1, 2)  # the run's last block is short
    blocks = range(first, 6)
    draw = streams.stratified_draw(tracer, rays, blocks, key)
    drawn = ray_columns.drawn_masking_rays(tracer, table, wi, draw)
    drawn = [a.copy() for a in drawn.outcome], _masking_rays(drawn.mask, drawn.m)
    x, _ = streams.chunk_origins(tracer, rays, blocks, key, False)
    cols = ray_columns.tabled_masking_rays(tracer, table, wi, [c.copy() for c in x])
    assert len(drawn[0][0]) == len(x[0]) == rays - first * BLOCK and cols.m > 0
    for a, b in zip(drawn[0], cols.outcome):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(drawn[1], _masking_rays(cols.mask, cols.m)):
        np.testing.assert_array_equal(a, b)
    outside = draw._replace(hx=draw.hx / 2)  # most starts now outside the (shrunk) tile
    assert ray_columns.drawn_masking_rays(tracer, table, wi, outside) is None


def test_the_facet_table_path_gives_the_same_bits_when_it_draws_the_origins_as_columns(
    monkeypatch,
):
    """``paths.FacetTablePath.follow`` traces a chunk from its origin columns where the drawn
    pass declines it (a start outside the tile): the same outcome as the drawn pass."""
    from microsim.analytic.fresnel import resolve_material

    tracer = Tracer(_rough(seed=7), grid=True)
    wi, al = spherical_deg(40.0, 20.0), resolve_material("aluminium")
    bins = Bins(18, 12)
    incidence = paths.Incidence(tracer, wi, 20.0, bins, al, 3 * BLOCK + 7, (1, 0, 0))
    path = paths.FacetTablePath(incidence, facet_tables.facet_table(tracer, wi, al, bins, 20.0))
    drawn = [a.copy() for a in path.follow(range(1, 4))]
    monkeypatch.setattr(paths, "drawn_masking_rays", lambda *a: None)  # declined
    for a, b in zip(drawn, path.follow(range(1, 4))):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("theta, phi", [(0.0, 0.0), (30.0, 0.0), (55.0, 37.0), (70.0, 200.0)])
def test_fused_traced_walk_gives_the_bits_of_walk_then_shading_then_masking_rays(theta, phi):
    """``ray_columns.trace_columns`` on a grid (``primary.cast_traced_primary``: the walk, the
    per-ray classes and mirror directions and the masking rays' walk, tile by tile) returns
    exactly what the walk into whole columns, ``primary.traced_primary``, the masking rays
    walked afterwards, the Fresnel weights and the bins give, ray by ray."""
    from microsim.analytic.fresnel import resolve_material
    from microsim.sim import fresnel_kernels
    from microsim.sim.engine import primary, segments
    from microsim.sim.ray_bins import locate_single

    tracer = Tracer(_rough(seed=7), grid=True)
    wi = spherical_deg(theta, phi)
    bins, ior = Bins(18, 12), resolve_material("aluminium")
    x = _starts(tracer, 3 * 1024 + 17, seed=3)  # several tiles and a short last one
    down = [float(-c) for c in wi]
    assert tracer.grid_walk(x, down) is not None
    fused = [a.copy() for a in ray_columns.trace_columns(tracer, None, wi, phi, bins, x, None, ior)]
    hs, prim, p = tracer.cast_falling(x, down)
    n = len(x[0])
    status, cosine, wo = np.empty(n, np.int8), np.empty(n), [np.empty(n) for _ in range(3)]
    mask = masking_rays.MaskingRays.work(n)
    m = primary.traced_primary(
        segments.WalkResult(hs, prim, *p),
        tuple(np.array([float(c)]) for c in wi),
        tracer.facets,
        True,
        tracer.rise_bound,
        tracer.horizon,
        tracer.groove_clear,
        masking_rays.segment_geometry(tracer),
        primary.TracedLedger(status, cosine, *wo),
        mask.kernel_args(),
    )
    assert m > 0  # some masking rays are walked
    mask.trace(tracer, m, status)
    weight, where = np.empty(n), np.full(n, -1, np.int64)
    mode, n2, k2 = fresnel_kernels.fresnel_mode(ior)
    fresnel_kernels.fresnel_weights(cosine, n2, k2, mode, weight)
    locate_single(bins, status, wo, phi, None, where)
    for a, b in zip(fused, (status, weight, where)):
        np.testing.assert_array_equal(a, b)


DIRECTIONS = [
    (t, p) for t in (20.0, 45.0, 70.0, 85.0) for p in (0.0, 90.0, 180.0, 270.0, 37.0, 225.0)
]


@pytest.mark.parametrize("theta, phi", DIRECTIONS)
def test_cells_surely_stepped_over_give_the_walks_bits(theta, phi):
    """The walk of falling rays from above the relief with the table of cells surely stepped
    over (``steps_over``) gives every output bitwise as without it, on a non-square tile,
    along the axes and off them; and the table skips cells at grazing incidence."""
    from microsim.sim.heightfield_caster import NO_STEPS, cast_falling, steps_over

    h = np.vstack([random_heights(n=48, sigma=0.03, seed=5)] * 2)[:80]  # 80 × 48 cells
    tracer = Tracer(heightfield_surface(h, 1 / 48), grid=True)
    down = [float(-c) for c in spherical_deg(theta, phi)]
    ahead = steps_over(tracer.grid, down, tracer.zmax)
    ahead.flags.writeable = False  # as a kept facet table's: the walk compiled once
    x = _starts(tracer, 4000, seed=int(theta + phi))
    geometry = tracer.grid_walk(x, down)
    outs = []
    for table in (NO_STEPS, ahead):
        out = [np.empty(4000, np.int8), np.empty(4000, np.int32)] + [np.empty(4000) for _ in "xyz"]
        cast_falling(*x, *down, geometry, table, *out)
        outs.append(out)
    for a, b in zip(*outs):
        np.testing.assert_array_equal(a, b)
    if theta >= 70.0:
        assert ahead.mean() > 1.0


def _walk_both_ways(tracer, x, down, ahead, max_wraps=None):
    """``cast_falling``'s outputs for the starts ``x`` one ray at a time and ``LANES`` at a
    time (``HeightfieldGrid.geometry``'s ``lanes``), with ``max_wraps`` (default the
    tracer's)."""
    from microsim.sim.heightfield_caster import cast_falling

    wraps = tracer.max_wraps if max_wraps is None else max_wraps
    n = len(x[0])
    outs = []
    for lanes in (False, True):
        geometry = tracer.grid.geometry(tracer.zmin, tracer.zmax, wraps, lanes=lanes)
        out = [np.empty(n, np.int8), np.empty(n, np.int32)] + [np.empty(n) for _ in "xyz"]
        cast_falling(*x, *down, geometry, ahead, *out)
        outs.append(out)
    return outs


@pytest.mark.parametrize("theta, phi", DIRECTIONS + [(0.0, 0.0), (89.5, 3.0)])
def test_the_walk_in_lanes_gives_the_bits_of_the_walk_ray_by_ray(theta, phi):
    """``cast_lanes`` (rays walked side by side, branches as selects) gives every output
    bitwise as ``cast_one`` ray by ray: random starts and starts exactly above vertices, walls
    and diagonals (ties), on a rough and on a terraced surface (flat facets and level edges,
    where a ray enters a cell on the surface), with and without the cells surely stepped
    over, for ray counts that fill the lanes partly, and with a wrap cap that leaves grazing
    rays UNRESOLVED."""
    from microsim.sim.heightfield_caster import LANES, NO_STEPS, steps_over

    rough = random_heights(n=48, sigma=0.03, seed=5)
    terraced = np.round(random_heights(n=32, sigma=0.05, seed=6) / 0.02) * 0.02
    down = [float(-c) for c in spherical_deg(theta, phi)]
    if theta == 0.0:
        down = [0.0, 0.0, -1.0]
    for h, cell in ((np.vstack([rough] * 2)[:80], 1 / 48), (terraced, 1 / 32)):
        tracer = Tracer(heightfield_surface(h, cell), grid=True)
        ahead = steps_over(tracer.grid, down, tracer.zmax)
        ahead.flags.writeable = False
        x = _starts(tracer, 3000, seed=int(theta + phi))
        k = np.arange(-12, 12) * cell
        gx, gy = (a.ravel() for a in np.meshgrid(k, k))
        ties = [np.concatenate([gx, gx + cell / 2, gx + cell * 3 / 8]),
                np.concatenate([gy, gy, gy + cell * 3 / 8])]  # fmt: skip
        x = [np.concatenate([x[0], ties[0]]), np.concatenate([x[1], ties[1]])]
        x.append(np.full(len(x[0]), tracer.zmax + tracer.top_margin))
        for table in (NO_STEPS, ahead):
            for n in (1, LANES - 1, LANES + 1, len(x[0])):
                per_ray, lanes = _walk_both_ways(tracer, [c[:n] for c in x], down, table)
                for a, b in zip(per_ray, lanes):
                    np.testing.assert_array_equal(a, b)
        if theta > 80.0:  # a cap the grazing rays exceed: UNRESOLVED in both
            per_ray, lanes = _walk_both_ways(tracer, x, down, NO_STEPS, max_wraps=0)
            assert np.any(per_ray[0] != HIT)
            for a, b in zip(per_ray, lanes):
                np.testing.assert_array_equal(a, b)


def test_cells_surely_stepped_over_are_stepped_over_from_anywhere_in_the_cell():
    """``steps_over``'s count, checked against a plain march of the grid walk (exact cell
    sequence by the walls' distances) from random points of each cell at the level zmax: every
    counted cell is left above its highest vertex, and no counted step crosses a tile wall."""
    from microsim.sim.heightfield_caster import steps_over

    tracer = Tracer(_rough(seed=9, n=32), grid=True)
    g = tracer.grid
    rng = np.random.default_rng(2)
    for theta, phi in [(60.0, 0.0), (75.0, 33.0), (80.0, 200.0), (50.0, 270.0)]:
        down = np.array([-c for c in spherical_deg(theta, phi)])
        ahead = steps_over(g, down, tracer.zmax)
        dh = np.hypot(down[0], down[1])
        cot = -down[2] / dh
        for cj, ci in zip(*np.nonzero(ahead)):
            for _ in range(3):
                u, v = ci + rng.random(), cj + rng.random()  # grid units, at zmax
                i, j = ci, cj
                for _ in range(int(ahead[cj, ci])):
                    # distance (grid units, horizontal) to the next x and y walls
                    sx = ((i + (down[0] > 0)) - u) / (down[0] / dh) if down[0] else np.inf
                    sy = ((j + (down[1] > 0)) - v) / (down[1] / dh) if down[1] else np.inf
                    run = min(sx, sy)
                    assert tracer.zmax - run * g.cell * cot > g.cell_max[j, i]
                    if sx <= sy:
                        i += int(np.sign(down[0]))
                    else:
                        j += int(np.sign(down[1]))
                    assert 0 <= i < g.nx and 0 <= j < g.ny
        assert ahead.max() > 0


def _masking_rays(mask, m):
    """Copies of the first m masking rays' arrays (``MaskingRays.kernel_args``)."""
    return [a[:m].copy() for a in mask.kernel_args()]
