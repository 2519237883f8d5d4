"""Paths through a dielectric interface on a heightfield grid in one compiled loop
(``microsim.sim.interface_grid``): the same estimator as the step-by-step path through
Embree (``dielectric.trace_dielectric``), so the two must end the same paths the same way —
class, weight, bin, total internal reflections — except the rare ray that the float64 grid
walk and Embree's float32 mesh send to different facets (within rounding of an edge); and the
facet table of the first interactions must change nothing at all."""

from __future__ import annotations

import numpy as np
import pytest

from microsim.bins import Bins
from microsim.sim import dielectric, interface_grid, tallies
from microsim.sim.bounces import ChainLimits, bounce_limit
from microsim.sim.dielectric import InterfaceOutcome, interface_of
from microsim.sim.dielectric_kernels import Roulette
from microsim.sim.streams import BLOCK
from microsim.sim.tracer_cache import tracer_for
from microsim.surfaces import gaussian

ETA = 1.5
PATHS = 2**14
EDGE_TIES = 1e-3
"""Most paths the two walks may end differently: rays within float32 rounding of a facet edge
(~1e-7 of a cell) meet a neighbour in one walk and not the other — a few in 10⁵."""


@pytest.fixture(scope="module")
def grid_tracer():
    """A Gaussian heightfield of rms slope ~0.7 (multiple scattering and total internal
    reflection both occur), its tracer walking the grid."""
    surface = gaussian(64, 1.0, 2.0, 4.0, seed=4)
    tracer = tracer_for(surface, "traced").tracer
    assert tracer.grid is not None
    return tracer


def _paths(tracer, theta_i: float, bins: Bins, table: bool | None, sums=None):
    """The ``InterfaceOutcome`` of ``PATHS`` paths lit from θi (φi = 30°) from the same
    random starts: through Embree step by step (``table`` None) or on the grid, its per-block
    tallies summed into ``sums`` (``tallies.chunk_sums``; fresh ones when None)."""
    rng = np.random.default_rng(7)
    starts = [
        rng.uniform(-tracer.half[0], tracer.half[0], PATHS),
        rng.uniform(-tracer.half[1], tracer.half[1], PATHS),
        np.full(PATHS, tracer.zmax + tracer.top_margin),
    ]
    t, p = np.radians(theta_i), np.radians(30.0)
    wi = np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    limit, floor = bounce_limit("all")
    chain = ChainLimits(limit, floor, bins.shape[0] * bins.shape[1])
    roulette = Roulette(np.uint64(0x5EED), 0)
    if table is None:
        return dielectric.trace_dielectric(
            tracer, wi, 30.0, bins, starts, None, ETA, chain, roulette
        )
    assert interface_grid.uses_grid_walk(tracer, bins, wi, None)
    out = InterfaceOutcome.empty(PATHS)
    path = (chain, interface_of(ETA, tracer), roulette, table)
    sums = _sums(bins) if sums is None else sums
    interface_grid.trace_grid_interface(tracer, wi, 30.0, bins, starts, path, out, sums)
    return out


def _sums(bins: Bins):
    """Per-block sums of ``PATHS`` dielectric paths over 2 sides × 4 order slots × bins."""
    blocks = -(-PATHS // BLOCK)
    nbin = 2 * 4 * bins.shape[0] * bins.shape[1]
    return tallies.chunk_sums(PATHS, blocks, nbin, tallies.ledger_columns(True)[0])


def _differing(a: InterfaceOutcome, b: InterfaceOutcome) -> np.ndarray:
    return np.any([x != y for x, y in zip(a, b)], axis=0)


@pytest.mark.parametrize("theta_i", [0.0, 40.0, 65.0, 140.0, 175.0])
def test_the_grid_walk_ends_every_path_as_the_embree_path_does(grid_tracer, theta_i):
    bins = Bins(30, 13)
    embree = _paths(grid_tracer, theta_i, bins, None)
    grid = _paths(grid_tracer, theta_i, bins, False)
    assert _differing(embree, grid).mean() <= EDGE_TIES
    # something happened beyond a single interaction: the comparison covers continuations
    assert (embree.status1 == 1).any()  # MASKED: the first continuation met the surface
    below = theta_i > 90
    if below:
        assert embree.tir.any()  # total internal reflection inside the medium


@pytest.mark.parametrize("theta_i", [30.0, 160.0])
def test_the_first_interactions_table_changes_nothing(grid_tracer, theta_i):
    bins = Bins(30, 13)
    walked = _paths(grid_tracer, theta_i, bins, False)
    tabled = _paths(grid_tracer, theta_i, bins, True)
    assert not _differing(walked, tabled).any()


@pytest.mark.parametrize("theta_i", [40.0, 160.0])
def test_the_tallies_summed_as_paths_end_are_those_of_their_outcome(grid_tracer, theta_i):
    """The grid loop adds each path to its block's sums as it ends: bitwise the per-block
    tallies the outcome arrays give afterwards (``tallies.split_order_tallies``)."""
    bins = Bins(30, 13)
    sums = _sums(bins)
    out = _paths(grid_tracer, theta_i, bins, True, sums)
    fused = tallies.chunk_of(sums).take()
    blocks, nbin = len(sums.offsets) - 1, sums.acc.shape[1]
    # the work arrays the loop summed into are reused below: ``fused`` holds copies
    after = tallies.split_order_tallies(**out._asdict(), n_blocks=blocks, nbin_total=nbin).take()
    assert blocks > 1 and len(fused[0]) > blocks  # several blocks, several bins each
    for a, b in zip(fused, after):
        np.testing.assert_array_equal(a, b)


def test_the_grid_walk_is_used_only_where_it_applies(grid_tracer):
    wi = np.array([0.5, 0.0, np.sqrt(0.75)])
    assert interface_grid.uses_grid_walk(grid_tracer, Bins(30, 13), wi, None)
    assert not interface_grid.uses_grid_walk(grid_tracer, Bins(30, 13), wi, np.zeros(4))
    assert not interface_grid.uses_grid_walk(grid_tracer, Bins(30, 14, folded=False), wi, None)


def _height(hp: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """h at grid coordinates (u, v) of the periodic piecewise-linear relief of vertex heights
    ``hp`` (ny + 1, nx + 1): each cell split along its (0, 0)–(1, 1) diagonal."""
    ny, nx = hp.shape[0] - 1, hp.shape[1] - 1
    i, j = np.floor(u).astype(int), np.floor(v).astype(int)
    fu, fv = u - i, v - j
    i, j = i % nx, j % ny
    h00, h10, h01, h11 = hp[j, i], hp[j, i + 1], hp[j + 1, i], hp[j + 1, i + 1]
    upper = fu >= fv
    return np.where(
        upper, h00 + fu * (h10 - h00) + fv * (h11 - h10), h00 + fv * (h01 - h00) + fu * (h11 - h01)
    )


@pytest.mark.slow  # compiles its own loop over ``cast_one`` (~7 s)
@pytest.mark.parametrize("below", [False, True])
def test_the_walk_finds_the_first_crossing_from_either_side(below):
    """``cast_one`` from random starts on either side of a relief, rising and falling, against
    a brute-force march along the ray (steps of 1/500 cell, the crossing refined by
    bisection): the same outcome — the hit point, or leaving the relief upward (ESCAPED) or
    downward (MISSED) — except rays that graze the relief within the march's resolution."""
    from microsim.jit import compiled
    from microsim.sim.engine.codes import ESCAPED, HIT, MISSED
    from microsim.sim.heightfield_caster import (
        NO_STEPS,
        HeightfieldGrid,
        cast_one,
        direction_terms,
    )

    @compiled
    def cast(x, y, z, d, geometry, side, out):
        for k in range(len(x)):
            terms = direction_terms(d[k, 0], d[k, 1], d[k, 2], geometry[4])
            s, f, px, py, pz = cast_one(
                x[k],
                y[k],
                z[k],
                d[k, 0],
                d[k, 1],
                d[k, 2],
                terms,
                geometry,
                side,
                geometry[9],
                NO_STEPS,
            )
            out[k, 0], out[k, 1], out[k, 2], out[k, 3] = s, px, py, pz

    rng = np.random.default_rng(3 + below)
    n = 16
    h = rng.normal(0.0, 1.0, (n, n))
    hp = np.pad(h, ((0, 1), (0, 1)), mode="wrap")
    grid = HeightfieldGrid(hp, 1.0)
    zmin, zmax = float(hp.min()), float(hp.max())
    geometry = grid.geometry(zmin, zmax, 64)
    rays = 400
    u0, v0 = rng.uniform(0, n, rays), rng.uniform(0, n, rays)
    s = -1.0 if below else 1.0
    z0 = _height(hp, u0, v0) + s * rng.uniform(1e-3, 1.0, rays)
    d = rng.normal(size=(rays, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    out = np.empty((rays, 4))
    x0, y0 = grid.x0, grid.y0
    cast(u0 + x0, v0 + y0, z0, d, geometry, grid.side(below), out)

    # the march: f = s·(z − h) until the ray leaves [zmin, zmax]
    t_end = np.where(d[:, 2] > 0, zmax - z0, zmin - z0) / d[:, 2]
    checked = 0
    for k in range(rays):
        t = np.linspace(0.0, t_end[k], max(2, int(t_end[k] * 500)))
        f = s * (z0[k] + t * d[k, 2] - _height(hp, u0[k] + t * d[k, 0], v0[k] + t * d[k, 1]))
        root = np.flatnonzero(f <= 0.0)
        before = f[1 : root[0] - 1] if root.size else f[1:]
        if before.size and before.min() < 2e-3:  # grazes the relief within resolution
            continue
        checked += 1
        if root.size == 0:
            assert out[k, 0] == (ESCAPED if d[k, 2] > 0 else MISSED)
            continue
        lo, hi = t[root[0] - 1], t[root[0]]
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            fm = s * (
                z0[k] + mid * d[k, 2] - _height(hp, u0[k] + mid * d[k, 0], v0[k] + mid * d[k, 1])
            )
            lo, hi = (lo, mid) if fm <= 0.0 else (mid, hi)
        assert out[k, 0] == HIT
        assert abs(out[k, 3] - (z0[k] + hi * d[k, 2])) < 1e-9
        # the hit lies in the tile, x and y by whole tiles from the marched point
        dx = (out[k, 1] - x0) - (u0[k] + hi * d[k, 0])
        assert abs(dx - n * np.round(dx / n)) < 1e-9
    assert checked > 0.9 * rays
