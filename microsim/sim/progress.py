"""Structured progress of ``simulate``: one event per chunk of rays tallied.

``simulate(..., progress=callback)`` calls ``callback(RaysDone(...))`` in the calling thread
after every chunk is added to the running sums, so a bar can advance ray by ray instead of
parsing text. ``finished`` marks the last chunk of a (realisation, incidence) pair.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["RaysDone"]


@dataclass(frozen=True)
class RaysDone:
    """``rays`` more primary rays of (``realisation``, ``incidence``) are tallied.

    ``realisation``: 0-based index of the realisation; ``realisations``: their count;
    ``incidence``: index into ``theta_i``; ``theta_i``: that incidence in degrees;
    ``rays``: rays tallied by this chunk (≥ 0); ``finished``: the pair is now complete.
    """

    realisation: int
    realisations: int
    incidence: int
    theta_i: float
    rays: int
    finished: bool
