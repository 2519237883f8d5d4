"""Timing of the wave solver (``microsim.wave``) for ``microsim bench``: one incidence,
all propagating orders, on an n² ABC tile of side ``tile`` λ, in the smooth regime
(σ = λ/100) and at σ = λ.

The tile is ``surfaces.abc`` with B = 2π·10 λ (correlation length 10 λ), C = 3.5, seed 0.
Where the grid does not sample the height phase (σ = λ on 1024² over 200 λ: dx = 0.195 λ),
the heights are Fourier-upsampled ×2, ×4 … until ``kirchhoff_orders``' sampling check passes;
the factor used is reported. Timed: ``kirchhoff_orders`` only (not the synthesis), wall clock.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

from microsim.errors import UsageError
from microsim.wave.kirchhoff import kirchhoff_orders

__all__ = ["WaveTiming", "wave_bench"]


@dataclass(frozen=True)
class WaveTiming:
    """One timed incidence: roughness ``sigma`` (λ), the ``n``² tile of side ``tile`` λ, the
    incidence ``theta_i`` (degrees), the Fourier ``upsample`` factor used, the propagating
    ``orders``, the ``qz_nodes``, the wall ``seconds``, the ``albedo`` (sum of order powers)
    and the ``surface`` interpolant ("smooth" or "mesh", ``kirchhoff_orders``)."""

    sigma: float
    n: int
    tile: float
    theta_i: float
    upsample: int
    orders: int
    qz_nodes: int
    seconds: float
    albedo: float
    surface: str


def _tile(n, dx, sigma):
    from microsim.surfaces.heightfields import abc

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return abc(n, dx, sigma, 2.0 * math.pi * 10.0, 3.5, seed=0)


def wave_bench(
    n: int = 1024,
    tile: float = 200.0,
    theta_i: float = 30.0,
    sigmas=(0.01, 1.0),
    *,
    material="aluminium",
    workers: int = 2,
    surface: str = "smooth",
) -> list[WaveTiming]:
    """One ``WaveTiming`` per σ (in λ)."""
    dx = float(tile) / int(n)
    out = []
    for sigma in sigmas:
        s = _tile(int(n), dx, float(sigma))
        for u in (1, 2, 4, 8) if surface == "smooth" else (1,):
            try:
                t0 = time.perf_counter()
                o = kirchhoff_orders(
                    s.heights,
                    s.dx,
                    1.0,
                    theta_i,
                    material=material,
                    upsample=u,
                    workers=workers,
                    surface=surface,
                )
                sec = time.perf_counter() - t0
                break
            except UsageError as err:
                if "too coarse" not in str(err) or u == 8:
                    raise
        out.append(
            WaveTiming(
                sigma=float(sigma),
                n=int(n),
                tile=float(tile),
                theta_i=float(theta_i),
                upsample=int(u),
                orders=int(len(o.m)),
                qz_nodes=int(o.meta["qz_nodes"]),
                seconds=float(sec),
                albedo=float(o.power.sum()),
                surface=surface,
            )
        )
    return out
