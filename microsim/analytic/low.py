"""Löw, Kronander, Ynnerman & Unger 2012, *BRDF models for accurate and efficient rendering of
glossy surfaces*: the ABC spectrum, the Rayleigh–Rice BRDF, the smooth-surface and microfacet
BRDFs, their importance samplers and the fit metrics E1/E2.

Conventions (docs/design.md, "Conventions"): macro normal n = +z; ``wi`` (towards the light)
and ``wo`` (towards the viewer) are unit (..., 3) arrays pointing *away* from the surface and
come first, ``(wi, wo, ...)`` (samplers: ``(wo, u1, u2, ...)``); BRDFs in sr⁻¹; model
parameters A, B, C, kd are scalars and ``material`` is anything ``fresnel.resolve_material``
accepts. Equation and section numbers without an author refer to Löw et al. 2012. Löw's L, V
are our wi, wo, so their unnormalised half vector H = L + V is ours, and the projected
deviation vector (eq. 9–10, §4)

    Dp = Vp − Rp = Vp + Lp = wo_t + wi_t          (_t: component in the tangent plane),

because the mirror direction R of L has Rp = −Lp. |Dp| = 0 exactly in the specular direction.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import numpy as np

from microsim import checks as _checks
from microsim import vectors
from microsim.errors import UsageError

from .fresnel import fresnel, resolve_material
from .masking import vgroove_g
from .ndf import ABC
from .protocol import ModelBase

__all__ = [
    "LowSmooth",
    "LowMicrofacet",
    "RayleighRice",
    "abc_psd",
    "abc_psd_church",
    "abc_psd_church_integral",
    "abc_psd_anisotropic",
    "church_to_condensed",
    "rayleigh_rice",
    "RR_POLARISATIONS",
    "low_smooth",
    "LOW_OBLIQUITIES",
    "low_microfacet",
    "low_microfacet_A_from_ndf",
    "LowSample",
    "sample_low_smooth",
    "pdf_low_smooth",
    "sample_low_microfacet",
    "pdf_low_microfacet",
    "pdf_low_halfvector",
    "low_e1",
    "low_e2",
]

RR_POLARISATIONS = ("unpolarised", "s", "p", "ss", "sp", "ps", "pp")
"""``polarisation`` values of ``rayleigh_rice``: incident polarisation (s, p; the detector sees
both scattered polarisations), incident+scattered pairs, or unpolarised light."""

LOW_OBLIQUITIES = ("one", "cos", "harvey")
"""``obliquity`` values of ``low_smooth`` (G' of eq. 12): 1, cosθi cosθo (eq. 3),
((cosθi + cosθo)/2)² (eq. 6, scaled to agree with eq. 3 in the specular direction)."""


# --- parameter checks ---------------------------------------------------------------------------
def _nonneg(name: str, value) -> float:
    """``value`` as float, or raise unless it is finite and ≥ 0."""
    v = float(value)
    if not (np.isfinite(v) and v >= 0.0):
        raise UsageError(f"{name} must be a finite number >= 0, got {value!r}")
    return v


def _abc(A, B, C) -> tuple[float, float, float]:
    """Validated ABC parameters: A ≥ 0, B > 0, C > 0 (eq. 11)."""
    return _nonneg("A", A), _checks.positive("B", B), _checks.positive("C", C)


def _unit_numbers(name: str, u) -> np.ndarray:
    """Uniform numbers as float64, or raise unless all lie in [0, 1]."""
    u = np.asarray(u, dtype=np.float64)
    if not np.all((u >= 0.0) & (u <= 1.0)):
        raise UsageError(f"{name} must lie in [0, 1]")
    return u


def _choice(name: str, value: str, allowed: tuple) -> str:
    if value not in allowed:
        raise UsageError(f"{name} must be one of {', '.join(allowed)}; got {value!r}")
    return value


# --- small numerics -----------------------------------------------------------------------------
def _tsq(v: np.ndarray) -> np.ndarray:
    """Squared length of the tangent-plane component, v_x² + v_y²."""
    return v[..., 0] ** 2 + v[..., 1] ** 2


def _expm1_ratio(x):
    """(eˣ − 1)/x, = 1 at x = 0, without cancellation for small |x|."""
    x = np.asarray(x, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(x == 0.0, 1.0, np.expm1(x) / np.where(x == 0.0, 1.0, x))


def _log1p_ratio(y):
    """ln(1 + y)/y for y > −1, = 1 at y = 0."""
    y = np.asarray(y, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(y == 0.0, 1.0, np.log1p(y) / np.where(y == 0.0, 1.0, y))


def _s_of_sq(A: float, B: float, C: float, x2) -> np.ndarray:
    """Condensed ABC function as a function of the squared argument: A (1 + B x²)^−C."""
    return A * np.exp(-C * np.log1p(B * np.asarray(x2, dtype=np.float64)))


def _one_minus_cos_h(H: np.ndarray) -> np.ndarray:
    """1 − ĥ·n from the *unnormalised* half vector H with H_z ≥ 0 (eq. 25):
    (|H| − H_z)/|H| = |H_t|²/(|H|(|H| + H_z)), free of cancellation near ĥ = n; 0 for H = 0."""
    t2 = _tsq(H)
    norm = np.sqrt(t2 + H[..., 2] ** 2)
    den = norm * (norm + H[..., 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0.0, np.minimum(t2 / np.where(den > 0.0, den, 1.0), 1.0), 0.0)


# --- the ABC spectrum (eq. 7, 8, 11) --------------------------------------------------------
def abc_psd(f, A, B, C):
    """Löw's condensed ABC function S(f) = A/(1 + B f²)^C (eq. 11).

    It is Church's ABC PSD (eq. 7) re-parametrised: S(f; A=a, B=b², C=(c+1)/2) equals
    ``abc_psd_church(f, a, b, c)`` (``church_to_condensed``). In the BRDFs of Löw §3.2, f is the
    dimensionless |Dp| (unit-disk distance) and A is a free amplitude in sr⁻¹; as a PSD (in
    ``rayleigh_rice``) f is a spatial frequency in 1/length, B in length², A in length⁴.
    A ≥ 0, B > 0, C > 0; broadcasts over f.
    """
    A, B, C = _abc(A, B, C)
    f = np.asarray(f, dtype=np.float64)
    return _s_of_sq(A, B, C, f * f)


def abc_psd_church(f, A, B, C):
    """Church's isotropic 2D ABC PSD A/(1 + B² f²)^((C+1)/2) (eq. 7; Church et al. 1989).

    Here A, B, C are Church's a, b, c: a ≥ 0 (length⁴, the low-frequency level), b > 0 (length,
    b = 2π × correlation length), c > 0 (high-frequency fall-off); f in 1/length.
    Equal to ``abc_psd(f, a, b², (c+1)/2)`` (eq. 11).
    """
    A, B, C = _nonneg("A", A), _checks.positive("B", B), _checks.positive("C", C)
    f = np.asarray(f, dtype=np.float64)
    return A * np.exp(-0.5 * (C + 1.0) * np.log1p((B * f) ** 2))


def abc_psd_church_integral(A, B, C) -> float:
    """∫ PSD d²f = 2πA/(B²(C − 1)) of ``abc_psd_church`` over the whole frequency plane, i.e. the
    surface's height variance σ² (Church et al. 1989); finite only for C > 1 (Church's c)."""
    A, B = _nonneg("A", A), _checks.positive("B", B)
    C = _checks.positive("C", C)
    if not C > 1.0:
        raise UsageError(f"C must be > 1 for a finite PSD integral (Church's c), got {C!r}")
    return 2.0 * np.pi * A / (B * B * (C - 1.0))


def abc_psd_anisotropic(fx, fy, A, B, C, B_y, rotation=0.0):
    """Löw's condensed ABC function (eq. 11) made elliptical: S = A/(1 + B f'x² + B_y f'y²)^C
    (B_y = B is ``abc_psd`` at |f|).

    (f'x, f'y) is (fx, fy) in the frame rotated by ``rotation`` degrees (counter-clockwise about
    n = +z, the convention of ``AnisotropicBeckmann``): f'x = c fx + s fy, f'y = −s fx + c fy,
    c = cos(rotation), s = sin(rotation). Church's elliptical PSD a/(1 + b² f'x² + b_y² f'y²)^
    ((c+1)/2) is this with (A, B, B_y, C) = (a, b², b_y², (c + 1)/2) (``church_to_condensed``
    per axis). A ≥ 0, B > 0, B_y > 0, C > 0, rotation finite; broadcasts over fx, fy.
    """
    A, B, C = _abc(A, B, C)
    B_y = _checks.positive("B_y", B_y)
    rotation = _checks.finite("rotation", rotation)
    c, s = np.cos(np.radians(rotation)), np.sin(np.radians(rotation))
    fx, fy = np.asarray(fx, dtype=np.float64), np.asarray(fy, dtype=np.float64)
    u, v = c * fx + s * fy, -s * fx + c * fy
    return A * np.exp(-C * np.log1p(B * u * u + B_y * v * v))


def church_to_condensed(a, b, c) -> tuple[float, float, float]:
    """Church's (a, b, c) → Löw's condensed (A, B, C) = (a, b², (c + 1)/2) (eq. 11)."""
    a, b, c = _nonneg("a", a), _checks.positive("b", b), _checks.positive("c", c)
    return a, b * b, 0.5 * (c + 1.0)


# --- Rayleigh–Rice (eq. 3–5) ----------------------------------------------------------------
def _rr_q(wi, wo, eta: complex, polarisation: str) -> np.ndarray:
    """Rayleigh–Rice polarisation factor Q for a surface of relative permittivity ε = η².

    Löw refers to Stover (1995) for Q; these are Stover's expressions (first-order vector
    perturbation theory), with g = √(ε − sin²θ) (principal root, as in ``fresnel``) and φ the
    azimuth of wo from the specular plane (φ = 0 forward), first index incident, second scattered:
        Q_ss = |(ε−1) cosφ / ((cosθi + g_i)(cosθo + g_o))|²
        Q_sp = |(ε−1) g_o sinφ / ((cosθi + g_i)(ε cosθo + g_o))|²
        Q_ps = |(ε−1) g_i sinφ / ((ε cosθi + g_i)(cosθo + g_o))|²
        Q_pp = |(ε−1)(g_i g_o cosφ − ε sinθi sinθo) / ((ε cosθi + g_i)(ε cosθo + g_o))|²
    Checks (tests/test_low.py): in the specular direction Q_ss = R_s, Q_pp = R_p (Fresnel), and
    swapping wi ↔ wo swaps Q_sp ↔ Q_ps, so the unpolarised Q is reciprocal. Where φ is undefined
    (θi = 0 or θo = 0) cosφ = 1 is used; the unpolarised and the s+p sums do not depend on it.
    """
    ci, co = wi[..., 2], wo[..., 2]
    si, so = np.sqrt(_tsq(wi)), np.sqrt(_tsq(wo))
    sinsin = si * so
    cross = -(wi[..., 0] * wo[..., 0] + wi[..., 1] * wo[..., 1])  # sinθi sinθo cosφ
    wedge = wi[..., 0] * wo[..., 1] - wi[..., 1] * wo[..., 0]  # ± sinθi sinθo sinφ
    ok = sinsin > 0.0
    safe = np.where(ok, sinsin, 1.0)
    cos_phi = np.where(ok, np.clip(cross / safe, -1.0, 1.0), 1.0)
    sin2_phi = np.where(ok, np.clip((wedge / safe) ** 2, 0.0, 1.0), 0.0)
    eps = eta * eta
    em1 = (eta - 1.0) * (eta + 1.0)
    if em1 == 0:  # no index contrast, no scatter
        return np.zeros(np.broadcast_shapes(ci.shape, co.shape))
    gi = np.sqrt(em1 + ci * ci + 0j)
    go = np.sqrt(em1 + co * co + 0j)
    s_i, s_o = ci + gi, co + go  # s-type denominators
    p_i, p_o = eps * ci + gi, eps * co + go  # p-type denominators
    a2 = abs(em1) ** 2
    q = {}
    if polarisation in ("unpolarised", "s", "ss"):
        q["ss"] = a2 * cos_phi**2 / np.abs(s_i * s_o) ** 2
    if polarisation in ("unpolarised", "s", "sp"):
        q["sp"] = a2 * np.abs(go) ** 2 * sin2_phi / np.abs(s_i * p_o) ** 2
    if polarisation in ("unpolarised", "p", "ps"):
        q["ps"] = a2 * np.abs(gi) ** 2 * sin2_phi / np.abs(p_i * s_o) ** 2
    if polarisation in ("unpolarised", "p", "pp"):
        q["pp"] = a2 * np.abs(gi * go * cos_phi - eps * sinsin) ** 2 / np.abs(p_i * p_o) ** 2
    total = sum(q.values())
    return 0.5 * total if polarisation == "unpolarised" else total


def rayleigh_rice(
    wi, wo, wavelength, A, B, C, material, polarisation="unpolarised", B_y=None, rotation=0.0
):
    """First-order Rayleigh–Rice BRDF (sr⁻¹) of a smooth surface with an ABC PSD (eq. 3–5):

        f = (16π²/λ⁴) cosθi cosθo Q S(|Dp|/λ),   S(f) = A/(1 + B f²)^C  (``abc_psd``).

    The spatial frequency is |Dp|/λ with Dp = wi_t + wo_t, which is (f_x, f_y) of eq. 4–5 when wi
    lies in the φ = π half-plane. Units: ``wavelength`` and √B in one length unit, A in that
    unit⁴ (a 2D PSD: height² × area). Q is the full polarisation factor (``_rr_q``; Löw gives no
    expression and cites Stover 1995), for a ``material`` of index η (real: dielectric;
    complex n + ik: conductor; a name from ``fresnel.MATERIALS``; not the mirror None).
    Reciprocal for "unpolarised", "s"+"p" sums and ss/pp. Zero if either direction is below the
    horizon.

    Anisotropic PSD (``B_y`` given, length²): S(f) = A/(1 + B f'x² + B_y f'y²)^C at
    f = (wi_t + wo_t)/λ, (f'x, f'y) its components along axes rotated by ``rotation`` degrees
    (``abc_psd_anisotropic``). For the heightfield ``surfaces.abc(..., B=b, C=c, B_y=b_y,
    rotation=r)``, whose PSD is a/(1 + b² f'x² + b_y² f'y²)^((c+1)/2) with a = σ² b b_y (c − 1)/
    (2π) (its ``nominal["A"]``), the parameters are (A, B, B_y, C) = (a, b², b_y², (c + 1)/2)
    and the same ``rotation`` — as for the isotropic field, (A, B, C) = (a, b², (c + 1)/2)
    (``church_to_condensed``). Q is unchanged: it depends on the directions only.
    ``RayleighRice(...).f``.
    """
    return RayleighRice(wavelength, A, B, C, material, polarisation, B_y, rotation).f(wi, wo)


# --- smooth-surface BRDF (eq. 12–14) --------------------------------------------------------
def _obliquity(kind: str, ci, co):
    if kind == "one":
        return np.ones(np.broadcast_shapes(np.shape(ci), np.shape(co)))
    if kind == "cos":
        return ci * co
    return 0.25 * (ci + co) ** 2


def low_smooth(wi, wo, A, B, C, kd=0.0, material=None, obliquity="one"):
    """Löw's smooth-surface BRDF (sr⁻¹), eq. 12:  f = kd/π + G' Q' S(|Dp|).

    S(|Dp|) = A/(1 + B|wi_t + wo_t|²)^C (eq. 11; A in sr⁻¹). Q' = F(θd; η) (eq. 13–14) with
    cos θd = √(1 − |wi_t − wo_t|²/4): Löw writes arcsin(|Lp − Vp|/2) with L, V pointing away from
    the surface, as here; in the specular direction wo_t = −wi_t so θd = θi, and in general
    |wi − wo| = 2 sin θd exactly, so θd approximates the wi–h angle (Neumann et al. 1999).
    F is Cook–Torrance's Fresnel "with extinction set to zero" = the exact unpolarised dielectric
    ``fresnel`` of the real part of ``material``'s index; ``material=None`` gives Q' = 1 (Löw's
    other choice).
    G' (``obliquity``): "one" (Löw's choice), "cos" = cosθi cosθo (eq. 3), "harvey" =
    ((cosθi + cosθo)/2)² (eq. 6). Reciprocal. Zero if either direction is below the horizon.
    ``LowSmooth(...).f``.
    """
    return LowSmooth(A, B, C, kd, material, obliquity).f(wi, wo)


# --- microfacet BRDF (eq. 15) ---------------------------------------------------------------
def low_microfacet(wi, wo, A, B, C, kd=0.0, material=None, shadowing="cook-torrance"):
    """Löw's ABC microfacet BRDF (sr⁻¹), eq. 15 (Cook–Torrance 1982 with an ABC facet term):

        f = kd/π + S(√(1 − ĥ·n)) F(wi·ĥ; η) G / (π (n·wi)(n·wo)),
        S(√(1 − ĥ·n)) = A/(1 + B(1 − ĥ·n))^C.

    The OCR of eq. 15's denominator is garbled; π(n·wi)(n·wo) is Cook & Torrance's. A (sr⁻¹) is
    a free amplitude; ``low_microfacet_A_from_ndf`` gives the A that makes the specular term the
    Torrance–Sparrow BRDF of the normalised ``ndf.ABC``. 1 − ĥ·n is computed from the unnormalised
    half vector (docs/design.md). F: exact unpolarised ``fresnel`` for ``material`` (real:
    identical to Cook–Torrance's formula; complex: conductor; None: 1). G (``shadowing``):
    "cook-torrance" = V-groove ``shadowing.vgroove_g`` (Mikkelsen 2009, eq. 25), or "none"
    (G = 1). The specular term is 0 when either direction is at or below the horizon (as G is).
    Reciprocal. ``LowMicrofacet(...).f``.
    """
    return LowMicrofacet(A, B, C, kd, material, shadowing).f(wi, wo)


def low_microfacet_A_from_ndf(B, C) -> float:
    """The A of ``low_microfacet`` that makes its specular term Torrance–Sparrow with the
    normalised ABC NDF D = M/(1 + B(1 − ĥ·n))^C (``ndf.ABC``, ∫ D (ĥ·n) dω = 1):

        TS = D F G/(4 cosθi cosθo),   eq. 15: S F G/(π cosθi cosθo), S = A/(1 + B(1−ĥ·n))^C
        ⇒ S/π = D/4  ⇒  A = π M/4,   M = 1/(2π ∫₀¹ (1 − x)(1 + Bx)^−C dx).

    Used to compare V-groove surfaces whose facets follow the ABC NDF with Löw's model.
    """
    B, C = _checks.positive("B", B), _checks.positive("C", C)
    return float(np.pi * ABC(B, C).M / 4.0)


# --- importance sampling (Löw §4, eq. 17–28) ----------------------------------------------------
class LowSample(NamedTuple):
    """Directions drawn by a Löw sampler: ``wi`` unit (..., 3); ``pdf`` its solid-angle density
    (sr⁻¹, over the whole sphere of wi); ``above`` True where wi_z > 0 (others contribute 0)."""

    wi: np.ndarray
    pdf: np.ndarray
    above: np.ndarray


def _disk_log_norm(B: float, ro2, k):
    """Λ = ln[(1 + Bk + √(1 + 2B(1 + r_o²) + B²k²))/2], k = 1 − r_o² = cos²θo (eq. 19,
    re-derived: the OCR is garbled), written with log1p and √(1+X) − 1 = X/(√(1+X) + 1)."""
    X = 2.0 * B * (1.0 + ro2) + (B * k) ** 2
    return np.log1p(0.5 * (B * k + X / (1.0 + np.sqrt(1.0 + X))))


def _disk_density(B: float, wo, wi):
    """eq. 18 with C = 1: P_d = M_d/(1 + B|Lp + Vp|²) on the unit disk, M_d = B/(πΛ).

    Derivation of M_d (eq. 19): ∫₀^{2π} dψ/(a + b cos ψ) = 2π/√(a² − b²) with a = 1 + B(r² + r_o²),
    b = 2B r r_o; in s = r², a² − b² = B²s² + 2Bs(1 − B r_o²) + (1 + B r_o²)², whose
    ∫₀¹ ds/√(·) = ln[(Bs + 1 − B r_o² + √(·))/2]/B |₀¹ = Λ/B; so 1/M_d = πΛ/B.
    """
    ro2 = _tsq(wo)
    lam = _disk_log_norm(B, ro2, wo[..., 2] ** 2)
    return B / (np.pi * lam) / (1.0 + B * _tsq(wi + wo))


def pdf_low_smooth(wi, wo, B):
    """Solid-angle density (sr⁻¹) of ``sample_low_smooth``: P_ω = P_d cos θi (eq. 17–19);
    0 for wi below the horizon. Integrates to 1 over the upper hemisphere."""
    wo = vectors.normalize(_checks.directions("wo", wo, upper=True))
    wi = _checks.directions("wi", wi)
    _checks.broadcast({"wi": wi, "wo": wo})
    B = _checks.positive("B", B)
    ci = wi[..., 2]
    return np.where(ci >= 0.0, _disk_density(B, wo, wi) * np.maximum(ci, 0.0), 0.0)


def sample_low_smooth(wo, u1, u2, B) -> LowSample:
    """Draw wi for Löw's smooth-surface BRDF with the C = 1 disk density (eq. 17–22).

    Lp = r(cos φ, sin φ) on the unit disk with density ∝ 1/(1 + B|Lp + Vp|²), centred on −Vp
    (the projected mirror direction of wo). Inversion (re-derived; eq. 20–22 are garbled):
      radial CDF  u1 = ln[(Bs + 1 − B r_o² + √(…))/2]/Λ  ⇒  with x = u1 Λ,
                  s = r² = (eˣ − 1)/B + r_o²(1 − e^{−x})        (eq. 20, 22);
      azimuth     χ = φ − φ_o − π has density ∝ 1/(a − b cos χ) ⇒
                  χ = 2 arctan(√((a − b)/(a + b)) tan(π(u2 − ½)))  (eq. 21, centred on the peak),
    with a − b = 1 + B(r − r_o)², a + b = 1 + B(r + r_o)². wi_z = √(1 − r²) ≥ 0 always.
    ``wo`` unit (..., 3) in the upper hemisphere, u1, u2 ∈ [0, 1] broadcast with it; B > 0.
    """
    wo = vectors.normalize(_checks.directions("wo", wo, upper=True))
    B = _checks.positive("B", B)
    u1, u2 = _unit_numbers("u1", u1), _unit_numbers("u2", u2)
    _checks.broadcast({"wo": wo}, {"u1": u1, "u2": u2})
    ro2 = _tsq(wo)
    ro = np.sqrt(ro2)
    x = u1 * _disk_log_norm(B, ro2, wo[..., 2] ** 2)
    s = np.clip(np.expm1(x) / B - ro2 * np.expm1(-x), 0.0, 1.0)
    r = np.sqrt(s)
    ratio = np.sqrt((1.0 + B * (r - ro) ** 2) / (1.0 + B * (r + ro) ** 2))
    chi = 2.0 * np.arctan(ratio * np.tan(np.pi * (u2 - 0.5)))
    phi = np.arctan2(wo[..., 1], wo[..., 0]) + np.pi + chi
    wi = np.stack(np.broadcast_arrays(r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - s)), axis=-1)
    pdf = _disk_density(B, wo, wi) * wi[..., 2]
    return LowSample(wi, pdf, wi[..., 2] > 0.0)


def _halfvector_norm(B: float, C: float) -> float:
    """M_h of eq. 24 (A omitted): 1/(2π ∫₀¹ (1 + Bx)^−C dx) = B/(2π L φ((1−C)L)),
    L = ln(1 + B), φ(z) = (eᶻ − 1)/z; smooth through C = 1 (eq. 24's two cases in one)."""
    L = np.log1p(B)
    return float(B / (2.0 * np.pi * L * _expm1_ratio((1.0 - C) * L)))


def _halfvector_density(B: float, C: float, x):
    """eq. 23: P_h = M_h/(1 + B x)^C as a function of x = 1 − ĥ·n (solid angle, sr⁻¹)."""
    return _halfvector_norm(B, C) * np.exp(-C * np.log1p(B * x))


def _tilt_quantile(u, B: float, C: float):
    """x = 1 − cos θh at tilt CDF value u (eq. 25), in one form for all C:

        x = (e^ℓ − 1)/B,  ℓ = ln(1 + u((1+B)^{1−C} − 1))/(1 − C)  (→ u L as C → 1)
          = u L φ(aL) · ln(1 + y)/y,   a = 1 − C, y = u (e^{aL} − 1) = u aL φ(aL),

    which has no division by 1 − C, so C = 1 ± 1e-9 and B = 1e8 lose no precision.
    """
    L = np.log1p(B)
    aL = (1.0 - C) * L
    e = _expm1_ratio(aL)
    ell = u * L * e * _log1p_ratio(u * aL * e)
    with np.errstate(over="ignore", invalid="ignore"):
        return np.clip(np.expm1(ell) / B, 0.0, 1.0)


def pdf_low_halfvector(h, B, C):
    """eq. 23–24: solid-angle density (sr⁻¹) of the sampled half vectors,
    ∝ 1/(1 + B(1 − ĥ·n))^C, normalised over the upper hemisphere; 0 below it.
    ``h`` (..., 3), unit or unnormalised (1 − ĥ·n is computed without cancellation)."""
    h = np.asarray(h, dtype=np.float64)
    if h.ndim == 0 or h.shape[-1] != 3 or not np.all(np.isfinite(h)):
        raise UsageError(f"h must be a finite array of shape (..., 3), got shape {h.shape}")
    B, C = _checks.positive("B", B), _checks.positive("C", C)
    up = h[..., 2] >= 0.0
    return np.where(
        up, _halfvector_density(B, C, _one_minus_cos_h(np.where(up[..., None], h, -h))), 0.0
    )


def _reflected_pdf(B, C, H):
    """P_h(ĥ)/(4|wo·ĥ|) (eq. 28) at H = wi + wo, ĥ = ±H/|H| taken in the upper hemisphere.

    Every wi on the sphere comes from exactly one ĥ in the upper hemisphere, with Jacobian
    4|wo·ĥ|, so this integrates to 1 over the sphere; where wo·ĥ < 0 the wi lies below the horizon.
    For unit wi, wo, |wo·ĥ| = |H|/2 exactly; using it (not wo·H = 1 + wo·wi) keeps full precision
    near the integrable singularity wi → −wo. 0 at H = 0.
    """
    H = np.where((H[..., 2] < 0.0)[..., None], -H, H)
    hlen = np.sqrt(np.sum(H * H, axis=-1))
    ph = _halfvector_density(B, C, _one_minus_cos_h(H))
    ok = hlen > 0.0
    return np.where(ok, ph / (2.0 * np.where(ok, hlen, 1.0)), 0.0)


def pdf_low_microfacet(wi, wo, B, C):
    """Solid-angle density (sr⁻¹) of ``sample_low_microfacet`` at any wi on the sphere (eq. 28),
    below-horizon directions included; integrates to 1 over the sphere."""
    wo = vectors.normalize(_checks.directions("wo", wo, upper=True))
    wi = vectors.normalize(_checks.directions("wi", wi))
    _checks.broadcast({"wi": wi, "wo": wo})
    B, C = _checks.positive("B", B), _checks.positive("C", C)
    return _reflected_pdf(B, C, wi + wo)


def sample_low_microfacet(wo, u1, u2, B, C) -> LowSample:
    """Draw wi for Löw's microfacet BRDF (eq. 23–28).

    ĥ from P_h ∝ 1/(1 + B(1 − cos θh))^C in solid angle (eq. 23–25, ``_tilt_quantile``; the
    sampler uses the exact C — no switch to C = 1 near 1 is needed in this form), φh = 2π u2
    (eq. 26), wi = 2(wo·ĥ)ĥ − wo (eq. 27 with both vectors pointing away), pdf = P_h/(4|wo·ĥ|)
    (eq. 28). Samples below the horizon are kept, with their correct pdf, and flagged
    ``above = False`` (Löw: their contribution is zero). A degenerate sample with wo·ĥ = 0 (wo on
    the horizon), or so close to 0 that P_h/(4|wo·ĥ|) exceeds the float64 range (a denormal
    wo·ĥ), is reported with pdf 0; such samples lie below the horizon and have measure zero.
    """
    wo = vectors.normalize(_checks.directions("wo", wo, upper=True))
    B, C = _checks.positive("B", B), _checks.positive("C", C)
    u1, u2 = _unit_numbers("u1", u1), _unit_numbers("u2", u2)
    _checks.broadcast({"wo": wo}, {"u1": u1, "u2": u2})
    x = _tilt_quantile(u1, B, C)
    sin_h = np.sqrt(x * (2.0 - x))
    phi = 2.0 * np.pi * u2
    h = np.stack(np.broadcast_arrays(sin_h * np.cos(phi), sin_h * np.sin(phi), 1.0 - x), axis=-1)
    voh = vectors.dot(wo, h)
    wi = vectors.normalize(2.0 * voh[..., None] * h - wo)
    with np.errstate(divide="ignore", over="ignore"):
        pdf = _halfvector_density(B, C, x) / (4.0 * np.abs(voh))
    pdf = np.where(np.isfinite(pdf), pdf, 0.0)
    return LowSample(wi, pdf, (wi[..., 2] > 0.0) & (voh > 0.0))


# --- fit metrics (eq. 29–33) ----------------------------------------------------------------
def _fit_error(transform, measured, model, theta_i, theta_o, d_theta_i, d_theta_o, d_phi_o):
    """Σ (g(measured) − g(model))² sin θo Δθi Δθo Δφo (eq. 33, widths in radians)."""
    arrays = np.broadcast_arrays(
        *(
            np.asarray(a, dtype=np.float64)
            for a in (measured, model, theta_i, theta_o, d_theta_i, d_theta_o, d_phi_o)
        )
    )
    meas, mod, ti, to, dti, dto, dpo = arrays
    for name, a in (("measured", meas), ("model", mod)):
        if not np.all(np.isfinite(a)):
            raise UsageError(f"{name} must be finite")
    for name, a in (("theta_i", ti), ("theta_o", to)):
        if not np.all((a >= 0.0) & (a <= 90.0)):
            raise UsageError(f"{name} must lie in [0, 90] degrees")
    for name, a in (("d_theta_i", dti), ("d_theta_o", dto), ("d_phi_o", dpo)):
        if not np.all((a > 0.0) & np.isfinite(a)):
            raise UsageError(f"{name} must be finite and > 0 (degrees)")
    ci = np.cos(np.radians(ti))
    w = np.sin(np.radians(to)) * np.radians(dti) * np.radians(dto) * np.radians(dpo)
    return float(np.sum(w * (transform(ci * meas, "measured") - transform(ci * mod, "model")) ** 2))


def _identity(g, name):
    return g


def _log1p_checked(g, name):
    if not np.all(g > -1.0):
        raise UsageError(f"{name} must satisfy cos θi · f > −1 for the E2 logarithm")
    return np.log1p(g)


def low_e1(measured, model, theta_i, theta_o, d_theta_i, d_theta_o, d_phi_o) -> float:
    """Löw's fit error E1 (eq. 29, 30, 33): Σ (cosθi f_meas − cosθi f_model)² sinθo Δθi Δθo Δφo.

    Inputs broadcast: bin-averaged BRDF values (sr⁻¹), the bins' incidence θi and outgoing θo
    centres and their widths, all angles in degrees (the Δ's enter in radians). Returns E itself;
    Löw's Table II prints √E.
    """
    return _fit_error(_identity, measured, model, theta_i, theta_o, d_theta_i, d_theta_o, d_phi_o)


def low_e2(measured, model, theta_i, theta_o, d_theta_i, d_theta_o, d_phi_o) -> float:
    """Löw's logarithmic fit error E2 (eq. 31–33): as ``low_e1`` on g = ln(1 + cosθi f).
    Returns E itself; Löw's Table II prints √E."""
    return _fit_error(
        _log1p_checked, measured, model, theta_i, theta_o, d_theta_i, d_theta_o, d_phi_o
    )


# --- the models as objects (the free functions above wrap them) ---------------------------------
@dataclass(frozen=True)
class LowSmooth(ModelBase):
    """Löw's smooth-surface BRDF f = kd/π + G' Q' A/(1 + B|wi_t + wo_t|²)^C (Löw et al. 2012,
    eq. 12–14); ``low_smooth`` wraps it. Sampler: the C = 1 disk density (``sample_low_smooth``)."""

    A: float
    B: float
    C: float
    kd: float = 0.0
    material: Any = None
    obliquity: str = "one"
    name: ClassVar[str] = "LowSmooth"
    params_doc: ClassVar[str] = (
        "A ≥ 0 (sr⁻¹), B > 0, C > 0, kd ≥ 0, material, obliquity=one|cos|harvey"
    )
    source: ClassVar[str] = "Löw et al. 2012, eq. 12–14"
    functions: ClassVar[tuple[str, ...]] = ("low_smooth",)
    sampler_doc: ClassVar[str] = "wo, u1, u2; B only (C = 1 disk density about the mirror)"
    sampler_source: ClassVar[str] = "Löw et al. 2012, eq. 17–22"
    sampler_functions: ClassVar[tuple[str, ...]] = ("sample_low_smooth", "pdf_low_smooth")

    def f(self, wi, wo):
        wi = _checks.directions("wi", wi)
        wo = _checks.directions("wo", wo)
        _checks.broadcast({"wi": wi, "wo": wo})
        A, B, C = _abc(self.A, self.B, self.C)
        kd = _nonneg("kd", self.kd)
        _choice("obliquity", self.obliquity, LOW_OBLIQUITIES)
        eta = resolve_material(self.material)
        ci, co = wi[..., 2], wo[..., 2]
        cos_d = np.sqrt(np.clip(1.0 - 0.25 * _tsq(wi - wo), 0.0, 1.0))
        q = fresnel(cos_d, None if eta is None else complex(eta).real)
        spec = _obliquity(self.obliquity, ci, co) * q * _s_of_sq(A, B, C, _tsq(wi + wo))
        return np.where((ci >= 0.0) & (co >= 0.0), kd / np.pi + spec, 0.0)

    def sample(self, wo, u1, u2):
        return sample_low_smooth(wo, u1, u2, self.B)

    def pdf(self, wi, wo):
        return pdf_low_smooth(wi, wo, self.B)


@dataclass(frozen=True)
class LowMicrofacet(ModelBase):
    """Löw's ABC microfacet BRDF f = kd/π + S F G/(π cos θi cos θo), S = A/(1 + B(1 − ĥ·n))^C
    (Löw et al. 2012, eq. 15); ``low_microfacet`` wraps it. ``shadowing``: "cook-torrance"
    (V-groove) or "none". Sampler: ĥ ∝ (1 + B(1 − ĥ·n))^−C (``sample_low_microfacet``)."""

    A: float
    B: float
    C: float
    kd: float = 0.0
    material: Any = None
    shadowing: str = "cook-torrance"
    name: ClassVar[str] = "LowMicrofacet"
    params_doc: ClassVar[str] = (
        "A ≥ 0 (sr⁻¹), B > 0, C > 0, kd ≥ 0, material, shadowing=cook-torrance|none"
    )
    source: ClassVar[str] = "Löw et al. 2012, eq. 15"
    functions: ClassVar[tuple[str, ...]] = ("low_microfacet", "low_microfacet_A_from_ndf")
    sampler_doc: ClassVar[str] = "wo, u1, u2; B, C (half vectors, eq. 23 density)"
    sampler_source: ClassVar[str] = "Löw et al. 2012, eq. 23–28"
    sampler_functions: ClassVar[tuple[str, ...]] = ("sample_low_microfacet", "pdf_low_microfacet")

    def f(self, wi, wo):
        wi = _checks.directions("wi", wi)
        wo = _checks.directions("wo", wo)
        _checks.broadcast({"wi": wi, "wo": wo})
        A, B, C = _abc(self.A, self.B, self.C)
        kd = _nonneg("kd", self.kd)
        _choice("shadowing", self.shadowing, ("cook-torrance", "none"))
        eta = resolve_material(self.material)
        wi, wo = np.broadcast_arrays(wi, wo)
        ci, co = wi[..., 2], wo[..., 2]
        H = wi + wo
        hlen = np.sqrt(np.sum(H * H, axis=-1, keepdims=True))
        inside = (ci > 0.0) & (co > 0.0)  # then H_z > 0, H ≠ 0
        h = np.where(inside[..., None], H / np.where(hlen > 0.0, hlen, 1.0), [0.0, 0.0, 1.0])
        d = _s_of_sq(A, B, C, _one_minus_cos_h(np.where(inside[..., None], H, h)))
        f = fresnel(np.clip(vectors.dot(wi, h), 0.0, 1.0), eta)
        g = vgroove_g(wi, wo, h) if self.shadowing == "cook-torrance" else 1.0
        spec = np.where(inside, d * f * g / (np.pi * np.where(inside, ci * co, 1.0)), 0.0)
        return np.where((ci >= 0.0) & (co >= 0.0), kd / np.pi + spec, 0.0)

    def sample(self, wo, u1, u2):
        return sample_low_microfacet(wo, u1, u2, self.B, self.C)

    def pdf(self, wi, wo):
        return pdf_low_microfacet(wi, wo, self.B, self.C)


@dataclass(frozen=True)
class RayleighRice(ModelBase):
    """First-order Rayleigh–Rice BRDF (16π²/λ⁴) cos θi cos θo Q S(|Dp|/λ) with the ABC PSD
    (Löw et al. 2012, eq. 3–8); ``rayleigh_rice`` wraps it. With ``B_y`` the anisotropic PSD
    A/(1 + B f'x² + B_y f'y²)^C along axes rotated by ``rotation`` degrees (``B_y`` None: the
    isotropic PSD, ``rotation`` unused). No sampler."""

    wavelength: float
    A: float
    B: float
    C: float
    material: Any
    polarisation: str = "unpolarised"
    B_y: float | None = None
    rotation: float = 0.0
    name: ClassVar[str] = "RayleighRice"
    params_doc: ClassVar[str] = (
        "wavelength > 0, A ≥ 0, B > 0, C > 1 (lengths in one unit), material (an ior), "
        "polarisation, B_y > 0 or None (isotropic), rotation (degrees)"
    )
    source: ClassVar[str] = "Löw et al. 2012, eq. 3–8"
    functions: ClassVar[tuple[str, ...]] = ("rayleigh_rice",)

    @property
    def symmetric(self) -> bool:
        """Mirror symmetric about the plane of incidence for an isotropic PSD only (an
        elliptical one is, only where that plane holds one of its axes)."""
        return self.B_y is None

    def f(self, wi, wo):
        wi = _checks.directions("wi", wi)
        wo = _checks.directions("wo", wo)
        _checks.broadcast({"wi": wi, "wo": wo})
        lam = _checks.positive("wavelength", self.wavelength)
        A, B, C = _abc(self.A, self.B, self.C)
        eta = resolve_material(self.material)
        if eta is None:
            raise UsageError(
                "material must have an index of refraction (ior) n or n+ik "
                "(Rayleigh–Rice needs ε = ior²), got None"
            )
        _choice("polarisation", self.polarisation, RR_POLARISATIONS)
        rotation = _checks.finite("rotation", self.rotation)
        ci, co = wi[..., 2], wo[..., 2]
        if self.B_y is None:
            s = _s_of_sq(A, B, C, _tsq(wi + wo) / lam**2)
        else:
            d = (wi + wo) / lam
            s = abc_psd_anisotropic(d[..., 0], d[..., 1], A, B, C, self.B_y, rotation)
        q = _rr_q(wi, wo, complex(eta), self.polarisation)
        f = 16.0 * np.pi**2 / lam**4 * ci * co * q * s
        return np.where((ci >= 0.0) & (co >= 0.0), f, 0.0)
