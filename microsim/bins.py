"""Bins over the outgoing hemisphere, shared by the estimator and the model predictions.

A result is always a BRDF averaged over a bin B (docs/design.md, Conventions):

    f̄_B = (1/Ω_B) ∫_B f(wi, wo) cos θo dω_o,   Ω_B = ∫_B cos θo dω_o,

with Ω_B the bin's exact projected solid angle, (φ₂ − φ₁)(sin²θ₂ − sin²θ₁)/2.

Azimuths are measured *relative to the incident azimuth*: Δφ = φo − φi, so the mirror direction
lies at Δφ = 180°. The φ edges are offset by half a bin so that one bin is centred on Δφ = 180°
(the in-plane forward-scattering slice) and one on Δφ = 0° (the backward slice). For isotropic
surfaces ``folded=True`` maps Δφ and −Δφ together: Δφ ∈ [0°, 180°], the first and last bins
being half bins centred on 0° and 180°.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from microsim.checks import integer
from microsim.errors import UsageError

__all__ = ["Bins", "MAX_BINS"]

MAX_BINS = 2**22
"""Most bins of a grid (4,194,304, e.g. 2048 × 2048): every bin costs ≥ 72 bytes per
(realisation, incidence) in the running sums and the Result, ~96 more per incidence and
32 per thread task (``estimator.BIN_BYTES_*``), i.e. ~0.7 GB per incidence at the cap; and
finer bins than 90°/2048 ≈ 0.04° hold almost no events at any feasible ray count."""


def _half_turn(phi_deg):
    """Azimuth(s) in degrees taken to (−180°, 180°]."""
    phi = np.mod(phi_deg, 360.0)
    return np.where(phi > 180.0, phi - 360.0, phi)


def _column(a, shape) -> np.ndarray:
    """``a`` broadcast to ``shape`` as a flat, C-contiguous, writeable float64 array (a copy
    only where it is not one already): the compiled bin pass then has one specialisation."""
    a = np.asarray(a, dtype=np.float64)
    if a.shape != shape:
        a = np.broadcast_to(a, shape)
    return np.require(a.reshape(-1), np.float64, ["C", "W"])


@dataclass(frozen=True)
class Bins:
    """(θo, Δφ) grid. ``n_theta`` bins uniform over θo ∈ [0°, 90°]; ``n_phi`` bins over Δφ;
    at most ``MAX_BINS`` in all (else UsageError stating the limit and why).

    Unfolded: ``n_phi`` bins of width 360°/n_phi, centred on k·360°/n_phi (n_phi must be even
    so that 180° is a bin centre). Folded: Δφ ∈ [0°, 180°] with ``n_phi`` bins, width
    180°/(n_phi − 1), the first and last being half-width bins centred on 0° and 180°.
    """

    n_theta: int = 45
    n_phi: int = 72
    folded: bool = True

    def __post_init__(self):
        cost = "each bin takes >= 72 bytes of tallies per realisation and incidence, 32 per thread"
        n_theta = integer("n_theta", self.n_theta, 1, MAX_BINS, " (the limit: MAX_BINS in all)")
        n_phi = integer("n_phi", self.n_phi, 2, MAX_BINS, " (the limit: MAX_BINS in all)")
        if not isinstance(self.folded, (bool, np.bool_)):
            raise UsageError(f"folded must be True or False, got {self.folded!r}")
        if n_theta * n_phi > MAX_BINS:
            raise UsageError(
                f"n_theta × n_phi = {n_theta:,} × {n_phi:,} = {n_theta * n_phi:,} "
                f"bins is above the limit of {MAX_BINS:,} bins ({cost}: "
                f"{n_theta * n_phi * 72 / 1e9:.3g} GB per incidence)"
            )
        object.__setattr__(self, "n_theta", n_theta)
        object.__setattr__(self, "n_phi", n_phi)
        object.__setattr__(self, "folded", bool(self.folded))
        if not self.folded and self.n_phi % 2:
            raise UsageError(
                f"n_phi must be even when folded=False (a bin centred on 180°), got {self.n_phi}"
            )

    # --- edges ------------------------------------------------------------------------
    @property
    def theta_edges(self) -> np.ndarray:
        """θo edges in degrees, shape (n_theta + 1,)."""
        return np.linspace(0.0, 90.0, self.n_theta + 1)

    @property
    def phi_edges(self) -> np.ndarray:
        """Δφ edges in degrees, shape (n_phi + 1,). Unfolded edges start at −half a bin."""
        if self.folded:
            w = 180.0 / (self.n_phi - 1)
            inner = (np.arange(self.n_phi - 1) + 0.5) * w
            return np.concatenate([[0.0], inner, [180.0]])
        w = 360.0 / self.n_phi
        return (np.arange(self.n_phi + 1) - 0.5) * w

    @property
    def theta_centers(self) -> np.ndarray:
        e = self.theta_edges
        return 0.5 * (e[1:] + e[:-1])

    @property
    def phi_centers(self) -> np.ndarray:
        """Nominal Δφ centres in degrees (0°, …, 180° exactly for folded bins)."""
        if self.folded:
            return np.linspace(0.0, 180.0, self.n_phi)
        return np.arange(self.n_phi) * (360.0 / self.n_phi)

    @property
    def shape(self) -> tuple[int, int]:
        return (self.n_theta, self.n_phi)

    @property
    def forward_index(self) -> int:
        """Index of the Δφ bin centred on 180° (the mirror direction's azimuth)."""
        return self.n_phi - 1 if self.folded else self.n_phi // 2

    @property
    def backward_index(self) -> int:
        """Index of the Δφ bin centred on 0° (back towards the light)."""
        return 0

    def projected_solid_angle(self) -> np.ndarray:
        """Exact Ω_B = Δφ (sin²θ₂ − sin²θ₁)/2 per bin in sr, shape (n_theta, n_phi).

        Folded bins cover both ±Δφ, so their Ω counts both halves.
        """
        t = np.radians(self.theta_edges)
        p = np.radians(self.phi_edges)
        s2 = np.sin(t) ** 2
        band = 0.5 * (s2[1:] - s2[:-1])
        dphi = np.diff(p) * (2.0 if self.folded else 1.0)
        return band[:, None] * dphi[None, :]

    # --- locating directions ------------------------------------------------------------
    @staticmethod
    def angles(wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(θo, φo) in degrees of unit directions wo (..., 3), by the arctangent ``locate``
        bins with (``trig.atan2_portable``: the same bits on every machine)."""
        from . import bin_kernels

        wo = np.asarray(wo, dtype=np.float64)
        cols = [np.ascontiguousarray(wo[..., k]).ravel() for k in range(3)]
        theta, phi = np.empty(len(cols[0])), np.empty(len(cols[0]))
        bin_kernels.direction_angles(*cols, theta, phi)
        to_deg = 180.0 / np.pi  # as the kernels convert
        shape = wo.shape[:-1]
        return (theta * to_deg).reshape(shape), (phi * to_deg).reshape(shape)

    def relative_azimuth(self, wo: np.ndarray, phi_i_deg: float) -> np.ndarray:
        """Δφ = φo − φi in degrees: in [−half bin, 360 − half bin) unfolded, [0, 180] folded."""
        d = self.angles(wo)[1] - _half_turn(phi_i_deg)
        d = np.where(d < 0.0, d + 360.0, d)  # = np.mod(d, 360), cheaper
        if self.folded:
            return np.where(d > 180.0, 360.0 - d, d)
        w = 360.0 / self.n_phi
        return np.where(d >= 360.0 - 0.5 * w, d - 360.0, d)

    def locate(self, wo: np.ndarray, phi_i_deg: float = 0.0) -> np.ndarray:
        """Flat bin index (θ-major, i·n_phi + j) of each unit direction wo; −1 if wo_z ≤ 0."""
        wo = np.asarray(wo, dtype=np.float64)
        return self.locate_xyz(wo[..., 0], wo[..., 1], wo[..., 2], phi_i_deg)

    def locate_xyz(self, x, y, z, phi_i_deg: float = 0.0) -> np.ndarray:
        """``locate`` for unit directions given by their coordinates ``x``, ``y``, ``z``
        (arrays of one shape; contiguous columns are fastest). θo = atan2(√(x² + y²), z) in
        degrees, bin ⌊θo·n_theta/90⌋; Δφ = φo − φi as ``relative_azimuth``, its bin the one
        whose ``phi_edges`` hold it (edge_j ≤ Δφ < edge_j+1). Computed by
        ``bin_kernels.bin_index``, whose arctangent (``trig.atan2_portable``) gives the same
        bits on every machine, so a direction exactly on an edge is binned alike everywhere
        and alike by the simulation's compiled bin passes."""
        from . import bin_kernels

        x, y, z = (np.asarray(a, dtype=np.float64) for a in (x, y, z))
        shape = np.broadcast_shapes(x.shape, y.shape, z.shape)
        phi_i = _half_turn(phi_i_deg)
        phi_i = np.array([float(phi_i)]) if np.ndim(phi_i) == 0 else _column(phi_i, shape)
        out = np.empty(shape, dtype=np.int64)
        bin_kernels.bin_index(
            *(_column(a, shape) for a in (x, y, z)),
            phi_i,
            self.n_theta,
            self.n_phi,
            self.folded,
            self.phi_edges,
            out.reshape(-1),
        )
        return out

    def kernel_grid(self, phi_i_deg: float = 0.0) -> tuple:
        """(φi in degrees, taken to (−180°, 180°], n_theta, n_phi, folded, ``phi_edges``):
        the grid as the compiled ``bin_kernels._bin_of`` takes it, for directions seen from
        one incidence azimuth."""
        phi_i = float(_half_turn(phi_i_deg))
        return (phi_i, int(self.n_theta), int(self.n_phi), bool(self.folded), self.phi_edges)

    def to_dict(self) -> dict:
        return {"n_theta": self.n_theta, "n_phi": self.n_phi, "folded": self.folded}
