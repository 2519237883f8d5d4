"""Closed-form energy compensation for the light single scattering misses.

Two reciprocal, diffuse-shaped lobes that put back, as a function of cos θ only, the energy a
single-scattering microfacet model loses:

* Kulla & Conty 2017 ("Revisiting physically based shading at Imageworks", SIGGRAPH course
  *Physically Based Shading in Theory and Practice*), after Kelemen & Szirmay-Kalos 2001:

      f_ms(wi, wo) = (1 − E(μo)) (1 − E(μi)) / (π (1 − E_avg)),

  E(μ) the directional albedo of the single-scattering model with F = 1 and
  E_avg = 2∫₀¹ E(μ) μ dμ. Its albedo is ∫ f_ms μo dωo = (1 − E(μi)) (1 − E_avg)/(1 − E_avg), so
  E(μi) + albedo(f_ms) = 1 for every μi: the white furnace closes (``KullaConty``).

  Coloured conductors (optional ``fresnel_factor=True``): Kulla & Conty scale f_ms by
  F_ms = F_avg² E_avg / (1 − F_avg (1 − E_avg)), F_avg = 2∫₀¹ F(μ) μ dμ. Derivation (the
  geometric series the slide sums): light not leaving after the first bounce (fraction
  1 − E_avg, already weighted by one Fresnel factor) bounces again with F_avg and leaves with
  probability E_avg each time, so the multiply scattered energy is
  Σ_{k≥1} F_avg^{k+1} (1 − E_avg)^k E_avg = F_avg² E_avg (1 − E_avg)/(1 − F_avg(1 − E_avg)),
  i.e. F_ms times the white energy 1 − E_avg. (F_ms = 1 for F = 1. A form with F_avg instead
  of F_avg² omits the first bounce's Fresnel factor.) Off by default: the white (E from F = 1)
  lobe is what the compensation is defined by.

* Mikkelsen 2009, eq. 28: f = k_s f_s + (1 − k_s ρ(wi)) (k_d/π) (1 − k_s ρ(wo)), ρ the specular
  albedo (eq. 27, ``brdf.AlbedoTable``). Here only the diffuse-like second term is modelled, with
  k_d chosen so that its energy matches a given multiply-scattered energy
  (``mikkelsen_kd``). Its albedo is k_d (1 − k_s ρ(θi)) (1 − k_s ρ̄), ρ̄ = 2∫ρ μ dμ. With
  k_s = 1, F = 1 and the white target 1 − ρ(θi), k_d = 1/(1 − ρ̄) for every θi and the term *is*
  Kulla–Conty's f_ms. k_d here may exceed 1 (eq. 28 as printed has no 1/(1 − ρ̄)).

E(μ) and ρ(θ) come from ``brdf.AlbedoTable``: deterministic quadrature over the half vector at
46 + 24 polar angles (accuracy ≲ 5e-6 at the nodes, ≲ 2e-5 between them by its cubic spline;
tests/test_brdf.py), E_avg = ``AlbedoTable.rho_bar`` by 8-point Gauss–Legendre on every spline
interval (error well below the table's). Directions: unit (..., 3), n = +z, pointing away from
the surface; BRDFs in sr⁻¹; angles in public arguments in degrees.
"""

from __future__ import annotations

import numpy as np

from microsim import checks as _checks
from microsim.errors import UsageError

from .brdf import AlbedoTable
from .fresnel import fresnel, resolve_material

__all__ = [
    "fresnel_average",
    "cos_lobe_bin_averages",
    "KullaConty",
    "mikkelsen_diffuse",
    "mikkelsen_diffuse_albedo",
    "mikkelsen_kd",
]

_MU_PANELS = np.array([0.0, 1e-3, 1e-2, 0.05, 0.2, 0.5, 1.0])


def _mu_rule(n: int = 32):
    """Composite Gauss–Legendre nodes/weights on μ ∈ [0, 1], panels refined towards μ = 0."""
    x, w = np.polynomial.legendre.leggauss(n)
    a, b = _MU_PANELS[:-1, None], _MU_PANELS[1:, None]
    return (0.5 * (a + b) + 0.5 * (b - a) * x).ravel(), (0.5 * (b - a) * w).ravel()


def fresnel_average(material) -> float:
    """F_avg = 2∫₀¹ F(μ) μ dμ (cosine-weighted hemispherical average of the Fresnel reflectance;
    Kulla & Conty 2017), by composite 32-point Gauss–Legendre on 6 panels (error ≲ 1e-12 for
    the smooth F of a conductor or dielectric seen from air). 1 for the mirror (None)."""
    eta = resolve_material(material)
    if eta is None:
        return 1.0
    mu, w = _mu_rule()
    return float(2.0 * np.sum(w * mu * fresnel(mu, eta)))


def cos_lobe_bin_averages(g, theta_edges, n_phi: int):
    """Bin averages (1/Ω_B)∫_B g(μo) μo dωo of a lobe that depends on μo = cos θo only, over
    θo bands ``theta_edges`` (degrees, increasing in [0, 90]) and repeated over ``n_phi`` Δφ
    bins (the value does not depend on Δφ or on the bins' widths): shape (n_theta, n_phi).

    Per band: ∫ g(cos θ) cos θ sin θ dθ / ((sin²θ₂ − sin²θ₁)/2) by 16-point Gauss–Legendre
    in θ on the band (g smooth: error ≲ 1e-10 relative for the E(μ) splines here).
    Multiply by the lobe's θi-dependent factor to get f̄_B in sr⁻¹.
    """
    te = np.radians(np.asarray(theta_edges, dtype=np.float64))
    if te.ndim != 1 or len(te) < 2 or np.any(np.diff(te) <= 0) or te[0] < 0 or te[-1] > np.pi / 2:
        raise UsageError("theta_edges must be >= 2 increasing values in degrees within [0, 90]")
    n_phi = _checks.integer("n_phi", n_phi, 1, 2**22)
    x, w = np.polynomial.legendre.leggauss(16)
    a, b = te[:-1, None], te[1:, None]
    t = 0.5 * (a + b) + 0.5 * (b - a) * x
    num = np.sum(0.5 * (b - a) * w * g(np.cos(t)) * np.cos(t) * np.sin(t), axis=1)
    den = 0.5 * np.diff(np.sin(te) ** 2)
    return np.repeat((num / den)[:, None], n_phi, axis=1)


def _table(ndf, table, shadowing: str) -> AlbedoTable:
    if table is not None:
        if not isinstance(table, AlbedoTable):
            raise UsageError(f"table must be an AlbedoTable, got {type(table).__name__}")
        return table
    if ndf is None:
        raise UsageError("give ndf (to build the F = 1 albedo table) or table (an AlbedoTable)")
    return AlbedoTable(ndf, shadowing=shadowing, material=None)


class KullaConty:
    """Kulla & Conty 2017 energy compensation lobe f_ms (module docstring).

    ``ndf`` builds E(μ) as the albedo of Torrance–Sparrow with ``shadowing`` (default
    height-correlated Smith) and F = 1 (``AlbedoTable``); or pass ``table``, the albedo table of
    any single-scattering model (its material should be the mirror for the white compensation).
    ``material``: only used with ``fresnel_factor=True`` (F_avg of the conductor).
    """

    def __init__(
        self,
        ndf=None,
        table: AlbedoTable | None = None,
        shadowing: str = "smith-correlated",
        material=None,
        fresnel_factor: bool = False,
    ):
        self.table = _table(ndf, table, shadowing)
        if not isinstance(fresnel_factor, (bool, np.bool_)):
            raise UsageError(f"fresnel_factor must be True or False, got {fresnel_factor!r}")
        self.e_avg = float(self.table.rho_bar)
        if not self.e_avg < 1.0:
            raise UsageError(
                f"table must lose energy (E_avg < 1) for a compensation lobe, got E_avg = "
                f"{self.e_avg:.6g}"
            )
        self.f_avg = fresnel_average(material)
        self.fresnel_factor = bool(fresnel_factor)
        self.scale = (
            self.f_avg**2 * self.e_avg / (1.0 - self.f_avg * (1.0 - self.e_avg))
            if self.fresnel_factor
            else 1.0
        )

    def E(self, cos_theta):
        """E(μ), the single-scattering albedo at μ = cos θ (clipped to [0, 1])."""
        return self.table.rho(cos_theta)

    def brdf(self, wi, wo):
        """f_ms(wi, wo) in sr⁻¹ (0 where wi or wo is at or below the horizon); reciprocal."""
        wi = _checks.directions("wi", wi)
        wo = _checks.directions("wo", wo)
        _checks.broadcast({"wi": wi, "wo": wo})
        ci, co = np.broadcast_arrays(wi[..., 2], wo[..., 2])
        f = (1.0 - self.E(ci)) * (1.0 - self.E(co)) / (np.pi * (1.0 - self.e_avg))
        return np.where((ci > 0) & (co > 0), self.scale * np.maximum(f, 0.0), 0.0)

    def albedo(self, theta_deg):
        """∫ f_ms cos θo dωo = F_ms (1 − E(cos θi)) (closed form; θi in degrees)."""
        t = np.radians(np.asarray(theta_deg, dtype=np.float64))
        if np.any((t < 0) | (t > 0.5 * np.pi)) or np.any(np.isnan(t)):
            raise UsageError(f"theta_deg must lie in [0, 90], got {theta_deg!r}")
        return self.scale * (1.0 - self.E(np.cos(t)))

    def bin_averages(self, theta_i, theta_edges, n_phi: int):
        """f̄_B of f_ms (sr⁻¹) for incidence angles ``theta_i`` (degrees) over θo bands
        ``theta_edges`` (degrees) × ``n_phi`` Δφ bins (f_ms has no Δφ dependence): shape
        (len(theta_i), n_theta, n_phi). Exact up to the band quadrature
        (``cos_lobe_bin_averages``)."""
        band = cos_lobe_bin_averages(lambda c: 1.0 - self.E(c), theta_edges, n_phi)
        pre = self.albedo(np.atleast_1d(theta_i)) / (np.pi * (1.0 - self.e_avg))
        return pre[:, None, None] * band[None]

    def __repr__(self) -> str:
        return (
            f"KullaConty(E_avg={self.e_avg:.6g}, F_avg={self.f_avg:.6g}, "
            f"fresnel_factor={self.fresnel_factor})"
        )


# --- Mikkelsen 2009, eq. 28 --------------------------------------------------------------------
def _ks(ks, table):
    ks = _checks.in_range("ks", ks, 0.0, 1.0)
    if ks * table.rho_max > 1.0 + 1e-3:
        raise UsageError(
            f"table must have ks·ρ <= 1, got ks·max ρ = {ks * table.rho_max:.6g} "
            "(use V-groove or Smith shadowing)"
        )
    return ks


def mikkelsen_diffuse(wi, wo, table: AlbedoTable, kd, ks: float = 1.0):
    """Diffuse-like term of Mikkelsen 2009, eq. 28, (1 − ks ρ(wi)) (kd/π) (1 − ks ρ(wo)), sr⁻¹.

    ``table``: the specular albedo ρ (eq. 27) as an ``AlbedoTable``; ``kd`` ≥ 0 a scalar (may
    exceed 1, see the module docstring); ``ks`` ∈ [0, 1]. Reciprocal (a symmetric product).
    0 where wi or wo is at or below the horizon.
    """
    ks = _ks(ks, table)
    kd = _checks.in_range("kd", kd, 0.0, np.inf, hi_open=True)
    wi = _checks.directions("wi", wi)
    wo = _checks.directions("wo", wo)
    _checks.broadcast({"wi": wi, "wo": wo})
    ci, co = np.broadcast_arrays(wi[..., 2], wo[..., 2])
    f = kd / np.pi * (1.0 - ks * table.rho(ci)) * (1.0 - ks * table.rho(co))
    return np.where((ci > 0) & (co > 0), np.maximum(f, 0.0), 0.0)


def mikkelsen_diffuse_albedo(theta_deg, table: AlbedoTable, kd, ks: float = 1.0):
    """Albedo of ``mikkelsen_diffuse``: kd (1 − ks ρ(θi)) (1 − ks ρ̄), ρ̄ = 2∫ρ μ dμ
    (``table.rho_bar``); θi in degrees. ``kd`` scalar or broadcasting with θi."""
    ks = _ks(ks, table)
    t = np.radians(np.asarray(theta_deg, dtype=np.float64))
    if np.any((t < 0) | (t > 0.5 * np.pi)) or np.any(np.isnan(t)):
        raise UsageError(f"theta_deg must lie in [0, 90], got {theta_deg!r}")
    kd = np.asarray(kd, dtype=np.float64)
    if np.any(kd < 0) or np.any(~np.isfinite(kd)):
        raise UsageError(f"kd must be finite and >= 0, got {kd!r}")
    return kd * (1.0 - ks * table.rho(np.cos(t))) * (1.0 - ks * table.rho_bar)


def mikkelsen_kd(
    theta_deg,
    target,
    table: AlbedoTable,
    ks: float = 1.0,
    target_stderr=None,
    per_angle: bool = False,
):
    """k_d of Mikkelsen 2009, eq. 28 so that the diffuse term's energy matches ``target``.

    ``target``: multiply-scattered energy (per incident unit) at the incidence angles
    ``theta_deg`` (degrees), e.g. a random walk's or a simulation's orders ≥ 2.
    With A(θ) = (1 − ks ρ(θ))(1 − ks ρ̄) the term's albedo is kd·A(θ), so

    * ``per_angle=True``: kd(θ) = target/A(θ) per angle (array) — matches every energy, but a
      kd depending on θi is no longer reciprocal; use it to read the energy, not as a BRDF;
    * else one kd by weighted least squares, kd = Σ w A T / Σ w A², w = 1/σ² from
      ``target_stderr`` (or 1): a reciprocal model fitted to all angles (exact for one angle).
    """
    t = np.atleast_1d(np.asarray(theta_deg, dtype=np.float64))
    y = np.atleast_1d(np.asarray(target, dtype=np.float64))
    if t.ndim != 1 or y.shape != t.shape or not np.all(np.isfinite(y)):
        raise UsageError(
            f"target must be finite values of the shape of theta_deg {t.shape}, got {y.shape}"
        )
    a = mikkelsen_diffuse_albedo(t, table, 1.0, ks)
    if not np.all(a > 0):
        raise UsageError("the specular albedo leaves no energy to compensate (1 − ks ρ = 0)")
    if per_angle:
        return y / a
    if target_stderr is None:
        w = np.ones_like(y)
    else:
        s = np.atleast_1d(np.asarray(target_stderr, dtype=np.float64))
        if s.shape != y.shape or not np.all(s > 0):
            raise UsageError("target_stderr must be positive values of the shape of target")
        w = 1.0 / s**2
    return float(np.sum(w * a * y) / np.sum(w * a * a))
