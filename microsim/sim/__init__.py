"""Ray-traced explicit-integral BRDFs (Mikkelsen eq. 9) on periodic microsurfaces.

    from microsim.sim import simulate, Bins
    res = simulate(surface, "aluminium", [0, 30, 60, 80], rays=10**6, bins=Bins(45, 37))
    res.brdf, res.stderr, res.ledger["single_fresnel"], res.in_plane(), res.save("out/")
"""
from .bins import Bins
from .estimator import BLOCK, LEDGER, Events, ray_events, simulate
from .progress import RaysDone
from .result import InPlane, Result
from .tracer import Tracer, VGrooveProfile

__all__ = ["simulate", "ray_events", "Events", "Result", "InPlane", "Bins", "Tracer",
           "VGrooveProfile", "BLOCK", "LEDGER", "RaysDone"]
