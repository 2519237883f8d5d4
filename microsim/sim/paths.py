"""Trace paths: how a chunk of primary rays is followed to its ledger class, weight and bin.

At its first hit with unit facet normal n a primary ray from wi carries the weight F(n·wi)
(exact Fresnel) and reflects to wo = 2(wi·n)n − wi; if wo points up and the reflected ray
escapes (visibility V), the weight counts in the (θo, Δφ) bin of wo — one sample of the
explicit microfacet integral (Mikkelsen 2009, eq. 9). Every primary ray ends in exactly one
ledger class (``LEDGER``): ``single`` (escaped after one bounce), ``masked`` (the reflected ray
met the surface), ``downward`` (wo_z ≤ 0: a multiple-scattering event), ``unresolved`` (wrap
cap reached, or a numerically back-facing hit) or ``missed`` (no hit at all: impossible for a
closed periodic surface). These are the single-bounce paths (``simulate(bounces=1)``, the
default); module ``bounces`` follows masked and downward paths on to their later bounces.

One interface, ``TracePath.follow(blocks) -> RayOutcome`` (status, weight, bin per ray;
``ray_columns``), chosen once per (surface, masking, incidence) by ``choose_path``:

- ``AnalyticVGroovePath`` (``masking="analytic"``, V-grooves): no Embree. Every rim lies at
  z = 0, so the groove a falling ray enters decides its facet and the hit follows in closed
  form (``vgroove_profile.VGrooveCaster``); masking is the float64 test of ``"exact"``. Same
  rays, bins and streams as the traced paths, which stay the reference in the tests.
- ``RotatedIncidencePath`` (``isotropic=True``): each block's incidence azimuth rotated by its
  own ψ_b (``streams.block_rotation``).
- ``FacetTablePath``: surfaces without azimuth averaging and with no more facets than the
  incidence has rays look up Fresnel weight, mirror direction and bin per hit facet
  (``facet_tables.facet_table``); only the two ray casts remain per ray.
- ``TracedPath``: everything else (Embree hit; masking traced, or exact for V-grooves).

V-grooves (``surface.azimuth_average``): each ray gets its own uniformly random groove azimuth
ψ; wi is rotated by −ψ about z into the groove frame, traced, and wo binned against the rotated
incident azimuth (Δφ is rotation-invariant). This gives the isotropic V-cavity BRDF.

Masking offsets: traced masking rays start eps ≈ 2 float32 ulp of the largest coordinate above
the facet (1.2e-7 on a unit tile). The resulting bias scales like eps/feature depth, amplified
~1/cos θo near the horizon: on heightfields with features ≥ 1e-3 of the tile it is ~1e-4
relative (≪ 0.1 %); on a unit tile of 4000 V-grooves it was measured at +0.1–0.4 % for
θo ≥ 80° (below the statistical error of 10⁶ rays), and ``masking="exact"`` removes it.

Bitwise reproducibility: every per-ray operation is elementwise, in compiled loops that
evaluate each ray alone (``engine``, ``*_kernels``); Fresnel, whose complex NumPy kernels
round by array position, is evaluated per block (``events.fresnel_by_block``) or in real
arithmetic. So a ray's outcome never depends on the chunk it is traced in.
``events.trace_events`` is the per-ray diagnostic path behind ``ray_events`` (full ``Events``,
slower).
Directions are unit vectors in the global frame pointing away from the surface; φi in degrees.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from microsim.bins import Bins

from .facet_tables import FacetTable, facet_table, uses_facet_table
from .ledger import DOWNWARD, LEDGER, MASKED, RAY_MISSED, RAY_UNRESOLVED, SINGLE
from .ray_columns import (
    RayOutcome,
    analytic_columns,
    drawn_masking_rays,
    tabled_masking_rays,
    trace_columns,
)
from .streams import (
    BLOCK,
    block_rotation,
    block_span,
    chunk_origins,
    groove_starts,
    stratified_draw,
)
from .tracer import Tracer
from .vgroove_profile import GrooveMasking, VGrooveCaster, casts_primaries

__all__ = [
    "SINGLE",
    "MASKED",
    "DOWNWARD",
    "RAY_UNRESOLVED",
    "RAY_MISSED",
    "LEDGER",
    "MASKING",
    "ANALYTIC_BATCH",
    "Incidence",
    "TracePath",
    "TracedPath",
    "FacetTablePath",
    "RotatedIncidencePath",
    "AnalyticVGroovePath",
    "choose_path",
]

MASKING = ("traced", "exact", "analytic")
ANALYTIC_BATCH = 16  # blocks per vectorised batch of masking="analytic" (measured best)
assert (SINGLE, MASKED, DOWNWARD) == (0, 1, 2)  # vgroove_kernels.analytic_vgroove relies on it


@dataclass(frozen=True, eq=False)
class Incidence:
    """One incidence on one traced surface: what every trace path needs. ``wi`` unit incident
    direction (global frame), ``phi_i`` its azimuth in degrees (Δφ is taken from it), ``ior``
    as ``resolve_material`` returns it, ``rays`` the primary rays N of this (realisation,
    incidence), ``key`` its random stream (seed, realisation, incidence), ``origins`` one of
    ``streams.ORIGINS``; ``replicates``: every block a stratified sweep of the whole tile by
    itself (``streams.chunk_origins``; ``simulate(isotropic=True)``)."""

    tracer: Tracer
    wi: np.ndarray
    phi_i: float
    bins: Bins
    ior: object
    rays: int
    key: tuple
    origins: str = "stratified"
    replicates: bool = False

    def origins_of(self, blocks, azimuth: bool):
        """Origin columns and groove azimuths of consecutive ``blocks`` (``chunk_origins``)."""
        return chunk_origins(
            self.tracer, self.rays, blocks, self.key, azimuth, self.origins, self.replicates
        )

    def groove_starts_of(self, blocks):
        """(x, ψ) of the rays of consecutive ``blocks``, as ``origins_of(blocks, True)``
        gives them: for the exact V-groove paths, where y plays no part (stratified origins:
        ``groove_starts``, y not even drawn)."""
        if self.origins == "stratified":
            return groove_starts(self.tracer, self.rays, blocks, self.key, self.replicates)
        (x, _, _), psi = self.origins_of(blocks, True)
        return x, psi


class TracePath:
    """How the primary rays of one ``Incidence`` are followed (module docstring).

    ``follow(blocks)`` → the ``RayOutcome`` of the rays of the consecutive ``blocks``, in ray
    order; bitwise independent of how blocks are grouped. Thread-safe: one path serves all
    worker threads."""

    def __init__(self, incidence: Incidence):
        self.incidence = incidence

    def follow(self, blocks) -> RayOutcome:
        raise NotImplementedError


class TracedPath(TracePath):
    """Embree primary hit; masking traced (``profile`` None) or decided exactly in float64
    (``VGrooveProfile``); groove azimuths per ray when ``azimuth``."""

    def __init__(self, incidence: Incidence, profile: GrooveMasking | None, azimuth: bool):
        super().__init__(incidence)
        self.profile, self.azimuth = profile, azimuth

    def follow(self, blocks):
        inc = self.incidence
        starts, psi = inc.origins_of(blocks, self.azimuth)
        return trace_columns(
            inc.tracer,
            self.profile,
            inc.wi,
            inc.phi_i,
            inc.bins,
            starts,
            psi if self.azimuth else None,
            inc.ior,
        )


class FacetTablePath(TracePath):
    """Primary and masking rays walked on the heightfield grid or traced by Embree; weight,
    mirror direction and bin looked up per hit facet in a ``FacetTable`` built once for the
    incidence (``tabled_masking_rays``). Stratified rays (not replicates) walked on the grid
    draw their origins in the walk's own pass (``drawn_masking_rays``): the same bits."""

    def __init__(self, incidence: Incidence, table: FacetTable):
        super().__init__(incidence)
        self.table = table

    def follow(self, blocks):
        inc, found = self.incidence, None
        if inc.origins == "stratified" and not inc.replicates:
            draw = stratified_draw(inc.tracer, inc.rays, blocks, inc.key)
            found = drawn_masking_rays(inc.tracer, self.table, inc.wi, draw)
        if found is None:
            starts, _ = inc.origins_of(blocks, False)
            found = tabled_masking_rays(inc.tracer, self.table, inc.wi, starts)
        return found.traced(inc.tracer)


class RotatedIncidencePath(TracePath):
    """Every block's incidence azimuth rotated by its own ψ_b (``streams.block_rotation``)
    about the macro normal, bins taken relative to the rotated azimuth φi + ψ_b: φi is then
    uniform, which averages a statistically isotropic surface's realisation over incident
    azimuths without changing the expected BRDF. One shared direction per block keeps the
    batch coherent; the rays of a block share ψ_b, so each block (a sweep of the whole tile
    by itself, ``Incidence.replicates``) is one replicate, and the standard error comes from
    the scatter between blocks (``tallies.bin_estimate``), which holds the azimuth-to-azimuth
    scatter of the one surface."""

    def __init__(self, incidence: Incidence, profile: GrooveMasking | None):
        super().__init__(incidence)
        self.profile = profile

    def follow(self, blocks):
        inc, wi, out = self.incidence, self.incidence.wi, []
        for b in blocks:
            starts, _ = inc.origins_of([b], False)
            psi = block_rotation(inc.key, b)
            c, s = np.cos(psi), np.sin(psi)
            wb = np.array([c * wi[0] - s * wi[1], s * wi[0] + c * wi[1], wi[2]])
            out.append(
                trace_columns(
                    inc.tracer,
                    self.profile,
                    wb,
                    inc.phi_i + np.degrees(psi),
                    inc.bins,
                    starts,
                    None,
                    inc.ior,
                )
            )
        return RayOutcome(*(np.concatenate(parts) for parts in zip(*out)))


class AnalyticVGroovePath(TracePath):
    """``masking="analytic"``: closed-form V-groove hits and masking (``analytic_columns``),
    in cache-sized batches of ``ANALYTIC_BATCH`` blocks."""

    def __init__(self, incidence: Incidence, caster: VGrooveCaster):
        super().__init__(incidence)
        self.caster = caster

    def follow(self, blocks):
        inc, blocks = self.incidence, list(blocks)
        wi = np.asarray(inc.wi, dtype=np.float64)
        z = inc.tracer.zmax + inc.tracer.top_margin
        n = block_span(inc.rays, blocks)[1]
        out = RayOutcome(np.empty(n, dtype=np.int8), np.empty(n), np.empty(n, dtype=np.int64))
        for a in range(0, len(blocks), ANALYTIC_BATCH):
            x, psi = inc.groove_starts_of(blocks[a : a + ANALYTIC_BATCH])
            lo = a * BLOCK
            part = RayOutcome(*(c[lo : lo + len(x)] for c in out))
            analytic_columns(self.caster, wi, inc.phi_i, inc.bins, x, z, psi, inc.ior, part)
        return out


def choose_path(
    incidence: Incidence,
    profile: GrooveMasking | None,
    azimuth: bool,
    isotropic: bool = False,
    pool: ThreadPoolExecutor | None = None,
    parts: int = 1,
) -> TracePath:
    """The trace path of ``incidence`` on a surface prepared by ``tracer_cache.tracer_for``
    (``profile``, ``azimuth``), with ``isotropic`` block rotations or not. A facet table is
    built here, in ``parts`` facet ranges on ``pool`` (once per incidence, shared by the
    threads)."""
    inc = incidence
    if casts_primaries(profile):
        return AnalyticVGroovePath(inc, profile)
    if isotropic and not azimuth:
        return RotatedIncidencePath(inc, profile)
    if uses_facet_table(inc.tracer, profile, azimuth, isotropic, inc.rays):
        return FacetTablePath(
            inc, facet_table(inc.tracer, inc.wi, inc.ior, inc.bins, inc.phi_i, pool, parts)
        )
    return TracedPath(inc, profile, azimuth)
