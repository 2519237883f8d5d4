"""Bins of the single-bounce rays' reflected directions (``locate_single``)."""

from __future__ import annotations

import numpy as np

from . import bin_kernels
from .bins import Bins
from .ledger import SINGLE
from .scratch import WorkArray

__all__ = ["locate_single"]

_NEAR_EDGE = WorkArray("near-edge", np.bool_)  # this thread's work array (``scratch``)


def locate_single(bins: Bins, status, wo, phi_i: float, psi, where) -> None:
    """Set ``where`` to the bin of wo (3 columns) for the SINGLE rays, Δφ taken against
    φi (degrees) or, with groove azimuths ``psi`` (wo in each ray's groove frame), against
    φi − ψ: folded grids by ``bin_kernels.bin_rays`` (compiled, vectorised), unfolded ones by
    ``Bins.locate``."""
    if bins.folded:
        bin_kernels.bin_rays(
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
