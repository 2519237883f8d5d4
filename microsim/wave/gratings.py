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
``SampledGrating``: the piecewise-linear profile through N samples h_j at x_j = jΛ/N (the
periodic random profiles of ``wave.random_profiles``; SCATMECH's ``Generic_Grating``).

Kirchhoff (``kirchhoff_efficiencies``; Beckmann & Spizzichino 1963, ch. 3; the 1D case of
``wave.kirchhoff``'s tile amplitude, the y-integral being trivial): with q = k(wo + wi),
    η_m = R_m (1 + wi·wo)² / (cos θi cos θm (cos θi + cos θm)²) · |I_m|²,
    I_m = (1/Λ) ∫₀^Λ exp(i(q_x x + q_z h(x))) dx,   q_x = 2πm/Λ,
R_m the unpolarised Fresnel reflectance at the half-vector angle (scalar: no polarisation, no
shadowing, no multiple scattering). These equal ``wave.kirchhoff.kirchhoff_orders`` on the
profile extruded along y (tests/test_fullwave.py; ``surfaces.sinusoidal_grating`` builds such
a tile for the sinusoid). For the sinusoid |I_m| = |J_m(q_z a/2)| (Jacobi–Anger); for
the triangle each linear piece integrates in closed form, ∫₀^L e^{iκx} dx = L e^{iκL/2}
sinc(κL/2) (the sampled profile likewise, piece by piece).

Rayleigh–Rice (``rayleigh_rice_efficiencies``: first-order vector perturbation, Rice 1951, in
Stover's form as ``analytic.low.rayleigh_rice``, Löw et al. 2012, eq. 3): a periodic profile
h = Σ_m c_m e^{2πimx/Λ} has the discrete 2-D PSD Σ_m |c_m|² δ(f − m/Λ), and
cos θo dΩ = λ² d²f, so order m ≠ 0 carries
    η_m = (16π²/λ⁴) cos θi cos θm Q |c_m|² λ² = 16π² cos θi cos θm Q |c_m|² / λ²,
Q the polarisation factor (``analytic.low._rr_q``: "s", "p" or "unpolarised"); for the
sinusoid (c_±1 = a/4, no other) η_±1 = π² a² cos θi cos θ±1 Q / λ². c_m: ``fourier_coefficients``.
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
    "SampledGrating",
    "order_directions",
    "fourier_coefficients",
    "fresnel_sp",
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
class SampledGrating:
    """A periodic profile sampled on N points per period (module docstring): ``heights`` h_j
    (µm, a tuple: the profile is part of the frozen configuration) at x_j = jΛ/N, joined
    linearly and periodically; ``period`` Λ in µm; ``material`` as ``Grating``'s."""

    period: float
    heights: tuple
    material: object = "aluminium"

    def __post_init__(self):
        object.__setattr__(self, "period", positive("period", self.period))
        h = np.asarray(self.heights, dtype=np.float64)
        if h.ndim != 1 or h.size < 2 or not np.all(np.isfinite(h)):
            raise UsageError(f"heights must be >= 2 finite numbers, got shape {h.shape}")
        if np.ptp(h) <= 0.0:
            raise UsageError("heights must not all be equal (a flat profile is no grating)")
        object.__setattr__(self, "heights", tuple(h.tolist()))
        resolve_material(self.material)

    profile = "sampled"

    @property
    def h(self) -> np.ndarray:
        """The samples h_j as an array (µm)."""
        return np.asarray(self.heights)

    @property
    def amplitude(self) -> float:
        """Peak-to-valley height (µm)."""
        return float(np.ptp(self.h))

    @property
    def rms_height(self) -> float:
        """σ of the piecewise-linear profile about its mean (µm):
        Σ_j w_j (h_j² + h_j h_{j+1} + h_{j+1}²)/3 / Λ − mean²."""
        h, h1 = self.h, np.roll(self.h, -1)
        mean = 0.5 * np.mean(h + h1)
        return float(np.sqrt(np.mean(h * h + h * h1 + h1 * h1) / 3.0 - mean * mean))

    @property
    def index(self) -> complex:
        """The material's complex refractive index n + ik."""
        return complex(resolve_material(self.material))


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


def _segment(kappa: np.ndarray, length) -> np.ndarray:
    """∫₀^L exp(iκx) dx = L e^{iκL/2} sinc(κL/2) (finite at κ = 0)."""
    half = 0.5 * kappa * length
    return length * np.exp(1j * half) * np.sinc(half / np.pi)


def _vertices(grating) -> tuple[np.ndarray, np.ndarray]:
    """(x_j, h_j) of a piecewise-linear profile's vertices on [0, Λ), joined periodically:
    the triangle's valley and apex (0, 0), (Λ/2, a); a ``SampledGrating``'s samples."""
    if isinstance(grating, SampledGrating):
        h = grating.h
        return np.arange(h.size) * grating.period / h.size, h
    return np.array([0.0, 0.5 * grating.period]), np.array([0.0, grating.amplitude])


def _pieces(grating):
    """(x_j, h_j, width w_j, slope s_j) of each linear piece of the profile."""
    x, h = _vertices(grating)
    w = np.diff(np.append(x, grating.period))
    return x, h, w, (np.roll(h, -1) - h) / w


def _phase_integral(grating, qx: np.ndarray, qz: np.ndarray) -> np.ndarray:
    """I_m = (1/Λ) ∫₀^Λ exp(i(q_x x + q_z h(x))) dx per order (module docstring); on a
    piecewise-linear profile Σ_j exp(i(q_x x_j + q_z h_j)) ∫₀^{w_j} exp(i(q_x + q_z s_j)u) du."""
    if grating.profile == "sinusoidal":
        m = np.rint(qx * grating.period / (2.0 * np.pi)).astype(int)
        return jv(m, qz * grating.amplitude / 2.0) * (1j) ** m
    x, h, w, s = _pieces(grating)
    qx, qz = np.asarray(qx)[:, None], np.asarray(qz)[:, None]
    terms = np.exp(1j * (qx * x + qz * h)) * _segment(qx + qz * s, w)
    return terms.sum(axis=1) / grating.period


def fourier_coefficients(grating, m: np.ndarray) -> np.ndarray:
    """c_m = (1/Λ) ∫₀^Λ h(x) e^{−2πimx/Λ} dx of the profile (µm), m ≠ 0 (0 at m = 0): the
    sinusoid's a/4 at m = ±1; a piecewise-linear profile's by parts, c_m = (1/(iκΛ)) Σ_j s_j
    ∫ over piece j of e^{−iκx} dx, κ = 2πm/Λ."""
    m = np.asarray(m)
    if grating.profile == "sinusoidal":
        return np.where(np.abs(m) == 1, grating.amplitude / 4.0, 0.0).astype(complex)
    x, _, w, s = _pieces(grating)
    kappa = (2.0 * np.pi / grating.period * m)[:, None]
    safe = np.where(kappa == 0.0, 1.0, kappa)
    parts = s * np.exp(-1j * safe * x) * _segment(-safe, w)
    return np.where(m == 0, 0.0, parts.sum(axis=1) / (1j * safe[:, 0] * grating.period))


def fresnel_sp(cos_theta: np.ndarray, index: complex) -> tuple[np.ndarray, np.ndarray]:
    """(R_s, R_p) from vacuum onto index n + ik at cos θ (their mean is ``fresnel``'s
    unpolarised R): r_s = (c − g)/(c + g), r_p = (η²c − g)/(η²c + g), g = √(η² − sin²θ)."""
    c = np.asarray(cos_theta, dtype=np.float64)
    eta2 = complex(index) ** 2
    g = np.sqrt(eta2 - 1.0 + c * c + 0j)
    return np.abs((c - g) / (c + g)) ** 2, np.abs((eta2 * c - g) / (eta2 * c + g)) ** 2


def kirchhoff_efficiencies(grating, wavelength: float, theta_i_deg: float) -> Efficiencies:
    """Scalar Kirchhoff efficiencies of the reflected orders (module docstring): unpolarised,
    and s (TE) and p (TM) with R_s, R_p at the half-vector angle in place of R (in the plane
    of incidence of a 1D profile the two do not mix; the scalar amplitude is the same)."""
    m, wo = order_directions(grating, wavelength, theta_i_deg)
    wi = incident(theta_i_deg)
    q = 2.0 * np.pi / wavelength * (wo + wi)
    R = reflectance(wi, wo, grating.index, "half")
    phase = obliquity(wi, wo) * np.abs(_phase_integral(grating, q[:, 0], q[:, 2])) ** 2
    Rs, Rp = fresnel_sp(np.sqrt(np.clip(0.5 * (1.0 + wo @ wi), 0.0, 1.0)), grating.index)
    return Efficiencies(m, wo, R * phase, "kirchhoff", Rs * phase, Rp * phase)


def rayleigh_rice_efficiencies(grating, wavelength: float, theta_i_deg: float) -> Efficiencies:
    """First-order Rayleigh–Rice efficiencies of every order m ≠ 0 (module docstring), s, p
    and unpolarised; the specular order (1 − first-order losses, not a first-order quantity)
    is left at 0."""
    from microsim.analytic.low import _rr_q

    m, wo = order_directions(grating, wavelength, theta_i_deg)
    wi = incident(theta_i_deg)
    c2 = np.abs(fourier_coefficients(grating, m)) ** 2
    base = 16.0 * np.pi**2 * c2 * wi[2] * wo[:, 2] / wavelength**2
    out = {pol: base * _rr_q(wi, wo, grating.index, pol) for pol in ("s", "p", "unpolarised")}
    return Efficiencies(m, wo, out["unpolarised"], "rayleigh-rice", out["s"], out["p"])
