"""What a simulation measures and how its work is executed: two of the three frozen
descriptions of a run ``estimate(Experiment, Estimator, Execution)`` (``Estimator``, the
third, is defined beside ``estimate`` in ``estimator``).

``Experiment``  the physics asked about: the surface(s), the material, the incidences
                (θi, φi in degrees), the outgoing (θo, Δφ) bins and the scattering orders.
``Execution``   how the work runs — it never changes a number: worker threads, rays per
                thread task, the progress callback.

Each checks its fields when it is made (a ``UsageError`` naming the field and its allowed
values, before any work) and stores them normalised: angles as tuples of floats, integers as
``int``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from microsim.analytic.fresnel import resolve_material
from microsim.bins import Bins
from microsim.checks import integer

from .arguments import (
    CHUNK,
    MAX_CHUNK,
    check_angles,
    check_bins,
    check_progress,
    realisation_source,
    thread_count,
)
from .bounces import check_bounces
from .cluster import check_client
from .dielectric import check_light_from_below, check_transmission
from .progress import RaysDone

__all__ = ["Experiment", "Execution", "normalise"]


def normalise(obj, name: str, value) -> None:
    """Store the normalised ``value`` of a frozen dataclass's own field ``name``."""
    object.__setattr__(obj, name, value)


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
    [2, ``bounces.MAX_BOUNCES``] or "all" (module ``bounces``). ``transmission``: the
    material is a dielectric medium below the surface and light is reflected *and* refracted
    (module ``dielectric``); θi may then also lie in (90, 180] (light from inside the medium).
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
    transmission: bool = False

    def __post_init__(self):
        ior = resolve_material(self.material)
        transmission = check_transmission(self.transmission, ior)
        th, ph = check_angles(self.theta_i, self.phi_i, below=transmission)
        normalise(self, "transmission", transmission)
        normalise(self, "theta_i", tuple(float(t) for t in th))
        normalise(self, "phi_i", tuple(float(p) for p in ph))
        check_light_from_below(ior, th)
        normalise(self, "bounces", check_bounces(self.bounces))
        check_bins(self.bins)
        if isinstance(self.realisations, list):
            normalise(self, "realisations", tuple(self.realisations))
        if self.seeds is not None and not isinstance(self.seeds, (str, bytes)):
            if hasattr(self.seeds, "__iter__"):
                normalise(self, "seeds", tuple(self.seeds))
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
class Execution:
    """How the work runs; results are bitwise identical for any of these. ``threads``: worker
    threads in [1, ``MAX_THREADS``] (None: the machine's CPU count); ``chunk``: rays per
    thread task in [1, ``MAX_CHUNK``], rounded to whole blocks; ``progress``: None or a
    callable receiving ``RaysDone`` events in the calling thread after every chunk;
    ``cluster``: None (local threads) or a ``dask.distributed.Client`` whose workers trace the
    tasks instead (``sim.cluster``; ``threads`` is then unused)."""

    threads: int | None = None
    chunk: int = CHUNK
    progress: Callable[[RaysDone], None] | None = None
    cluster: object | None = None

    def __post_init__(self):
        normalise(self, "threads", thread_count(self.threads))
        normalise(self, "cluster", check_client(self.cluster))
        normalise(
            self, "chunk", integer("chunk", self.chunk, 1, MAX_CHUNK, " (rays per thread task)")
        )
        check_progress(self.progress, "microsim.sim.RaysDone events")
