"""Periodic Embree tracing (microsim.sim.tracer): exact periodic repetition, flat-mirror
energy, exact V-groove masking against traced masking, input validation.

Test geometry is built here with plain numpy (``Surface`` only as the container), so these
tests do not depend on the surface generators.
"""

import numpy as np
import pytest
from support import heightfield_surface, random_heights, vgroove_surface

from microsim.analytic.fresnel import fresnel, resolve_material
from microsim.sim import Bins, Tracer, VGrooveProfile, ray_events, simulate
from microsim.sim.tracer import ESCAPED, HIT, MISSED, UNRESOLVED
from microsim.surfaces.surface import Surface, flat, heightfield_mesh
from microsim.vectors import spherical_deg


# --- test geometry -------------------------------------------------------------------------
# --- periodic walk ---------------------------------------------------------------------------
def _grazing_rays(n, theta_lo, theta_hi, seed, z0):
    rng = np.random.default_rng(seed)
    th = rng.uniform(theta_lo, theta_hi, n)
    ph = rng.uniform(0, 360, n)
    o = np.stack([rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n), np.full(n, z0)], 1)
    return o, spherical_deg(th, ph)


def test_periodic_walk_matches_a_3x3_replicated_mesh():
    """Hits on the wrapped unit tile equal hits on an explicit 3×3 copy (modulo the period)."""
    h = random_heights(sigma=0.012, seed=3)  # height range < 0.1: at 85° a ray crosses < 1 tile
    small = Tracer(heightfield_surface(h, 1 / 64))
    big = Tracer(
        Surface("gaussian", *heightfield_mesh(np.tile(h, (3, 3)), 1 / 64), (3.0, 3.0), False, {})
    )
    o, d = _grazing_rays(20_000, 60, 88, 1, small.zmax + small.top_margin)
    a, b = small.first_hit(o, -d), big.first_hit(o, -d)
    assert np.all(a.status == HIT) and np.all(b.status == HIT)
    delta = a.point - b.point
    delta[:, :2] -= np.round(delta[:, :2])  # equal modulo the unit period
    assert np.max(np.abs(delta)) < 1e-5
    # secondary rays from those hits, upwards 50°–85° from +z: same fate on both meshes
    small.eps = big.eps  # one offset for both (valid for both)
    rng = np.random.default_rng(2)
    up = spherical_deg(rng.uniform(50, 85, len(o)), rng.uniform(0, 360, len(o)))
    ea = small.escapes(a.point, a.normal, up)
    eb = big.escapes(b.point, b.normal, up)
    assert set(np.unique(ea)) <= {ESCAPED, HIT}
    blocked = np.mean(ea == HIT)
    assert 0.02 < blocked < 0.98  # the comparison is not vacuous
    # decisions may differ only for rays grazing the surface within float32 rounding
    assert np.sum(ea != eb) <= 1e-3 * len(o)


def test_no_unresolved_or_missed_rays_below_85_degrees():
    h = random_heights(sigma=0.03, seed=5)  # height range ~ 0.2 tile: many wraps at 85°
    tr = Tracer(heightfield_surface(h, 1 / 64))
    o, d = _grazing_rays(20_000, 0, 85, 7, tr.zmax + tr.top_margin)
    hits = tr.first_hit(o, -d)
    assert np.all(hits.status == HIT)
    up = d * np.array([1, 1, 1])
    esc = tr.escapes(hits.point, hits.normal, up)
    assert not np.any((esc == UNRESOLVED) | (esc == MISSED))


def test_wrap_cap_covers_89_5_degrees():
    """max_wraps is derived from the geometry: a ray at 89.5° crosses the height range."""
    h = random_heights(sigma=0.03, seed=5)
    tr = Tracer(heightfield_surface(h, 1 / 64))
    need = (tr.zmax - tr.zmin) * np.tan(np.radians(89.5)) * 2
    assert tr.max_wraps >= need
    o, d = _grazing_rays(4000, 89.0, 89.5, 9, tr.zmax + tr.top_margin)
    assert np.all(tr.first_hit(o, -d).status == HIT)


# --- flat mirror ------------------------------------------------------------------------------
@pytest.mark.parametrize("material", ["aluminium", "methanol"])
def test_flat_mirror_puts_fresnel_energy_in_the_specular_bin(material):
    bins = Bins(n_theta=45, n_phi=37)  # 2° bins: odd θ lie at bin centres
    theta = np.array([0.0, 31.0, 61.0, 81.0, 89.0])
    res = simulate(flat(), material, theta, phi_i=17.0, rays=5000, bins=bins, seed=4)
    omega = bins.projected_solid_angle()
    F = fresnel(np.cos(np.radians(theta)), resolve_material(material))
    for i, t in enumerate(theta):
        mirror = spherical_deg(t, 17.0 + 180.0)
        k = bins.locate(mirror, 17.0)
        energy = res.brdf[i] * omega
        # at normal incidence Δφ is undefined: the whole first θo ring is the mirror bin
        in_mirror_bin = energy[0].sum() if t == 0 else energy.ravel()[k]
        assert in_mirror_bin == pytest.approx(F[i], rel=1e-6)
        assert np.sum(energy) == pytest.approx(F[i], rel=1e-6)  # nothing anywhere else
        assert res.ledger["single"][i] == 1.0
        assert res.ledger["single_fresnel"][i] == pytest.approx(F[i], rel=1e-12)


# --- exact V-groove masking --------------------------------------------------------------------
def test_exact_and_traced_masking_agree_ray_by_ray():
    """Same primary rays, two masking tests: decisions differ only where the exact margin is
    within the traced ray's start offset: eps along the normal moves the point where the
    reflected ray crosses z = 0 by ≲ eps·(1 + tan θo) (a few eps allowed for float32 rounding)."""
    rng = np.random.default_rng(11)
    s = vgroove_surface(np.degrees(np.arctan(rng.uniform(0.05, 1.5, 64))))
    eps = Tracer(s).eps
    for th in (30.0, 60.0, 80.0, 89.0):
        a = ray_events(s, None, th, rays=100_000, seed=2, masking="traced")
        b = ray_events(s, None, th, rays=100_000, seed=2, masking="exact")
        differ = a.status != b.status
        assert np.sum(b.status == 1) > 100  # some rays are masked
        tan_o = np.hypot(b.wo[differ, 0], b.wo[differ, 1]) / b.wo[differ, 2]
        assert np.all(np.abs(b.margin[differ]) < 4 * eps * (1 + tan_o))
        assert differ.sum() <= 1e-4 * len(differ) + 2


def test_exact_masking_rejects_non_groove_surfaces():
    with pytest.raises(ValueError, match="masking"):
        simulate(heightfield_surface(random_heights(), 1 / 64), None, 30, rays=10, masking="exact")
    with pytest.raises(ValueError, match="rim"):
        VGrooveProfile(Tracer(heightfield_surface(random_heights(), 1 / 64)))


# --- validation -------------------------------------------------------------------------------
def test_bad_meshes_raise():
    good = vgroove_surface([30.0] * 4)
    bad_v = good.vertices.copy()
    bad_v[3, 2] = np.nan
    with pytest.raises(ValueError, match="vertices"):
        Tracer(Surface("vgrooves", bad_v, good.faces, (1.0, 1.0), True, {}))
    with pytest.raises(ValueError, match="faces"):
        Tracer(Surface("vgrooves", good.vertices, np.zeros((0, 3), np.int32), (1.0, 1.0), True, {}))
    with pytest.raises(ValueError, match="faces"):
        Tracer(Surface("vgrooves", good.vertices, good.faces + 1000, (1.0, 1.0), True, {}))
    with pytest.raises(ValueError, match="tile"):
        Tracer(Surface("vgrooves", good.vertices, good.faces, (0.5, 0.5), True, {}))
    with pytest.raises(ValueError, match="faces.*up"):
        Tracer(Surface("vgrooves", good.vertices, good.faces[:, ::-1].copy(), (1.0, 1.0), True, {}))


@pytest.mark.parametrize("parts", [2, 3])
def test_the_set_up_in_parts_is_the_set_up_in_one(monkeypatch, parts):
    """Facet normals and plane offsets of a mesh, and the bounds built from a heightfield's
    facet slopes, are the same bits computed in facet ranges on several threads
    (``schedule.in_parts``) as in one pass; a degenerate or downward facet in any range is
    still refused."""
    from microsim.sim import schedule

    s = heightfield_surface(random_heights(sigma=0.02, seed=7), 1 / 64)
    mesh = Surface("gaussian", s.vertices, s.faces, s.tile_size, True, {})  # stored facets
    one, one_mesh = Tracer(s), Tracer(mesh)
    monkeypatch.setattr(schedule, "PART_ITEMS", 1000)
    monkeypatch.setattr(schedule.os, "cpu_count", lambda: parts)
    many, many_mesh = Tracer(s), Tracer(mesh)
    assert many_mesh.facets.stored and np.array_equal(many_mesh.normals, one_mesh.normals)
    assert np.array_equal(many_mesh.facets.plane, one_mesh.facets.plane)
    assert many.rise_bound == one.rise_bound
    assert np.array_equal(many.horizon.cslope, one.horizon.cslope)
    assert np.array_equal(many.horizon.cmax, one.horizon.cmax)
    flipped = s.faces.copy()
    flipped[-1] = flipped[-1, ::-1]  # in the last range
    with pytest.raises(ValueError, match="faces.*up"):
        Tracer(Surface("gaussian", s.vertices, flipped, s.tile_size, True, {}))


@pytest.mark.parametrize("shape", [(48, 64), (33, 17)])
def test_facets_derived_from_the_heights_are_the_stored_bits(shape):
    """On a heightfield grid the tracer keeps no per-facet normals or planes: derived from the
    heights where they are read (``engine.facets``), they are bit for bit those computed from
    the mesh (the same surface as a custom mesh), in odd and non-square grids; the kernels'
    reader ``facet_plane`` gives the same, and a grid tracer stores nothing per facet."""
    from microsim.sim.engine.facets import fill_normals

    s = heightfield_surface(np.random.default_rng(11).normal(0.0, 0.01, shape), 1 / 48)
    grid, mesh = Tracer(s), Tracer(Surface("gaussian", s.vertices, s.faces, s.tile_size, True, {}))
    assert not grid.facets.stored and mesh.facets.stored
    assert grid.facets.count == mesh.facets.count == len(s.faces)
    every = np.arange(len(s.faces))
    assert np.array_equal(grid.normals, mesh.normals)
    assert np.array_equal(grid.facets.planes(every), mesh.facets.plane)
    cols, plane = np.empty((3, len(every))), np.empty(len(every))
    fill_normals(grid.facets, every[::-1].copy(), cols, plane)
    assert np.array_equal(cols.T, mesh.normals[::-1])
    assert np.array_equal(plane, mesh.facets.plane[::-1])
    some = np.random.default_rng(2).integers(0, len(every), 500)
    assert np.array_equal(grid.facets.normals(some), mesh.normals[some])
    assert sum(a.nbytes for a in grid.facets[:4]) == 0


# --- masking rays decided without tracing (Tracer.rise_bound) ----------------------------------
def test_rise_bound_is_the_steepest_facet_slope_of_heightfields_only():
    from microsim.surfaces import gaussian

    s = gaussian(64, 1.0, 1.2, 8.0, seed=3)
    tr = Tracer(s)
    n = tr.normals
    assert tr.rise_bound == pytest.approx(np.max(np.hypot(n[:, 0], n[:, 1]) / n[:, 2]), rel=1e-15)
    assert Tracer(flat()).rise_bound == 0.0
    other = _not_a_heightfield(s)  # the same mesh: every ray is traced
    assert Tracer(other).rise_bound == np.inf
    assert not Tracer(other).surely_escapes(0.0, 0.0, 1.0)


def _not_a_heightfield(s):
    """The periodic mesh of ``s`` as a custom surface, not known to be a heightfield."""
    return Surface(
        kind="custom",
        vertices=s.vertices,
        faces=s.faces,
        tile_size=s.tile_size,
        periodic=True,
        nominal={},
    )


def _surface_points(tr, n: int, seed: int):
    """Points on the tracer's surface (first hits of n vertical rays from random positions)
    with their facet normals, and the random generator that placed them."""
    rng = np.random.default_rng(seed)
    lx, ly = tr.tile
    xy = rng.uniform(-0.5, 0.5, (n, 2)) * [lx, ly]
    hits = tr.first_hit(np.column_stack([xy, np.full(n, tr.zmax + 1)]), np.array([0, 0, -1.0]))
    ok = hits.status == HIT
    return hits.point[ok], hits.normal[ok], rng


def test_rays_steeper_than_the_rise_bound_are_never_blocked():
    """From points on a rough heightfield (σ/ℓ = 0.3, slopes up to ~1.5), rays rising more
    steeply than the bound all escape when traced; rays just below it are sometimes blocked
    (so the trace does meet the surface in this geometry)."""
    from microsim.surfaces import gaussian

    tr = Tracer(gaussian(96, 1.0, 2.4, 8.0, seed=5))
    L = tr.rise_bound
    p, nrm, rng = _surface_points(tr, 40_000, seed=0)
    m = len(p)
    phi = rng.uniform(0, 2 * np.pi, m)

    def rays(cot):
        d = np.column_stack([np.cos(phi), np.sin(phi), cot])
        d /= np.linalg.norm(d, axis=1)[:, None]
        up = np.einsum("ij,ij->i", d, nrm) > 0  # leaving the facet's front
        return d[up], up

    steep, up = rays(L * rng.uniform(1.0 + 2e-6, 1.5, m))
    assert tr.surely_escapes(*steep.T).all()
    assert np.all(tr.escapes(p[up], nrm[up], steep) == ESCAPED)
    shallow, up = rays(L * rng.uniform(0.2, 0.9, m))
    assert not tr.surely_escapes(*shallow.T).any()
    assert np.sum(tr.escapes(p[up], nrm[up], shallow) == HIT) > 100


def test_skipping_sure_masking_rays_changes_no_result(monkeypatch):
    """simulate with the rise bound (70 % of masking rays untraced at θi = 30°) equals, tally
    for tally, the run that traces every masking ray: per-facet table path (rays ≥ facets)
    and per-ray path (fewer rays than facets)."""
    import microsim.sim.tracer as tracer_module
    from microsim.surfaces import gaussian

    def run(rays):
        s = gaussian(32, 1.0, 1.2, 8.0, seed=1)  # a new object: no tracer reuse
        return simulate(s, "aluminium", [0.0, 30.0, 70.0], rays=rays, bins=Bins(9, 7), seed=2)

    fast = [run(r) for r in (1500, 8000)]
    monkeypatch.setattr(tracer_module, "rise_bound", lambda surface, normals: np.inf)
    slow = [run(r) for r in (1500, 8000)]
    for a, b in zip(fast, slow):
        assert np.array_equal(a.brdf, b.brdf) and np.array_equal(a.stderr, b.stderr)
        assert all(np.array_equal(a.ledger_counts[k], b.ledger_counts[k]) for k in a.ledger_counts)
        assert all(np.array_equal(a.ledger[k], b.ledger[k]) for k in a.ledger)


def _rays_below_the_rise_bound(tr, cots, seed: int) -> tuple:
    """(points, normals, directions) of rays leaving 60,000 random points of the tracer's
    surface above their facets, in random azimuths, with cot θ uniform in ``cots`` × the rise
    bound."""
    p, nrm, rng = _surface_points(tr, 60_000, seed=seed)
    phi = rng.uniform(0, 2 * np.pi, len(p))
    d = np.column_stack([np.cos(phi), np.sin(phi), tr.rise_bound * rng.uniform(*cots, len(p))])
    d /= np.linalg.norm(d, axis=1)[:, None]
    up = np.einsum("ij,ij->i", d, nrm) > 0
    return p[up], nrm[up], d[up]


def test_rays_cleared_by_the_coarse_grid_are_never_blocked():
    """Masking rays of a rough heightfield below the rise bound (cot θ < L) that the coarse
    grid of cell maxima clears (Tracer.clears_horizon) all escape when traced; it clears a
    good share of them, and of the rays it does not clear some are blocked."""
    from microsim.surfaces import gaussian

    tr = Tracer(gaussian(128, 1.0, 2.0, 8.0, seed=7))
    p, nrm, d = _rays_below_the_rise_bound(tr, (0.05, 0.99), seed=3)
    clear = tr.clears_horizon(p + tr.eps * nrm, d)  # the start a masking ray gets
    status = tr.escapes(p, nrm, d)
    assert 0.2 < clear.mean() < 0.99
    assert np.all(status[clear] == ESCAPED)
    assert np.sum(status[~clear] == HIT) > 100
    s = gaussian(128, 1.0, 2.0, 8.0, seed=7)
    other = _not_a_heightfield(s)  # the same mesh: nothing is cleared
    assert not Tracer(other).clears_horizon(p + tr.eps * nrm, d).any()


def test_rays_whose_first_cell_is_walked_exactly_are_never_blocked():
    """Where the masking rays are walked on the heightfield's grid, the coarse test walks a
    first cell steeper than the ray exactly (``HorizonGrid.walked``): the rays it clears all
    escape when walked, they include every ray the grid's bounds alone clear, and more."""
    from microsim.surfaces import gaussian

    tr = Tracer(gaussian(128, 1.0, 2.0, 8.0, seed=7), grid=True)
    assert tr.horizon.walked and not Tracer(gaussian(32, 1.0, 2.0, 8.0), grid=False).horizon.walked
    p, nrm, d = _rays_below_the_rise_bound(tr, (0.05, 0.99), seed=5)
    start = p + tr.eps * nrm  # the start a masking ray gets
    clear = tr.clears_horizon(start, d)
    assert np.all(tr.escapes(p, nrm, d)[clear] == ESCAPED)
    hz, tr.horizon = tr.horizon, tr.horizon._replace(walked=False)
    bounds = tr.clears_horizon(start, d)
    tr.horizon = hz
    assert np.all(clear[bounds]) and clear.sum() > bounds.sum() + 0.02 * len(d)


def test_rays_cleared_by_the_nearby_slope_bound_are_never_blocked():
    """The coarse grid's ``nearby`` bound (the steepest facet within ``NEARBY_CELLS`` cells,
    wrapped) is the window maximum of ``cslope``, at most the tile's rise bound. Masking rays
    below the tile's bound that it clears alone (the grid's cell maxima and slopes set to inf,
    so that ``horizon_clear``'s walk over the grid clears nothing) all escape when traced, and
    they are a good share of them. Its window is what makes it sound: each cell's own slope
    taken as the bound over the same reach clears rays that are blocked."""
    from microsim.sim.horizon_bounds import NEARBY_CELLS
    from microsim.surfaces import gaussian

    tr = Tracer(gaussian(128, 1.0, 2.0, 8.0, seed=7))
    hz, L = tr.horizon, tr.rise_bound
    k = NEARBY_CELLS
    window = np.max(
        [
            np.roll(hz.cslope, (a, b), axis=(0, 1))
            for a in range(-k, k + 1)
            for b in range(-k, k + 1)
        ],
        axis=0,
    )
    assert np.array_equal(hz.nearby, window) and hz.nearby.max() <= L
    assert hz.reach == k * min(hz.cw, hz.ch) and hz.nearby.mean() < 0.8 * L
    p, nrm, d = _rays_below_the_rise_bound(tr, (0.3, 0.99), seed=4)
    status = tr.escapes(p, nrm, d)
    inf = np.full_like(hz.cmax, np.inf)
    tr.horizon = hz._replace(cmax=inf, cslope=inf)  # only the nearby bound can clear
    clear = tr.clears_horizon(p + tr.eps * nrm, d)
    assert np.all(status[clear] == ESCAPED)
    assert clear.mean() > 0.2
    tr.horizon = tr.horizon._replace(nearby=hz.cslope)  # wrong: no window, each cell alone
    assert np.sum(status[tr.clears_horizon(p + tr.eps * nrm, d)] == HIT) > 0


@pytest.mark.parametrize("theta", [0.0, 45.0, 75.0, 87.0])
def test_vgroove_masking_rays_cleared_by_their_exact_margin_escape_when_traced(theta, monkeypatch):
    """On V-grooves the traced path skips the masking rays whose exact float64 margin is
    below −``GROOVE_CLEAR_EPS``·eps (``Tracer.groove_clear``): the whole traced run is bitwise
    the same with the test switched off (every skipped ray, traced, escapes), and the test
    skips most of the masking rays (not vacuous)."""
    from microsim import analytic as an
    from microsim.sim import masking_rays, ray_columns
    from microsim.sim.streams import chunk_origins
    from microsim.sim.vgroove_profile import NO_GROOVES
    from microsim.surfaces import vgrooves

    s = vgrooves(400, an.Beckmann(0.5), seed=2)
    tr = Tracer(s, backend="auto")
    assert len(tr.groove_clear[0]) == len(tr.faces)
    traced = []
    real_trace = masking_rays.MaskingRays.trace
    monkeypatch.setattr(
        masking_rays.MaskingRays,
        "trace",
        lambda self, tracer, m, status: traced.append(m) or real_trace(self, tracer, m, status),
    )
    n = 40_000
    x, psi = chunk_origins(tr, n, range(10), (1, 0, int(theta)), True)
    wi = spherical_deg(theta, 0.0)
    ior, bins = resolve_material("aluminium"), Bins(30, 37)
    on = ray_columns.trace_columns(tr, None, wi, 0.0, bins, x, psi, ior)
    on = [a.copy() for a in on]
    tr.groove_clear = NO_GROOVES
    off = ray_columns.trace_columns(tr, None, wi, 0.0, bins, x, psi, ior)
    for a, b in zip(on, off):
        np.testing.assert_array_equal(a, b)
    assert traced[0] < 0.5 * traced[1] and np.any(on[0] == 1)  # skipped most; some masked
    assert not Tracer(heightfield_surface(random_heights(), 1 / 64)).groove_clear[0].size
