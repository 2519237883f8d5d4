"""Ray tracing of an infinite periodic microsurface with Embree (embreex), one tile at a time.

The scene holds a single tile [-Lx/2, Lx/2] x [-Ly/2, Ly/2] (float32, centred on the origin,
robust mode). A ray sees the infinite periodic repetition exactly: each segment is traced up
to the point where the ray leaves the tile's xy box (or rises above the surface top zmax);
without a hit, the ray re-enters through the opposite wall at the same height and goes on.
A ray that reaches z >= zmax going up has escaped; one that sinks below zmin without a hit has
leaked through the mesh ("missed", impossible for a closed periodic surface).

Secondary rays start from the hit point recomputed in float64 (barycentrics on the float64
vertices, then projected onto the facet plane) offset along the unit facet normal by ``eps``,
a few float32 ulp of the tile's largest coordinate (Embree's tnear is fixed at 0). The offset
biases grazing masking by ~eps / feature depth (DESIGN.md "Facts"), so V-groove surfaces
can instead decide masking exactly in float64 (``VGrooveProfile``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from embreex import mesh_construction as mc
from embreex import rtcore_scene as rs

__all__ = ["Tracer", "Hits", "VGrooveProfile", "HIT", "ESCAPED", "UNRESOLVED", "MISSED",
           "BLOCKED", "MAX_TRACED_DEG"]

HIT, ESCAPED, UNRESOLVED, MISSED = 0, 1, 2, 3
BLOCKED = HIT                      # an occlusion ray that met the surface
MAX_TRACED_DEG = 89.5              # rays up to this polar angle are always resolved (wrap cap)
BASE_WRAPS = 64
_TFAR_REL = 4e-7                   # a segment is traced a hair beyond its exit (float32 rounding)


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
        raise ValueError(f"surface.vertices must be a (V >= 3, 3) array, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("surface.vertices must be finite (got NaN or inf)")
    if f.ndim != 2 or f.shape[1] != 3 or len(f) < 1:
        raise ValueError(f"surface.faces must be a non-empty (F, 3) integer array, got shape {f.shape}")
    if not np.issubdtype(f.dtype, np.integer) or f.min() < 0 or f.max() >= len(v):
        raise ValueError(f"surface.faces must hold vertex indices in [0, {len(v) - 1}]")
    lx, ly = (float(t) for t in surface.tile_size)
    if not (lx > 0 and ly > 0 and np.isfinite(lx) and np.isfinite(ly)):
        raise ValueError(f"surface.tile_size must be two finite lengths > 0, got {surface.tile_size!r}")
    tol = 1e-9 * max(lx, ly)
    if np.any(np.abs(v[:, 0]) > lx / 2 + tol) or np.any(np.abs(v[:, 1]) > ly / 2 + tol):
        raise ValueError("surface.vertices must lie in the tile [-Lx/2, Lx/2] x [-Ly/2, Ly/2]")
    return v, f.astype(np.int64), lx, ly


def wrap_into_tile(p: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Points moved by whole periods so that x ∈ [-Lx/2, Lx/2), y ∈ [-Ly/2, Ly/2) (in place)."""
    for a in (0, 1):
        out = (p[:, a] < -half[a]) | (p[:, a] >= half[a])
        if np.any(out):
            p[out, a] = np.mod(p[out, a] + half[a], 2 * half[a]) - half[a]
    return p


class Tracer:
    """Periodic Embree scene of one tile of ``surface`` (a ``microsim.surfaces.Surface``).

    Attributes: ``vertices`` (V, 3) / ``faces`` (F, 3) float64/int64 copies, ``normals`` (F, 3)
    unit float64 facet normals, ``tile`` (Lx, Ly), ``zmin``/``zmax``, ``eps`` (secondary-ray
    offset along the normal, length units), ``top_margin`` (primary rays start at zmax + it)
    and ``max_wraps`` (tile crossings per ray before it counts as unresolved: 64 plus enough
    for a ray 89.5° from the normal to cross the whole height range).
    """

    def __init__(self, surface):
        v, f, lx, ly = _validated_mesh(surface)
        cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        norm = np.linalg.norm(cross, axis=1)
        if np.any(norm == 0):
            raise ValueError("surface.faces must not contain degenerate (zero-area) triangles")
        if np.any(cross[:, 2] <= 0):
            raise ValueError("surface.faces must be ordered so that every normal "
                             "cross(v1 - v0, v2 - v0) points up (z > 0)")
        self.vertices, self.faces = v, f
        self._v0, self._e1, self._e2 = v[f[:, 0]], v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
        self.normals = cross / norm[:, None]
        self.tile = (lx, ly)
        self.half = np.array([lx / 2, ly / 2])
        self.zmin, self.zmax = float(v[:, 2].min()), float(v[:, 2].max())
        big = max(float(np.abs(v).max()), lx / 2, ly / 2)
        self.eps = 2.0 * float(np.spacing(np.float32(big)))   # 2 ulp: 1.2e-7 on a unit tile
        self.top_margin = 4.0 * self.eps                       # primary rays start this far above zmax
        depth = self.zmax - self.zmin + self.top_margin
        crossings = depth * np.tan(np.radians(MAX_TRACED_DEG)) * (1 / lx + 1 / ly)
        self.max_wraps = BASE_WRAPS + int(np.ceil(crossings))
        self.periodic = bool(surface.periodic)
        self._scene = rs.EmbreeScene(robust=True)
        self._mesh = mc.TriangleMesh(self._scene, v.astype(np.float32), f.astype(np.int32))

    # --- periodic walk ------------------------------------------------------------------
    def _segments(self, o, d):
        """Distance to the exit wall (N,), which walls (N, 2) bool, and distance up to z = zmax
        (inf unless rising)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            txy = (np.copysign(self.half, d[:, :2]) - o[:, :2]) / d[:, :2]
            ttop = (self.zmax - o[:, 2]) / d[:, 2]
        txy[d[:, :2] == 0] = np.inf
        np.maximum(txy, 0.0, out=txy)
        twall = txy.min(axis=1)
        ttop[~(d[:, 2] > 0)] = np.inf
        return twall, txy <= twall[:, None], np.maximum(ttop, 0.0)

    def _walk(self, origins, dirs, occlusion: bool):
        """Trace rays through the periodic repetition; returns (status, prim, u, v).

        The arrays of live rays are compacted after every segment; embree gets float32 copies."""
        oo = wrap_into_tile(np.array(origins, dtype=np.float64), self.half)
        dd = np.asarray(dirs, dtype=np.float64)
        d32 = dd.astype(np.float32)
        n = len(oo)
        status = np.full(n, UNRESOLVED, dtype=np.int8)
        prim = np.full(n, -1, dtype=np.int64)
        u = np.zeros(n)
        v = np.zeros(n)
        live = np.arange(n)
        query = "OCCLUDED" if occlusion else "INTERSECT"
        for _ in range(self.max_wraps + 1):
            gone = (dd[:, 2] > 0) & (oo[:, 2] >= self.zmax)           # nothing above zmax
            if gone.any():
                status[live[gone]] = ESCAPED
                keep = ~gone
                live, oo, dd, d32 = live[keep], oo[keep], dd[keep], d32[keep]
            if live.size == 0:
                break
            twall, walls, ttop = self._segments(oo, dd)
            tend = np.minimum(twall, ttop)
            tq = tend * (1 + _TFAR_REL) + self.eps                      # inf stays inf
            res = self._scene.run(oo.astype(np.float32), d32, dists=tq.astype(np.float32),
                                  query=query, output=None if occlusion else 1)
            pid = np.asarray(res if occlusion else res["primID"])
            hit = pid >= 0
            lh = live[hit]
            status[lh] = HIT
            if not occlusion:
                prim[lh] = pid[hit]
                u[lh] = res["u"][hit]
                v[lh] = res["v"][hit]
            # no hit: escaped through the top, leaked below, or re-enter through the opposite wall
            top = ~hit & (ttop <= twall)
            status[live[top]] = ESCAPED
            go = np.flatnonzero(~hit & ~top)
            p = oo[go] + twall[go, None] * dd[go]
            leaked = (p[:, 2] < self.zmin - self.eps) | ~np.isfinite(twall[go])
            if leaked.any():
                status[live[go[leaked]]] = MISSED
                go, p = go[~leaked], p[~leaked]
            np.clip(p[:, :2], -self.half, self.half, out=p[:, :2])   # rounding along the wall
            p[:, :2] = np.where(walls[go], -np.copysign(self.half, dd[go, :2]), p[:, :2])
            live, oo, dd, d32 = live[go], p, dd[go], d32[go]
            if live.size == 0:
                break
        return status, prim, u, v

    def first_hit(self, origins: np.ndarray, dirs: np.ndarray) -> Hits:
        """Closest intersection of rays ``origins + t·dirs`` (t > 0) with the periodic surface.

        ``origins`` (N, 3) anywhere (wrapped into the tile), ``dirs`` (N, 3) unit, float64.
        The hit point p = v0 + u(v1 − v0) + v(v2 − v0) is evaluated in float64 from Embree's
        barycentrics, so it lies on the facet plane to float64 precision.
        """
        status, prim, u, v = self._walk(origins, dirs, occlusion=False)
        hit = np.flatnonzero(status == HIT)
        pr = prim[hit]
        point = np.full((len(status), 3), np.nan)
        normal = np.full((len(status), 3), np.nan)
        point[hit] = self._v0[pr] + u[hit, None] * self._e1[pr] + v[hit, None] * self._e2[pr]
        normal[hit] = self.normals[pr]
        return Hits(status=status, prim=prim, point=point, normal=normal)

    def escapes(self, points: np.ndarray, normals: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Status of rays leaving surface ``points`` (offset by ``eps`` along ``normals``) along
        ``dirs``: ESCAPED, BLOCKED (= HIT), UNRESOLVED or MISSED, (N,) int8."""
        start = np.asarray(points) + self.eps * np.asarray(normals)
        return self._walk(start, dirs, occlusion=True)[0]


class VGrooveProfile:
    """Exact float64 masking for straight V-grooves running along y (Mikkelsen eq. 25 geometry).

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
            raise ValueError("masking='exact' needs V-grooves running along y with every rim at "
                             "z = 0 and nothing above (surface.kind 'vgrooves')")
        xs = v[f, 0]
        lo, hi = xs.min(axis=1), xs.max(axis=1)
        left = n[:, 0] > 0                        # slopes down towards +x: rim at the low x
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
                raise ValueError("masking='exact' needs whole V-grooves inside "
                                 "the tile (a facet has no opposite facet sharing its bottom)")
            self.opposite[mine] = orim[order][k]
        # rims at z = 0, bottoms at depth |bottom − rim|·tanθ: the mesh must be such a profile
        zr = np.where(np.isclose(xs, self.rim[:, None], rtol=0, atol=1e-12 * scale), v[f, 2], 0.0)
        zb = np.where(np.isclose(xs, bottom[:, None], rtol=0, atol=1e-12 * scale),
                      v[f, 2] + np.abs(bottom - self.rim)[:, None] * self.tan[:, None], 0.0)
        if np.any(np.abs(zr) > 1e-9 * scale) or np.any(np.abs(zb) > 1e-9 * scale):
            raise ValueError("masking='exact' needs every groove rim at z = 0 (surface.kind 'vgrooves')")
        self.extent = np.abs(bottom - self.rim)
        self.sloped = left | right

    def masking_margin(self, prim: np.ndarray, point: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """s(1 + tanθ σ w_x/w_z) − W in length units: > 0 ⇔ masked (−inf for flat facets)."""
        rim, opp, t = self.rim[prim], self.opposite[prim], self.tan[prim]
        width = np.abs(np.where(np.isnan(opp), 0.0, opp) - rim)
        s = np.clip(np.abs(point[:, 0] - rim), 0.0, self.extent[prim])
        sigma = np.sign(opp - rim)
        with np.errstate(divide="ignore", invalid="ignore"):
            margin = s * (1.0 + t * sigma * wo[:, 0] / wo[:, 2]) - width
        return np.where(self.sloped[prim], margin, -np.inf)
