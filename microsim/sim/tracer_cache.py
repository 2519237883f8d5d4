"""The prepared tracer of a surface (``tracer_for``): its ``Tracer``, its exact V-groove masking
and whether rays get their own groove azimuth, kept for repeated calls on the same surface."""

from __future__ import annotations

import os
import threading
import weakref
from typing import NamedTuple

from microsim.errors import UsageError

from .tracer import Tracer
from .vgroove_profile import GrooveMasking, VGrooveCaster, VGrooveProfile

__all__ = ["TRACER_BACKEND", "GRID_CASTER", "GRID_SWITCH", "PreparedSurface", "tracer_for"]


class PreparedSurface(NamedTuple):
    """A surface ready to trace: its ``tracer``; ``profile`` None for traced masking, else the
    exact V-groove masking (``VGrooveProfile`` for "exact", ``VGrooveCaster`` for
    "analytic": ``GrooveMasking``); ``azimuth`` whether each ray gets its own groove azimuth
    (``surface.azimuth_average``)."""

    tracer: Tracer
    profile: GrooveMasking | None
    azimuth: bool


_REUSED: dict = {}  # id(weakref to surface) → (weakref, fingerprint, masking, prepared)
_REUSE_SLOTS = 2
TRACER_BACKEND = "auto"
"""The simulations' Embree backend (``Tracer``): coherent packets over the library embreex
ships when they bind (the scene and BVH build in 0.10 s instead of embreex's ~0.5 s on the
bench mesh; tracing at about the same rate on AVX2), else embreex. ``MICROSIM_EMBREE_PACKETS=0``
forces embreex, which stays the reference path of the tests."""
GRID_CASTER = True
"""Simulations walk every ray on heightfield tiles on the grid (``heightfield_caster``,
``Tracer``'s ``grid``): faster than Embree per primary ray up to θi ≈ 85° on the bench mesh,
exact in float64, the same facet as Embree's but for edge ties, and no Embree scene to build.
``GRID_SWITCH`` = "0" in the environment (or ``GRID_CASTER = False``) keeps every ray on
Embree."""
GRID_SWITCH = "MICROSIM_GRID_CASTER"
_REUSE_LOCK = threading.Lock()


def tracer_for(surface, masking: str, fingerprint: str | None = None) -> PreparedSurface:
    """The ``PreparedSurface`` of ``surface`` for ``masking``. UsageError for
    "exact"/"analytic" on a surface that is not azimuth-averaged V-grooves.

    Reuse: with ``fingerprint`` (``surface.fingerprint()``, the mesh's identity) the prepared
    tracer is kept for the same surface object — at most the ``_REUSE_SLOTS`` most recent
    (surface, masking) pairs, dropped when their surface is garbage-collected — and handed
    out again while its mesh is unchanged, so repeated ``simulate`` calls on one surface
    (``simulate_auto``'s batches, sweeps over θi, speed runs) build the Embree scene and BVH
    once. Tracers are read-only after construction and shared safely between threads."""
    grid = GRID_CASTER and os.environ.get(GRID_SWITCH, "1") != "0"
    if fingerprint is None:
        return _prepare(surface, masking, grid)
    with _REUSE_LOCK:
        for ref, fp, mode, prepared in list(_REUSED.values()):
            if ref() is surface and fp == fingerprint and mode == (masking, grid):
                return prepared
    prepared = _prepare(surface, masking, grid)
    try:  # the entry goes with its surface (dict.pop is atomic: safe in a GC callback)
        ref = weakref.ref(surface, lambda r: _REUSED.pop(id(r), None))
    except TypeError:  # not weak-referenceable: no reuse
        return prepared
    with _REUSE_LOCK:
        _REUSED[id(ref)] = (ref, fingerprint, (masking, grid), prepared)
        for key in list(_REUSED)[:-_REUSE_SLOTS]:
            _REUSED.pop(key, None)
    return prepared


def _prepare(surface, masking: str, grid: bool) -> PreparedSurface:
    tracer = Tracer(surface, backend=TRACER_BACKEND, grid=grid)
    azimuth = bool(getattr(surface, "azimuth_average", False))
    profile = None
    if masking in ("exact", "analytic"):
        if not azimuth:
            raise UsageError(
                f"masking={masking!r} is only available for azimuth-averaged V-groove surfaces "
                "(azimuth_average=True); use masking='traced'"
            )
        profile = VGrooveProfile(tracer) if masking == "exact" else VGrooveCaster(tracer)
    return PreparedSurface(tracer, profile, azimuth)
