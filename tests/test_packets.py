"""Coherent Embree packets (microsim.sim.embree_packets) against embreex's single rays.

Both trace the same float32 rays through robust scenes built from the same arrays by the same
Embree library, with exact per-triangle tests: primIDs and distances agree exactly except
where a ray meets two facets at the same float32 distance (a shared edge or vertex), whose
order of visit may differ. Those ties are rare (measure-zero for random rays); they are
bounded here at 1e-4 of the rays.
"""

import functools

import numpy as np
import pytest
from embreex import mesh_construction as mc
from embreex import rtcore_scene as rs
from support import heightfield_surface, random_heights, vgroove_surface

from microsim.sim import embree_packets as ep

pytestmark = pytest.mark.skipif(
    not ep.packets_available(), reason=f"Embree packets unavailable: {ep.binding_error()}"
)
TIES = 1e-4  # allowed fraction of edge/vertex ties


@functools.cache
def _bound(width):
    return ep._Lib(ep.library_path(), width)


def _scenes(surface, width=None):
    v = np.asarray(surface.vertices, dtype=np.float32)
    f = np.asarray(surface.faces).astype(np.int32)
    ref = rs.EmbreeScene(robust=True)
    mc.TriangleMesh(ref, v, f)
    return ref, ep.PacketScene(v, f, _bound=None if width is None else _bound(width))


def _compare(surface, o, d, tf, width=None):
    ref, pk = _scenes(surface, width)
    r = ref.run(o, d if len(d) == len(o) else np.repeat(d, len(o), 0), dists=tf, output=1)
    prim, t = pk.run(o, d, tf)
    assert 0.05 < np.mean(prim >= 0) < 0.95  # hits and misses both occur: not vacuous
    differ = (r["primID"] != prim) | (r["tfar"] != t)
    assert np.sum(differ) <= TIES * len(o)
    same = ~differ
    np.testing.assert_array_equal(r["tfar"][same], t[same])
    occ = ref.run(o, d if len(d) == len(o) else np.repeat(d, len(o), 0), dists=tf, query="OCCLUDED")
    blocked, none = pk.run(o, d, tf, occlusion=True)
    assert none is None
    assert np.sum((occ >= 0) != (blocked >= 0)) <= TIES * len(o)
    # an occlusion query is blocked exactly when the intersection query hits
    assert np.array_equal(blocked >= 0, prim >= 0)


def _random_rays(n, zlo, zhi, seed, tmax=3.0):
    rng = np.random.default_rng(seed)
    o = np.stack([rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n), rng.uniform(zlo, zhi, n)])
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    tf = rng.uniform(0.05, tmax, n)
    return o.T.astype(np.float32), d.astype(np.float32), tf.astype(np.float32)


@pytest.mark.parametrize("width", [None, 4, 16])  # native width (8 or 16), 4, 16
def test_packets_equal_embreex_on_a_random_heightfield(width):
    s = heightfield_surface(random_heights(sigma=0.03, seed=5), 1 / 64)
    z = np.asarray(s.vertices)[:, 2]
    o, d, tf = _random_rays(50_003, z.min(), z.max() + 0.05, 1)  # partial last packet
    _compare(s, o, d, tf, width)
    if width is not None:
        return
    # one shared direction for all rays, falling 40° from the normal
    shared = np.array([[np.sin(0.7), 0.0, -np.cos(0.7)]], dtype=np.float32)
    _compare(s, o, shared, tf)


def test_native_width_is_chosen():
    lib = ep._lib()
    assert lib.width in (4, 8, 16)
    assert lib.width == max(lib.native, default=8)


def test_packets_equal_embreex_on_vgrooves_from_the_tile_walls():
    s = vgroove_surface([30.0, -55.0, 70.0, -15.0])
    z = np.asarray(s.vertices)[:, 2]
    o, d, tf = _random_rays(40_000, z.min(), 0.02, 2)
    o[::2, 0] = -0.5  # half the rays start on the x walls (the tile boundary of the walk)
    o[1::4, 0] = 0.5
    _compare(s, o, d, tf)
    # rays falling from above the tile along the grooves, from the y walls
    o[:, 1], o[:, 2] = -0.5, z.max() + 0.01
    d[:, 1] = np.abs(d[:, 1]) + 1.0
    d[:, 2] = -np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1)[:, None]
    _compare(s, o, d, tf)


def test_packets_leave_no_gap_on_a_closed_periodic_tile():
    """Rays falling onto a V-groove tile from above, started anywhere in it (walls
    included), all hit it: the packet path does not leak through shared edges."""
    s = vgroove_surface([45.0, -60.0, 20.0])
    _, pk = _scenes(s)
    rng = np.random.default_rng(4)
    n = 30_000
    top = np.asarray(s.vertices)[:, 2].max() + 0.01
    o = np.stack([rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n), np.full(n, top)], 1)
    o[: n // 3, 0] = -0.5
    o[n // 3 : 2 * n // 3, 1] = 0.5
    # steep rays (≤ 30° from −z, depth ≤ 0.42) aimed towards the tile centre stay in the tile
    th = np.radians(rng.uniform(0, 30, n))
    ph = rng.uniform(0, 2 * np.pi, n)
    d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), -np.cos(th)], 1)
    d[:, :2] = -np.sign(o[:, :2]) * np.abs(d[:, :2])
    prim, _ = pk.run(o.astype(np.float32), d.astype(np.float32), np.full(n, 10, np.float32))
    assert np.all(prim >= 0)


def test_missing_library_gives_a_clear_error(monkeypatch):
    with pytest.raises(ep.PacketBindingError, match="cannot load"):
        ep._Lib("/nonexistent/libembree4.so.4")
    monkeypatch.setattr(ep, "_lib", lambda: (_ for _ in ()).throw(ep.PacketBindingError("x")))
    assert ep.binding_error() == "x" and not ep.packets_available()


def test_environment_switch_disables_packets(monkeypatch):
    monkeypatch.setenv(ep.ENV_SWITCH, "0")
    assert not ep.packets_available()
    assert ep.ENV_SWITCH in ep.binding_error()


def test_self_test_rejects_a_wrong_layout(monkeypatch):
    """If the hit fields were not where the binding assumes, loading refuses."""
    monkeypatch.setattr(ep, "PRIM_ID", ep.U)  # read primID from the u coordinate
    lib = ep._Lib(ep.library_path())
    with pytest.raises(ep.PacketBindingError, match="layouts"):
        ep._self_test(lib)


# --- the tracer's packet backend -----------------------------------------------------------
def test_tracer_backends_agree_on_vgroove_walks_through_the_tile_walls():
    """Periodic walks (many wall re-entries at grazing angles) with both backends: same fate,
    facet and point for every ray; no ray leaks or stays unresolved."""
    from microsim.sim import Tracer
    from microsim.sim.tracer import HIT, MISSED, UNRESOLVED
    from microsim.vectors import spherical_deg

    s = vgroove_surface([40.0, -65.0, 25.0, -80.0])
    a, b = Tracer(s, backend="packets"), Tracer(s, backend="embreex")
    assert (a.backend, b.backend) == ("packets", "embreex")
    rng = np.random.default_rng(6)
    n = 20_000
    o = np.stack([rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n), np.full(n, a.zmax)], 1)
    o[: n // 2, 0] = -0.5  # on the wall
    o[:, 2] += a.top_margin
    d = -spherical_deg(rng.uniform(0, 85, n), rng.uniform(0, 360, n))
    ha, hb = a.first_hit(o, d), b.first_hit(o, d)
    assert np.all(ha.status == HIT)
    differ = (ha.status != hb.status) | (ha.prim != hb.prim)
    assert np.sum(differ) <= TIES * n
    same = ~differ
    np.testing.assert_array_equal(ha.point[same], hb.point[same])
    up = spherical_deg(rng.uniform(50, 88, n), rng.uniform(0, 360, n))
    ea, eb = a.escapes(ha.point, ha.normal, up), b.escapes(ha.point, ha.normal, up)
    assert not np.any((ea == MISSED) | (ea == UNRESOLVED))
    assert 0.02 < np.mean(ea == HIT) < 0.98  # masking decisions both ways: not vacuous
    assert np.sum(ea != eb) <= TIES * n


def test_simulate_with_packets_equals_embreex_and_is_reproducible(monkeypatch):
    """Same simulate run with the packet and the embreex backends: identical ledgers, bins
    equal up to edge ties; with packets, bitwise identical for 1/2 threads and chunk sizes."""
    from microsim.sim import BLOCK, Bins, Tracer, simulate, tracer_cache

    # simulate builds Tracer(surface): make its default "auto" (packets) for this test, and
    # keep the primary rays on Embree (not the heightfield grid walk)
    monkeypatch.setitem(Tracer.__init__.__kwdefaults__, "backend", "auto")
    monkeypatch.setattr(tracer_cache, "GRID_CASTER", False)
    rough = heightfield_surface(random_heights(sigma=0.03, seed=4), 1 / 64)
    kw = dict(rays=2 * BLOCK + 77, bins=Bins(18, 13), seed=3)
    a = simulate(rough, "aluminium", [25.0, 70.0], threads=1, chunk=BLOCK, **kw)
    b = simulate(rough, "aluminium", [25.0, 70.0], threads=2, chunk=2 * BLOCK, **kw)
    for name in ("sum_w", "sum_w2", "counts", "brdf"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert all(np.array_equal(a.ledger[k], b.ledger[k]) for k in a.ledger)
    monkeypatch.setenv(ep.ENV_SWITCH, "0")
    c = simulate(rough, "aluminium", [25.0, 70.0], threads=2, chunk=BLOCK, **kw)
    assert all(np.array_equal(a.ledger[k], c.ledger[k]) for k in a.ledger)
    moved = np.abs(a.counts.astype(np.int64) - c.counts.astype(np.int64)).sum() / 2
    assert moved <= TIES * kw["rays"] * 2
