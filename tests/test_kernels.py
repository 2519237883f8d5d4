"""Compiled per-ray bookkeeping (``microsim.sim.engine``, the ``sim.*_kernels`` modules and
their callers): each kernel against the plain NumPy statement of what it computes.
Reproducibility for any threads/chunk is tested on whole runs in test_bench.py and
test_resume.py; the periodic walk against a replicated mesh in test_tracer.py; the analytic
V-groove kernel ray by ray against Embree in test_analytic_vgroove.py."""

import threading

import numpy as np
import pytest

from microsim.analytic.fresnel import fresnel, resolve_material
from microsim.sim import BLOCK, Bins, facet_tables, paths, streams, tracer_cache
from microsim.sim.engine.facets import mesh_facets
from microsim.sim.horizon_bounds import CLEAR_MARGIN
from microsim.sim.scratch import WorkArray, WorkColumns
from microsim.sim.tallies import Tally, split_tallies
from microsim.sim.tracer import Tracer
from microsim.surfaces.surface import flat
from microsim.vectors import spherical_deg

AL = resolve_material("aluminium")


def ray_outcomes(n, nbin, seed):
    """Spatially coherent synthetic ledger classes, weights and bins (runs of equal bins, as
    coherent rays give), with every class present."""
    rng = np.random.default_rng(seed)
    status = rng.choice(
        np.array(
            [paths.SINGLE] * 6
            + [paths.MASKED, paths.DOWNWARD, paths.RAY_UNRESOLVED, paths.RAY_MISSED],
            dtype=np.int8,
        ),
        n,
    )
    where = (np.arange(n) // 7 + rng.integers(0, 3, n)) % nbin
    where = np.where((status == paths.SINGLE) & (rng.random(n) > 0.05), where, -1).astype(np.int64)
    return status, rng.random(n), where


@pytest.mark.parametrize("n", [3 * BLOCK, 3 * BLOCK + 77])
def test_block_tallies_are_per_block_bincounts(n):
    """Per block: Σw, Σw², counts per bin exactly as np.bincount (rays added in order), the
    pair sums over (2k, 2k + 1) in the same bin, and the ledger per class."""
    nbin = 50
    status, weight, where = ray_outcomes(n, nbin, seed=1)
    n_blocks = -(-n // BLOCK)
    bins, sums, cnt, offsets, ln, lf = split_tallies(status, weight, where, n_blocks, nbin).take()
    for b in range(n_blocks):
        lo, hi = b * BLOCK, min(n, (b + 1) * BLOCK)
        s, w, k = status[lo:hi], weight[lo:hi], where[lo:hi]
        tallied = (s == paths.SINGLE) & (k >= 0)
        part = slice(offsets[b], offsets[b + 1])
        assert len(np.unique(bins[part])) == offsets[b + 1] - offsets[b]  # each bin once
        dense = np.zeros((4, nbin))
        dense[:3, bins[part]] = sums[:, part]
        dense[3, bins[part]] = cnt[part]
        assert np.array_equal(dense[0], np.bincount(k[tallied], w[tallied], nbin))
        assert np.array_equal(dense[1], np.bincount(k[tallied], w[tallied] ** 2, nbin))
        assert np.array_equal(dense[3], np.bincount(k[tallied], minlength=nbin))
        e = np.arange(0, hi - lo - 1, 2)
        both = e[tallied[e] & tallied[e + 1] & (k[e] == k[e + 1])]
        assert len(both) > 0  # not vacuous
        assert np.array_equal(dense[2], np.bincount(k[both], w[both] * w[both + 1], nbin))
        assert np.array_equal(ln[b], np.bincount(s, minlength=len(paths.LEDGER)))
        assert np.array_equal(lf[b], np.bincount(s, w, len(paths.LEDGER)))


@pytest.mark.parametrize("n", [3 * BLOCK, 3 * BLOCK + 77])
def test_order_block_tallies_are_per_block_bincounts(n):
    """Bounce chains through an interface (``split_order_tallies``): per block, Σw, Σw²,
    counts and pair sums of the escapes' carried weights per (slot, bin) as np.bincount, the
    first-bounce and terminal ledgers, and each total-internal-reflection bit counted in its
    column; and the tallies of a chunk split in two and ``ChunkTallies.joined`` are the
    whole's."""
    from microsim.sim.ledger import DIELECTRIC_TERMINAL, LEDGER
    from microsim.sim.tallies import ChunkTallies, ledger_columns, split_order_tallies

    nbin = 50
    status1, weight1, where = ray_outcomes(n, nbin, seed=4)
    rng = np.random.default_rng(5)
    term = rng.integers(0, len(DIELECTRIC_TERMINAL), n).astype(np.int8)
    wterm = rng.random(n)
    tir = rng.integers(0, 16, n).astype(np.int8) * (rng.random(n) < 0.2)
    n_blocks = -(-n // BLOCK)
    outcome = dict(status1=status1, weight1=weight1, term=term, wterm=wterm, where=where, tir=tir)
    bins, sums, cnt, offsets, ln, lf = split_order_tallies(**outcome, n_blocks=n_blocks,
                                                           nbin_total=nbin).take()  # fmt: skip
    classes, tir_col = ledger_columns(True)
    for b in range(n_blocks):
        lo, hi = b * BLOCK, min(n, (b + 1) * BLOCK)
        w, k = wterm[lo:hi], where[lo:hi]
        esc = k >= 0
        part = slice(offsets[b], offsets[b + 1])
        dense = np.zeros((4, nbin))
        dense[:3, bins[part]] = sums[:, part]
        dense[3, bins[part]] = cnt[part]
        assert np.array_equal(dense[0], np.bincount(k[esc], w[esc], nbin))
        assert np.array_equal(dense[1], np.bincount(k[esc], w[esc] ** 2, nbin))
        assert np.array_equal(dense[3], np.bincount(k[esc], minlength=nbin))
        e = np.arange(0, hi - lo - 1, 2)
        both = e[esc[e] & (k[e] == k[e + 1])]
        assert len(both) > 0
        assert np.array_equal(dense[2], np.bincount(k[both], w[both] * w[both + 1], nbin))
        first = len(LEDGER)
        assert np.array_equal(ln[b, :first], np.bincount(status1[lo:hi], minlength=first))
        assert np.array_equal(lf[b, :first], np.bincount(status1[lo:hi], weight1[lo:hi], first))
        terminal = len(DIELECTRIC_TERMINAL)
        assert np.array_equal(ln[b, first:tir_col], np.bincount(term[lo:hi], minlength=terminal))
        assert np.array_equal(lf[b, first:tir_col], np.bincount(term[lo:hi], w, terminal))
        bits = (tir[lo:hi, None] >> np.arange(4)) & 1
        assert ln.shape[1] == classes and np.array_equal(ln[b, tir_col:], bits.sum(axis=0))
    halves = [
        split_order_tallies(**{c: a[s] for c, a in outcome.items()}, n_blocks=m, nbin_total=nbin)
        for s, m in ((slice(0, BLOCK), 1), (slice(BLOCK, n), n_blocks - 1))
    ]
    whole = (bins, sums, cnt, offsets, ln, lf)
    for a, b in zip(ChunkTallies.joined(halves).take(), whole):
        assert np.array_equal(a, b)


def test_adding_a_chunk_adds_its_blocks_in_order():
    """``Tally.add_chunk`` (sparse, one call) equals adding every block's dense sums in block
    order, bitwise."""
    nbin, n = 40, 4 * BLOCK
    status, weight, where = ray_outcomes(n, nbin, seed=2)
    got = Tally.empty(nbin)
    got.sum_w += 0.1  # a running total to add to
    want = Tally.empty(nbin)
    want.sum_w += 0.1
    assert got.add_chunk(split_tallies(status, weight, where, 4, nbin)) == 4
    for b in range(4):
        one = Tally.empty(nbin)
        one.add_chunk(
            split_tallies(
                *(a[b * BLOCK : (b + 1) * BLOCK] for a in (status, weight, where)), 1, nbin
            )
        )
        for total, part in zip(want.items(), one.items()):
            total += part
    assert all(np.array_equal(a, b) for a, b in zip(got.items(), want.items()))


def test_chunk_tallies_hand_out_once():
    chunk = split_tallies(*ray_outcomes(BLOCK, 5, seed=3), 1, 5)
    chunk.take()
    with pytest.raises(RuntimeError, match="already taken"):
        chunk.take()


def _grooves(n=64):
    from microsim import analytic as an
    from microsim.surfaces import vgrooves

    return vgrooves(n, an.Beckmann(0.3), seed=1)


@pytest.mark.parametrize("surface", [flat, _grooves])
@pytest.mark.parametrize("azimuth", [False, True])
@pytest.mark.parametrize("origins", ["stratified", "independent"])
def test_block_rays_do_not_depend_on_the_chunking(azimuth, origins, surface):
    tracer = tracer_cache.tracer_for(surface(), "traced")[0]
    n = 5 * BLOCK + 11
    (x, y, z), psi = (
        np.copy(a) if a is not None else None
        for a in streams.chunk_origins(tracer, n, range(6), (3, 1, 2), azimuth, origins)
    )
    one = [streams.block_origins(tracer, n, b, (3, 1, 2), azimuth, origins) for b in range(6)]
    assert np.array_equal(np.stack([x, y, z], axis=1), np.concatenate([o for o, _ in one]))
    if azimuth:
        assert np.array_equal(psi, np.concatenate([p for _, p in one]))
        assert 0 <= psi.min() and psi.max() < 2 * np.pi and np.ptp(psi) > 6
    other = streams.chunk_origins(tracer, n, range(6), (3, 1, 3), azimuth, origins)[0][0]
    assert not np.array_equal(x, other)  # the key selects the stream


@pytest.mark.parametrize("surface", [flat, _grooves])
def test_groove_starts_are_the_chunk_origins_without_y(surface):
    """``streams.groove_starts`` (η skipped by advancing the generator) gives x and ψ bitwise
    as ``chunk_origins`` does, for any grouping of blocks and a short last block."""
    tracer = tracer_cache.tracer_for(surface(), "traced")[0]
    n = 5 * BLOCK + 11
    (x, _, _), psi = streams.chunk_origins(tracer, n, range(6), (3, 1, 2), True)
    x, psi = x.copy(), psi.copy()
    for blocks in (range(6), range(2, 6), [5]):
        gx, gpsi = streams.groove_starts(tracer, n, blocks, (3, 1, 2))
        part = slice(blocks[0] * BLOCK, n)
        assert np.array_equal(gx, x[part]) and np.array_equal(gpsi, psi[part])


def test_vgroove_strata_sweep_the_grooves_in_order_of_tilt_and_psi_by_row():
    """On V-grooves (``Tracer.groove_strata``) each row of the stratified sweep runs over the
    grooves in order of tilt (x in the tile, the groove rank never decreasing from one ray pair
    — one stratum — to the next along the row),
    every groove gets its share of the rays (within one per row), and ψ lies in the row's
    own stratum [row, row + 1)·2π/rows."""
    tracer = tracer_cache.tracer_for(_grooves(), "traced")[0]
    rims, width = tracer.groove_strata
    g = len(rims)
    assert g == 64 and np.all(np.diff(np.sort(rims)) > 0)
    lx, ly = tracer.tile
    n = 6 * BLOCK + 7
    rows = max(1, int(round(np.sqrt(n * ly / lx))))
    (x, y, _), psi = streams.chunk_origins(tracer, n, range(7), (5, 0, 1), True)
    assert np.all((x >= -lx / 2) & (x < lx / 2))
    groove = np.floor((x + lx / 2) / width).astype(int)
    order_rank = np.empty(g, int)  # groove (in x order) → its rank in order of tilt
    order_rank[np.round((rims + lx / 2) / width).astype(int)] = np.arange(g)
    r = order_rank[groove]
    row = np.floor((y + ly / 2) / ly * rows)
    pair = np.arange(n) // 2
    for k in np.unique(row):
        rank, p = r[row == k], pair[row == k]
        starts = np.flatnonzero(np.r_[True, np.diff(p) > 0])
        hi, lo = np.maximum.reduceat(rank, starts), np.minimum.reduceat(rank, starts)
        assert np.all(hi[:-1] <= lo[1:])
    assert np.all(np.abs(np.bincount(groove, minlength=g) - n / g) <= rows + 1)
    assert np.all((psi * rows / (2 * np.pi) >= row) & (psi * rows / (2 * np.pi) < row + 1))


def test_stratified_origins_lie_in_their_own_strata():
    """Rays 2k and 2k + 1 lie in one stratum: ray r's origin is q = (2k + w·ξ)/N·rows of the
    row-major sweep, k = ⌊r/2⌋, w = min(2, N − 2k), ξ ∈ [0, 1), its y jittered inside row ⌊q⌋
    (η ∈ [0, 1)); N odd leaves the last ray a stratum of width 1/N to itself."""
    tracer = tracer_cache.tracer_for(flat(), "traced")[0]
    lx, ly = tracer.tile
    n = 3 * BLOCK + 5
    rows = max(1, int(round(np.sqrt(n * ly / lx))))
    (x, y, z), _ = streams.chunk_origins(tracer, n, range(4), (0, 0, 0), False, "stratified")
    row = np.floor((y + ly / 2) / ly * rows)
    q = row + (x + lx / 2) / lx
    pair = np.arange(n) // 2 * 2
    width = np.minimum(2, n - pair)
    xi = (q * n / rows - pair) / width
    eta = (y + ly / 2) / ly * rows - row
    tol = 1e-9
    assert np.all((xi > -tol) & (xi < 1 + tol)) and np.all((eta > -tol) & (eta < 1 + tol))
    assert width[-1] == 1 and np.all(width[:-1] == 2)
    # the two rays of a pair are independent: their ξ are not ordered
    assert 0.4 < np.mean(xi[0:-1:2] < xi[1::2]) < 0.6
    assert np.all(z == tracer.zmax + tracer.top_margin)


@pytest.mark.parametrize(
    "bins",
    [Bins(45, 37), Bins(45, 91), Bins(9, 2), Bins(18, 72, folded=False), Bins(10, 4, folded=False)],
)
@pytest.mark.parametrize("phi_i", [0.0, 30.0, -170.0, 725.0, "per ray"])
def test_locate_is_the_search_over_the_edges(bins, phi_i):
    """``Bins.locate`` (compiled ``bin_kernels.bin_index``: arithmetic guess corrected against the
    edges) gives θo bin ⌊θo·n/90⌋ and the Δφ bin of ``relative_azimuth`` exactly as
    searchsorted(phi_edges, Δφ, 'right') − 1 — also for directions on and next to every
    Δφ edge."""
    rng = np.random.default_rng(0)
    wo = rng.normal(size=(100_000, 3))
    edges = np.radians(np.concatenate([bins.phi_edges[:, None] + [[-1e-9, 0.0, 1e-9]]]).ravel())
    phi = float(phi_i) if phi_i != "per ray" else 0.0
    on_edges = np.stack(
        [
            np.cos(edges + np.radians(phi)),
            np.sin(edges + np.radians(phi)),
            np.full(len(edges), 0.3),
        ],
        axis=1,
    )
    wo = np.concatenate([wo, on_edges, -on_edges])
    wo /= np.linalg.norm(wo, axis=1)[:, None]
    if phi_i == "per ray":
        phi = rng.uniform(-400.0, 400.0, len(wo))
    theta = bins.angles(wo)[0]
    it = np.minimum((theta * (bins.n_theta / 90.0)).astype(np.int64), bins.n_theta - 1)
    ip = np.clip(
        np.searchsorted(bins.phi_edges, bins.relative_azimuth(wo, phi), side="right") - 1,
        0,
        bins.n_phi - 1,
    )
    want = np.where(wo[:, 2] > 0, it * bins.n_phi + ip, -1)
    assert np.array_equal(bins.locate(wo, phi), want)


@pytest.mark.parametrize("ior", [AL, 1.5, None])
def test_facet_table_is_the_mirror_law_with_fresnel_weights(ior):
    rng = np.random.default_rng(4)
    n = rng.normal(size=(20_000, 3))
    n[:, 2] = np.abs(n[:, 2]) + 0.05
    n /= np.linalg.norm(n, axis=1)[:, None]

    class Tile:  # the table reads only these
        facets = mesh_facets(np.ascontiguousarray(n.T), np.zeros(len(n)), 0.0)
        rise_bound = 0.8  # steepest slope of a pretend heightfield
        beam = None  # no heightfield grid: no beams cleared (tests/test_beam.py)
        grid = None  # nor a grid walk: no steps table
        surely_escapes = staticmethod(lambda *d: Tracer.surely_escapes(Tile, *d))

    wi, bins = spherical_deg(55.0, 20.0), Bins(18, 13)
    table = facet_tables.facet_table(Tile, wi, ior, bins, 20.0)
    c = n @ wi
    wo = 2 * c[:, None] * n - wi
    assert np.array_equal(table.wo32, wo.astype(np.float32))
    want = np.where(
        c <= 0, paths.RAY_UNRESOLVED, np.where(wo[:, 2] > 0, paths.SINGLE, paths.DOWNWARD)
    )
    assert np.array_equal(table.code, want) and len(set(want)) == 3
    np.testing.assert_allclose(
        table.weight, np.where(c > 0, fresnel(np.clip(c, 0, 1), ior), 0.0), rtol=1e-12, atol=1e-15
    )
    assert np.array_equal(table.bin, bins.locate(wo, 20.0))
    w32 = table.wo32.astype(np.float64)  # clear: lit, rising more steeply than slope 0.8
    steep = w32[:, 2] > CLEAR_MARGIN * 0.8 * np.hypot(w32[:, 0], w32[:, 1])
    assert np.array_equal(table.clear, (want == paths.SINGLE) & steep)
    assert 0 < table.clear.sum() < (want == paths.SINGLE).sum()


def test_work_arrays_are_reused_per_declaration_generation_and_thread():
    a, b = WorkArray("test-a"), WorkArray("test-b", np.int32, columns=3)
    x = a(100)
    assert np.shares_memory(x, a(50))  # same buffer, new view
    assert not np.shares_memory(x, b(100)) and b(7).shape == (7, 3) and b(7).dtype == np.int32
    assert a(1000).size == 1000  # grows when too small
    g = WorkArray("test-g", generations=2)
    assert not np.shares_memory(g(10, 0), g(10, 1))
    assert WorkArray("test-r", rows=3)(5).shape == (3, 5)
    cols = WorkColumns("test-c")(4)
    assert len(cols) == 3 and not np.shares_memory(cols[0], cols[1])
    other = {}
    t = threading.Thread(target=lambda: other.setdefault("a", a(100)))
    t.start()
    t.join()
    assert not np.shares_memory(a(100), other["a"])  # per thread
    with pytest.raises(ValueError, match="declared twice"):
        WorkArray("test-a")


def test_every_work_array_of_the_pipeline_is_declared_once():
    """The pipeline's modules declare their work arrays at import, each name once (a clash
    would raise on import); the tracer's, the masking rays' and the bounce chain's exist."""
    import microsim.sim.bounces  # noqa: F401  (imports paths, tracer, streams, tallies)
    from microsim.sim.scratch import declared

    names = declared()
    for name in ("walk-o32", "masking-ray", "bounce-next-live", "chunk-origin-x", "tally-sums"):
        assert name in names


def test_rays_rounding_onto_a_wall_still_hit():
    """Starts within half a float32 ulp of the walls round onto them; a ray on the wall runs
    along the mesh's boundary edge, which Embree's watertight test may give to the absent
    neighbour. ``_strictly_inside`` keeps them in the tile: every falling ray hits."""
    from support import heightfield_surface, random_heights

    from microsim.sim import Tracer
    from microsim.sim.tracer import HIT

    tracer = Tracer(heightfield_surface(random_heights(n=32, sigma=0.02, seed=5), 1 / 32))
    h = tracer.tile[0] / 2
    edge = np.nextafter(h, 0.0)  # rounds to h in float32
    rng = np.random.default_rng(6)
    n = 4000
    along = rng.uniform(-h, h, n)
    z = np.full(n, tracer.zmax + tracer.top_margin)
    for origins in (
        np.stack([along, np.full(n, edge), z], 1),
        np.stack([np.full(n, edge), along, z], 1),
    ):
        for theta, phi in ((0.0, 0.0), (30.0, 90.0), (30.0, 0.0), (60.0, 180.0)):
            status = tracer.trace(origins, -spherical_deg(theta, phi))[0]
            assert np.all(status == HIT), (theta, phi, np.count_nonzero(status != HIT))


def test_cos_sin_is_libm_to_an_ulp():
    """``trig.cos_sin`` (fdlibm's polynomials after a two-part π/2 reduction) agrees with
    math.cos/math.sin within 2.3e-16 over [−2π, 2π], quadrant edges included."""
    import math

    from microsim.trig import cos_sin

    psi = np.concatenate(
        [
            np.linspace(-2 * np.pi, 2 * np.pi, 20_001),
            (np.arange(-4, 5) * np.pi / 4)[:, None] + [[-1e-12, 0.0, 1e-12]],
        ],
        axis=None,
    )
    err = max(
        max(abs(c - math.cos(p)), abs(s - math.sin(p))) for p in psi for c, s in [cos_sin(float(p))]
    )
    assert err <= 2.3e-16


def test_atan_approx_is_within_its_bound():
    """``trig.atan_approx`` is within ``ATAN_ERROR`` of atan2 for y ≥ 0 over every
    octant (and exactly 0 at the origin): ``bin_rays`` relies on the bound."""
    from microsim.trig import ATAN_ERROR, atan_approx

    rng = np.random.default_rng(3)
    y, x = np.abs(rng.normal(size=50_000)), rng.normal(size=50_000)
    a = np.linspace(0.0, np.pi, 10_001)
    y, x = (
        np.concatenate([y, np.sin(a), [0.0, 1.0, 0.0]]),
        np.concatenate([x, np.cos(a), [1.0, 0.0, -1.0]]),
    )
    got = np.array([atan_approx(float(p), float(q)) for p, q in zip(y, x)])
    assert np.max(np.abs(got - np.arctan2(y, x))) <= ATAN_ERROR
    assert atan_approx(0.0, 0.0) == 0.0


@pytest.mark.parametrize(
    "bins", [Bins(45, 37), Bins(45, 91), Bins(9, 2), Bins(90, 181), Bins(30, 145)]
)
@pytest.mark.parametrize("rotate", [False, True])
def test_bin_rays_is_locate(bins, rotate):
    """``ray_bins.bin_rays`` (vectorised ``atan_approx`` bins, those near an edge by
    ``Bins.locate``'s own arithmetic) bins every SINGLE ray as ``Bins.locate`` does against
    φi (less ψ per ray when ``rotate``): random directions, directions on and 1e-9 rad either
    side of every θ and ±Δφ edge, the mirror directions of a flat facet (θo = θi, Δφ = 180°:
    on an edge for θi = 30° and 60° on 2° or 3° bins) and the zenith; other rays keep their
    bin."""
    from microsim.sim import ray_bins

    rng = np.random.default_rng(4)
    phi_i = 35.0
    te = np.radians(bins.theta_edges[1:-1])[:, None] + [[-1e-9, 0.0, 1e-9]]
    pe = np.radians(bins.phi_edges[1:-1])[:, None] + [[-1e-9, 0.0, 1e-9]]
    t, dp = np.meshgrid(np.append(te, 0.4), np.concatenate([pe.ravel(), -pe.ravel(), [0.3]]))
    t = np.concatenate([t.ravel(), np.radians(np.arange(0.0, 90.0, 0.5))])
    dp = np.concatenate([dp.ravel(), np.full(180, np.pi)])  # the mirror of a flat facet
    n = 60_000
    m = n + len(t) + 1
    psi = rng.uniform(0, 2 * np.pi, m) if rotate else np.zeros(m)
    wo = rng.normal(size=(m, 3)) * [0.4, 0.4, 1.0]
    wo[:, 2] = np.abs(wo[:, 2])
    phi = dp + np.radians(phi_i - np.degrees(psi[n : n + len(t)]))  # Δφ = dp against φi − ψ
    wo[n : n + len(t)] = np.stack([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.cos(t)], 1)
    wo[-1] = [0.0, 0.0, 1.0]
    wo[:n] /= np.linalg.norm(wo[:n], axis=1)[:, None]
    status = np.where(rng.random(m) < 0.9, paths.SINGLE, paths.MASKED).astype(np.int8)
    status[n:] = paths.SINGLE
    where = np.full(m, -7, dtype=np.int64)
    near = np.empty(m, dtype=np.bool_)
    cols = [np.ascontiguousarray(wo[:, k]) for k in range(3)]
    args = (bins.n_theta, bins.phi_edges, near, where)
    ray_bins.bin_rays(status, *cols, psi, rotate, phi_i, *args)
    want = bins.locate(wo, phi_i - np.degrees(psi))
    single = status == paths.SINGLE
    assert np.array_equal(where[single], want[single])
    assert np.all(where[~single] == -7)
    assert near[n:].mean() > 0.5  # the edge directions did take the exact branch
