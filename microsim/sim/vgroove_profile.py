"""V-groove geometry decided exactly in float64: the masking test of ``masking="exact"``
(``VGrooveProfile``), the closed-form primary hit of ``masking="analytic"`` (``VGrooveCaster``)
and the per-facet tables the traced paths read (``groove_tables``).

The trace paths ask of either one thing through ``GrooveMasking``: the exact masking margin of
a hit, and whether the primary hits come in closed form too (``casts_primaries``).
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np

from microsim.errors import UsageError

__all__ = [
    "GROOVE_CLEAR_EPS",
    "GrooveMasking",
    "VGrooveProfile",
    "VGrooveCaster",
    "GrooveProfile",
    "GrooveClear",
    "GrooveStrata",
    "NO_GROOVES",
    "NO_STRATA",
    "groove_tables",
    "casts_primaries",
]


class GrooveMasking(Protocol):
    """Exact V-groove masking as the trace paths use it (``VGrooveProfile``, ``VGrooveCaster``).

    ``casts_primaries``: the primary hits are computed in closed form too (no Embree:
    ``masking="analytic"``), by ``first_hit_columns``/``profile``."""

    casts_primaries: bool

    def masking_margin(self, prim: np.ndarray, point: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """s(1 + tanθ σ w_x/w_z) − W per hit: > 0 ⇔ masked."""
        ...

    def margin_columns(self, prim, x, wo_x, wo_z) -> np.ndarray:
        """``masking_margin`` on columns."""
        ...


def casts_primaries(masking: GrooveMasking | None) -> bool:
    """Whether ``masking`` (None: traced masking) computes the primary hits in closed form."""
    return masking is not None and masking.casts_primaries


GROOVE_CLEAR_EPS = 64.0
"""A masking ray of a V-groove surface escapes without tracing when its exact float64 margin
(``VGrooveProfile.margin_from_rim``) is below −this × ``Tracer.eps``: 32 times the start
offset of a traced masking ray, far beyond Embree's float32 error, so Embree would have let it
pass too (tested by tracing the cleared rays anyway)."""


class GrooveClear(NamedTuple):
    """``primary.traced_primary``'s exact clear test of a V-groove mesh, per facet: ``rim`` x,
    ``signed_tan`` tanθ σ, rim-to-rim ``width`` W, rim-to-bottom ``extent``; and ``tol`` the
    tolerance ``GROOVE_CLEAR_EPS`` · eps in length units. Flat facets get NaN (never cleared)."""

    rim: np.ndarray
    signed_tan: np.ndarray
    width: np.ndarray
    extent: np.ndarray
    tol: float


class GrooveStrata(NamedTuple):
    """Equal-width V-grooves tiling the tile, for the stratified origins
    (``origin_kernels._groove_strata``): the left rim x of every groove in order of tilt
    ``x_left`` (G,) (ties keep mesh order: grooves sort by left, then right wall slope) and
    the groove ``width`` W."""

    x_left: np.ndarray
    width: float


NO_GROOVES = GrooveClear(np.empty(0), np.empty(0), np.empty(0), np.empty(0), 0.0)
NO_STRATA = GrooveStrata(np.empty(0), 0.0)


def groove_tables(tracer) -> tuple[GrooveClear, GrooveStrata]:
    """(``GrooveClear``, ``GrooveStrata``) of a V-groove mesh, from one ``VGrooveCaster`` (or,
    for grooves with a flat facet, ``VGrooveProfile``, which gives no strata); ``NO_GROOVES``
    and ``NO_STRATA`` for what the profile or caster refuses."""
    strata = NO_STRATA
    try:
        profile = VGrooveCaster(tracer)
    except UsageError:
        try:
            profile = VGrooveProfile(tracer)
        except UsageError:
            return NO_GROOVES, NO_STRATA
    else:
        order = np.lexsort((profile.depth / profile.w_right, profile.depth / profile.w_left))
        x_left = np.ascontiguousarray(profile.x_left[order])
        strata = GrooveStrata(x_left, tracer.tile[0] / profile.n_grooves)
    opposite, rim = profile.opposite, profile.rim
    with np.errstate(invalid="ignore"):
        signed_tan = profile.tan * np.sign(opposite - rim)
    width = np.abs(opposite - rim)
    return GrooveClear(
        rim, signed_tan, width, profile.extent, GROOVE_CLEAR_EPS * tracer.eps
    ), strata


class VGrooveProfile:
    """Exact float64 masking for straight V-grooves along y (Mikkelsen 2009, eq. 25 geometry).

    Every rim lies at z = 0 and the surface lies below, so a ray leaving a facet upwards can
    only be blocked by the opposite facet of the same groove before rising above z = 0. For a
    hit at horizontal distance s from the facet's rim, with facet tilt tan θ = |n_x|/n_z, the
    ray reaches z = 0 after travelling s·tanθ·(w_x σ)/w_z horizontally towards the opposite rim
    (σ its side, W the rim-to-rim width); it is masked iff s(1 + tanθ σ w_x / w_z) > W.
    """

    casts_primaries = False

    def __init__(self, tracer):
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

    casts_primaries = True

    def __init__(self, tracer):
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
