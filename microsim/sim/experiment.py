"""What a simulation measures, how it estimates it, and how the work is executed: three
frozen descriptions, so that a run is ``estimate(Experiment, Estimator, Execution)``.

``Experiment``  the physics asked about: the surface(s), the material, the incidences
                (θi, φi in degrees), the outgoing (θo, Δφ) bins and the scattering orders.
``Estimator``   the Monte Carlo estimator of Mikkelsen 2009, eq. 9: primary rays per
                incidence, the random stream, the masking test, how ray origins are sampled
                and whether the incidence azimuth is randomised per block.
``Execution``   how the work runs — it never changes a number: worker threads, rays per
                thread task, the progress callback.

Each checks its fields when it is made (a ``UsageError`` naming the field and its allowed
values, before any work) and stores them normalised: angles as tuples of floats, integers as
``int``. ``simulate`` (the keyword-argument entry point) builds the three and calls
``estimator.estimate``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from microsim.analytic.fresnel import resolve_material
from microsim.bins import Bins
from microsim.checks import integer
from microsim.errors import UsageError

from .arguments import (
    MAX_CHUNK,
    MAX_RAYS,
    check_angles,
    check_bins,
    check_choice,
    check_progress,
    realisation_source,
    thread_count,
)
from .bounces import check_bounces
from .cluster import check_client
from .paths import MASKING
from .progress import RaysDone
from .streams import ORIGINS

__all__ = ["Experiment", "Estimator", "Execution"]


def _set(obj, name: str, value) -> None:
    object.__setattr__(obj, name, value)  # normalising a frozen dataclass's own field


@dataclass(frozen=True, eq=False)
class Experiment:
    """The physics of one run.

    ``surface``: a ``microsim.surfaces.Surface`` (None when ``realisations`` lists the
    surfaces or ``surface_factory`` builds them); ``realisations``: a list of surfaces, or a
    count with ``surface_factory`` (a callable(seed) -> Surface, called lazily, one
    realisation at a time, with each of ``seeds`` or with seed, seed + 1, … of the
    ``Estimator``); see ``arguments.realisation_source``. ``material``: a name, an index n or
    n + ik, or None (a mirror; ``fresnel.resolve_material``). ``theta_i``: incidence polar
    angle(s) in degrees, each in [0, 90); ``phi_i``: azimuth(s) in degrees, a scalar or one
    per θi. ``bins``: the outgoing grid. ``bounces``: 1 (single scattering), K in
    [2, ``bounces.MAX_BOUNCES``] or "all" (module ``bounces``).
    """

    surface: object = None
    material: object = None
    theta_i: tuple = (0.0,)
    phi_i: tuple = (0.0,)
    bins: Bins = Bins()
    bounces: int | str = 1
    realisations: object = None
    surface_factory: Callable[[int], object] | None = None
    seeds: tuple | None = None

    def __post_init__(self):
        th, ph = check_angles(self.theta_i, self.phi_i)
        _set(self, "theta_i", tuple(float(t) for t in th))
        _set(self, "phi_i", tuple(float(p) for p in ph))
        _set(self, "bounces", check_bounces(self.bounces))
        check_bins(self.bins)
        resolve_material(self.material)
        if isinstance(self.realisations, list):
            _set(self, "realisations", tuple(self.realisations))
        if self.seeds is not None and not isinstance(self.seeds, (str, bytes)):
            if hasattr(self.seeds, "__iter__"):
                _set(self, "seeds", tuple(self.seeds))
        realisation_source(self.surface, self.realisations, self.surface_factory, self.seeds, 0)

    @property
    def ior(self):
        """The material's complex index (None for a mirror)."""
        return resolve_material(self.material)

    def surfaces(self, seed: int):
        """(count, getter) of the realisations traced with stream ``seed``
        (``arguments.realisation_source``)."""
        return realisation_source(
            self.surface, self.realisations, self.surface_factory, self.seeds, seed
        )


@dataclass(frozen=True)
class Estimator:
    """The estimator of one run: ``rays`` primary rays per incidence in [1, ``MAX_RAYS``]
    (spread over the realisations); ``seed`` ≥ 0, the random stream (results are a function
    of it alone); ``masking``: "traced" (Embree, the reference), "exact" or "analytic"
    (V-groove surfaces only, ``paths``); ``origins``: "stratified" or "independent"
    (``streams.chunk_origins``); ``isotropic``: rotate each block's incidence azimuth by its
    own uniform angle (statistically isotropic surfaces only, ``paths.RotatedIncidencePath``),
    each block a sweep of the whole tile by itself, so the blocks are independent replicates
    and the standard error comes from their scatter (``stderr_method``).
    """

    rays: int = 1_000_000
    seed: int = 0
    masking: str = "traced"
    origins: str = "stratified"
    isotropic: bool = False

    def __post_init__(self):
        _set(self, "rays", integer("rays", self.rays, 1, MAX_RAYS, " (primary rays per incidence)"))
        _set(self, "seed", integer("seed", self.seed, 0, None, " (the random stream)"))
        check_choice("masking", self.masking, MASKING)
        check_choice("origins", self.origins, ORIGINS)
        if not isinstance(self.isotropic, (bool, np.bool_)):
            raise UsageError(f"isotropic must be True or False, got {self.isotropic!r}")
        _set(self, "isotropic", bool(self.isotropic))

    @property
    def stderr_method(self) -> str:
        """One of ``tallies.STDERR_METHODS``: "blocks" for ``isotropic`` runs (every block an
        independent replicate: its own sweep of the tile, its own incidence azimuth), else
        "pairs" (paired strata) for stratified origins, "per-ray" for independent ones."""
        if self.isotropic:
            return "blocks"
        return "pairs" if self.origins == "stratified" else "per-ray"


@dataclass(frozen=True)
class Execution:
    """How the work runs; results are bitwise identical for any of these. ``threads``: worker
    threads in [1, ``MAX_THREADS``] (None: the machine's CPU count); ``chunk``: rays per
    thread task in [1, ``MAX_CHUNK``], rounded to whole blocks; ``progress``: None or a
    callable receiving ``RaysDone`` events in the calling thread after every chunk;
    ``cluster``: None (local threads) or a ``dask.distributed.Client`` whose workers trace the
    tasks instead (``sim.cluster``; ``threads`` is then unused)."""

    threads: int | None = None
    chunk: int = 2**16
    progress: Callable[[RaysDone], None] | None = None
    cluster: object | None = None

    def __post_init__(self):
        _set(self, "threads", thread_count(self.threads))
        _set(self, "cluster", check_client(self.cluster))
        _set(self, "chunk", integer("chunk", self.chunk, 1, MAX_CHUNK, " (rays per thread task)"))
        check_progress(self.progress, "microsim.sim.RaysDone events")
