"""First hits of falling rays on a periodic heightfield, by walking its grid (no Embree).

A heightfield tile (``surfaces.heightfield_mesh``: heights H (ny, nx) on a square grid of
spacing c, cell (i, j) split along its (i, j)–(i + 1, j + 1) diagonal into triangle A =
(v00, v01, v11), face j·nx + i, and B = (v00, v11, v10), face nx·ny + j·nx + i) is a
continuous, piecewise-linear height function h(x, y), periodic in x and y. Along a ray
o + t·d the height above the surface f(t) = z(t) − h(x(t), y(t)) is then piecewise linear in t,
with breakpoints where the ray's footprint crosses a cell wall or a cell's diagonal. The first
hit is the first root of f: the walk visits the footprint's cells in order (2-D DDA, indices
wrapped), evaluates f once at every breakpoint (from the two vertices of the edge crossed) and
stops in the first piece where f falls from > 0 to ≤ 0; the hit is that piece's root, on that
piece's triangle. Because f is evaluated once per breakpoint and shared by the two pieces that
meet there, the walk is watertight by construction: a ray cannot pass between two triangles.

The same walk serves a ray on either side of the surface and in either direction
(``cast_one``'s ``side``): above it (f = z − h, the first root where f falls to ≤ 0) or below it
(inside a dielectric medium: f = h − z), rising or falling. A ray moving toward its side's
surface (falling above it, rising below it) meets it by the time it crosses the relief's far
level (zmin, resp. zmax); one moving away from it leaves the relief there without a hit
(ESCAPED past zmax, MISSED past zmin) unless it meets a higher (lower) part of the surface first.

The walk starts where the ray falls through z = zmax (nothing lies above it) and is exact in
float64 on the float64 heights, where Embree tests the float32 mesh: the two agree on the hit
triangle except for rays within float32 rounding of an edge (ties), and on the hit point to
float32 precision. A ray that crosses the tile walls more than ``max_wraps`` times is
UNRESOLVED, as in ``Tracer``'s walk.

A ray's walk is a chain of dependent steps with unpredictable branches (which triangle,
whether the diagonal is crossed, whether the cell is hit), so one ray at a time leaves the
CPU idle for much of each step. ``cast_falling`` therefore walks falling rays from above the
relief ``LANES`` at a time where the vector units are wide enough to pay for the gathers
(``LANE_WALK``): the same steps as ``cast_one``, its branches computed and selected, one cell
of every lane per round (``cast_lanes``).
"""

from __future__ import annotations

import functools
import math
import os

import numpy as np

from microsim.jit import lane_scratch, vector_inlined, vectorised, wide_vectors

from .engine.codes import ESCAPED, HIT, MISSED, UNRESOLVED

__all__ = ["HeightfieldGrid", "heightfield_grid", "cast_falling"]

_compiled = vectorised
# the walk inlined into the ray loop: ~30 % faster than as separate calls (same bits)
_inlined = vector_inlined

NO_STEPS = np.zeros((0, 0), dtype=np.int8)
NO_STEPS.flags.writeable = False  # read-only, as a facet table's ``ahead``: one compiled type
"""``cast_one``'s ``ahead`` without a table of cells surely stepped over."""


class HeightfieldGrid:
    """The grid of a heightfield tile: its mesh's vertex heights ``hp`` (ny + 1, nx + 1) (the
    last row and column repeat the first), each cell's highest vertex ``cell_max`` (ny, nx)
    and lowest ``cell_min`` (built on first use: by the first walk whose rays may start below
    the surface — any ``cast_columns`` walk, masking rays included; the primary walks of
    ``cast_falling`` never need it), cell size ``cell`` and lower tile corner (``x0``,
    ``y0``)."""

    def __init__(self, hp: np.ndarray, cell: float):
        self.hp = np.ascontiguousarray(hp, dtype=np.float64)
        self.ny, self.nx = self.hp.shape[0] - 1, self.hp.shape[1] - 1
        hp = self.hp
        self.cell_max = np.maximum(hp[:-1, :-1], hp[:-1, 1:])  # then in place: one array
        np.maximum(self.cell_max, hp[1:, :-1], out=self.cell_max)
        np.maximum(self.cell_max, hp[1:, 1:], out=self.cell_max)
        self.cell = float(cell)
        self.x0, self.y0 = -self.nx * self.cell / 2.0, -self.ny * self.cell / 2.0

    @classmethod
    def of_heights(cls, heights: np.ndarray, cell: float) -> "HeightfieldGrid":
        """The grid of ``heightfield_mesh(heights, cell)`` from the heights alone."""
        ny, nx = heights.shape
        hp = np.empty((ny + 1, nx + 1))
        hp[:-1, :-1] = heights
        hp[-1, :-1] = heights[0]  # the last row and column repeat the first
        hp[:, -1] = hp[:, 0]
        return cls(hp, cell)

    @functools.cached_property
    def cell_min(self) -> np.ndarray:
        hp = self.hp
        low = np.minimum(hp[:-1, :-1], hp[:-1, 1:])  # then in place: one array
        np.minimum(low, hp[1:, :-1], out=low)
        return np.minimum(low, hp[1:, 1:], out=low)

    def side(self, below: bool) -> tuple:
        """``cast_one``'s ``side`` argument for a ray above the surface or ``below`` it."""
        return (-1.0, self.cell_min) if below else (1.0, self.cell_max)

    def geometry(
        self, zmin: float, zmax: float, max_wraps: int, lanes: bool | None = None
    ) -> tuple:
        """The kernels' grid argument: (hp, cell_max, nx, ny, cell, x0, y0, zmin, zmax,
        max_wraps, lanes): ``cast_falling`` walks ``LANES`` rays side by side where ``lanes``
        (default ``LANE_WALK``), else one at a time — the same bits."""
        return (
            self.hp,
            self.cell_max,
            self.nx,
            self.ny,
            self.cell,
            self.x0,
            self.y0,
            float(zmin),
            float(zmax),
            int(max_wraps),
            LANE_WALK if lanes is None else bool(lanes),
        )


LANE_SWITCH = "MICROSIM_LANE_WALK"
LANE_WALK = wide_vectors() and os.environ.get(LANE_SWITCH, "1") != "0"
"""Whether ``cast_falling`` walks its rays ``LANES`` at a time (``cast_lanes``): where numba
compiles for AVX-512 (``jit.wide_vectors``), unless ``MICROSIM_LANE_WALK=0``. On the AVX2
path its gathers make it slower than the walk one ray at a time (docs/performance.md,
``tools/walk_cost.py --lanes``). Both give the same bits."""


def heightfield_grid(surface, vertices=None, faces=None) -> HeightfieldGrid | None:
    """The ``HeightfieldGrid`` of a periodic heightfield ``surface``: from its heights when it
    stores no mesh (``Surface.stores_mesh`` False), or when its mesh (``vertices``, ``faces``,
    as the tracer holds them) is exactly ``heightfield_mesh(surface.heights, surface.dx)``;
    else None (any other mesh is traced by Embree)."""
    heights, dx = getattr(surface, "heights", None), getattr(surface, "dx", None)
    if heights is None or dx is None or not getattr(surface, "periodic", False):
        return None
    from microsim.surfaces.surface import is_heightfield_mesh

    heights = np.asarray(heights, dtype=np.float64)
    if getattr(surface, "stores_mesh", True) is False:
        return HeightfieldGrid.of_heights(heights, float(dx))
    if heights.ndim != 2 or not is_heightfield_mesh(heights, float(dx), vertices, faces):
        return None
    ny, nx = heights.shape
    return HeightfieldGrid(vertices[:, 2].reshape(ny + 1, nx + 1), float(dx))


STEPS_AHEAD = 16
"""The most cells ``steps_over`` counts ahead of a start (int8)."""


def steps_over(grid: "HeightfieldGrid", down, zmax: float) -> np.ndarray:
    """Per cell (ny, nx) int8: how many cells, from that one on, every ray falling along
    ``down`` (dx, dy, dz < 0) from where it crosses the level ``zmax`` in that cell surely
    steps over — it leaves each of them above its highest vertex (``cell_max``) — so that
    ``cast_one`` need not test them (``ahead``), at most ``STEPS_AHEAD``. After k wall
    crossings a ray is in one of the cells k steps away along the walk's axis directions (every
    split of the k steps between the axes is taken), and its horizontal run r at the next
    crossing is at most (k + 1)·c/|û_x| on one axis, (k + 2)·c/(|û_x| + |û_y|) on two (walls
    c/|û| apart, the first within one spacing); it is then at least zmax − r·|d_z|/|d_h|,
    which must clear the cells' highest vertex by a margin far above rounding. Periodic."""
    dx, dy, dz = (float(c) for c in down)
    h = math.hypot(dx, dy)
    ahead = np.zeros(grid.cell_max.shape, dtype=np.int8)
    if not dz < 0.0 or h == 0.0:  # a vertical ray stays in its cell
        return ahead
    ux, uy = abs(dx) / h, abs(dy) / h
    si, sj = int(np.sign(dx)), int(np.sign(dy))
    one_axis = min(ux, uy) == 0.0
    drops = [  # the drop over the run bound at the (k + 1)th wall crossing, k = 0, 1, ...
        (k + 1 if one_axis else (k + 2) / (ux + uy)) * grid.cell * (-dz / h)
        for k in range(STEPS_AHEAD)
    ]
    margin = 1e-9 * (1.0 + abs(zmax) + drops[-1])  # far above the walk's rounding
    clear = [zmax - drop - margin for drop in drops]  # the ray's least height there
    for j0 in range(0, ahead.shape[0], STEPS_BAND):  # bands of rows: small temporaries
        _steps_over_band(grid.cell_max, j0, si, sj, clear, ahead)
    return ahead


STEPS_BAND = 64
"""Rows of cells ``steps_over`` works on at a time."""


def _steps_over_band(cell_max, j0: int, si: int, sj: int, clear: list, ahead) -> None:
    """``steps_over`` for the rows j0 … j0 + ``STEPS_BAND`` − 1 (of ``ahead``): ``clear[k]``
    the height the ray surely keeps when it leaves the cell k steps away."""
    ny, nx = cell_max.shape
    rows = np.arange(j0, min(ny, j0 + STEPS_BAND))
    ci, cj = np.arange(nx)[None, :], rows[:, None]
    none = np.full((len(rows), nx), -np.inf)
    reach = cell_max[rows]  # highest vertex of the cells k steps away, any split: k = 0
    alive = np.ones(reach.shape, dtype=bool)
    for k, least in enumerate(clear):
        # the (k + 1)th step stays in the tile along each axis it may take
        alive &= (0 <= ci + (k + 1) * si) & (ci + (k + 1) * si < nx)
        alive &= (0 <= cj + (k + 1) * sj) & (cj + (k + 1) * sj < ny)
        if k > 0:  # the cells k steps away: one more x step from k − 1, or k steps along y
            along_x = np.roll(reach, -si, axis=1) if si else none
            reach = np.maximum(along_x, cell_max[(rows + k * sj) % ny] if sj else none)
        alive &= least > reach
        if not alive.any():
            return
        ahead[rows[0] : rows[-1] + 1] += alive


@_inlined
def _plane_height(hp, ci, cj, fu, fv, upper):
    """h at fractions (fu, fv) of cell (ci, cj) on the plane of its triangle A (``upper``,
    where fu ≥ fv) or B."""
    h00 = hp[cj, ci]
    h11 = hp[cj + 1, ci + 1]
    if upper:
        return h00 + fu * (hp[cj, ci + 1] - h00) + fv * (h11 - hp[cj, ci + 1])
    return h00 + fv * (hp[cj + 1, ci] - h00) + fu * (h11 - hp[cj + 1, ci])


@_inlined
def _corner_plane(h00, h10, h01, h11, fu, fv, upper):
    """``_plane_height`` from the cell's four corner heights (h10 = hp[cj, ci + 1], h01 =
    hp[cj + 1, ci]), its triangle chosen by selects: the same arithmetic, the same bits."""
    hc = h10 if upper else h01
    w1 = fu if upper else fv
    w2 = fv if upper else fu
    return h00 + w1 * (hc - h00) + w2 * (h11 - hc)


@_inlined
def _tile_of(i, n):
    """⌊i / n⌋ (the starts lie in or next to the first tile)."""
    return 0 if 0 <= i < n else i // n


@_compiled
def direction_terms(dx, dy, dz, cell):
    """Per-direction constants of ``cast_one``: grid steps du, dv and their reciprocals
    (inf for 0), 1/dz, da = du − dv and 1/da (inf for 0), step signs si, sj."""
    du, dv = dx / cell, dy / cell
    rdu = 1.0 / du if du != 0.0 else math.inf
    rdv = 1.0 / dv if dv != 0.0 else math.inf
    da = du - dv
    rda = 1.0 / da if da != 0.0 else math.inf
    si = 1 if du > 0.0 else (-1 if du < 0.0 else 0)
    sj = 1 if dv > 0.0 else (-1 if dv < 0.0 else 0)
    return du, dv, rdu, rdv, 1.0 / dz, da, rda, si, sj


@_inlined
def _step(k, t_wall, dt, c, tile, s, n):
    """One DDA step along an axis: (index k, time of its next wall, index c wrapped into
    [0, n), the tile, 1 if a tile wall was crossed else 0) after moving by ``s`` = ±1."""
    c += s
    if c == n or c < 0:
        return k + s, t_wall + dt, c - s * n, tile + s, 1
    return k + s, t_wall + dt, c, tile, 0


@_inlined
def _clamp01(a):
    return 0.0 if a < 0.0 else (1.0 if a > 1.0 else a)


@_inlined
def _first_cell(x, y, z, t, terms, geometry, ahead):
    """Where the walk of the ray (x, y, z) + t·d starts: (t, u0, v0, i, j, tx, ty, ti, tj, ci,
    cj) — t past the ``ahead`` cells stepped over, the grid coordinates (u0, v0) at t = 0, the
    cell's indices (i, j) and, wrapped into the tile, (ci, cj), the tile (ti, tj) they are in,
    and the times (tx, ty) of the next x and y walls (``cast_one``)."""
    _, _, nx, ny, cell, x0, y0, _, zmax = geometry[:9]
    du, dv, rdu, rdv, _, _, _, si, sj = terms
    inv = 1.0 / cell
    u0, v0 = (x - x0) * inv, (y - y0) * inv  # grid coordinates at t = 0
    i, j = int(math.floor(u0 + t * du)), int(math.floor(v0 + t * dv))
    tx = ((i + (1 if si > 0 else 0)) - u0) * rdu if si != 0 else math.inf
    ty = ((j + (1 if sj > 0 else 0)) - v0) * rdv if sj != 0 else math.inf
    stx, sty = abs(rdu), abs(rdv)
    ti, tj = _tile_of(i, nx), _tile_of(j, ny)  # the tile the walk is in
    ci, cj = i - ti * nx, j - tj * ny
    for _ in range(ahead[cj, ci] if len(ahead) and z >= zmax else 0):  # stepped over, no test
        t = min(tx, ty)  # < t_end, and no tile wall is crossed (``steps_over``)
        if tx <= ty:
            i, ci, tx = i + si, ci + si, tx + stx
        else:
            j, cj, ty = j + sj, cj + sj, ty + sty
    return t, u0, v0, i, j, tx, ty, ti, tj, ci, cj


@_inlined
def cast_one(x, y, z, dx, dy, dz, terms, geometry, side, max_wraps, ahead):
    """(status, face, px, py, pz) of the ray (x, y, z) + t·(dx, dy, dz), dz ≠ 0, started on
    ``side`` of the surface, on ``geometry`` = (hp, cell_max, nx, ny, cell, x0, y0, zmin, zmax,
    max_wraps) with the ray's ``direction_terms``: HIT with the face and the hit point (x and
    y shifted by whole tiles into the tile of the face's cell); ESCAPED (MISSED) for a ray
    that rises past zmax (falls past zmin) without a hit; UNRESOLVED after ``max_wraps`` wall
    crossings (module docstring). ``side`` = (s, bound): (1, cell_max) for a ray at or above
    the surface (f = z − h), (−1, cell_min) for one at or below it (f = h − z)
    (``HeightfieldGrid.side``). Cells the ray crosses wholly on its side (above their highest
    vertex, resp. below their lowest) are stepped over without evaluating f; for a ray falling
    from zmax or above, the first ``ahead[cell]`` of them without testing them either
    (``steps_over``'s table for this direction; ``NO_STEPS``: none), the same steps with the
    same bits."""
    hp, cell_max, nx, ny, cell, _, _, zmin, zmax = geometry[:9]
    s, bound = side
    du, dv, rdu, rdv, rdz, da, rda, si, sj = terms
    if dz < 0.0:  # from where it falls through zmax (nothing lies above) to zmin
        t = (zmax - z) * rdz if z > zmax else 0.0
        t_end = max(t, (zmin - z) * rdz)
    else:  # from where it rises through zmin to zmax
        t = (zmin - z) * rdz if z < zmin else 0.0
        t_end = max(t, (zmax - z) * rdz)
    toward = (dz < 0.0) == (s > 0.0)  # meets the surface by t_end: f ≤ 0 there
    t, u0, v0, i, j, tx, ty, ti, tj, ci, cj = _first_cell(x, y, z, t, terms, geometry, ahead)
    stx, sty = abs(rdu), abs(rdv)
    wraps = 0
    fa, known = 0.0, False  # f at t, once known (the previous cell was not stepped over)
    while True:
        t_exit = min(tx, ty, t_end)
        # the ray's point nearest the surface in this cell: where it leaves the cell when
        # moving toward it, where it enters when moving away
        if t_exit < t_end and s * (z + (t_exit if toward else t) * dz) > s * bound[cj, ci]:
            known = False  # the ray stays on its side of the whole cell
        else:
            # a = (u − i) − (v − j) > 0 in triangle A; the side of a piece is taken at its
            # midpoint, so that a crossing lost to rounding cannot mislabel it
            a = (u0 + t * du - i) - (v0 + t * dv - j)
            upper = a + da * (0.5 * (t_exit - t)) > 0.0
            if not known:  # f where the ray enters the cell
                fu, fv = _clamp01(u0 + t * du - i), _clamp01(v0 + t * dv - j)
                fa = s * (z + t * dz - _plane_height(hp, ci, cj, fu, fv, fu >= fv))
            tb, fb = t_exit, 1.0
            if fa <= 0.0:  # at the surface already (entered exactly on an edge)
                tb, fb = t, fa
                upper = a > 0.0 or (a == 0.0 and da > 0.0)
            elif da != 0.0:
                td = t - a * rda
                if t < td < t_exit:  # crosses the diagonal inside the cell
                    upper = a + da * (0.5 * (td - t)) > 0.0
                    r = _clamp01(u0 + td * du - i)
                    h00 = hp[cj, ci]
                    fd = s * (z + td * dz - (h00 + r * (hp[cj + 1, ci + 1] - h00)))
                    if fd <= 0.0:
                        tb, fb = td, fd
                    else:
                        t, fa, upper = td, fd, not upper
            if tb == t_exit:
                if t_exit == t_end:  # at the relief's far level, on this piece's plane
                    fu, fv = _clamp01(u0 + t_end * du - i), _clamp01(v0 + t_end * dv - j)
                    h = _plane_height(hp, ci, cj, fu, fv, upper)
                elif tx <= ty:  # leaves through the x wall at column ib
                    ib = ci + 1 if si > 0 else ci
                    fv = _clamp01(v0 + t_exit * dv - j)
                    h = hp[cj, ib] + fv * (hp[cj + 1, ib] - hp[cj, ib])
                else:  # through the y wall at row jb
                    jb = cj + 1 if sj > 0 else cj
                    fu = _clamp01(u0 + t_exit * du - i)
                    h = hp[jb, ci] + fu * (hp[jb, ci + 1] - hp[jb, ci])
                fb = s * (z + t_exit * dz - h)
                if t_exit == t_end and fb > 0.0:
                    if not toward:  # cleared the relief
                        return ESCAPED if dz > 0.0 else MISSED, -1, math.nan, math.nan, math.nan
                    fb = 0.0  # below every vertex (above, from below): only rounding says not
            if fb <= 0.0:  # the root of this piece
                th = t + (tb - t) * (fa / (fa - fb)) if fa > fb else t
                face = cj * nx + ci if upper else nx * ny + cj * nx + ci
                return (
                    HIT,
                    face,
                    x + th * dx - ti * nx * cell,
                    y + th * dy - tj * ny * cell,
                    z + th * dz,
                )
            fa, known = fb, True
        t = t_exit
        if tx <= ty:
            i, tx, ci, ti, wrapped = _step(i, tx, stx, ci, ti, si, nx)
        else:
            j, ty, cj, tj, wrapped = _step(j, ty, sty, cj, tj, sj, ny)
        wraps += wrapped
        if wraps > max_wraps:
            return UNRESOLVED, -1, math.nan, math.nan, math.nan


@_compiled
def cast_falling(x, y, z, dx, dy, dz, geometry, ahead, status, prim, px, py, pz):
    """``cast_one`` for rays (x, y, z)[i] along one falling direction (dx, dy, dz) on
    ``geometry`` (``HeightfieldGrid.geometry``, then zmin, zmax, max_wraps, lanes), with the
    cells ``ahead`` surely stepped over (``steps_over`` of this direction, or ``NO_STEPS``);
    writes ``status``, ``prim`` and the hit point columns. ``LANES`` rays at a time
    (``cast_lanes``) where ``lanes`` is set, else one by one: the same bits."""
    if geometry[10]:
        cast_lanes(x, y, z, dx, dy, dz, geometry, ahead, status, prim, px, py, pz)
        return
    terms = direction_terms(dx, dy, dz, geometry[4])
    above = (1.0, geometry[1])
    for i in range(len(x)):
        s, f, a, b, c = cast_one(
            x[i], y[i], z[i], dx, dy, dz, terms, geometry, above, geometry[9], ahead
        )
        status[i], prim[i], px[i], py[i], pz[i] = s, f, a, b, c


LANES = 16
"""Rays ``cast_lanes`` walks side by side: two AVX-512 registers of float64 per quantity."""


@_inlined
def _above_cells(z, dz, t, t_end, tx, ty, stx, sty, i, j, ci, cj, si, sj, nx, ny, cell_max):
    """(t, tx, ty, i, j, ci, cj) after the cells a ray falling from height z above the
    surface leaves above their highest vertex, up to a tile wall: the steps ``cast_one``
    takes through them (each sets nothing else), taken one by one here, where a mispredicted
    exit costs less than a step of all the lanes."""
    while True:
        t_exit = min(tx, ty, t_end)
        if not (t_exit < t_end and z + t_exit * dz > cell_max[cj, ci]):
            return t, tx, ty, i, j, ci, cj
        if tx <= ty:
            if ci + si == nx or ci + si < 0:
                return t, tx, ty, i, j, ci, cj
            t, i, tx, ci = t_exit, i + si, tx + stx, ci + si
        else:
            if cj + sj == ny or cj + sj < 0:
                return t, tx, ty, i, j, ci, cj
            t, j, ty, cj = t_exit, j + sj, ty + sty, cj + sj


@_compiled
def cast_lanes(x, y, z, dx, dy, dz, geometry, ahead, status, prim, px, py, pz):
    """``cast_falling`` with ``LANES`` rays walked side by side, one cell of each per round:
    a round is ``cast_one``'s loop body for a ray above the surface (s = 1), its branches
    turned into selects (``_lane_cell``), in a loop over the lanes that the compiler
    vectorises (each lane's corner heights and highest vertex gathered); between rounds, one
    by one, each lane whose ray hit (or went UNRESOLVED) writes it out and takes the next ray,
    whose first cell and the cells it leaves above are found on its own (``_first_cell``,
    ``_above_cells``). Every ray takes the same steps with the same arithmetic as
    ``cast_one``: the same bits (tests/test_heightfield_caster.py). Lane state lives on the
    stack (``lane_scratch``); with no ray left, a lane idles (its rounds read valid cells)."""
    hp, cell_max, nx, ny, cell, _, _, zmin, zmax, max_wraps = geometry[:10]
    terms = direction_terms(dx, dy, dz, cell)
    du, dv, rdu, rdv, rdz, da, rda, si, sj = terms
    stx, sty = abs(rdu), abs(rdv)
    n = len(x)
    ray, done = lane_scratch(LANES, np.int64), lane_scratch(LANES, np.int8)
    t_, t_end_ = lane_scratch(LANES, np.float64), lane_scratch(LANES, np.float64)
    u0_, v0_ = lane_scratch(LANES, np.float64), lane_scratch(LANES, np.float64)
    tx_, ty_ = lane_scratch(LANES, np.float64), lane_scratch(LANES, np.float64)
    fa_, z_ = lane_scratch(LANES, np.float64), lane_scratch(LANES, np.float64)
    i_, j_ = lane_scratch(LANES, np.int64), lane_scratch(LANES, np.int64)
    ci_, cj_ = lane_scratch(LANES, np.int64), lane_scratch(LANES, np.int64)
    ti_, tj_ = lane_scratch(LANES, np.int64), lane_scratch(LANES, np.int64)
    wraps_, known_ = lane_scratch(LANES, np.int64), lane_scratch(LANES, np.uint8)
    th_, face_ = lane_scratch(LANES, np.float64), lane_scratch(LANES, np.int64)
    for k in range(LANES):
        ray[k], done[k] = -2, 1  # empty: takes a ray (or ray 0's start, idle) before round 1
    nxt, live = 0, 0
    while n > 0:
        for k in range(LANES):  # one by one: write out the finished rays, start the next
            if done[k] == 0:
                continue
            q = ray[k]
            if q >= 0 and done[k] == 1:
                th = th_[k]
                status[q], prim[q] = HIT, face_[k]
                px[q] = x[q] + th * dx - ti_[k] * nx * cell
                py[q] = y[q] + th * dy - tj_[k] * ny * cell
                pz[q] = z[q] + th * dz
            elif q >= 0:
                status[q], prim[q] = UNRESOLVED, -1
                px[q], py[q], pz[q] = math.nan, math.nan, math.nan
            live -= q >= 0
            if nxt == n and q != -2:  # no ray left: the lane idles where it is
                ray[k] = -1
                continue
            q = nxt if nxt < n else -1
            nxt, live, r = nxt + (q >= 0), live + (q >= 0), max(q, 0)
            t = (zmax - z[r]) * rdz if z[r] > zmax else 0.0
            t_end = max(t, (zmin - z[r]) * rdz)
            t, u0, v0, i, j, tx, ty, ti, tj, ci, cj = _first_cell(
                x[r], y[r], z[r], t, terms, geometry, ahead
            )
            t, tx, ty, i, j, ci, cj = _above_cells(
                z[r], dz, t, t_end, tx, ty, stx, sty, i, j, ci, cj, si, sj, nx, ny, cell_max
            )
            ray[k], done[k], z_[k], fa_[k], known_[k], wraps_[k] = q, 0, z[r], 0.0, 0, 0
            t_[k], t_end_[k], u0_[k], v0_[k], tx_[k], ty_[k] = t, t_end, u0, v0, tx, ty
            i_[k], j_[k], ci_[k], cj_[k], ti_[k], tj_[k] = i, j, ci, cj, ti, tj
        if live == 0:
            return
        for k in range(LANES):  # vectorised: one cell of every lane
            t, t_exit, above, hit, upper, th, fb = _lane_cell(
                t_[k], t_end_[k], u0_[k], v0_[k], tx_[k], ty_[k], fa_[k], z_[k], known_[k] != 0,
                i_[k], j_[k], ci_[k], cj_[k], dz, terms, hp, cell_max,
            )  # fmt: skip
            ci, cj, tx, ty = ci_[k], cj_[k], tx_[k], ty_[k]
            th_[k], face_[k] = th, cj * nx + ci if upper else nx * ny + cj * nx + ci
            fa_[k], known_[k], t_[k] = fa_[k] if above else fb, 0 if above else 1, t_exit
            # the next cell (``_step``); a ray that hit keeps its tile for its hit point
            xw = tx <= ty
            c, m, sc = (ci + si, nx, si) if xw else (cj + sj, ny, sj)
            wrapped = c == m or c < 0
            c = c - sc * m if wrapped else c
            tile = sc if wrapped and not hit else 0
            if xw:
                i_[k], tx_[k], ci_[k], ti_[k] = i_[k] + si, tx + stx, c, ti_[k] + tile
            else:
                j_[k], ty_[k], cj_[k], tj_[k] = j_[k] + sj, ty + sty, c, tj_[k] + tile
            wraps_[k] += 1 if wrapped else 0
            done[k] = 1 if hit else (2 if wraps_[k] > max_wraps else 0)


@_inlined
def _lane_cell(t, t_end, u0, v0, tx, ty, fa, z, known, i, j, ci, cj, dz, terms, hp, cell_max):
    """``cast_one``'s loop body for one cell of a falling ray above the surface (s = 1, toward),
    every branch computed and the taken one selected: (t, t_exit, above, hit, upper, th, fb) —
    t as the body leaves it (past a diagonal crossed above the surface), the cell's exit time,
    whether the ray left the cell above its highest vertex (f not evaluated), whether the
    piece's root lies in this cell, the hit triangle (A if ``upper``), the hit's time th, and
    f at the exit."""
    du, dv, _, _, _, da, rda, si, sj = terms
    uci, ucj = np.uint64(ci), np.uint64(cj)  # ≥ 0: no index wrap-around per lane
    one = np.uint64(1)
    t_exit = min(tx, ty, t_end)
    far = t_exit == t_end
    above = not far and z + t_exit * dz > cell_max[ucj, uci]
    h00, h10 = hp[ucj, uci], hp[ucj, uci + one]
    h01, h11 = hp[ucj + one, uci], hp[ucj + one, uci + one]
    fi, fj = float(i), float(j)
    ut, vt = u0 + t * du - fi, v0 + t * dv - fj
    a = ut - vt
    upper = a + da * (0.5 * (t_exit - t)) > 0.0
    fu, fv = _clamp01(ut), _clamp01(vt)
    fa = fa if known else z + t * dz - _corner_plane(h00, h10, h01, h11, fu, fv, fu >= fv)
    at_surface = fa <= 0.0  # entered exactly on an edge
    td = t - a * rda
    crosses = not at_surface and da != 0.0 and t < td < t_exit  # the diagonal, in the cell
    r = _clamp01(u0 + td * du - fi)
    fd = z + td * dz - (h00 + r * (h11 - h00))
    ends = crosses and fd <= 0.0  # the root lies before the diagonal
    passes = crosses and not fd <= 0.0
    upper_d = a + da * (0.5 * (td - t)) > 0.0
    if at_surface:
        upper = a > 0.0 or (a == 0.0 and da > 0.0)
    elif crosses:
        upper = upper_d if ends else not upper_d
    tb = t if at_surface else (td if ends else t_exit)
    fb = fa if at_surface else (fd if ends else 1.0)
    t, fa = (td, fd) if passes else (t, fa)
    # f where the piece ends: at the relief's far level on its plane, else on the wall crossed
    fu_end, fv_end = _clamp01(u0 + t_end * du - fi), _clamp01(v0 + t_end * dv - fj)
    h_end = _corner_plane(h00, h10, h01, h11, fu_end, fv_end, upper)
    fv_x, fu_y = _clamp01(v0 + t_exit * dv - fj), _clamp01(u0 + t_exit * du - fi)
    xa, xb = (h10, h11) if si > 0 else (h00, h01)
    ya, yb = (h01, h11) if sj > 0 else (h00, h10)
    h = h_end if far else (xa + fv_x * (xb - xa) if tx <= ty else ya + fu_y * (yb - ya))
    f_wall = z + t_exit * dz - h
    f_wall = 0.0 if far and f_wall > 0.0 else f_wall  # below every vertex: only rounding says not
    fb = f_wall if tb == t_exit else fb
    hit = not above and fb <= 0.0
    th = t + (tb - t) * (fa / (fa - fb)) if fa > fb else t
    return t, t_exit, above, hit, upper, th, fb


@_inlined
def height_at(hp, nx, ny, cell, x0, y0, x, y):
    """h(x, y) on the periodic tile (any x, y; wrapped into it)."""
    u, v = (x - x0) / cell, (y - y0) / cell
    i, j = int(math.floor(u)), int(math.floor(v))
    fu, fv = u - i, v - j
    ci, cj = i - _tile_of(i, nx) * nx, j - _tile_of(j, ny) * ny
    return _plane_height(hp, ci, cj, _clamp01(fu), _clamp01(fv), fu >= fv)


@_compiled
def cast_columns(x, y, z, dx, dy, dz, shared, geometry, cell_min, max_wraps, occlusion, out):
    """``cast_one`` for rays (x, y, z)[i] along (dx, dy, dz)[i] (index 0 for all when
    ``shared``), rising or falling, on ``geometry`` with the wrap cap ``max_wraps``; writes
    ``out`` = (status, prim, px, py, pz) (``segments.WalkResult``; status only for
    ``occlusion``). Each ray's side is that of its start: above the surface where z ≥ h(x, y)
    (a start above zmax, or lifted off a facet along its normal), else below it (inside a
    dielectric medium, bounded by ``cell_min``). A horizontal ray (dz = 0) beyond the relief
    leaves it; one within it walks until it meets the surface or reaches the wrap cap."""
    status, prim, px, py, pz = out
    hp, nx, ny, cell, x0, y0 = (
        geometry[0],
        geometry[2],
        geometry[3],
        geometry[4],
        geometry[5],
        geometry[6],
    )
    zmin, zmax = geometry[7], geometry[8]
    above, below = (1.0, geometry[1]), (-1.0, cell_min)
    terms = direction_terms(dx[0], dy[0], dz[0], cell)
    for i in range(len(x)):
        k = 0 if shared else i
        if not shared:
            terms = direction_terms(dx[k], dy[k], dz[k], cell)
        zi = z[i]
        up = zi >= zmax or (zi > zmin and zi >= height_at(hp, nx, ny, cell, x0, y0, x[i], y[i]))
        if dz[k] == 0.0 and (zi >= zmax or zi <= zmin):
            status[i] = ESCAPED if zi >= zmax else MISSED
            continue
        s, f, a, b, c = cast_one(
            x[i],
            y[i],
            zi,
            dx[k],
            dy[k],
            dz[k],
            terms,
            geometry,
            above if up else below,
            max_wraps,
            NO_STEPS,
        )
        status[i] = s
        if not occlusion:
            prim[i], px[i], py[i], pz[i] = f, a, b, c
