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

* Kulla & Conty 2017, the dielectric variant (``KullaContyDielectric``): a rough interface
  between air (index 1) above and a medium of real index η below loses, in single scattering,
  1 − E±(μ) of the flux arriving from the air (+) or from inside (−), E± = R + T of the
  single-scattering BSDF *with* its Fresnel factors (the interface absorbs nothing, so the
  whole loss is put back; no F_ms factor). The slides give the ingredients — E tabulated
  entering and exiting, E±_avg = 2∫₀¹ E±(μ) μ dμ, the lost energy split between reflection
  and transmission, reciprocity — not one printed formula; this is our reading. Four
  separable lobes, each (1 − E(μ)) on the side of each direction:

      f_ms(i, o) = (1 − x±)(1 − E±(μi))(1 − E±(μo)) / (π (1 − E±_avg))   (o on i's side ±)
      f_ms(i, o) = x±(1 − E±(μi))(1 − E∓(μo)) / (π (1 − E∓_avg))         (o on the other)

  so light from side ± regains 1 − E±(μi), a fraction x± of it transmitted (the white
  furnace closes: E±(μi) + R_ms + T_ms = 1). The reflection lobes are symmetric; the
  transmission lobes obey the generalised reciprocity f_t(i, o)/η_o² = f_t(o, i)/η_i²
  (Walter et al. 2007, eq. 21) iff x₊(1 − E₊_avg) = η² x₋(1 − E₋_avg) — the reciprocity
  constraint, which fixes x₋ from x₊. The remaining freedom is x₊; the slides' own choice
  could not be checked against their text here, so we take x₊ = 1 − F_avg(η), the
  cosine-averaged Fresnel transmittance from the air (``fresnel_average``): the multiply
  scattered light crosses as a diffuse flux would cross the smooth interface, the Fresnel
  average being what Kulla & Conty weight multiply scattered light with. Or give
  ``transmitted_fraction`` (e.g. a random walk's). x₋ must come out in [0, 1] (else
  UsageError). Heitz et al. 2016's walk (GGX α = 0.5, η = 1.5) transmits about 0.95–0.97 of
  its orders ≥ 2 from the air (x₊ = 0.908 here) and 0.07–0.23 from inside (x₋ ≈ 0.13).

  E±(μ): ``DielectricAlbedoTable``, here from the first order of Heitz et al. 2016's
  dielectric random walk (``DielectricAlbedoTable.from_walk``), which is Walter et al. 2007's
  BSDF with height-correlated Smith masking (``random_walk`` module docstring): Monte Carlo,
  so the table carries its standard errors; any other single-scattering albedo fills the same
  table.

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

from dataclasses import dataclass

import numpy as np

from microsim import checks as _checks
from microsim.errors import UsageError

from .brdf import AlbedoTable
from .fresnel import fresnel, resolve_material

__all__ = [
    "fresnel_average",
    "cos_lobe_bin_averages",
    "KullaConty",
    "DielectricAlbedoTable",
    "KullaContyDielectric",
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
    return AlbedoTable.of(ndf, shadowing, None)


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


# --- Kulla & Conty 2017, dielectric -------------------------------------------------------
_DIELECTRIC_NODES_DEG = (0.0, 20.0, 35.0, 48.0, 58.0, 66.0, 72.0, 77.0, 81.0, 84.0, 86.5, 88.5)
"""Incidence angles (degrees from the pole of the incidence's side) of the walk's albedo table:
denser towards the horizon, where E changes fastest."""

_SIDES = ("outside", "inside")


@dataclass(frozen=True)
class DielectricAlbedoTable:
    """Single-scattering albedo E(μ) = R + T of a rough dielectric interface at the cosines
    ``mu`` (increasing, in (0, 1]) for light from the air (``outside``) and from inside the
    medium (``inside``), with their standard errors (``stderr_outside``, ``stderr_inside``;
    zeros for an exact table). Between nodes E is linear in μ, constant beyond the end nodes.
    """

    mu: np.ndarray
    outside: np.ndarray
    inside: np.ndarray
    stderr_outside: np.ndarray
    stderr_inside: np.ndarray

    def __post_init__(self):
        mu = np.asarray(self.mu, dtype=np.float64)
        if mu.ndim != 1 or len(mu) < 2 or np.any(np.diff(mu) <= 0) or mu[0] <= 0 or mu[-1] > 1:
            raise UsageError("mu must be >= 2 increasing cosines within (0, 1]")
        for name in ("outside", "inside", "stderr_outside", "stderr_inside"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.shape != mu.shape or np.any(~(a >= 0)) or np.any(a > 1):
                raise UsageError(f"{name} must be values in [0, 1] of the shape of mu {mu.shape}")
            object.__setattr__(self, name, a)
        object.__setattr__(self, "mu", mu)

    @classmethod
    def from_walk(cls, ndf, eta, n_paths: int = 100_000, seed=0) -> DielectricAlbedoTable:
        """E± from the order-1 exits of Heitz et al. 2016's dielectric walk
        (``random_walk.smith_random_walk(..., transmission=True)``), ``n_paths`` per node and
        side: the fraction of paths that leave after one event (standard error
        √(E(1 − E)/(n − 1))). ``ndf``: one of ``random_walk.WALK_NDFS``; ``seed``: one
        generator for the whole table."""
        from .random_walk import smith_random_walk

        n_paths = _checks.integer("n_paths", n_paths, 2, 10**9)
        rng = np.random.default_rng(seed)
        theta = np.radians(np.asarray(_DIELECTRIC_NODES_DEG[::-1]))
        mu = np.cos(theta)
        values = {}
        for side, sign in zip(_SIDES, (1.0, -1.0)):
            e = np.empty(len(mu))
            for j, t in enumerate(theta):
                wi = np.array([np.sin(t), 0.0, sign * np.cos(t)])
                p = smith_random_walk(
                    np.broadcast_to(wi, (n_paths, 3)), ndf, eta, rng, 2, transmission=True
                )
                e[j] = np.count_nonzero(p.order == 1) / n_paths
            values[side] = e
            values["stderr_" + side] = np.sqrt(e * (1.0 - e) / (n_paths - 1.0))
        return cls(mu, **values)

    @classmethod
    def from_model(cls, model) -> DielectricAlbedoTable:
        """E± = R + T of a single-scattering dielectric BSDF ``model`` (a
        ``dielectric.WalterDielectric``) by its quadrature (``dielectric.dielectric_albedo``,
        ≲ 1e-5) at the table's nodes, from the air and from inside; standard errors 0."""
        from .dielectric import dielectric_albedo

        theta = np.asarray(_DIELECTRIC_NODES_DEG[::-1])
        mu = np.cos(np.radians(theta))
        values = {}
        for side, angles in zip(_SIDES, (theta, 180.0 - theta)):
            values[side] = np.array([sum(dielectric_albedo(model, float(t))) for t in angles])
            values["stderr_" + side] = np.zeros(len(mu))
        return cls(mu, **values)

    def E(self, mu, side: str):
        """E(μ) of ``side`` ("outside" | "inside") at cosines μ (absolute values taken)."""
        return np.interp(np.abs(np.asarray(mu, dtype=np.float64)), self.mu, self._values(side))

    def average(self, side: str) -> float:
        """E_avg = 2∫₀¹ E(μ) μ dμ of ``side``, exact for the table's interpolant (2-point
        Gauss–Legendre per panel: E μ is quadratic on each)."""
        x, w = np.polynomial.legendre.leggauss(2)
        edges = np.unique(np.concatenate([[0.0], self.mu, [1.0]]))
        a, b = edges[:-1, None], edges[1:, None]
        mu = 0.5 * (a + b) + 0.5 * (b - a) * x
        return float(2.0 * np.sum(0.5 * (b - a) * w * mu * self.E(mu, side)))

    def _values(self, side: str) -> np.ndarray:
        if side not in _SIDES:
            raise UsageError(f"side must be one of {', '.join(map(repr, _SIDES))}, got {side!r}")
        return self.outside if side == "outside" else self.inside


class KullaContyDielectric:
    """Kulla & Conty 2017 energy compensation of a rough dielectric interface (module
    docstring, our reading): the multiply scattered light's BSDF f_ms(wi, wo) for wi, wo on
    either side (sr⁻¹, radiance convention).

    ``ndf`` and ``eta`` (the medium's real index, ≠ 1; air above) build the single-scattering
    table from the walk (``DielectricAlbedoTable.from_walk``), or pass ``table``;
    ``transmitted_fraction``: x₊, the fraction of the energy put back for light from the air
    that is transmitted (default 1 − F_avg(η)); x₋ follows from reciprocity.
    """

    def __init__(
        self,
        ndf=None,
        eta: float = 1.5,
        table: DielectricAlbedoTable | None = None,
        transmitted_fraction: float | None = None,
    ):
        eta = resolve_material(eta)
        if eta is None or isinstance(eta, complex) or eta == 1.0:
            raise UsageError(f"eta must be a real index of refraction > 0, != 1, got {eta!r}")
        self.eta = float(eta)
        if table is None:
            if ndf is None:
                raise UsageError("give ndf (to build the albedo table) or table")
            table = DielectricAlbedoTable.from_walk(ndf, self.eta)
        if not isinstance(table, DielectricAlbedoTable):
            raise UsageError(f"table must be a DielectricAlbedoTable, got {type(table).__name__}")
        self.table = table
        self.e_avg = {side: table.average(side) for side in _SIDES}
        if not max(self.e_avg.values()) < 1.0:
            raise UsageError(f"table must lose energy on both sides (E_avg < 1), got {self.e_avg}")
        if transmitted_fraction is None:
            x_out = 1.0 - fresnel_average(self.eta)
        else:
            x_out = _checks.in_range("transmitted_fraction", transmitted_fraction, 0.0, 1.0)
        loss = {side: 1.0 - self.e_avg[side] for side in _SIDES}
        x_in = x_out * loss["outside"] / (self.eta**2 * loss["inside"])
        if not x_in <= 1.0:
            raise UsageError(
                f"transmitted_fraction {x_out:.6g} needs {x_in:.6g} > 1 of the energy put back "
                "for light from inside to be transmitted (reciprocity); give a smaller one"
            )
        self.transmitted = {"outside": x_out, "inside": x_in}
        self._loss = loss

    def bsdf(self, wi, wo):
        """f_ms(wi, wo) in sr⁻¹ for unit wi, wo on either side (0 on the horizon)."""
        wi = _checks.directions("wi", wi)
        wo = _checks.directions("wo", wo)
        _checks.broadcast({"wi": wi, "wo": wo})
        ci, co = np.broadcast_arrays(wi[..., 2], wo[..., 2])
        out = np.zeros(ci.shape)
        for side_i, sign in zip(_SIDES, (1.0, -1.0)):
            for side_o, same in ((side_i, True), (_other(side_i), False)):
                mask = (sign * ci > 0) & ((sign * co > 0) == same) & (co != 0)
                x = self.transmitted[side_i]
                share = (1.0 - x) if same else x
                out[mask] = (
                    share
                    * (1.0 - self.table.E(ci[mask], side_i))
                    * (1.0 - self.table.E(co[mask], side_o))
                    / (np.pi * self._loss[side_o])
                )
        return out

    def albedo(self, theta_deg):
        """(R_ms, T_ms): the energy f_ms reflects and transmits for light at θi (degrees, [0,
        90] from the air or [90, 180] from inside), (1 − x)(1 − E(μi)) and x(1 − E(μi))."""
        t = np.asarray(theta_deg, dtype=np.float64)
        if np.any(~((t >= 0) & (t <= 180))):
            raise UsageError(f"theta_deg must lie in [0, 180], got {theta_deg!r}")
        mu = np.cos(np.radians(t))
        outside = mu >= 0
        lost = np.where(
            outside, 1.0 - self.table.E(mu, "outside"), 1.0 - self.table.E(mu, "inside")
        )
        x = np.where(outside, self.transmitted["outside"], self.transmitted["inside"])
        return (1.0 - x) * lost, x * lost

    def __repr__(self) -> str:
        return (
            f"KullaContyDielectric(eta={self.eta:.6g}, E_avg={self.e_avg}, "
            f"transmitted={self.transmitted})"
        )


def _other(side: str) -> str:
    return "inside" if side == "outside" else "outside"


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
