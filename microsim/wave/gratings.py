"""Diffraction by 1D-periodic profiles (gratings): three methods on the same profile, each to be
judged against the one above it — first-order Rayleigh–Rice, scalar Kirchhoff per order, and
the rigorous coupled-wave (RCW) solution of Maxwell's equations (``microsim.wave.fullwave``).

Conventions (microsim's, as ``wave.kirchhoff``): lengths in micrometres (period Λ, amplitude,
wavelength λ); the grooves run along y, the profile h(x) has period Λ; the incidence lies in the
x–z plane, wi = (sin θi, 0, cos θi) pointing towards the light; reflected order m leaves along
wo = (−sin θi + mλ/Λ, 0, cos θm), propagating while |wo_x| < 1 (order 0 is the mirror
direction; m > 0 lies towards the light's side). Efficiency η_m: the order's share of the
incident power.

Profiles (``Grating``): "sinusoidal", h = (a/2) cos(2πx/Λ); "triangular", the symmetric
V-groove profile rising linearly from 0 to a over Λ/2 and falling back (facet slope
tan α = 2a/Λ) — a V-groove surface extruded along y. a is the peak-to-valley amplitude (NIST
SCATMECH's ``amplitude`` of both its ``Sinusoidal_Relief_Grating`` and ``Triangular_Grating``).

Kirchhoff (``kirchhoff_efficiencies``; Beckmann & Spizzichino 1963, ch. 3; the 1D case of
``wave.kirchhoff``'s tile amplitude, the y-integral being trivial): with q = k(wo + wi),
    η_m = R_m (1 + wi·wo)² / (cos θi cos θm (cos θi + cos θm)²) · |I_m|²,
    I_m = (1/Λ) ∫₀^Λ exp(i(q_x x + q_z h(x))) dx,   q_x = 2πm/Λ,
R_m the unpolarised Fresnel reflectance at the half-vector angle (scalar: no polarisation, no
shadowing, no multiple scattering). These equal ``wave.kirchhoff.kirchhoff_orders`` on the
profile extruded along y (tests/test_fullwave.py; ``surfaces.sinusoidal_grating`` builds such
a tile for the sinusoid). For the sinusoid |I_m| = |J_m(q_z a/2)| (Jacobi–Anger); for
the triangle each linear piece integrates in closed form, ∫₀^L e^{iκx} dx = L e^{iκL/2}
sinc(κL/2).

Rayleigh–Rice (``rayleigh_rice_efficiencies``, sinusoids only: first-order vector perturbation,
Rice 1951, in Stover's form as ``analytic.low.rayleigh_rice``, Löw et al. 2012, eq. 3): the 2-D
PSD of h = b cos(2πx/Λ) is (b²/4)[δ(f − 1/Λ) + δ(f + 1/Λ)], and cos θo dΩ = λ² d²f, so
    η_±1 = (16π²/λ⁴) cos θi cos θ±1 Q (b²/4) λ² = π² a² cos θi cos θ±1 Q / λ²    (b = a/2),
Q the polarisation factor (``analytic.low._rr_q``: "s", "p" or "unpolarised"); no other order
carries first-order power.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import jv

from microsim.analytic.fresnel import resolve_material
from microsim.checks import positive
from microsim.errors import UsageError

from .kirchhoff import incident_direction, obliquity, reflectance

__all__ = [
    "PROFILES",
    "Grating",
    "Efficiencies",
    "order_directions",
    "kirchhoff_efficiencies",
    "rayleigh_rice_efficiencies",
]

PROFILES = ("sinusoidal", "triangular")


@dataclass(frozen=True)
class Grating:
    """A 1D-periodic profile (module docstring): ``profile`` in ``PROFILES``, ``period`` Λ and
    peak-to-valley ``amplitude`` a in µm, ``material`` a microsim material (name, n or n + ik:
    ``fresnel.resolve_material``)."""

    profile: str
    period: float
    amplitude: float
    material: object = "aluminium"

    def __post_init__(self):
        if self.profile not in PROFILES:
            raise UsageError(f"profile must be one of {PROFILES}, got {self.profile!r}")
        object.__setattr__(self, "period", positive("period", self.period))
        object.__setattr__(self, "amplitude", positive("amplitude", self.amplitude))
        resolve_material(self.material)  # a UsageError naming it if unknown

    @property
    def index(self) -> complex:
        """The material's complex refractive index n + ik."""
        return complex(resolve_material(self.material))

    @property
    def facet_slope_deg(self) -> float:
        """Facet tilt α of the triangular profile, tan α = 2a/Λ (degrees)."""
        return float(np.degrees(np.arctan(2.0 * self.amplitude / self.period)))


@dataclass(frozen=True)
class Efficiencies:
    """Reflected order efficiencies of one incidence: ``orders`` m (K,), their directions
    ``wo`` (K, 3), ``unpolarised`` (K,) and, where the method has polarisation, ``s`` and ``p``
    (K,); ``method`` names it; ``info``: what the method reports of itself (convergence)."""

    orders: np.ndarray
    wo: np.ndarray
    unpolarised: np.ndarray
    method: str
    s: np.ndarray | None = None
    p: np.ndarray | None = None
    info: dict | None = None

    def total(self) -> float:
        """Reflected power: the sum over the propagating orders."""
        return float(np.sum(self.unpolarised))

    def at(self, m: int) -> float:
        """η of order ``m`` (0 where it does not propagate)."""
        hit = np.flatnonzero(self.orders == m)
        return float(self.unpolarised[hit[0]]) if hit.size else 0.0


def incident(theta_i_deg: float) -> np.ndarray:
    """wi = (sin θi, 0, cos θi) for θi in [0°, 90°) (``kirchhoff.incident_direction``)."""
    if not 0.0 <= float(theta_i_deg) < 90.0:
        raise UsageError(f"theta_i must lie in [0, 90) degrees, got {theta_i_deg!r}")
    return incident_direction(float(theta_i_deg), 0.0)


def order_directions(grating: Grating, wavelength: float, theta_i_deg: float):
    """(orders m, directions wo (K, 3)) of the propagating reflected orders."""
    wavelength = positive("wavelength", wavelength)
    wi = incident(theta_i_deg)
    step = wavelength / grating.period
    lo, hi = int(np.ceil((-1.0 + wi[0]) / step)), int(np.floor((1.0 + wi[0]) / step))
    m = np.arange(lo, hi + 1)
    x = -wi[0] + m * step
    keep = np.abs(x) < 1.0 - 1e-12
    m, x = m[keep], x[keep]
    return m, np.stack([x, np.zeros_like(x), np.sqrt(1.0 - x * x)], axis=1)


def _segment(kappa: np.ndarray, length: float) -> np.ndarray:
    """∫₀^L exp(iκx) dx = L e^{iκL/2} sinc(κL/2) (finite at κ = 0)."""
    half = 0.5 * kappa * length
    return length * np.exp(1j * half) * np.sinc(half / np.pi)


def _phase_integral(grating: Grating, qx: np.ndarray, qz: np.ndarray) -> np.ndarray:
    """I_m = (1/Λ) ∫₀^Λ exp(i(q_x x + q_z h(x))) dx per order (module docstring)."""
    a, lam_g = grating.amplitude, grating.period
    if grating.profile == "sinusoidal":
        m = np.rint(qx * lam_g / (2.0 * np.pi)).astype(int)
        return jv(m, qz * a / 2.0) * (1j) ** m
    s = 2.0 * a / lam_g  # rising piece on [0, Λ/2], h = s x; falling on [Λ/2, Λ], h = a − s x'
    half = 0.5 * lam_g
    rise = _segment(qx + qz * s, half)
    fall = np.exp(1j * (qx * half + qz * a)) * _segment(qx - qz * s, half)
    return (rise + fall) / lam_g


def kirchhoff_efficiencies(grating: Grating, wavelength: float, theta_i_deg: float) -> Efficiencies:
    """Scalar Kirchhoff efficiencies of the reflected orders (module docstring)."""
    m, wo = order_directions(grating, wavelength, theta_i_deg)
    wi = incident(theta_i_deg)
    q = 2.0 * np.pi / wavelength * (wo + wi)
    R = reflectance(wi, wo, grating.index, "half")
    eta = R * obliquity(wi, wo) * np.abs(_phase_integral(grating, q[:, 0], q[:, 2])) ** 2
    return Efficiencies(m, wo, eta, "kirchhoff")


def rayleigh_rice_efficiencies(
    grating: Grating, wavelength: float, theta_i_deg: float
) -> Efficiencies:
    """First-order Rayleigh–Rice efficiencies of a sinusoidal grating: the orders ±1 (module
    docstring), s, p and unpolarised; every other order 0 (the specular order, 1 − first-order
    losses, is not a first-order quantity and is left at 0 too)."""
    from microsim.analytic.low import _rr_q

    if grating.profile != "sinusoidal":
        raise UsageError(
            f"rayleigh_rice_efficiencies: first-order efficiencies are those of a sinusoid; "
            f"got profile {grating.profile!r}"
        )
    m, wo = order_directions(grating, wavelength, theta_i_deg)
    wi = incident(theta_i_deg)
    first = np.abs(m) == 1
    base = np.pi**2 * grating.amplitude**2 * wi[2] * wo[:, 2] / wavelength**2
    out = {
        pol: np.where(first, base * _rr_q(wi, wo, grating.index, pol), 0.0)
        for pol in ("s", "p", "unpolarised")
    }
    return Efficiencies(m, wo, out["unpolarised"], "rayleigh-rice", out["s"], out["p"])
