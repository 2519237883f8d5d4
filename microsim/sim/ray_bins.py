"""Bins of the single-bounce rays' reflected directions (``locate_single``), on folded grids
by the compiled, vectorised ``bin_rays``: it guesses with ``trig.atan_approx`` and settles the
rays near an edge by ``Bins.locate``'s own arithmetic (``bin_kernels``)."""

from __future__ import annotations

import math

import numpy as np

from microsim.bin_kernels import bin_guess, bin_scales, locate_one
from microsim.bins import Bins
from microsim.jit import vectorised
from microsim.trig import cos_sin

from .engine.codes import SINGLE
from .scratch import WorkArray

__all__ = ["locate_single", "bin_rays"]

_NEAR_EDGE = WorkArray("near-edge", np.bool_)  # this thread's work array (``scratch``)


def locate_single(bins: Bins, status, wo, phi_i: float, psi, where) -> None:
    """Set ``where`` to the bin of wo (3 columns) for the SINGLE rays, Δφ taken against
    φi (degrees) or, with groove azimuths ``psi`` (wo in each ray's groove frame), against
    φi − ψ: folded grids by ``bin_rays`` (compiled, vectorised), unfolded ones by
    ``Bins.locate``."""
    if bins.folded:
        bin_rays(
            status,
            *wo,
            np.empty(0) if psi is None else psi,
            psi is not None,
            float(phi_i),
            bins.n_theta,
            bins.phi_edges,
            _NEAR_EDGE(len(status)),
            where,
        )
        return
    single = np.flatnonzero(status == SINGLE)
    ws = np.stack([a[single] for a in wo], axis=1)
    where[single] = bins.locate(ws, phi_i if psi is None else phi_i - np.degrees(psi[single]))


@vectorised
def bin_rays(status, wox, woy, woz, psi, rotate, phi_i_deg, n_theta, edges, near, where):
    """``where[i]`` = ``Bins.locate`` of wo_i on the folded grid (``n_theta``, Δφ ``edges``
    in degrees) for the SINGLE rays (others untouched), against the incident azimuth
    ``phi_i_deg`` (degrees), less ψ_i when ``rotate`` (wo in the ray's groove frame: Δφ is
    unchanged by the rotation). Two passes: a branch-free one that the compiler vectorises
    (``bin_guess``: ``atan_approx`` angles, ~4× faster than the same arithmetic ray by
    ray) flags in ``near`` (bool work array) the rays whose angle lies within twice
    ``ATAN_ERROR`` of an edge; the second bins those with ``Bins.locate``'s own arithmetic
    (``locate_one``), so the result is ``Bins.locate``'s for every ray, ties on an edge
    included (a mirror at θo = 30° on 2° bins)."""
    n_phi = len(edges) - 1
    ts, fs, gt, gf = bin_scales(n_theta, n_phi)
    cos_phi, sin_phi = math.cos(math.radians(phi_i_deg)), math.sin(math.radians(phi_i_deg))
    for i in range(len(status)):
        ex, ey = cos_phi, sin_phi
        if rotate:
            cp, sp = cos_sin(psi[i])
            ex = cp * cos_phi + sp * sin_phi
            ey = -sp * cos_phi + cp * sin_phi
        flat, near[i] = bin_guess(wox[i], woy[i], woz[i], ex, ey, n_theta, n_phi, ts, fs, gt, gf)
        where[i] = flat if status[i] == SINGLE else where[i]
    for i in range(len(status)):
        if near[i] and status[i] == SINGLE:
            phi = phi_i_deg - psi[i] * (180.0 / math.pi) if rotate else phi_i_deg
            where[i] = locate_one(wox[i], woy[i], woz[i], phi, n_theta, n_phi, True, edges)
