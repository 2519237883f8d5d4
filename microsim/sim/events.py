"""Per-ray diagnostics of primary rays (``trace_events``, behind ``ray_events``): every
per-ray quantity kept (``Events``), vectorised in NumPy; slower than the tally paths."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from microsim.analytic.fresnel import fresnel

from .ledger import DOWNWARD, MASKED, RAY_MISSED, RAY_UNRESOLVED, SINGLE
from .masking_rays import FROM_ESCAPE
from .streams import BLOCK
from .tracer import ESCAPED, HIT, MISSED, Hits, Tracer
from .vgroove_profile import GrooveMasking, VGrooveCaster, casts_primaries

__all__ = ["Events", "trace_events", "fresnel_by_block"]


@dataclass(frozen=True)
class Events:
    """Per-ray outcome of primary rays (global frame).

    ``status`` (N,) int8 index into ``LEDGER``; ``weight`` (N,) Fresnel weight F(n·wi) (0 when
    nothing was hit); ``wo`` (N, 3) reflected direction (NaN without a hit); ``normal`` (N, 3)
    facet normal (rotated back to the global frame for azimuth-averaged grooves);
    ``margin`` (N,) exact V-groove masking margin (> 0 ⇔ masked; NaN unless computed).
    """

    status: np.ndarray
    weight: np.ndarray
    wo: np.ndarray
    normal: np.ndarray
    margin: np.ndarray


def _rotate_z(w: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Rotate vectors (N, 3) about +z by the angles whose cosines/sines are ``c``/``s`` (N,)."""
    out = np.empty(np.broadcast_shapes(w.shape, c.shape + (3,)))
    out[:, 0] = c * w[..., 0] - s * w[..., 1]
    out[:, 1] = s * w[..., 0] + c * w[..., 1]
    out[:, 2] = w[..., 2]
    return out


def fresnel_by_block(c: np.ndarray, rows: np.ndarray, ior) -> np.ndarray:
    """Fresnel weights F(c) of the rays ``rows`` (sorted indices into a batch of whole blocks),
    evaluated with one ``fresnel`` call per block.

    NumPy's complex kernels round the last bit differently in the SIMD body and in the scalar
    tail of an array (measured: (η² − 1)·z over a complex array differs by 1 ulp depending on
    the position), so evaluating block by block keeps every weight independent of how many
    blocks share a batch; all other per-ray operations are elementwise and position-independent.
    """
    if rows.size == 0:
        return np.zeros(0)
    cuts = np.searchsorted(rows, np.arange(BLOCK, int(rows[-1]) + 1, BLOCK))
    return np.concatenate([fresnel(part, ior) for part in np.split(c, cuts)])


def trace_events(
    tracer: Tracer, profile: GrooveMasking | None, wi: np.ndarray, origins, psi, ior, azimuth: bool
) -> Events:
    """Follow primary rays from direction ``wi`` (global) to their ledger class (vectorised),
    keeping every per-ray quantity (``Events``).

    ``origins`` is a batch of whole ``BLOCK``s (the last may be short); the outcome of every
    ray is independent of the batch size (see ``fresnel_by_block``)."""
    n = len(origins)
    if azimuth:  # trace in the groove frame: wi by −ψ
        cpsi, spsi = np.cos(psi), np.sin(psi)
        wl = _rotate_z(wi, cpsi, -spsi)
        hits = (
            _analytic_hits(tracer, profile, origins, wl)
            if casts_primaries(profile)
            else tracer.first_hit(origins, -wl)
        )
    else:
        wl = np.broadcast_to(wi, (n, 3))
        hits = tracer.first_hit(origins, -np.asarray(wi, dtype=np.float64))  # one shared direction
    status = np.full(n, RAY_UNRESOLVED, dtype=np.int8)
    status[hits.status == MISSED] = RAY_MISSED
    status[hits.status == ESCAPED] = RAY_MISSED  # a falling ray cannot escape
    weight = np.zeros(n)
    wo = np.full((n, 3), np.nan)
    margin = np.full(n, np.nan)
    h = np.flatnonzero(hits.status == HIT)
    nrm = hits.normal[h]
    c = np.einsum("ij,ij->i", wl[h], nrm)
    front = c > 0  # back-facing hits stay unresolved
    h, nrm, c = h[front], nrm[front], c[front]
    weight[h] = fresnel_by_block(c, h, ior)
    wlo = 2.0 * c[:, None] * nrm - wl[h]
    up = wlo[:, 2] > 0
    status[h[~up]] = DOWNWARD
    hu = h[up]
    if profile is not None:
        m = profile.masking_margin(hits.prim[hu], hits.point[hu], wlo[up])
        margin[hu] = m
        status[hu] = np.where(m > 0, MASKED, SINGLE)
    else:
        status[hu] = FROM_ESCAPE[tracer.escapes(hits.point[hu], nrm[up], wlo[up])]
    wo[h] = wlo if not azimuth else _rotate_z(wlo, cpsi[h], spsi[h])  # back by +ψ
    normal = np.full((n, 3), np.nan)
    normal[h] = nrm if not azimuth else _rotate_z(nrm, cpsi[h], spsi[h])
    return Events(status=status, weight=weight, wo=wo, normal=normal, margin=margin)


def _analytic_hits(tracer: Tracer, caster: VGrooveCaster, origins, wl) -> Hits:
    """``Tracer.first_hit`` of rays ``origins`` along −``wl`` (N, 3), computed exactly by
    ``caster`` (masking="analytic"): every ray hits; ``point`` holds x only (y, z are NaN,
    unused by the V-groove masking test)."""
    prim, x = caster.first_hit_columns(origins[:, 0], origins[:, 2], wl[:, 0], wl[:, 2])
    point = np.full((len(prim), 3), np.nan)
    point[:, 0] = x
    return Hits(
        status=np.full(len(prim), HIT, dtype=np.int8),
        prim=prim,
        point=point,
        normal=tracer.facets.normals(prim),
    )
