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
V-groove surfaces can instead decide masking exactly in float64 (``VGrooveProfile``).

Speed: each segment of the walk is one Embree call between two compiled passes over the live
rays (``segments.segment_setup``/``segment_finish``: float32 inputs and tfar; hits, escapes and
wall re-entries), which hands Embree a single direction when all rays share it and compacts
the rays still live (most finish in the first segment). The BVH is built in ``__init__``.

Backends: each segment's Embree call goes either to embreex (one ray per ``rtcIntersect1``)
or, when the Embree 4 library embreex bundles can be bound (``embree_packets``), to coherent
packets of the native width (``rtcIntersect8``/``16``), same robust scene, same float32 rays,
same tnear/tfar: per-ray answers equal except exact ties between facets at one float32
distance (tests/test_packets.py). ``backend="auto"`` picks packets when available (the packet
scene is also built from the arrays in one copy per buffer, not element by element).

``Tracer``'s own default is "embreex", the tests' reference path; simulations use "auto"
(``paths.TRACER_BACKEND``): on this project's AVX2 machines 8-wide packets trace about as fast
as single rays (1.0–1.2×, ``microsim bench``), but the packet scene builds in 0.10 s against
embreex's 0.5 s. Masking rays of heightfields are decided without tracing where a bound shows
they clear the surface (``rise_bound``, ``clears_horizon``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from embreex import mesh_construction as mc
from embreex import rtcore_scene as rs

from microsim.errors import UsageError
from microsim.surfaces.surface import MAX_COORDINATE, check_relief

from . import embree_packets
from .engine import beam, codes, horizon, segments
from .heightfield_caster import cast_falling, heightfield_grid
from .scratch import WorkArray, WorkColumns

__all__ = [
    "Tracer",
    "GRID_WALK_CELLS",
    "Hits",
    "VGrooveProfile",
    "VGrooveCaster",
    "HIT",
    "ESCAPED",
    "UNRESOLVED",
    "MISSED",
    "BLOCKED",
    "MAX_TRACED_DEG",
    "rise_bound",
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
GRID_WALK_CELLS = 64.0
"""The longest grid walk ``Tracer.cast_falling`` takes (cells crossed over the tile's height
range): on the 512² bench heightfield the walk and Embree cost about the same per primary ray
at θi = 80° (a 62-cell walk); the walk is several times faster at small θi and slower beyond."""
TFAR_REL = 4e-7  # a segment is traced a hair beyond its exit (float32 rounding)
HORIZON_FACETS = 32  # facets per cell of the coarse grid of ``Tracer.horizon``
CLEAR_MARGIN = horizon.CLEAR_MARGIN  # ``surely_escapes`` asks wo_z > this × rise_bound × |wo_h|


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
    if np.any(np.abs(v[:, 0]) > lx / 2 + tol) or np.any(np.abs(v[:, 1]) > ly / 2 + tol):
        raise UsageError("surface.vertices must lie in the tile [-Lx/2, Lx/2] x [-Ly/2, Ly/2]")
    return v, f.astype(np.int64), lx, ly


def _cross_columns(a: np.ndarray, b: np.ndarray) -> list:
    """a × b for (N, 3) arrays, as three (N,) columns."""
    return [
        a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
        a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
        a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
    ]


def rise_bound(surface, normals: np.ndarray) -> float:
    """The steepest facet slope L = max_f |∇h_f| = max_f √(n_x² + n_y²)/n_z of a periodic
    heightfield surface (one with ``heights``: Gaussian, ABC, file and grating tiles; or
    kind "vgrooves" or "flat", whose profiles are single-valued too), else inf.

    Such a surface is a continuous graph z = h(x, y) with |h(q) − h(p)| ≤ L |q − p|_h, so a
    ray leaving a point of it (at or above its facet) upwards along wo with
    wo_z > L |wo_h| stays strictly above it: after a horizontal run s it has climbed
    s wo_z/|wo_h| > L s ≥ h(p + s ŵo) − h(p). Its masking test is decided without tracing
    (``Tracer.surely_escapes``): on the bench heightfield (σ = 1.2, ℓ = 8, L = 0.96) that is
    70 % of the masking rays at θi = 30°. A mesh not known to be a heightfield gets inf
    (every masking ray is traced)."""
    known = surface.heights is not None or surface.kind in ("vgrooves", "flat")
    if not (known and surface.periodic):
        return math.inf
    n = np.asarray(normals)
    return float(np.max(np.hypot(n[:, 0], n[:, 1]) / n[:, 2]))


GROOVE_CLEAR_EPS = 64.0
"""A masking ray of a V-groove surface escapes without tracing when its exact float64 margin
(``VGrooveProfile.margin_from_rim``) is below −this × ``Tracer.eps``: 32 times the start
offset of a traced masking ray, far beyond Embree's float32 error, so Embree would have let it
pass too (tested by tracing the cleared rays anyway)."""
# this thread's work arrays (``scratch``): one walk's per-segment rays (the next segment's in
# two generations) and the grid walk's hits
_WALK_O32 = WorkArray("walk-o32", np.float32, columns=3)
_WALK_D32 = WorkArray("walk-d32", np.float32, columns=3)
_WALK_TFAR = WorkArray("walk-tfar", np.float32)
_WALK_KEEP = WorkArray("walk-keep", np.int64)
_WALK_TOP = WorkArray("walk-top", np.bool_)
_NEXT_LIVE = WorkArray("walk-next-live", np.int64, generations=2)
_NEXT_START = WorkColumns("walk-next-start", generations=2)
_NEXT_DIRECTION = WorkColumns("walk-next-direction", generations=2)
_NEXT_D32 = WorkArray("walk-next-d32", np.float32, columns=3, generations=2)
_CAST_STATUS = WorkArray("cast-status", np.int8)
_CAST_PRIM = WorkArray("cast-prim", np.int32)
_CAST_POINT = WorkColumns("cast-point")
_NO_GROOVES = (np.empty(0), np.empty(0), np.empty(0), np.empty(0), 0.0)
_NO_STRATA = (np.empty(0), 0.0)


def groove_tables(tracer) -> tuple:
    """(clear, strata) of a V-groove mesh, from one ``VGrooveCaster`` (or, for grooves with a
    flat facet, ``VGrooveProfile``):

    - clear: ``primary.traced_primary``'s exact clear test, per facet (rim x, tanθ σ,
      rim-to-rim width W, rim-to-bottom extent) and the tolerance ``GROOVE_CLEAR_EPS`` · eps
      in length units; flat facets get NaN (never cleared);
    - strata: (left rim x of every groove in order of tilt (G,), groove width W) of
      equal-width V-grooves tiling the tile, for the stratified origins
      (``origin_kernels._groove_strata``; ties in tilt keep mesh order: grooves sort by left, then
      right wall slope).

    Empty tables (``_NO_GROOVES``, ``_NO_STRATA``) for what the profile or caster refuses."""
    strata = _NO_STRATA
    try:
        profile = VGrooveCaster(tracer)
    except UsageError:
        try:
            profile = VGrooveProfile(tracer)
        except UsageError:
            return _NO_GROOVES, _NO_STRATA
    else:
        order = np.lexsort((profile.depth / profile.w_right, profile.depth / profile.w_left))
        strata = np.ascontiguousarray(profile.x_left[order]), tracer.tile[0] / profile.n_grooves
    opposite, rim = profile.opposite, profile.rim
    with np.errstate(invalid="ignore"):
        signed_tan = profile.tan * np.sign(opposite - rim)
    width = np.abs(opposite - rim)
    return (rim, signed_tan, width, profile.extent, GROOVE_CLEAR_EPS * tracer.eps), strata


_IDENTITY = np.arange(0, dtype=np.int64)


def _read_only(a: np.ndarray) -> np.ndarray:
    """A read-only view of ``a``: the walk's ``live`` rays are always typed read-only, so that
    its kernels compile one specialisation, not one per segment kind."""
    view = a.view()
    view.flags.writeable = False
    return view


def _identity(n: int) -> np.ndarray:
    """0 … n − 1 (int64), a read-only view of one shared array grown when needed (a fresh
    np.arange of a chunk faults in its pages on every walk)."""
    global _IDENTITY
    if len(_IDENTITY) < n:
        grown = np.arange(max(n, 2 * len(_IDENTITY)), dtype=np.int64)
        grown.flags.writeable = False
        _IDENTITY = grown
    return _IDENTITY[:n]


class Tracer:
    """Periodic Embree scene of one tile of ``surface`` (a ``microsim.surfaces.Surface``).

    Attributes: ``vertices`` (V, 3) / ``faces`` (F, 3) float64/int64 copies, ``normals`` (F, 3)
    unit float64 facet normals, ``tile`` (Lx, Ly), ``zmin``/``zmax``, ``eps`` (secondary-ray
    offset along the normal, length units), ``top_margin`` (primary rays start at zmax + it)
    and ``max_wraps`` (tile crossings per ray before it counts as unresolved: 64 plus enough
    for a ray 89.5° from the normal to cross the whole height range), ``rise_bound`` (the
    steepest facet slope of a heightfield, inf otherwise: masking rays steeper than it are
    not traced, ``surely_escapes``), ``horizon`` (a coarse grid of cell maxima on which the
    other masking rays of a heightfield are cleared without tracing when they can be,
    ``clears_horizon``), ``facet_tables`` (the facet tables ``paths.facet_table`` keeps for
    the tracer's most recent incidences).

    ``backend``: "embreex" (the default and reference), "auto" (packets when
    ``embree_packets`` can bind the library, else embreex) or "packets" (UsageError when
    unavailable); the one used is ``self.backend``.
    ``MICROSIM_EMBREE_PACKETS=0`` in the environment makes "auto" choose embreex.
    ``grid``: find the first hits of falling rays on a heightfield tile by walking its grid
    (``cast_falling``, ``heightfield_caster``) instead of Embree; ``self.grid`` is the
    ``HeightfieldGrid`` (None when off or when the mesh is not a heightfield grid).
    """

    def __init__(self, surface, *, backend: str = "embreex", grid: bool = False):
        if backend not in ("auto", "packets", "embreex"):
            raise UsageError(f"backend must be 'auto', 'packets' or 'embreex', got {backend!r}")
        v, f, lx, ly = _validated_mesh(surface)
        self.vertices, self.faces = v, f
        self._heightfield = heightfield_grid(surface, v, f)  # None unless a heightfield grid
        self.grid = self._heightfield if grid else None
        cross = _cross_columns(self._e1, self._e2)
        norm = np.sqrt(cross[0] ** 2 + cross[1] ** 2 + cross[2] ** 2)
        if np.any(norm == 0):
            raise UsageError("surface.faces must not contain degenerate (zero-area) triangles")
        if np.any(cross[2] <= 0):
            raise UsageError(
                "surface.faces must be ordered so that every normal "
                "cross(v1 - v0, v2 - v0) points up (z > 0)"
            )
        self.normals = np.empty((len(f), 3))
        for k in range(3):
            self.normals[:, k] = cross[k] / norm
        del cross, self._e1, self._e2  # cached: only needed to build
        v0 = self._v0
        self._plane = (
            self.normals[:, 0] * v0[:, 0]
            + self.normals[:, 1] * v0[:, 1]
            + self.normals[:, 2] * v0[:, 2]
        )  # n·v0 per facet
        del self._v0
        self.tile = (lx, ly)
        self.half = np.array([lx / 2, ly / 2])
        self.zmin, self.zmax = float(v[:, 2].min()), float(v[:, 2].max())
        big = max(float(np.abs(v).max()), lx / 2, ly / 2)
        self.eps = 2.0 * float(np.spacing(np.float32(big)))  # 2 ulp: 1.2e-7 on a unit tile
        self.top_margin = 4.0 * self.eps  # primary rays start this far above zmax
        depth = self.zmax - self.zmin + self.top_margin
        crossings = depth * np.tan(np.radians(MAX_TRACED_DEG)) * (1 / lx + 1 / ly)
        self.max_wraps = BASE_WRAPS + int(np.ceil(crossings))
        self.periodic = bool(surface.periodic)
        self.rise_bound = rise_bound(surface, self.normals)
        self.horizon = self._horizon_grid(lx, ly)
        grooved = getattr(surface, "azimuth_average", False)
        self.groove_clear, self.groove_strata = (
            groove_tables(self) if grooved else (_NO_GROOVES, _NO_STRATA)
        )
        self.facet_tables: dict = {}  # kept by paths.facet_table: its key → FacetTable
        reason = None if backend == "embreex" else embree_packets.binding_error()
        if backend == "packets" and reason is not None:
            raise UsageError(f"backend='packets' is unavailable here: {reason}")
        self.backend = "packets" if backend != "embreex" and reason is None else "embreex"
        self._packets = None
        if self.backend == "packets":
            self._packets = embree_packets.PacketScene(v, f)
            return
        self._scene = rs.EmbreeScene(robust=True)
        self._mesh = mc.TriangleMesh(self._scene, v.astype(np.float32), f.astype(np.int32))
        # embreex builds the BVH (rtcCommit) on the first query: do it now, as part of the
        # scene build, so that tracing times exclude it
        self._scene.run(
            np.zeros((1, 3), dtype=np.float32),
            np.array([[0.0, 0.0, -1.0]], dtype=np.float32),
            dists=0.0,
        )

    # --- facet geometry (float64, built on demand: 72 bytes per facet) --------------------
    @functools.cached_property
    def _v0(self) -> np.ndarray:
        """First vertex of every facet, (F, 3)."""
        return self.vertices[self.faces[:, 0]]

    @functools.cached_property
    def _e1(self) -> np.ndarray:
        """Edge v1 − v0 of every facet, (F, 3)."""
        return self.vertices[self.faces[:, 1]] - self._v0

    @functools.cached_property
    def _e2(self) -> np.ndarray:
        """Edge v2 − v0 of every facet, (F, 3)."""
        return self.vertices[self.faces[:, 2]] - self._v0

    @functools.cached_property
    def normal_columns(self) -> tuple:
        """Contiguous per-axis columns (3 × (F,)) of the unit facet normals."""
        return tuple(np.ascontiguousarray(self.normals[:, k]) for k in range(3))

    @functools.cached_property
    def beam(self) -> "beam.BeamGrid | None":
        """What ``beam.beam_clear`` reads to clear a lit facet's masking rays all at once
        (meshes that are heightfield grids, whether or not ``grid`` walks their primary
        rays; else None); tolerance that of ``horizon``."""
        if self._heightfield is None:
            return None
        return beam.beam_grid(self._heightfield, self.normals, self.zmax, self.horizon[6])

    @functools.cached_property
    def masking_lift(self) -> np.ndarray:
        """n·v0 + eps per facet (F,): a point p on facet f's plane moved to
        p − (p·n − lift)·n starts its secondary ray eps above the plane."""
        return self._plane + self.eps

    # --- periodic walk ------------------------------------------------------------------
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
        status, prim, p = self._walk_columns(x, d, d32, occlusion)
        if occlusion:
            return status, None, None
        point = np.empty((len(status), 3))
        for k in range(3):
            point[:, k] = p[k]
        point[status != HIT] = np.nan
        return status, prim, point

    def _walk_columns(self, x, d, d32, occlusion: bool, first=None, wraps=None):
        """``_walk`` on per-axis columns: origins ``x`` (3 arrays (N,), float64, wrapped into
        the tile here), directions ``d`` (3 arrays (N,) or 3 floats shared by all rays) and
        their float32 (N, 3) (or (1, 3)) copy ``d32``. Returns (status, prim, point columns);
        the point columns are undefined where status is not HIT.

        Each segment is one Embree call between two compiled passes (``segments.segment_setup``
        / ``segment_finish``): the rays still live after a segment (those re-entering through
        a wall; most finish in the first) are compacted for the next. ``first``: the first
        segment's Embree input (o32, tq, keep, top) already set up by the caller exactly as
        ``segment_setup`` would from these rays, which then all lie in the tile and are all
        traced (``primary.tabled_primary``, ``segments.falling_first_segment``). ``wraps``: the
        wrap cap (segments − 1) instead of ``max_wraps``."""
        n = len(x[0])
        shared = np.isscalar(d[0])
        x = [np.ascontiguousarray(c, dtype=np.float64) for c in x]
        if first is None and not self.holds(x):  # wrap the starts into the tile
            for a in (0, 1):
                h = self.half[a]
                out = (x[a] < -h) | (x[a] >= h)
                x[a] = np.where(out, np.mod(x[a] + h, 2 * h) - h, x[a])
        d = (
            [np.array([float(c)]) for c in d]
            if shared
            else [np.ascontiguousarray(c, dtype=np.float64) for c in d]
        )
        d32 = np.ascontiguousarray(d32, dtype=np.float32)
        falling_shared = bool(shared and d[2][0] <= 0)
        status = np.full(n, UNRESOLVED, dtype=np.int8)
        prim = np.full(0 if occlusion else n, -1, dtype=np.int32)
        point = [np.empty(0 if occlusion else n) for _ in range(3)]
        live = _identity(n)  # read only: the next segment's live rays are a new array
        # per-segment work arrays (this thread's, reused; sized for the first, largest segment)
        o32, d32k = _WALK_O32(n), _WALK_D32(0 if shared else n)
        tq, keep, top = _WALK_TFAR(n), _WALK_KEEP(n), _WALK_TOP(n)
        query = "OCCLUDED" if occlusion else "INTERSECT"
        no_tfar = np.empty(0, dtype=np.float32)
        hx, hy = float(self.half[0]), float(self.half[1])
        box = segments.WalkBox(hx, hy, float(self.zmax), float(self.zmin), float(self.eps))
        result = segments.WalkResult(status, prim, *point)
        for segment in range((self.max_wraps if wraps is None else int(wraps)) + 1):
            if live.size == 0:
                break
            if segment == 0 and first is not None:
                k, (o32_, tq_, keep_, top_), d32k_ = n, first, d32
            else:
                rays = segments.WalkRays(live, *x, *d, shared)
                k = segments.segment_setup(
                    rays, d32, box, TFAR_REL, status, o32, d32k, tq, keep, top
                )
                o32_, tq_, keep_, top_, d32k_ = o32, tq, keep, top, d32k
            if k == 0:
                break
            if self._packets is not None:
                pid, tfar = self._packets.run(
                    o32_[:k], d32 if shared else d32k_[:k], tq_[:k], occlusion
                )
                tfar = no_tfar if occlusion else tfar
            else:
                res = self._scene.run(
                    o32_[:k],
                    d32 if shared else d32k_[:k],
                    dists=tq_[:k],
                    query=query,
                    output=None if occlusion else 1,
                )
                pid, tfar = (res, no_tfar) if occlusion else (res["primID"], res["tfar"])
            if segment == 0 and first is not None and not occlusion:
                # slot i is ray i and most rays hit (primaries): the hits vectorised, the
                # others left to segment_finish
                segments.first_segment_hits(pid, tfar, *x, *d, shared, status, prim, *point)
                rest = np.flatnonzero(pid < 0)
                k, pid, tfar = len(rest), pid[rest], tfar[rest]
                keep_, top_ = keep_[rest], top_[rest]
                d32k_ = d32k_ if shared else d32k_[rest]
            nxt = segment % 2  # generation: written here, read by the next segment
            m_live = _NEXT_LIVE(k, nxt)
            nx_ = _NEXT_START(k, nxt)
            nd = _NEXT_DIRECTION(0 if shared else k, nxt)
            nd32 = _NEXT_D32(0 if shared else k, nxt)
            m = segments.segment_finish(
                k,
                pid,
                tfar,
                occlusion,
                keep_,
                top_,
                segments.WalkRays(live, *x, *d, shared),
                falling_shared,
                d32k_,
                box,
                result,
                segments.NextSegment(m_live, *nx_, *nd, nd32),
            )
            live, x = _read_only(m_live[:m]), [c[:m] for c in nx_]
            if not shared:
                d, d32 = [c[:m] for c in nd], nd32[:m]
        return status, (None if occlusion else prim), (None if occlusion else point)

    def trace(self, origins: np.ndarray, dirs: np.ndarray):
        """Lean first-hit query: (status (N,) int8, prim (N,) int32, point (N, 3) float64).

        ``point`` is the hit Embree found (its float32 ray and distance, evaluated in float64),
        not yet projected onto the facet plane (NaN without a hit); see ``first_hit``."""
        return self._walk(origins, dirs, occlusion=False)

    def holds(self, x) -> bool:
        """Whether every start of the columns ``x`` lies in the tile, −L/2 ≤ x, y < L/2
        (``_walk_columns`` wraps the others)."""
        return bool(
            len(x[0]) == 0
            or all(x[a].min() >= -self.half[a] and x[a].max() < self.half[a] for a in (0, 1))
        )

    def grid_walk(self, x, down):
        """The grid walk's geometry (``HeightfieldGrid.geometry``) for rays from the starts
        ``x`` (3 columns) along one falling direction ``down`` (3 floats), or None when the
        tracer has no grid, a start lies outside the tile or below zmax, or the direction is
        so grazing that its walk would cross more than ``GRID_WALK_CELLS`` cells (Embree is
        faster there)."""
        g = self.grid
        if g is None or not down[2] < 0.0 or not self.holds(x):
            return None
        run = (self.zmax - self.zmin) * (abs(down[0]) + abs(down[1])) / (-down[2] * g.cell)
        if run > GRID_WALK_CELLS or (len(x[0]) and x[2].min() < self.zmax):
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
        cast_falling(*x, *(float(c) for c in down), geometry, status, prim, *point)
        return status, prim, point

    def trace_columns(self, x, d, d32, wraps=None, first=None):
        """``trace`` on per-axis columns (see ``_walk_columns``, also for ``first``): (status,
        prim, [px, py, pz]), the point columns undefined where status is not HIT. ``wraps``:
        wrap cap (default ``max_wraps``; ``wraps_needed`` gives what a direction needs)."""
        return self._walk_columns(x, d, d32, occlusion=False, first=first, wraps=wraps)

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
        """Occlusion status of rays given as per-axis columns (see ``_walk_columns``, also for
        ``first``); the starts ``x`` must already be offset from the surface."""
        return self._walk_columns(x, d, d32, occlusion=True, first=first)[0]

    def _horizon_grid(self, lx: float, ly: float) -> tuple:
        """``horizon.horizon_clear``'s coarse grid of a heightfield (finite ``rise_bound``):
        (x0, y0, cw, ch, cmax, cslope, tol), cells of ~``HORIZON_FACETS`` facets (highest
        vertex, steepest facet of those overlapping each), tol = 4 eps (float32 rays); for
        other meshes a 1 × 1 grid that clears nothing."""
        if not math.isfinite(self.rise_bound):
            return (0.0, 0.0, 1.0, 1.0, np.full((1, 1), np.inf), np.full((1, 1), np.inf), 0.0)
        cells = len(self.faces) / HORIZON_FACETS
        nx = int(np.clip(round(math.sqrt(cells * lx / ly)), 1, 1024))
        ny = int(np.clip(round(math.sqrt(cells * ly / lx)), 1, 1024))
        cmax, cslope = np.full((ny, nx), -np.inf), np.zeros((ny, nx))
        n, v = self.normals, self.vertices
        slope = np.hypot(n[:, 0], n[:, 1]) / n[:, 2]
        x0, y0, cw, ch = -lx / 2, -ly / 2, lx / nx, ly / ny
        cols = [np.ascontiguousarray(v[:, k]) for k in range(3)]
        horizon.fill_horizon(*cols, self.faces, slope, x0, y0, cw, ch, cmax, cslope)
        return (x0, y0, cw, ch, cmax, cslope, 4.0 * self.eps)

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
        nrm = self.normals[prim]
        off = (
            point[:, 0] * nrm[:, 0]
            + point[:, 1] * nrm[:, 1]
            + point[:, 2] * nrm[:, 2]
            - self._plane[prim]
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
        normal[hit] = self.normals[pr]
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


class VGrooveProfile:
    """Exact float64 masking for straight V-grooves along y (Mikkelsen 2009, eq. 25 geometry).

    Every rim lies at z = 0 and the surface lies below, so a ray leaving a facet upwards can
    only be blocked by the opposite facet of the same groove before rising above z = 0. For a
    hit at horizontal distance s from the facet's rim, with facet tilt tan θ = |n_x|/n_z, the
    ray reaches z = 0 after travelling s·tanθ·(w_x σ)/w_z horizontally towards the opposite rim
    (σ its side, W the rim-to-rim width); it is masked iff s(1 + tanθ σ w_x / w_z) > W.
    """

    def __init__(self, tracer: Tracer):
        v, f, n = tracer.vertices, tracer.faces, tracer.normals
        scale = max(tracer.tile)
        if np.any(np.abs(n[:, 1]) > 1e-12) or tracer.zmax > 1e-12 * scale:
            raise UsageError(
                "masking='exact' needs V-grooves running along y with every rim at "
                "z = 0 and nothing above (surface.kind 'vgrooves')"
            )
        xs = v[f, 0]
        lo, hi = xs.min(axis=1), xs.max(axis=1)
        left = n[:, 0] > 0  # slopes down towards +x: rim at the low x
        right = n[:, 0] < 0
        self.rim = np.where(left, lo, hi)
        bottom = np.where(left, hi, lo)
        self.tan = np.abs(n[:, 0]) / n[:, 2]
        self.opposite = np.full(len(f), np.nan)
        for mine, other in ((left, right), (right, left)):
            ob, orim = bottom[other], self.rim[other]
            order = np.argsort(ob, kind="stable")
            k = np.clip(np.searchsorted(ob[order], bottom[mine]), 0, max(len(ob) - 1, 0))
            found = ob[order][k] == bottom[mine] if len(ob) else np.zeros(mine.sum(), bool)
            if not np.all(found):
                raise UsageError(
                    "masking='exact' needs whole V-grooves inside "
                    "the tile (a facet has no opposite facet sharing its bottom)"
                )
            self.opposite[mine] = orim[order][k]
        # rims at z = 0, bottoms at depth |bottom − rim|·tanθ: the mesh must be such a profile
        zr = np.where(np.isclose(xs, self.rim[:, None], rtol=0, atol=1e-12 * scale), v[f, 2], 0.0)
        zb = np.where(
            np.isclose(xs, bottom[:, None], rtol=0, atol=1e-12 * scale),
            v[f, 2] + np.abs(bottom - self.rim)[:, None] * self.tan[:, None],
            0.0,
        )
        if np.any(np.abs(zr) > 1e-9 * scale) or np.any(np.abs(zb) > 1e-9 * scale):
            raise UsageError(
                "masking='exact' needs every groove rim at z = 0 (surface.kind 'vgrooves')"
            )
        self.extent = np.abs(bottom - self.rim)
        self.sloped = left | right

    def masking_margin(self, prim: np.ndarray, point: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """s(1 + tanθ σ w_x/w_z) − W in length units: > 0 ⇔ masked (−inf for flat facets)."""
        return self.margin_columns(prim, point[:, 0], wo[:, 0], wo[:, 2])

    def margin_columns(self, prim, x, wo_x, wo_z) -> np.ndarray:
        """``masking_margin`` from the hit points' x and the reflected directions' x and z."""
        rim, opp, t = self.rim[prim], self.opposite[prim], self.tan[prim]
        width = np.abs(np.where(np.isnan(opp), 0.0, opp) - rim)
        s = np.clip(np.abs(x - rim), 0.0, self.extent[prim])
        margin = self.margin_from_rim(s, t * np.sign(opp - rim), width, wo_x, wo_z)
        return np.where(self.sloped[prim], margin, -np.inf)

    @staticmethod
    def margin_from_rim(s, signed_tan, width, wo_x, wo_z):
        """The masking margin s(1 + tanθ σ w_x/w_z) − W of a hit at horizontal distance ``s``
        from its facet's rim (``signed_tan`` = tanθ σ, σ = ±1 the side of the opposite rim,
        ``width`` W rim to rim): > 0 ⇔ masked."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return s * (1.0 + signed_tan * wo_x / wo_z) - width


class GrooveProfile(NamedTuple):
    """The V-groove closed form's geometry (``VGrooveCaster.profile``, built once per caster;
    the argument ``groove`` of ``vgroove_kernels.analytic_vgroove*``):
    half the tile width ``half``; per groove the rims ``x_left``, ``x_right``, the left
    wall's rim-to-bottom width ``w_left`` and the ``depth``; per facet f (2k left, 2k + 1
    right) its rim x, wall width, σ (+1 left, −1 right), unit normal (nx, 0, nz), tanθ·σ and
    the groove width W. Lengths in tile units."""

    half: float
    x_left: np.ndarray
    x_right: np.ndarray
    w_left: np.ndarray
    depth: np.ndarray
    facet_rim: np.ndarray
    facet_wall: np.ndarray
    facet_sigma: np.ndarray
    facet_nx: np.ndarray
    facet_nz: np.ndarray
    facet_signed_tan: np.ndarray
    facet_width: np.ndarray


class VGrooveCaster(VGrooveProfile):
    """``VGrooveProfile`` plus the exact float64 primary hit of a falling ray (no Embree), for
    equal-width grooves tiling the tile in x (``surfaces.vgrooves``).

    Every rim lies at z = 0 with the surface below, so a falling ray that crosses z = 0 at x0
    (wrapped into the tile) inside groove k = [x_k, x_k + W] must hit one of groove k's two
    facets before leaving it. With a = −wi_x/wi_z the horizontal advance per unit depth of the
    ray −wi, u = x0 − x_k, rim-to-bottom widths w_L, w_R and depth D, the walls are met at
    horizontal distance from their own rim
        s_L = u w_L / (w_L − a D)           (left facet, n_x > 0)   if u + a D < w_L,
        s_R = (W − u) w_R / (w_R + a D)     (right facet, n_x < 0)  otherwise,
    i.e. on the wall the ray reaches before the bottom (the denominator is then > 0). Facet
    f = 2k (left) or 2k + 1 (right) is reported as mesh triangle ``facet_prim[f]`` (the
    lower-index half of its quad), whose normal ``tracer.normals[facet_prim[f]]`` is the one a
    traced hit on that facet gets (to rounding: the quad's two triangles are coplanar).
    Per-facet columns (index f): ``facet_prim``, ``facet_rim`` (x), ``facet_nx``/``facet_nz``
    (unit normal, n_y = 0), ``facet_sigma`` (σ: +1 left, −1 right), ``facet_wall`` (w_L or w_R),
    ``facet_signed_tan`` (tanθ σ) and ``facet_width`` (W), the last two for ``margin_from_rim``.
    In this notation s = |x0 − rim| w / (w − σ a D) for both walls.
    """

    def __init__(self, tracer: Tracer):
        super().__init__(tracer)
        if not np.all(self.sloped):
            raise UsageError(
                "masking='analytic' needs every groove tilt > 0 (a flat facet has "
                "no V-groove walls)"
            )
        n, lx = tracer.normals, tracer.tile[0]
        tol = 1e-12 * max(tracer.tile)
        left, right = np.flatnonzero(n[:, 0] > 0), np.flatnonzero(n[:, 0] < 0)
        rim_l, first_l = np.unique(self.rim[left], return_index=True)  # sorted, one per facet
        rim_r, first_r = np.unique(self.rim[right], return_index=True)
        pl, pr = left[first_l], right[first_r]
        xr = self.opposite[pl]
        g = len(rim_l)
        if (
            len(rim_r) != g
            or not np.array_equal(rim_r, xr)
            or abs(rim_l[0] + lx / 2) > tol
            or np.any(np.abs(xr - rim_l - lx / g) > tol)
            or np.any(np.abs(rim_l[1:] - xr[:-1]) > tol)
        ):
            raise UsageError(
                "masking='analytic' needs whole equal-width V-grooves tiling the "
                "tile in x (surface.kind 'vgrooves')"
            )
        self.n_grooves, self.half = g, lx / 2
        self.x_left, self.x_right = rim_l, xr
        self.w_left, self.w_right = self.extent[pl], self.extent[pr]
        self.depth = self.w_left * self.tan[pl]
        self.facet_prim = np.stack([pl, pr], axis=1).ravel()
        self.facet_rim = np.stack([rim_l, xr], axis=1).ravel()
        self.facet_nx, self.facet_nz = n[self.facet_prim, 0], n[self.facet_prim, 2]
        self.facet_sigma = np.tile([1.0, -1.0], g)
        self.facet_wall = np.stack([self.w_left, self.w_right], axis=1).ravel()
        self.facet_signed_tan = self.tan[self.facet_prim] * self.facet_sigma
        self.facet_width = np.repeat(xr - rim_l, 2)
        self.profile = GrooveProfile(
            float(self.half),
            self.x_left,
            self.x_right,
            self.w_left,
            self.depth,
            self.facet_rim,
            self.facet_wall,
            self.facet_sigma,
            self.facet_nx,
            self.facet_nz,
            self.facet_signed_tan,
            self.facet_width,
        )
        """The same geometry as the kernels take it (``GrooveProfile``)."""

    def groove_hits(self, x, z, wi_x, wi_z):
        """(facet f (N,) int64, s (N,)) of rays from (x, z) (z ≥ 0: at or above the rims)
        along −wi (wi_z > 0): the facet hit and the hit's horizontal distance from its rim."""
        h = self.half
        x0 = x - (z / wi_z) * wi_x  # z = 0 crossing
        if x0.size and (x0.min() < -h or x0.max() >= h):  # wrap into the tile
            x0 = np.mod(x0 + h, 2 * h) - h
        g = self.n_grooves
        k = np.minimum(((x0 + h) * (g / (2 * h))).astype(np.int64), g - 1)  # ±1 at most
        k -= (x0 < self.x_left[k]) & (k > 0)
        k += (x0 >= self.x_right[k]) & (k < g - 1)
        ad = (-wi_x / wi_z) * self.depth[k]
        f = 2 * k + (x0 - self.x_left[k] + ad >= self.w_left[k])  # left wall unless
        w, sig = self.facet_wall[f], self.facet_sigma[f]  # the bottom comes first
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.abs(x0 - self.facet_rim[f]) * w / (w - sig * ad)
        return f, s

    def first_hit_columns(self, x, z, wi_x, wi_z):
        """(prim (N,) int64, hit x (N,) in tile coordinates): ``groove_hits`` as a mesh hit."""
        f, s = self.groove_hits(x, z, wi_x, wi_z)
        return self.facet_prim[f], self.facet_rim[f] + np.where(f % 2, -s, s)
