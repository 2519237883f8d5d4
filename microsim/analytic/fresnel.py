"""Fresnel reflectance of a planar interface, unpolarised (Mikkelsen 2009, §2.1; Mally 2015,
"Fresnel's Law").

Light arrives from air (index 1) at a medium of complex index η = n + ik (k ≥ 0: absorption).
A real index is a dielectric, a complex one a conductor, ``None`` an ideal mirror (R = 1).
Public functions take a ``material``: a name from ``MATERIALS``, an index n or n + ik, None, or
a (name, wavelength_nm) pair naming a real material at a wavelength (``materials.TABLE``)
(``resolve_material``).
``cos_theta`` is always the cosine between the incident direction and the *facet* normal; it
must lie in [0, 1] up to ``COS_TOL`` (values within the tolerance are clipped, others raise).
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from microsim.checks import UNIT_TOL
from microsim.errors import UsageError
from microsim.kernel_cache import cached_njit

from . import materials

__all__ = [
    "fresnel",
    "fresnel_transmittance",
    "schlick",
    "f0_from_material",
    "MATERIALS",
    "resolve_material",
    "material_name",
]

MATERIALS = {"aluminium": 0.769 + 6.08j, "methanol": 1.329, "mirror": None}
"""Indices of refraction at 500 nm used by Mikkelsen 2009 (Fig. 5): η = n + ik, None = mirror."""

_ALIASES = {"aluminum": "aluminium"}

COS_TOL = 3 * UNIT_TOL
"""Rounding allowed outside [0, 1] for a cosine: the package accepts as "unit" any vector with
| |w| − 1 | ≤ ``UNIT_TOL`` (``microsim.checks.directions``), and for two of them
|a·b| ≤ |a||b| ≤ (1 + UNIT_TOL)² < 1 + 3·UNIT_TOL; a cosine further out is not one of two unit
vectors (e.g. a bug or a value in degrees) and is refused."""


def _check_ior(ior, name: str = "ior") -> complex:
    """Return ``ior`` as complex η = n + ik, or raise unless n > 0, k ≥ 0, both finite.
    ``name`` prefixes the message (the caller's parameter)."""
    pre = "" if name == "ior" else f"{name}: "
    if isinstance(ior, (bool, np.bool_)) or not isinstance(ior, numbers.Number):
        raise UsageError(
            f"{pre}ior must be a real or complex number n+ik (n > 0, k >= 0) or None, got {ior!r}"
        )
    eta = complex(ior)
    if not (np.isfinite(eta.real) and np.isfinite(eta.imag)):
        raise UsageError(f"{pre}ior must be finite (n > 0, k >= 0), got {ior!r}")
    if not eta.real > 0:
        raise UsageError(f"{pre}ior real part n must be > 0, got {ior!r}")
    if not eta.imag >= 0:
        raise UsageError(f"{pre}ior imaginary part k (extinction) must be >= 0, got {ior!r}")
    return eta


def _cos(cos_theta) -> np.ndarray:
    """cos θ as float64 in [0, 1]: values within ``COS_TOL`` outside are clipped; NaN, inf,
    non-numbers and values further out raise a UsageError naming ``cos_theta``."""
    a = np.asarray(cos_theta)
    if a.dtype.kind not in "iuf":
        raise UsageError(f"cos_theta must be real numbers in [0, 1], got {cos_theta!r}")
    c = a.astype(np.float64, copy=False)
    bad = ~((c >= -COS_TOL) & (c <= 1.0 + COS_TOL))  # also NaN
    if np.any(bad):
        worst = float(c[bad].flat[0])
        raise UsageError(
            f"cos_theta must lie in [0, 1] (a cosine; tolerance {COS_TOL:g}), "
            f"got {worst!r}" + (f" among {c.size} values" if c.size > 1 else "")
        )
    return np.clip(c, 0.0, 1.0)


def fresnel(cos_theta, material=None):
    """Exact unpolarised reflectance (R_s + R_p)/2 from air onto ``material`` (dimensionless).

    ``cos_theta``: cosine of the incidence angle to the facet normal, in [0, 1] (``COS_TOL``).
    ``material``: a name (``MATERIALS``), a real index n > 0 (dielectric; n < 1 means the light
    comes from the denser medium and total internal reflection gives R = 1), a complex index
    n + ik with k ≥ 0 (conductor), or None (mirror, R = 1). R = 1 exactly at grazing incidence
    (cos θ = 0) for every interface.

    With g = η cos θ_t = √(η² − sin²θ) (principal complex root: Re g ≥ 0, Im g ≥ 0, the
    decaying transmitted wave), the amplitude ratios are written without subtracting nearly
    equal numbers (multiply r_s = (c − g)/(c + g) by (c + g)/(c + g) and use c² − g² = 1 − η²):
        r_s = (1 − η²) / (c + g)²,
        r_p = (η² c − g)/(η² c + g) = (η² − 1)(c²(η² + 1) − 1) / (η² c + g)².
    The second factor of r_p vanishes at Brewster's angle, where r_p is legitimately ~0.
    """
    c = _cos(cos_theta)
    ior = resolve_material(material) if isinstance(material, str | tuple) else material
    if ior is None:
        return np.ones_like(c)
    eta = _check_ior(ior, "material")
    if eta == 1.0:  # no interface: nothing reflects but grazing
        return np.where(c == 0.0, 1.0, 0.0)
    eta2 = eta * eta
    eta2m1 = (eta - 1.0) * (eta + 1.0)  # η² − 1 without cancellation for η ≈ 1
    g = np.sqrt(eta2m1 + c * c + 0j)  # √(η² − 1 + cos²θ) = √(η² − sin²θ)
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = -eta2m1 / (c + g) ** 2
        rp = eta2m1 * (c * c * (eta2 + 1.0) - 1.0) / (eta2 * c + g) ** 2
    r = 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)
    # grazing incidence: R → 1 for every η ≠ 1 (η = 1 is given the same value by that limit)
    r = np.where(c == 0.0, 1.0, r)
    return np.clip(r, 0.0, 1.0)


def fresnel_transmittance(cos_theta, material=None):
    """Fresnel transmittance F_t = 1 − F_r (Mikkelsen 2009, §2.1 and Fig. 6(c)(d))."""
    return 1.0 - fresnel(cos_theta, material)


def f0_from_material(material) -> float:
    """Normal-incidence reflectance |(η − 1)/(η + 1)|² of ``material`` (Edwards et al. 2006,
    eq. 31; 1 for a mirror)."""
    ior = resolve_material(material) if isinstance(material, str | tuple) else material
    if ior is None:
        return 1.0
    eta = _check_ior(ior, "material")
    return abs((eta - 1.0) / (eta + 1.0)) ** 2


def schlick(cos_theta, f0):
    """Schlick's approximation F = F0 + (1 − F0)(1 − cos θ)⁵ (Schlick 1994; Edwards et al. 2006,
    eq. 30).

    ``f0`` ∈ [0, 1] is the normal-incidence reflectance (``f0_from_material``); broadcasts.
    """
    c = _cos(cos_theta)
    f0 = np.asarray(f0, dtype=np.float64)
    if not np.all((f0 >= 0.0) & (f0 <= 1.0)):
        raise UsageError(f"f0 must lie in [0, 1], got {f0!r}")
    return f0 + (1.0 - f0) * (1.0 - c) ** 5


def material_name(material) -> str | None:
    """The canonical name of ``material`` if it names one of ``MATERIALS`` ("Aluminum" →
    "aluminium"), else None (numbers, None, unknown text)."""
    if not isinstance(material, str):
        return None
    key = material.strip().lower()
    key = _ALIASES.get(key, key)
    return key if key in MATERIALS else None


def _ior_text(text: str):
    """``text`` as a number if it is one ("1.5", "0.769+6.08i", "0.769+6.08j"), else None."""
    t = text.replace(" ", "")
    try:
        return float(t)
    except ValueError:
        pass
    if t.endswith(("i", "j")):
        try:
            return complex(t[:-1] + "j")
        except ValueError:
            return None
    return None


def resolve_material(material):
    """Index of refraction from a material name (case-insensitive), a number, None, or a
    (name, wavelength_nm) pair.

    Names: those of ``MATERIALS`` (plus "aluminum"), fixed indices; numbers are an index of
    refraction (ior) n > 0 or n + ik with k ≥ 0, also as text the way microsim writes them
    ("1.5", "0.769+6.08i"; "j" for i is accepted too). A pair ("gold", 550) is a material of
    ``materials.TABLE`` at a wavelength in nm (``materials.index``).
    Returns a float (dielectric), a complex (conductor) or None (mirror).
    """
    if material is None:
        return None
    if isinstance(material, tuple):
        return _material_at(material)
    if isinstance(material, str):
        name = material_name(material)
        if name is not None:
            return MATERIALS[name]
        number = _ior_text(material.strip().lower())
        if number is not None:
            return resolve_material(number)
        allowed = ", ".join(sorted(MATERIALS) + sorted(_ALIASES))
        if materials.table_name(material) is not None:
            raise UsageError(
                f"material {material!r} needs a wavelength: a pair (name, wavelength_nm) such as "
                f"({material!r}, 550); without one, material must be one of {allowed} or an "
                f"index of refraction (ior) n / n+ik / None"
            )
        raise UsageError(
            f"material must be one of {allowed} or an index of refraction "
            f"(ior) n / n+ik / None, got {material!r}"
        )
    eta = _check_ior(material, "material")
    if isinstance(material, complex | np.complexfloating):
        return eta
    return eta.real


def _material_at(pair: tuple):
    """The index of a (name, wavelength_nm) pair (``resolve_material``)."""
    if len(pair) != 2 or not isinstance(pair[0], str):
        raise UsageError(
            f"material as a pair must be (name, wavelength_nm), e.g. ('gold', 550), got {pair!r}"
        )
    name, wavelength_nm = pair
    if np.ndim(wavelength_nm) != 0:
        raise UsageError(
            f"material as a pair takes one wavelength_nm (a number), got {wavelength_nm!r}"
        )
    eta = materials.index(name, wavelength_nm)
    return eta.real if eta.imag == 0 else eta


def fresnel_real_arithmetic(c, ior):
    """``fresnel`` (unpolarised reflectance, c = cos θ ∈ [0, 1], ior a number or None) in real
    arithmetic, compiled (``fresnel_real_scalar``): every value is independent of its array
    position (NumPy's complex kernels round the last bit differently in their SIMD body and
    scalar tail) and ~10× faster than ``fresnel`` — the estimator's path for per-facet tables
    and analytic V-grooves. Agrees with ``fresnel`` to 1e-12 for physical materials (tests);
    ``fresnel`` stays the reference (it is also stable for η → 1). A mirror (None) and η = 1
    (no interface) are delegated to ``fresnel``."""
    c = _cos(c)
    if ior is None or complex(ior) == 1:
        return fresnel(c, ior)
    eta = _check_ior(ior)
    c = np.ascontiguousarray(c, dtype=np.float64)
    out = np.empty_like(c)
    _fresnel_real_fill(c.ravel(), eta.real**2, eta.imag**2, out.ravel())
    return out


@cached_njit(nogil=True, error_model="numpy")  # no zero divisor; vectorisable
def fresnel_real_scalar(c, n2, k2):
    """Unpolarised Fresnel reflectance onto η = n + ik (n2 = n², k2 = k²) at c = cos θ
    (clipped to [0, 1]) in real arithmetic (Born & Wolf §14.2; Cook–Torrance form): with
    s² = 1 − c², A = n² − k² − s², B = √(A² + 4n²k²), a² = (B + A)/2, b² = (B − A)/2 (the
    cancelling one of the two taken as 2n²k²/(B ∓ A)),
        R_s = ((a − c)² + b²) / ((a + c)² + b²),
        R_p = R_s ((ac − s²)² + b²c²) / ((ac + s²)² + b²c²)      (× c² on both sides),
    F = (R_s + R_p)/2; at c = 0 both ratios are 1. Needs η ≠ 1 (see ``fresnel``)."""
    c = min(max(c, 0.0), 1.0)
    s2 = (1.0 - c) * (1.0 + c)
    a_ = n2 - k2 - s2
    b_ = math.sqrt(a_ * a_ + 4.0 * n2 * k2)
    big = b_ + a_ if a_ >= 0 else b_ - a_  # the sum without cancellation
    small = 4.0 * n2 * k2 / big if big > 0 else 0.0
    a2, b2 = (0.5 * big, 0.5 * small) if a_ >= 0 else (0.5 * small, 0.5 * big)
    a = math.sqrt(a2)
    rs = ((a - c) * (a - c) + b2) / ((a + c) * (a + c) + b2)
    ac = a * c
    rp = rs * ((ac - s2) * (ac - s2) + b2 * c * c) / ((ac + s2) * (ac + s2) + b2 * c * c)
    return min(max(0.5 * (rs + rp), 0.0), 1.0)


@cached_njit(nogil=True)
def _fresnel_real_fill(c, n2, k2, out):
    for i in range(len(c)):
        out[i] = fresnel_real_scalar(c[i], n2, k2)
