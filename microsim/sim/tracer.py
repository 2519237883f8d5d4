"""Ray tracing of an infinite periodic microsurface with Embree (embreex), one tile at a time.

The scene holds a single tile [-Lx/2, Lx/2] x [-Ly/2, Ly/2] (float32, centred on the origin,
robust mode). A ray sees the infinite periodic repetition exactly: each segment is traced up
to the point where the ray leaves the tile's xy box (or rises above the surface top zmax);
without a hit, the ray re-enters through the opposite wall at the same height and goes on.
A ray that reaches z >= zmax going up has escaped; one that sinks below zmin without a hit has
leaked through the mesh ("missed", impossible for a closed periodic surface).

Secondary rays start from the hit point o + t·d (float64, Embree's float32 distance t)
projected along the unit facet normal onto the facet plane, then offset along that normal by
``eps``, a few float32 ulp of the tile's largest coordinate (Embree's tnear is fixed at 0). The
offset biases grazing masking by ~eps / feature depth (docs/design.md, "Numerical hazards"), so
V-groove surfaces can instead decide masking exactly in float64
(``vgroove_profile.VGrooveProfile``).

Speed: each segment of the walk (``periodic_walk``) is one Embree call between two compiled
passes over the live rays. The BVH is built on the first Embree query (``Tracer.scene``): a
heightfield tile traced with ``grid`` walks every ray on its grid (``heightfield_caster``)
and never builds it.

Backends (``embree_backends``): each segment's Embree call goes either to embreex (one ray per
``rtcIntersect1``) or, when the Embree 4 library embreex bundles can be bound
(``embree_packets``), to coherent packets of the native width (``rtcIntersect8``/``16``), same
robust scene, same float32 rays, same tnear/tfar: per-ray answers equal except exact ties
between facets at one float32 distance (tests/test_packets.py). ``backend="auto"`` picks packets
when available (the packet scene is also built from the arrays in one copy per buffer, not
element by element).

``Tracer``'s own default is "embreex", the tests' reference path; simulations use "auto"
(``tracer_cache.TRACER_BACKEND``): on this project's AVX2 machines 8-wide packets trace about as
fast as single rays (1.0–1.2×, ``microsim bench``), but the packet scene builds in 0.10 s
against embreex's 0.5 s. Masking rays of heightfields are decided without tracing where a bound
shows they clear the surface (``horizon_bounds``: ``rise_bound``, ``clears_horizon``). V-groove
geometry decided exactly in float64 lives in ``vgroove_profile``.
"""

from __future__ import annotations

import functools
import math
import threading
from dataclasses import dataclass

import numpy as np

from microsim.errors import UsageError
from microsim.jit import vectorised
from microsim.surfaces.surface import (
    MAX_COORDINATE,
    check_relief,
    heightfield_faces,
    heightfield_vertices,
)

from .embree_backends import check_backend, open_scene, scene_backend
from .engine import beam, codes, horizon
from .engine.facets import Facets, grid_facets, mesh_facets, triangle_plane
from .heightfield_caster import NO_STEPS, cast_falling, heightfield_grid
from .horizon_bounds import CLEAR_MARGIN, horizon_grid, rise_bound, slope_magnitudes
from .periodic_walk import ColumnHits, walk_columns
from .schedule import in_parts
from .scratch import WorkArray, WorkColumns
from .vgroove_profile import NO_GROOVES, NO_STRATA, groove_tables

__all__ = [
    "Tracer",
    "Hits",
    "HIT",
    "ESCAPED",
    "UNRESOLVED",
    "MISSED",
    "BLOCKED",
    "MAX_TRACED_DEG",
]

HIT, ESCAPED, UNRESOLVED, MISSED = 0, 1, 2, 3
assert (HIT, ESCAPED, UNRESOLVED, MISSED) == (
    codes.HIT,
    codes.ESCAPED,
    codes.UNRESOLVED,
    codes.MISSED,
)
BLOCKED = HIT  # an occlusion ray that met the surface
MAX_TRACED_DEG = 89.5  # rays up to this polar angle are always resolved (wrap cap)
BASE_WRAPS = 64


@dataclass(frozen=True)
class Hits:
    """First intersections of a batch of rays (tile coordinates, float64).

    ``status`` (N,) int8: HIT, ESCAPED, UNRESOLVED (wrap cap reached) or MISSED (leaked);
    ``prim`` (N,) face index (−1 without a hit); ``point`` (N, 3) hit point on the facet plane
    (NaN without a hit); ``normal`` (N, 3) unit facet normal (NaN without a hit).
    """

    status: np.ndarray
    prim: np.ndarray
    point: np.ndarray
    normal: np.ndarray


def _validated_mesh(surface) -> tuple[np.ndarray, np.ndarray, float, float]:
    v = np.asarray(surface.vertices, dtype=np.float64)
    f = np.asarray(surface.faces)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) < 3:
        raise UsageError(f"surface.vertices must be a (V >= 3, 3) array, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise UsageError("surface.vertices must be finite (got NaN or inf)")
    if f.ndim != 2 or f.shape[1] != 3 or len(f) < 1:
        raise UsageError(
            f"surface.faces must be a non-empty (F, 3) integer array, got shape {f.shape}"
        )
    if not np.issubdtype(f.dtype, np.integer) or f.min() < 0 or f.max() >= len(v):
        raise UsageError(f"surface.faces must hold vertex indices in [0, {len(v) - 1}]")
    lx, ly = (float(t) for t in surface.tile_size)
    if not (lx > 0 and ly > 0 and np.isfinite(lx) and np.isfinite(ly)):
        raise UsageError(
            f"surface.tile_size must be two finite lengths > 0, got {surface.tile_size!r}"
        )
    if not (max(lx, ly) <= MAX_COORDINATE):
        raise UsageError(
            f"surface.tile_size must be within {MAX_COORDINATE:g} (float32), "
            f"got {surface.tile_size!r}"
        )
    check_relief("surface", v[:, 2].min(), v[:, 2].max(), (lx, ly))
    tol = 1e-9 * max(lx, ly)
    if any(max(-v[:, k].min(), v[:, k].max()) > side / 2 + tol for k, side in ((0, lx), (1, ly))):
        raise UsageError("surface.vertices must lie in the tile [-Lx/2, Lx/2] x [-Ly/2, Ly/2]")
    return v, f if f.dtype in (np.int32, np.int64) else f.astype(np.int64), lx, ly


def _validated_heights(surface) -> tuple[np.ndarray, float, float]:
    """(heights, Lx, Ly) of a surface that stores no mesh (``Surface.stores_mesh`` False): a
    finite (ny, nx) grid whose derived mesh spans its tile (nx·dx, ny·dx)."""
    h = np.asarray(surface.heights, dtype=np.float64)
    dx = float(surface.dx)
    if h.ndim != 2 or min(h.shape) < 1:
        raise UsageError(f"surface.heights must be a 2D (ny, nx) array, got shape {h.shape}")
    if not (dx > 0 and np.isfinite(dx)):
        raise UsageError(f"surface.dx must be a finite length > 0, got {surface.dx!r}")
    ny, nx = h.shape
    lx, ly = (float(t) for t in surface.tile_size)
    if not np.allclose((lx, ly), (nx * dx, ny * dx), rtol=1e-9, atol=0.0):
        raise UsageError(
            f"surface.tile_size must be (nx·dx, ny·dx) = ({nx * dx:g}, {ny * dx:g}) for its "
            f"heights, got {surface.tile_size!r}"
        )
    if not (max(lx, ly) <= MAX_COORDINATE):
        raise UsageError(
            f"surface.tile_size must be within {MAX_COORDINATE:g} (float32), "
            f"got {surface.tile_size!r}"
        )
    zmin, zmax = float(h.min()), float(h.max())  # NaN propagates: refused as not finite
    check_relief("surface", zmin, zmax, (lx, ly))
    return h, lx, ly


@vectorised
def _fill_facet_planes(v, f, lo, hi, rows, plane) -> tuple:
    """The unit normal and plane offset n·v0 of facets ``lo`` … ``hi`` − 1 of (``v``, ``f``)
    (``facets.triangle_plane``) into ``rows`` (3, F) and ``plane`` (F,); (degenerate,
    downward): whether any of them has zero area (its entries left unset), any normal
    z ≤ 0."""
    degenerate, downward = False, False
    for k in range(lo, hi):
        a, b, c = f[k, 0], f[k, 1], f[k, 2]
        nx, ny, nz, offset, norm = triangle_plane(
            v[a, 0], v[a, 1], v[a, 2], v[b, 0], v[b, 1], v[b, 2], v[c, 0], v[c, 1], v[c, 2]
        )
        if norm == 0.0:
            degenerate = True
            continue
        downward |= nz <= 0.0
        rows[0, k], rows[1, k], rows[2, k] = nx, ny, nz
        plane[k] = offset
    return degenerate, downward


def _facet_planes(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The unit normals of the facets as rows (3, F) and their planes' offsets n·v0 (F,),
    float64 (``_fill_facet_planes``, in facet ranges on several threads, ``schedule.in_parts``:
    each facet's entries depend on it alone). UsageError for a degenerate facet or one whose
    normal does not point up."""
    rows, plane = np.empty((3, len(f))), np.empty(len(f))
    flags = in_parts(len(f), lambda lo, hi: _fill_facet_planes(v, f, lo, hi, rows, plane))
    degenerate, downward = (any(flag[k] for flag in flags) for k in range(2))
    if degenerate:
        raise UsageError("surface.faces must not contain degenerate (zero-area) triangles")
    if downward:
        raise UsageError(
            "surface.faces must be ordered so that every normal "
            "cross(v1 - v0, v2 - v0) points up (z > 0)"
        )
    return rows, plane


NO_MESH = (np.empty((0, 3)), np.empty((0, 3), dtype=np.int32))
"""``horizon_grid``'s corners argument for a heightfield grid: none (derived from heights)."""
_CAST_STATUS = WorkArray("cast-status", np.int8)  # the grid walk's hits (``scratch``)
_CAST_PRIM = WorkArray("cast-prim", np.int32)
_CAST_POINT = WorkColumns("cast-point")


class Tracer:
    """Periodic Embree scene of one tile of ``surface`` (a ``microsim.surfaces.Surface``).

    Attributes: ``vertices`` (V, 3) float64 and ``faces`` (F, 3) integer (the surface's own
    arrays where they already have these types; derived from the heights on each access for
    a surface that stores no mesh), ``facets`` (``engine.facets.Facets``: the
    unit facet normals and their planes' offsets n·v0, stored for a mesh and derived from the
    heights where they are read on a heightfield grid; a secondary ray from facet f starts on
    the plane n·x = n·v0 + eps), ``tile`` (Lx, Ly),
    ``zmin``/``zmax``, ``eps`` (secondary-ray offset along the normal, length units),
    ``top_margin`` (primary rays start at zmax + it) and ``max_wraps`` (tile crossings per ray
    before it counts as unresolved: 64 plus enough for a ray 89.5° from the normal to cross the
    whole height range), ``rise_bound`` (the steepest facet slope of a heightfield, inf
    otherwise: masking rays steeper than it are not traced, ``surely_escapes``), ``horizon`` (a
    coarse grid of cell maxima on which the other masking rays of a heightfield are cleared
    without tracing when they can be, ``clears_horizon``), ``facet_tables`` (the facet tables
    ``facet_tables.facet_table`` keeps for the tracer's most recent incidences).

    ``backend``: "embreex" (the default and reference), "auto" (packets when
    ``embree_packets`` can bind the library, else embreex) or "packets" (UsageError when
    unavailable); the one used is ``self.backend``.
    ``MICROSIM_EMBREE_PACKETS=0`` in the environment makes "auto" choose embreex.
    ``grid``: on a heightfield tile, walk every ray on its grid (``heightfield_caster``:
    primary, masking and bounce rays, from above or below the surface) instead of Embree,
    whose scene is then never built; ``self.grid`` is the ``HeightfieldGrid`` (None when off
    or when the mesh is not a heightfield grid).
    """

    _scene = None

    def __init__(self, surface, *, backend: str = "embreex", grid: bool = False):
        check_backend(backend)
        if getattr(surface, "stores_mesh", True) is False and surface.periodic:
            h, lx, ly = _validated_heights(surface)  # no mesh: derived where asked for
            self._mesh = None
            self._heightfield = heightfield_grid(surface)
            self.zmin, self.zmax = float(h.min()), float(h.max())
            big = max(-self.zmin, self.zmax, lx / 2, ly / 2)  # max |v| of the derived mesh
        else:
            v, f, lx, ly = _validated_mesh(surface)
            self._mesh = (v, f)
            self._heightfield = heightfield_grid(surface, v, f)  # None unless a grid
            self.zmin, self.zmax = float(v[:, 2].min()), float(v[:, 2].max())
            big = max(-float(v.min()), float(v.max()), lx / 2, ly / 2)  # max |v|, no copy
        self.grid = self._heightfield if grid else None
        self.tile = (lx, ly)
        self.half = np.array([lx / 2, ly / 2])
        self.eps = 2.0 * float(np.spacing(np.float32(big)))  # 2 ulp: 1.2e-7 on a unit tile
        hf = self._heightfield
        self.facets: Facets = (
            mesh_facets(*_facet_planes(*self._mesh), self.eps)
            if hf is None
            else grid_facets(hf.hp, hf.cell, self.eps)  # derived from the heights
        )
        self.top_margin = 4.0 * self.eps  # primary rays start this far above zmax
        depth = self.zmax - self.zmin + self.top_margin
        crossings = depth * np.tan(np.radians(MAX_TRACED_DEG)) * (1 / lx + 1 / ly)
        self.max_wraps = BASE_WRAPS + int(np.ceil(crossings))
        self.periodic = bool(surface.periodic)
        slopes = slope_magnitudes(self.facets)  # (F,), for the two bounds only
        self.rise_bound = rise_bound(surface, slopes)
        corners = NO_MESH if hf is not None else self._mesh  # a grid's: from its heights
        walk = (
            None if self.grid is None else self.grid.geometry(self.zmin, self.zmax, self.max_wraps)
        )
        self.horizon = horizon_grid(self.facets, *corners, slopes, self.rise_bound, self.tile, walk)
        del slopes
        grooved = getattr(surface, "azimuth_average", False)
        self.groove_clear, self.groove_strata = (
            groove_tables(self) if grooved else (NO_GROOVES, NO_STRATA)
        )
        self.facet_tables: dict = {}  # kept by facet_tables.facet_table: key → (table, bytes)
        self.backend = scene_backend(backend)
        self._scene_lock = threading.Lock()

    @property
    def vertices(self) -> np.ndarray:
        """(V, 3) float64 vertices: the surface's, or those of ``heightfield_mesh`` derived
        from the grid's heights on each access (a surface that stores no mesh)."""
        if self._mesh is not None:
            return self._mesh[0]
        return heightfield_vertices(self._heightfield.hp[:-1, :-1], self._heightfield.cell)

    @property
    def faces(self) -> np.ndarray:
        """(F, 3) integer faces, stored or derived as ``vertices``."""
        if self._mesh is not None:
            return self._mesh[1]
        return heightfield_faces(self._heightfield.hp[:-1, :-1], self._heightfield.cell)

    @property
    def normals(self) -> np.ndarray:
        """(F, 3) unit facet normals, float64 (``Facets.normals``: computed on each access
        on a heightfield grid)."""
        return self.facets.normals()

    @property
    def scene(self):
        """The Embree scene of the mesh (``embree_backends.open_scene``), built on first use:
        a run whose rays all walk the heightfield grid never builds it."""
        with self._scene_lock:
            if self._scene is None:
                self._scene = open_scene(self.vertices, self.faces, self.backend)
            return self._scene

    @functools.cached_property
    def beam(self) -> "beam.BeamGrid | None":
        """What ``beam.beam_clear`` reads to clear a lit facet's masking rays all at once
        (meshes that are heightfield grids, whether or not ``grid`` walks their primary
        rays; else None); tolerance that of ``horizon``."""
        if self._heightfield is None:
            return None
        return beam.beam_grid(self._heightfield, self.facets, self.zmax, self.horizon.tol)

    @functools.cached_property
    def beam_below(self) -> "beam.BeamGrid | None":
        """``beam``'s grid for rays leaving the surface downward below it (inside a dielectric
        medium): ``beam.mirrored_beam_grid``; None as ``beam``."""
        if self._heightfield is None:
            return None
        tol = self.horizon.tol
        return beam.mirrored_beam_grid(self._heightfield, self.facets, self.zmin, tol)

    # --- periodic walk (``periodic_walk``) ------------------------------------------------
    def _walk(self, origins, dirs, occlusion: bool):
        """Trace rays through the periodic repetition; returns (status, prim, point).

        ``dirs`` is (N, 3) or one direction (3,) shared by all rays (handed to Embree once).
        ``prim`` (N,) int32 face index, −1 without a hit; ``point`` (N, 3) float64 hit point
        o + t·d (Embree's float32 distance, not yet on the facet plane; NaN without a hit);
        both None for occlusion queries."""
        o = np.asarray(origins, dtype=np.float64)
        dirs = np.asarray(dirs, dtype=np.float64)
        shared = dirs.ndim == 1
        d = (
            [float(c) for c in dirs]
            if shared
            else [np.ascontiguousarray(dirs[:, k]) for k in range(3)]
        )
        d32 = (
            dirs.astype(np.float32)[None]
            if shared
            else np.ascontiguousarray(dirs, dtype=np.float32)
        )
        x = [np.ascontiguousarray(o[:, k]) for k in range(3)]
        status, prim, p = walk_columns(self, x, d, d32, occlusion)
        if occlusion:
            return status, None, None
        point = np.empty((len(status), 3))
        for k in range(3):
            point[:, k] = p[k]
        point[status != HIT] = np.nan
        return status, prim, point

    def trace(self, origins: np.ndarray, dirs: np.ndarray):
        """Lean first-hit query: (status (N,) int8, prim (N,) int32, point (N, 3) float64).

        ``point`` is the hit Embree found (its float32 ray and distance, evaluated in float64),
        not yet projected onto the facet plane (NaN without a hit); see ``first_hit``."""
        return self._walk(origins, dirs, occlusion=False)

    def holds(self, x) -> bool:
        """Whether every start of the columns ``x`` lies in the tile, −L/2 ≤ x, y < L/2
        (``periodic_walk.walk_columns`` wraps the others)."""
        return bool(
            len(x[0]) == 0
            or all(x[a].min() >= -self.half[a] and x[a].max() < self.half[a] for a in (0, 1))
        )

    def grid_walk(self, x, down):
        """The grid walk's geometry (``HeightfieldGrid.geometry``) for rays from the starts
        ``x`` (3 columns) along one falling direction ``down`` (3 floats), or None when the
        tracer has no grid or a start lies outside the tile or below zmax (``walk_columns``
        walks those)."""
        g = self.grid
        if g is None or not down[2] < 0.0 or not self.holds(x):
            return None
        if len(x[0]) and x[2].min() < self.zmax:
            return None
        return g.geometry(self.zmin, self.zmax, self.max_wraps)

    def cast_falling(self, x, down):
        """First hits of rays from the starts ``x`` (3 columns, in the tile, at or above zmax)
        along one falling direction ``down`` (3 floats) by the grid walk
        (``heightfield_caster.cast_falling``): (status, prim, point columns) as
        ``trace_columns`` returns them, in this thread's work arrays (valid until its next
        call) — or None where ``grid_walk`` is None."""
        geometry = self.grid_walk(x, down)
        if geometry is None:
            return None
        n = len(x[0])
        status, prim, point = _CAST_STATUS(n), _CAST_PRIM(n), _CAST_POINT(n)
        cast_falling(*x, *(float(c) for c in down), geometry, NO_STEPS, status, prim, *point)
        return ColumnHits(status, prim, point)

    def trace_columns(self, x, d, d32, wraps=None, first=None):
        """``trace`` on per-axis columns (``periodic_walk.walk_columns``, also for ``first``):
        ``ColumnHits``, the point columns undefined where status is not HIT. ``wraps``: wrap
        cap (default ``max_wraps``; ``wraps_needed`` gives what a direction needs)."""
        return walk_columns(self, x, d, d32, occlusion=False, first=first, wraps=wraps)

    def wraps_needed(self, dx, dy, dz) -> np.ndarray:
        """Tile crossings (N,) after which a ray along (dx, dy, dz) (columns, unit) has either
        met the surface, risen above zmax or sunk below zmin, wherever it starts between them:
        ``BASE_WRAPS`` + ⌈(zmax − zmin + top_margin)·|d_h|/|d_z|·(1/Lx + 1/Ly)⌉ (inf for
        d_z = 0). ``max_wraps`` is this for the steepest traced polar angle (89.5°)."""
        depth = self.zmax - self.zmin + self.top_margin
        with np.errstate(divide="ignore", invalid="ignore"):
            run = depth * np.hypot(dx, dy) / np.abs(dz)
        return BASE_WRAPS + np.ceil(run * (1 / self.tile[0] + 1 / self.tile[1]))

    def escape_columns(self, x, d, d32, first=None) -> np.ndarray:
        """Occlusion status of rays given as per-axis columns (``periodic_walk.walk_columns``,
        also for ``first``); the starts ``x`` must already be offset from the surface."""
        return walk_columns(self, x, d, d32, occlusion=True, first=first).status

    def clears_horizon(self, points: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Whether rays from surface ``points`` (N, 3) (inside the tile, at or just above
        the surface) along ``dirs`` (N, 3) surely clear the surface by the coarse grid
        (``horizon.horizon_clear``), (N,) bool; always False off heightfields."""
        p = [np.ascontiguousarray(points[:, k], dtype=np.float64) for k in range(3)]
        d = [np.ascontiguousarray(dirs[:, k], dtype=np.float64) for k in range(3)]
        out = np.empty(len(p[0]), dtype=np.bool_)
        horizon.horizon_clear_all(*p, *d, self.horizon, self.zmax, out)
        return out

    def surely_escapes(self, dx, dy, dz) -> np.ndarray:
        """Whether a ray leaving the surface along (dx, dy, dz) (columns or scalars) cannot
        meet it again, without tracing it: dz > ``CLEAR_MARGIN`` · ``rise_bound`` · |d_h|
        (always False when ``rise_bound`` is inf), |d_h| = √(dx² + dy²) as the kernels
        compute it (``horizon.surely_escaping``)."""
        shape = np.broadcast_shapes(np.shape(dx), np.shape(dy), np.shape(dz))
        out = np.zeros(shape, dtype=bool)
        if math.isfinite(self.rise_bound):
            d = [
                np.ascontiguousarray(np.broadcast_to(c, shape), dtype=np.float64)
                for c in (dx, dy, dz)
            ]
            slope = CLEAR_MARGIN * self.rise_bound
            horizon.surely_escaping(*(c.reshape(-1) for c in d), slope, out.reshape(-1))
        return out

    def on_plane(self, prim: np.ndarray, point: np.ndarray, lift: float = 0.0) -> np.ndarray:
        """``point`` (N, 3) moved along the unit normal of facet ``prim`` (N,) onto that facet's
        plane, then ``lift`` (length units) above it."""
        nrm = self.facets.normals(prim)
        off = (
            point[:, 0] * nrm[:, 0]
            + point[:, 1] * nrm[:, 1]
            + point[:, 2] * nrm[:, 2]
            - self.facets.planes(prim)
            - lift
        )
        return point - off[:, None] * nrm

    def first_hit(self, origins: np.ndarray, dirs: np.ndarray) -> Hits:
        """Closest intersection of rays ``origins + t·dirs`` (t > 0) with the periodic surface.

        ``origins`` (N, 3) anywhere (wrapped into the tile), ``dirs`` (N, 3) unit float64, or
        one direction (3,) shared by all rays (faster). The hit point Embree found (its float32
        ray, float32 distance, evaluated in float64) is projected along the facet normal onto
        the facet plane, so it lies on the plane to float64 precision.
        """
        status, prim, p = self._walk(origins, dirs, occlusion=False)
        hit = np.flatnonzero(status == HIT)
        pr = prim[hit]
        normal = np.full((len(status), 3), np.nan)
        normal[hit] = self.facets.normals(pr)
        p[hit] = self.on_plane(pr, p[hit])
        return Hits(status=status, prim=prim.astype(np.int64), point=p, normal=normal)

    def escapes(self, points: np.ndarray, normals: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Status of rays leaving surface ``points`` (offset by ``eps`` along ``normals``) along
        ``dirs`` ((N, 3) or one shared (3,)): ESCAPED, BLOCKED (= HIT), UNRESOLVED or MISSED,
        (N,) int8."""
        start = np.asarray(points) + self.eps * np.asarray(normals)
        return self._walk(start, dirs, occlusion=True)[0]

    def escapes_from(self, prim: np.ndarray, point: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """``escapes`` for raw hit points of ``trace`` on facets ``prim``: each start is put on
        its facet plane and ``eps`` above it (one step)."""
        return self._walk(self.on_plane(prim, point, self.eps), dirs, occlusion=True)[0]
