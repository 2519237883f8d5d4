"""Ray-traced explicit-integral BRDFs (Mikkelsen 2009, eq. 9) on periodic microsurfaces.

    from microsim.sim import simulate, Bins
    res = simulate(surface, "aluminium", [0, 30, 60, 80], rays=10**6, bins=Bins(45, 37))
    res.brdf, res.stderr, res.ledger["single_fresnel"], res.in_plane(), res.save("out/")

or, with the run's three frozen descriptions (``experiment``)::

    res = estimate(Experiment(surface, "aluminium", (0, 30, 60, 80), bins=Bins(45, 37)),
                   Estimator(rays=10**6), Execution(threads=2))

Modules: ``experiment`` (``Experiment``, ``Execution``), ``estimator`` (``Estimator``;
``estimate``, ``simulate``, ``ray_events``: the driver; ``estimate_spectral``,
``simulate_spectral``: many materials over one traced geometry, module ``spectral``),
``identity`` (``RunDescription``: the run's identity for resume, the testing cache and sweep
task ids), ``auto`` (``simulate_auto``, ``estimate_to_precision``), ``streams`` (random
streams, ray origins), ``paths`` (trace paths, ledger), ``tallies`` (running sums, bin estimate
and standard error), ``schedule`` (threads, interrupts), ``arguments`` (argument checks),
``tracer`` and ``engine`` (Embree, the periodic walk and its compiled per-ray loops), the
estimator's compiled loops (``ray_bins``, ``fresnel_kernels``, ``vgroove_kernels``,
``bounce_kernels``, ``tally_kernels``, ``origin_kernels``), ``result``, ``progress``,
``predict``, ``compare``. ``Bins`` (with ``MAX_BINS``) lives in the core layer,
``microsim.bins``, and is re-exported here.
"""

from microsim.bins import MAX_BINS, Bins

from .cluster import SchedulerLost
from .estimator import (
    Estimator,
    estimate,
    estimate_spectral,
    ray_events,
    simulate,
    simulate_spectral,
)
from .events import Events
from .experiment import Execution, Experiment
from .paths import LEDGER
from .progress import RaysDone
from .result import InPlane, Result
from .spectral import SpectralResult, Spectrum
from .streams import BLOCK
from .tracer import Tracer
from .vgroove_profile import VGrooveProfile

__all__ = [
    "simulate",
    "estimate",
    "simulate_spectral",
    "estimate_spectral",
    "Spectrum",
    "SpectralResult",
    "Experiment",
    "Estimator",
    "Execution",
    "ray_events",
    "Events",
    "Result",
    "InPlane",
    "Bins",
    "MAX_BINS",
    "Tracer",
    "VGrooveProfile",
    "BLOCK",
    "LEDGER",
    "RaysDone",
    "SchedulerLost",
]
