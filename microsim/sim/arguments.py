"""The arguments of ``simulate``, ``simulate_auto`` and ``ray_events``, checked before any work.

Every bad argument raises a ``UsageError`` naming it. Angles are degrees (θi in [0, 90), φi
finite, scalar or one per θi); the integer bounds (``MAX_RAYS``, ``MAX_THREADS``,
``MAX_CHUNK``) keep memory and float64 stratum positions sound. ``realisation_source`` gives
``realisations`` its one meaning (see ``simulate``).
"""

from __future__ import annotations

import inspect
import numbers
import os

import numpy as np

from microsim.bins import Bins
from microsim.checks import integer, short
from microsim.errors import UsageError

from .paths import MASKING
from .streams import ORIGINS

__all__ = [
    "MAX_RAYS",
    "MAX_THREADS",
    "MAX_CHUNK",
    "check_angles",
    "check_bins",
    "check_choice",
    "check_progress",
    "check_inputs",
    "check_run_options",
    "check_masking_bounces",
    "thread_count",
    "is_surface",
    "surface_error",
    "realisation_source",
]

MAX_RAYS = 2**48
"""Most primary rays per incidence (2.8·10¹⁴): a ray's stratum position r + ξ is a float64,
which above 2⁴⁸ keeps fewer than 5 bits of the jitter ξ; at ~10⁷ rays/s it is also a year of
tracing. Memory does not depend on it (rays are drawn and tallied one chunk at a time)."""
MAX_THREADS = 1024
CHUNK = 2**16
"""Rays per thread task unless asked otherwise: ~13 MB of work arrays per task (~200 bytes a
ray), and a run of 10⁶ rays splits into 16 tasks, enough to keep every thread busy to its end."""
MAX_CHUNK = 2**22
"""Most rays per thread task: every task holds ~200 bytes per ray of work arrays (0.8 GB);
bounce chains (``simulate(bounces=K)``, K > 1) ~230 bytes per ray more (``bounces.
trace_bounces``: per-path state and two generations of continuing rays)."""


def _angles(name: str, value, what: str) -> np.ndarray:
    """``value`` (scalar or 1-D sequence of numbers) as a float64 array, or a UsageError."""
    if value is None or isinstance(value, (str, bytes)):
        raise UsageError(f"{name} must be {what}, got {short(value)}")
    try:
        a = np.atleast_1d(np.asarray(value, dtype=np.float64))
    except (TypeError, ValueError):
        raise UsageError(f"{name} must be {what}, got {short(value)}") from None
    if a.ndim != 1 or a.size == 0:
        raise UsageError(f"{name} must be {what}, got {short(value)}")
    return a


def check_angles(theta_i, phi_i, below: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Validated (θi, φi) float64 arrays in degrees, φi broadcast to θi's shape; a UsageError
    naming theta_i or phi_i otherwise. ``below``: θi may also lie in (90, 180] (light from
    under the surface, through a dielectric: ``dielectric``)."""
    allowed = "[0, 90) or (90, 180]" if below else "[0, 90)"
    what = f"a scalar or a non-empty 1-D sequence of degrees in {allowed}"
    th = _angles("theta_i", theta_i, what)
    ok = (th >= 0) & (th < 90)
    if below:
        ok |= (th > 90) & (th <= 180)
    if not np.all(ok):
        raise UsageError(f"theta_i must lie in {allowed} degrees, got {short(theta_i)}")
    ph = _angles("phi_i", phi_i, f"finite degrees: a scalar or one per theta_i ({th.size})")
    if ph.size not in (1, th.size):
        raise UsageError(
            f"phi_i must be a scalar or one azimuth per theta_i ({th.size} values), "
            f"got {ph.size}: {short(phi_i)}"
        )
    ph = np.broadcast_to(ph, th.shape).copy()
    if not np.all(np.isfinite(ph)):
        raise UsageError(
            f"phi_i must be finite degrees (scalar or one per theta_i), got {short(phi_i)}"
        )
    return th, ph


def check_choice(name: str, value, allowed) -> str:
    """``value`` if it is one of the strings ``allowed``; else a UsageError naming ``name``."""
    if not isinstance(value, str) or value not in allowed:
        raise UsageError(f"{name} must be one of {', '.join(allowed)}, got {value!r}")
    return value


def check_progress(progress, receives: str) -> None:
    """UsageError unless ``progress`` is None or a callable (receiving ``receives``)."""
    if progress is not None and not callable(progress):
        raise UsageError(
            f"progress must be None or a callable receiving {receives}, got {progress!r}"
        )


def check_inputs(theta_i, phi_i, rays, chunk, masking, seed=0):
    """Validated (θi, φi) arrays (degrees); raises a UsageError naming the first bad one of
    theta_i, phi_i, rays, chunk, masking, seed (``MAX_RAYS``, ``MAX_CHUNK`` bound the
    integers)."""
    th, ph = check_angles(theta_i, phi_i)
    integer("rays", rays, 1, MAX_RAYS, " (primary rays per incidence)")
    integer("chunk", chunk, 1, MAX_CHUNK, " (rays per thread task)")
    integer("seed", seed, 0, None, " (the random stream)")
    check_choice("masking", masking, MASKING)
    return th, ph


def check_masking_bounces(masking: str, bounces) -> None:
    """UsageError for ``masking="exact"`` with ``bounces`` other than 1: it decides only the
    first masking test exactly."""
    if masking == "exact" and bounces != 1:
        raise UsageError(
            "masking='exact' decides only the first masking test exactly; with bounces "
            f"{bounces!r} use masking='analytic' (the exact V-groove bounce chain) or 'traced'"
        )


def thread_count(threads) -> int:
    """``threads`` as an int in [1, ``MAX_THREADS``]; None means the machine's CPU count
    (``os.cpu_count()``, capped at ``MAX_THREADS``). Results do not depend on it."""
    if threads is None:
        return min(os.cpu_count() or 1, MAX_THREADS)
    return integer("threads", threads, 1, MAX_THREADS, " (or None: the CPU count)")


def check_bins(bins) -> Bins:
    """``bins`` if it is a ``Bins``; else a UsageError."""
    if not isinstance(bins, Bins):
        raise UsageError(f"bins must be a microsim.sim.Bins (e.g. Bins(45, 37)), got {bins!r}")
    return bins


def check_run_options(bins, origins, progress, progress_receives: str) -> None:
    """UsageError unless ``bins`` is a ``Bins``, ``origins`` one of ``ORIGINS`` and
    ``progress`` None or a callable (receiving ``progress_receives``)."""
    check_bins(bins)
    check_choice("origins", origins, ORIGINS)
    check_progress(progress, progress_receives)


def is_surface(obj) -> bool:
    """A ``microsim.surfaces.Surface`` or an object with its mesh contract (looked up without
    reading them: a heightfield's mesh is derived on access)."""
    missing = object()
    names = ("vertices", "faces", "tile_size", "periodic", "fingerprint")
    return all(inspect.getattr_static(obj, a, missing) is not missing for a in names)


def surface_error(name: str, obj) -> UsageError:
    """The UsageError for ``name`` = ``obj`` that is not a surface."""
    return UsageError(
        f"{name} must be a microsim.surfaces.Surface (e.g. microsim.surfaces."
        f"vgrooves(4000, microsim.analytic.Beckmann(0.3)) or gaussian(...)), "
        f"got {type(obj).__name__} {short(obj, 60)}"
    )


def realisation_source(surface, realisations, surface_factory, seeds, seed: int):
    """(count, getter) over the surfaces ``simulate`` traces; ``getter(r)`` returns
    realisation r (built lazily, one at a time, by ``surface_factory`` and checked).

    - ``surface`` alone (``realisations`` None): one realisation.
    - ``realisations`` a non-empty list of surfaces (``surface`` None or the list's first).
    - ``surface_factory(seed) -> Surface`` (``surface`` None) with ``seeds`` (a non-empty
      sequence of integers ≥ 0, one realisation each), or with ``realisations`` = a count n
      (seeds ``seed``, ``seed`` + 1, …, ``seed`` + n − 1), or with neither (one, ``seed``).
    """
    if surface_factory is None:
        return _listed_realisations(surface, realisations, seeds)
    return _factory_realisations(surface, realisations, surface_factory, seeds, seed)


def _listed_realisations(surface, realisations, seeds):
    """(count, getter) of ``surface`` alone or of the list ``realisations``."""
    if seeds is not None:
        raise UsageError(
            "seeds are the seeds of surface_factory(seed): give surface_factory "
            f"too, or leave seeds None (got seeds={short(seeds)})"
        )
    if realisations is None:
        if not is_surface(surface):
            raise surface_error("surface", surface)
        return 1, lambda r: surface
    if _is_count(realisations):
        raise UsageError(
            f"realisations={realisations!r} is a count of surfaces built by "
            "surface_factory(seed): give surface_factory=callable(seed), or a "
            "list of surfaces as realisations"
        )
    if isinstance(realisations, tuple) and len(realisations) == 2 and callable(realisations[0]):
        raise UsageError(
            "realisations=(factory, seeds) is written surface_factory=factory, seeds=seeds"
        )
    if isinstance(realisations, (str, bytes)) or not hasattr(realisations, "__iter__"):
        raise UsageError(
            "realisations must be None, a non-empty list of surfaces or a count "
            f"(with surface_factory), got {short(realisations)}"
        )
    lst = list(realisations)
    if not lst:
        raise UsageError(
            "realisations must be a non-empty list of surfaces (or a count, with surface_factory)"
        )
    for k, s in enumerate(lst):
        if not is_surface(s):
            raise surface_error(f"realisations[{k}]", s)
    if surface is not None and surface is not lst[0]:
        raise UsageError(
            "surface must be None (or realisations[0]) when realisations lists "
            "the surfaces to trace"
        )
    return len(lst), lambda r: lst[r]


def _factory_realisations(surface, realisations, surface_factory, seeds, seed: int):
    """(count, getter) of the surfaces ``surface_factory`` builds from ``seeds`` (or from
    ``seed``, ``seed`` + 1, …)."""
    if not callable(surface_factory):
        raise UsageError(
            f"surface_factory must be a callable(seed) -> Surface, got {short(surface_factory)}"
        )
    if surface is not None:
        raise UsageError(
            "surface must be None when surface_factory builds the surfaces, got "
            f"{type(surface).__name__}"
        )
    if realisations is not None and not _is_count(realisations):
        raise UsageError(
            "realisations must be a count (or None) with surface_factory, got "
            f"{short(realisations)}"
        )
    count = None if realisations is None else integer("realisations", realisations, 1)
    if seeds is None:
        seeds = [seed + r for r in range(count or 1)]
    else:
        if isinstance(seeds, (str, bytes)) or not hasattr(seeds, "__iter__"):
            raise UsageError(f"seeds must be a sequence of integers >= 0, got {short(seeds)}")
        seeds = [integer(f"seeds[{k}]", s, 0) for k, s in enumerate(seeds)]
        if not seeds:
            raise UsageError("seeds must hold at least one seed (one per realisation)")
        if count is not None and count != len(seeds):
            raise UsageError(
                f"realisations ({count}) must equal the number of seeds "
                f"({len(seeds)}), or be left None"
            )

    def build(r):
        s = surface_factory(seeds[r])
        if not is_surface(s):
            raise surface_error(f"surface_factory({seeds[r]!r}) returned {type(s).__name__}; it", s)
        return s

    return len(seeds), build


def _is_count(value) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))
