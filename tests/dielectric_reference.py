"""An independent single-interface refraction tracer (pure NumPy, nothing of ``microsim.sim``):
the reference the dielectric estimator is checked against.

A periodic tile given by its triangle mesh (every facet normal up) separates air (index 1,
above) from a medium of index ``eta`` (below). Each ray is followed one interaction at a time:
the closest hit is found by brute force (Möller & Trumbore 1997, vectorised over the pairs
of rays × triangles of the tile and its 8 neighbour copies whose bounding boxes meet the ray's
segment, found through a uniform grid of cells); there it
reflects with the exact unpolarised Fresnel probability F (total internal reflection F = 1)
and refracts otherwise (Russian roulette, weight 1), until it leaves the relief slab upward or
downward. A ray that runs a whole tile sideways inside the slab without a hit is moved there
and wrapped back into the tile, so no bound on the directions is assumed.

``trace`` returns what became of every primary ray (``Escapes``); ``bin_averages`` turns that
into bin-averaged BSDFs with per-ray binomial standard errors, on the (θo, Δφ) grid of a
``microsim.bins.Bins`` (its edges and projected solid angles only: the binning is done here).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MAX_INTERACTIONS = 200
"""Interactions after which a path is given up (counted in ``Escapes.cut``)."""
MAX_WALKS = 1000
"""Tile-long hitless steps after which a path is given up (counted in ``Escapes.cut``)."""
BATCH = 2**15
"""Primary rays followed together (bounds the memory of the ray × triangle candidates)."""


@dataclass(frozen=True)
class Mesh:
    """A periodic tile: ``vertices`` (V, 3), ``faces`` (F, 3) with normals up, periods
    ``tile`` (Lx, Ly); the tile spans [−Lx/2, Lx/2) × [−Ly/2, Ly/2)."""

    vertices: np.ndarray
    faces: np.ndarray
    tile: tuple[float, float]

    @classmethod
    def of(cls, surface) -> "Mesh":
        """The mesh of a ``microsim.surfaces.Surface`` (only its arrays are read)."""
        return cls(
            np.asarray(surface.vertices, dtype=np.float64),
            np.asarray(surface.faces, dtype=np.int64),
            tuple(float(t) for t in surface.tile_size),
        )

    @property
    def z_range(self) -> tuple[float, float]:
        z = self.vertices[:, 2]
        return float(z.min()), float(z.max())


@dataclass(frozen=True)
class Escapes:
    """What became of ``n`` primary rays at one incidence: for each ray that left the slab,
    its exit direction ``wo`` (k, 3), its number of interactions ``order`` (k,) and
    ``reflected`` (k,) — True if it left on the incidence's side. ``cut``: paths given up."""

    n: int
    wo: np.ndarray
    order: np.ndarray
    reflected: np.ndarray
    cut: int


def incident_direction(theta_i: float, phi_i: float = 0.0) -> np.ndarray:
    """wi, the unit vector towards the light: θi in [0°, 90°) from above, (90°, 180°] below."""
    t, p = np.radians(theta_i), np.radians(phi_i)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def fresnel_dielectric(cos_i: np.ndarray, n1: np.ndarray, n2: np.ndarray) -> np.ndarray:
    """Unpolarised reflectance (|r_s|² + |r_p|²)/2 of light in index n1 meeting index n2 at
    cos θi = ``cos_i`` ≥ 0, from the amplitude coefficients (Born & Wolf 1999, §1.5.2,
    eq. 20) r_s = (n1 cos θi − n2 cos θt)/(n1 cos θi + n2 cos θt),
    r_p = (n2 cos θi − n1 cos θt)/(n2 cos θi + n1 cos θt); 1 under total internal reflection."""
    sin2_t = (n1 / n2) ** 2 * (1.0 - cos_i * cos_i)
    tir = sin2_t >= 1.0
    cos_t = np.sqrt(np.where(tir, 0.0, 1.0 - sin2_t))
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t)
    return np.where(tir, 1.0, 0.5 * (rs * rs + rp * rp))


def _expand(counts: np.ndarray):
    """(owner, k) pairs enumerating ``counts[i]`` slots k = 0 … counts[i] − 1 per item i."""
    owner = np.repeat(np.arange(len(counts)), counts)
    starts = np.cumsum(counts) - counts
    return owner, np.arange(len(owner)) - starts[owner]


class _Triangles:
    """The tile's triangles and their 8 neighbour copies, as Möller–Trumbore needs them
    (vertex v0, edges e1 = v1 − v0, e2 = v2 − v0, unit normal), filed in a uniform grid of
    cells over the 3 × 3 tiles by their xy bounding boxes."""

    def __init__(self, mesh: Mesh):
        v = mesh.vertices[mesh.faces]  # (F, 3 vertices, 3)
        lx, ly = mesh.tile
        shifts = np.array([(i * lx, j * ly, 0.0) for i in (-1, 0, 1) for j in (-1, 0, 1)])
        v = (v[None, :, :, :] + shifts[:, None, None, :]).reshape(-1, 3, 3)
        self.v0 = v[:, 0]
        self.e1 = v[:, 1] - v[:, 0]
        self.e2 = v[:, 2] - v[:, 0]
        cross = np.cross(self.e1, self.e2)
        self.normal = cross / np.linalg.norm(cross, axis=1, keepdims=True)
        assert np.all(self.normal[:, 2] > 0.0), "every facet normal must point up"
        per_tile = max(1, int(np.sqrt(len(mesh.faces) / 2)))
        self.origin = np.array([-1.5 * lx, -1.5 * ly])
        self.cell = np.array([lx, ly]) / per_tile
        self.n_cells = 3 * per_tile
        xy_lo, xy_hi = v[:, :, :2].min(axis=1), v[:, :, :2].max(axis=1)
        lo, hi = self._cells(xy_lo), self._cells(xy_hi - 1e-9 * self.cell)  # not the edge's
        self.z_lo, self.z_hi = v[:, :, 2].min(axis=1), v[:, :, 2].max(axis=1)
        tri, cell = self._pairs(lo, hi)
        by_cell = np.argsort(cell, kind="stable")
        self.filed = tri[by_cell]
        self.offsets = np.searchsorted(cell[by_cell], np.arange(self.n_cells**2 + 1))

    def _cells(self, xy: np.ndarray) -> np.ndarray:
        """(i, j) grid cells of points (…, 2), clipped to the grid."""
        ij = np.floor((xy - self.origin) / self.cell).astype(np.int64)
        return np.clip(ij, 0, self.n_cells - 1)

    def _pairs(self, lo: np.ndarray, hi: np.ndarray):
        """(item, flat cell) pairs of every cell in each item's range lo … hi (inclusive)."""
        span = hi - lo + 1
        item, k = _expand(span[:, 0] * span[:, 1])
        i = lo[item, 0] + k % span[item, 0]
        j = lo[item, 1] + k // span[item, 0]
        return item, j * self.n_cells + i

    def closest_hit(self, origin: np.ndarray, d: np.ndarray, t_max: np.ndarray):
        """(t, facet) of each ray's closest hit with 0 < t < t_max (t = inf, facet = −1 if
        none); origins inside the central tile, segments at most one tile long sideways."""
        n_rays = len(origin)
        t_best = np.full(n_rays, np.inf)
        facet = np.full(n_rays, -1, dtype=np.int64)
        end = origin[:, :2] + t_max[:, None] * d[:, :2]
        lo = self._cells(np.minimum(origin[:, :2], end))
        hi = self._cells(np.maximum(origin[:, :2], end))
        ray, cell = self._pairs(lo, hi)
        owner, k = _expand(self.offsets[cell + 1] - self.offsets[cell])
        ray, tri = ray[owner], self.filed[self.offsets[cell[owner]] + k]
        z_end = origin[:, 2] + t_max * d[:, 2]
        near = (self.z_lo[tri] <= np.maximum(origin[ray, 2], z_end[ray])) & (
            self.z_hi[tri] >= np.minimum(origin[ray, 2], z_end[ray])
        )
        ray, tri = ray[near], tri[near]
        t = _moller_trumbore(origin[ray], d[ray], self.v0[tri], self.e1[tri], self.e2[tri])
        ok = (t > 0.0) & (t < t_max[ray])
        ray, tri, t = ray[ok], tri[ok], t[ok]
        order = np.lexsort((t, ray))  # per ray, the smallest t first
        ray, tri, t = ray[order], tri[order], t[order]
        first = np.ones(len(ray), dtype=bool)
        first[1:] = ray[1:] != ray[:-1]
        t_best[ray[first]] = t[first]
        facet[ray[first]] = tri[first]
        return t_best, facet


def _moller_trumbore(o, d, v0, e1, e2) -> np.ndarray:
    """Distance t along each ray to its triangle's plane where the hit is inside the
    triangle (Möller & Trumbore 1997), NaN where it misses or runs parallel."""
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o - v0
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1)
        v = np.einsum("ij,ij->i", d, q) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
    inside = (det != 0.0) & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0)
    return np.where(inside, t, np.nan)


def _wrap(p: np.ndarray, tile) -> np.ndarray:
    """Points moved by whole periods into [−Lx/2, Lx/2) × [−Ly/2, Ly/2)."""
    out = p.copy()
    for k in range(2):
        out[:, k] -= tile[k] * np.floor(out[:, k] / tile[k] + 0.5)
    return out


def trace(
    mesh: Mesh, eta: float, theta_i: float, n: int, rng: np.random.Generator, *, phi_i: float = 0.0
) -> Escapes:
    """Trace ``n`` primary rays of light incident from wi(θi, φi) (``incident_direction``) on
    the interface air (above) / index ``eta`` (below); origins i.i.d. uniform over the tile
    just outside the relief slab on the light's side, ``BATCH`` rays at a time."""
    tracer = _Tracer(mesh, eta, rng)
    wi = incident_direction(theta_i, phi_i)
    assert wi[2] != 0.0, "grazing incidence has no side"
    from_above = wi[2] > 0.0
    lx, ly = mesh.tile
    parts = []
    for a in range(0, n, BATCH):
        m = min(BATCH, n - a)
        o = np.empty((m, 3))
        o[:, 0] = rng.uniform(-lx / 2, lx / 2, m)
        o[:, 1] = rng.uniform(-ly / 2, ly / 2, m)
        o[:, 2] = tracer.zmax if from_above else tracer.zmin
        parts.append(tracer.follow(o, np.tile(-wi, (m, 1))))
    wo, order = (np.concatenate([p[k] for p in parts]) for k in range(2))
    return Escapes(
        n=n, wo=wo, order=order, reflected=(wo[:, 2] > 0.0) == from_above, cut=n - len(wo)
    )


class _Tracer:
    """Rays followed through the relief slab of ``mesh`` (air above, index ``eta`` below)."""

    def __init__(self, mesh: Mesh, eta: float, rng: np.random.Generator):
        self.tile = mesh.tile
        self.eta = eta
        self.rng = rng
        self.triangles = _Triangles(mesh)
        scale = max(*mesh.tile, np.ptp(mesh.vertices[:, 2]))
        self.eps = 1e-9 * scale  # the offset of a new start from its hit, along the normal
        self.zmin, self.zmax = np.array(mesh.z_range) + np.array([-1e-6, 1e-6]) * scale

    def follow(self, o: np.ndarray, d: np.ndarray):
        """(exit directions, interactions) of the rays from ``o`` along ``d`` that leave the
        slab (in no particular order); ``o`` and ``d`` are overwritten."""
        lx, ly = self.tile
        n = len(o)
        order = np.zeros(n, dtype=np.int64)
        walks = np.zeros(n, dtype=np.int64)
        alive = np.arange(n)
        out_wo, out_order = [], []
        while len(alive):
            oa, da = o[alive], d[alive]
            with np.errstate(divide="ignore", invalid="ignore"):
                t_slab = np.where(da[:, 2] > 0, (self.zmax - oa[:, 2]) / da[:, 2], np.inf)
                t_slab = np.where(da[:, 2] < 0, (self.zmin - oa[:, 2]) / da[:, 2], t_slab)
                t_side = np.minimum(lx / np.abs(da[:, 0]), ly / np.abs(da[:, 1]))
            t_slab = np.maximum(t_slab, 0.0)
            t_max = np.minimum(t_slab, t_side)
            t_hit, facet = self.triangles.closest_hit(oa, da, np.nextafter(t_max, np.inf))
            hit = facet >= 0
            escaped = ~hit & (t_slab <= t_side)
            walked = ~hit & ~escaped
            out_wo.append(da[escaped])
            out_order.append(order[alive[escaped]])

            w = alive[walked]
            o[w] = _wrap(oa[walked] + t_max[walked, None] * da[walked], self.tile)
            walks[w] += 1

            h = alive[hit]
            p = oa[hit] + t_hit[hit, None] * da[hit]
            d[h], o[h] = self.interact(p, da[hit], self.triangles.normal[facet[hit]])
            order[h] += 1

            alive = np.concatenate([w, h])
            give_up = (order[alive] >= MAX_INTERACTIONS) | (walks[alive] >= MAX_WALKS)
            alive = np.sort(alive[~give_up])
        return np.concatenate(out_wo), np.concatenate(out_order)

    def interact(self, p: np.ndarray, d: np.ndarray, normal: np.ndarray):
        """(new direction, new start) of rays along ``d`` meeting facets of upward unit
        ``normal`` at ``p``: reflected with probability F (``fresnel_dielectric``), else
        refracted (Snell's law in vector form); the start is ``eps`` off the facet on the
        side the ray leaves to, wrapped into the tile."""
        c = -np.einsum("ij,ij->i", d, normal)
        above = c > 0.0  # the ray comes from the air
        n_f = np.where(above[:, None], normal, -normal)  # the normal on the ray's side
        cos_i = np.abs(c)
        n1 = np.where(above, 1.0, self.eta)
        n2 = np.where(above, self.eta, 1.0)
        reflect = self.rng.random(len(d)) < fresnel_dielectric(cos_i, n1, n2)
        ratio = n1 / n2
        cos_t = np.sqrt(np.maximum(1.0 - ratio**2 * (1.0 - cos_i**2), 0.0))
        d_refl = d + 2.0 * cos_i[:, None] * n_f
        d_refr = ratio[:, None] * d + (ratio * cos_i - cos_t)[:, None] * n_f
        new_d = np.where(reflect[:, None], d_refl, d_refr)
        side = np.where(reflect, 1.0, -1.0)
        start = _wrap(p + (side * self.eps)[:, None] * n_f, self.tile)
        return new_d / np.linalg.norm(new_d, axis=1, keepdims=True), start


@dataclass(frozen=True)
class BinAverages:
    """Bin-averaged BSDF of one side (reflected or transmitted) on a (θo, Δφ) grid:
    ``f`` (Θ, Φ) sr⁻¹ = rays in the bin / (N Ω_B) and ``stderr`` its per-ray binomial
    standard error; ``total`` the fraction of primary rays on that side, ``total_stderr``
    its binomial standard error."""

    f: np.ndarray
    stderr: np.ndarray
    total: float
    total_stderr: float


def bin_averages(esc: Escapes, bins, phi_i: float, *, reflected: bool, orders=None):
    """``BinAverages`` of the rays of ``esc`` that left on the incidence's side
    (``reflected``) or the other, in the order slots ``orders`` (a container of 1, 2, 3, 4:
    that many interactions, 4 standing for ≥ 4, as the estimator's slots; None: all).
    θo is the angle to the exit direction's own pole (+z upward, −z downward), Δφ =
    atan2(o_y, o_x) − φi, folded to [0°, 180°] if ``bins.folded``; edges and Ω_B are those of
    ``bins`` (a ``microsim.bins.Bins``)."""
    keep = esc.reflected == reflected
    if orders is not None:
        keep &= np.isin(np.minimum(esc.order, 4), list(orders))
    wo = esc.wo[keep]
    theta = np.degrees(np.arctan2(np.hypot(wo[:, 0], wo[:, 1]), np.abs(wo[:, 2])))
    dphi = np.mod(np.degrees(np.arctan2(wo[:, 1], wo[:, 0])) - phi_i, 360.0)
    if bins.folded:
        dphi = np.where(dphi > 180.0, 360.0 - dphi, dphi)
    else:
        dphi = np.where(dphi >= bins.phi_edges[-1], dphi - 360.0, dphi)
    counts, _, _ = np.histogram2d(theta, dphi, bins=(bins.theta_edges, bins.phi_edges))
    assert counts.sum() == len(wo), "every direction falls in a bin"
    p = counts / esc.n
    omega = bins.projected_solid_angle()
    total = len(wo) / esc.n
    return BinAverages(
        f=p / omega,
        stderr=np.sqrt(p * (1.0 - p) / esc.n) / omega,
        total=total,
        total_stderr=float(np.sqrt(total * (1.0 - total) / esc.n)),
    )
