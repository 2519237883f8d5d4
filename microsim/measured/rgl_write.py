"""Writing the RGL ".bsdf" format (``microsim.measured.rgl``): a microsim BRDF in the
coordinates of a microsim NDF's visible normals.

What ``write_rgl`` stores (exact where microsim knows the quantity):
    * ndf: ``ndf.D_cos`` at the nodes θ = u_θ² π/2, Pn = 2 identical rows (isotropic) —
      with ``floor`` > 0 the mixture (1 − floor) D + floor/π, for BRDFs with a diffuse term;
    * sigma: σ = (1 + Λ(θ)) cos θ (the Smith projected area of an isotropic NDF,
      ``analytic.shadowing.smith_lambda``: closed form or the numerical projected-area
      identity; finite at θ = 90°, where Λ cos θ has a finite limit; the mixture's adds
      floor · (1 + cos θ)/2, the projected area of the uniform NDF 1/π);
    * vndf: at each node of slice θi (φi = 0), p(u) = D(m)⟨wi, m⟩⁺/σ(wi) · 2π² u_θ sin θm,
      the VNDF density D_wi(m) = ⟨wi, m⟩⁺ D(m)/σ(wi) per unit area of (u_θ, u_φ)
      (dω = 2π² u_θ sin θ du_θ du_φ);
    * rgb / spectra: at each node s of slice θi, m = the forward warp of s (the exact inverse
      of the readers' inverse map), wo = 2(wi·m)m − wi and
      ρ = f(wi, wo) cos θo · 4 σ̂(wi)/D̂(m), with σ̂, D̂ the file's own interpolants as the
      readers see them, so that a reader returns f exactly (to float32) at the nodes; ρ = 0
      where wo is below the horizon. For a Torrance–Sparrow BRDF ρ = F G2 (1 + Λi): smooth
      and ≤ 1, which is why the grid can be small;
    * luminance: the luminance of ρ (0.212671 R + 0.715160 G + 0.072169 B, the weights of
      Mitsuba's ``luminance``; ρ itself for a grey BRDF, which the spectral flavour writes
      as a constant spectrum; for a spectral BRDF in the spectral flavour the mean of ρ over
      its wavelengths — a sampling density only, it does not enter f); a slice that is 0
      everywhere gets a uniform density (a reader would divide by its zero integral);
    * description: the text given, UTF-8; jacobian: 1.
A grey BRDF (f returns shape (M,)) gets equal channels; an RGB one ((M, 3)) its three
channels (RGB flavour only). A spectral BRDF (``spectral.SpectralBRDF``: one BRDF per
wavelength) gets in the spectral flavour its own wavelengths, ρ of each wavelength's BRDF at
the nodes — the format stores any increasing wavelengths and the readers interpolate linearly
between them (``read_rgl`` refuses a wavelength outside them, Mitsuba 3 holds the first and the
last value beyond) — and in the RGB flavour the linear sRGB of ρ's spectrum at each node
under D65 (``analytic.colour_matching``; ρ is linear in f), its negative components (a colour
outside the sRGB gamut) set to 0. A grey BRDF's spectral flavour: ``SPECTRAL_WAVELENGTHS_NM``
(the grey value at every wavelength). pbrt-v4 reads spectral files only, Mitsuba 3 spectral
files in its spectral variants and RGB files in its RGB variants.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from microsim import checks as _checks
from microsim.analytic import colour_matching
from microsim.analytic.ndf import NDF
from microsim.analytic.shadowing import smith_lambda
from microsim.atomic import atomic_open
from microsim.errors import UsageError
from microsim.vectors import spherical

from .merl import brdf_rgb
from .rgl_warp import Table2D, theta2u, u2phi, u2theta
from .spectral import SpectralBRDF
from .tensor_file import tensor_file_bytes

__all__ = [
    "RGLResolution",
    "DEFAULT_RESOLUTION",
    "RHO_LIMIT",
    "FLAVOURS",
    "SPECTRAL_WAVELENGTHS_NM",
    "LUMINANCE_WEIGHTS",
    "write_rgl",
]

FLAVOURS = ("rgb", "spectral")
"""``write_rgl``'s ``flavour``: an "rgb" field (Mitsuba 3 RGB variants) or "wavelengths" and
"spectra" (Mitsuba 3 spectral variants, pbrt-v4)."""

SPECTRAL_WAVELENGTHS_NM = (360.0, 1000.0)
"""Wavelengths (nm) of a spectral-flavour file of a grey BRDF: the range of the RGL database's
spectral measurements; the value is the same at both, so every wavelength reads the same."""

LUMINANCE_WEIGHTS = (0.212671, 0.715160, 0.072169)
"""Luminance of linear sRGB/Rec. 709 (R, G, B), as Mitsuba's ``luminance``."""


# --- writing ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class RGLResolution:
    """Grid sizes of a file ``write_rgl`` makes.

    ``theta_i``: number of incidences, θi_k = ``theta_max_deg`` · k/(n − 1) (uniform in θ:
    the warp and ρ change fastest towards grazing, where u_θ spacing would be coarsest);
    ``vndf``: (rows u_φ, columns u_θ) of the VNDF grid; ``samples``: nodes per side of the
    square ρ/luminance grid (the readers want it square); ``ndf``: u_θ nodes of ndf and sigma.
    """

    theta_i: int = 32
    theta_max_deg: float = 88.0
    vndf: tuple = (64, 64)
    samples: int = 64
    ndf: int = 512

    def __post_init__(self):
        object.__setattr__(self, "theta_i", _checks.integer("resolution.theta_i", self.theta_i, 2))
        object.__setattr__(
            self,
            "theta_max_deg",
            _checks.in_range("resolution.theta_max_deg", self.theta_max_deg, 0.0, 90.0,
                             lo_open=True, hi_open=True),
        )  # fmt: skip
        v = tuple(self.vndf) if isinstance(self.vndf, (tuple, list)) else (self.vndf,)
        if len(v) != 2:
            raise UsageError(f"resolution.vndf must be (rows, columns), got {self.vndf!r}")
        object.__setattr__(self, "vndf", tuple(_checks.integer("resolution.vndf", n, 3) for n in v))
        object.__setattr__(self, "samples", _checks.integer("resolution.samples", self.samples, 2))
        object.__setattr__(self, "ndf", _checks.integer("resolution.ndf", self.ndf, 2))

    def theta_i_rad(self) -> np.ndarray:
        """The incidence nodes (radians) as stored (float32 values)."""
        t = np.radians(self.theta_max_deg) * np.linspace(0.0, 1.0, self.theta_i)
        return t.astype(np.float32).astype(np.float64)


DEFAULT_RESOLUTION = RGLResolution()


def _check_ndf(ndf):
    if not isinstance(ndf, NDF) or not ndf.isotropic:
        raise UsageError(
            f"ndf must be an isotropic microsim NDF (microsim.analytic.ndf: Beckmann, GGX, "
            f"BlinnPhong, VonMisesFisher, ABC), got {_checks.short(ndf)}"
        )
    return ndf


def _sigma(ndf, theta) -> np.ndarray:
    """σ(θ) = (1 + Λ) cos θ (finite up to θ = 90°: cos θ is never exactly 0 in float64 here)."""
    c = np.maximum(np.cos(np.minimum(theta, 0.5 * np.pi)), 1e-300)
    w = np.stack([np.sqrt((1 - c) * (1 + c)), np.zeros_like(c), c], axis=-1)
    return c * (1.0 + smith_lambda(w, ndf))


class _WarpNDF:
    """The NDF a file stores and warps by: (1 − floor) D + floor/π (a Lambertian share, whose
    projected area is (1 + cos θ)/2), normalised like D (∫ D cos θm dω = 1)."""

    def __init__(self, ndf, floor: float):
        self.ndf, self.floor = ndf, floor

    def D_cos(self, c):
        d = np.asarray(self.ndf.D_cos(c), dtype=np.float64)
        return (1.0 - self.floor) * d + self.floor / np.pi

    def sigma(self, theta):
        lam = 0.5 * (1.0 + np.cos(np.minimum(theta, 0.5 * np.pi)))
        return (1.0 - self.floor) * _sigma(self.ndf, theta) + self.floor * lam


RHO_LIMIT = 1e3
"""Largest ρ = f cos θo · 4σ/D a file may hold: a microfacet BRDF's is F G2 (1 + Λi), a few at
most; far larger values mean energy where the warp's NDF has almost none (a diffuse term, or
an NDF narrower than the BRDF's lobe), which the file cannot interpolate."""


def _fields(
    brdf, ndf, res: RGLResolution, description: str, flavour: str, floor: float = 0.0
) -> dict:
    theta_i = res.theta_i_rad()
    T, (Hv, Wv), n, Nn = len(theta_i), res.vndf, res.samples, res.ndf
    ndf = _WarpNDF(ndf, floor)
    # NDF and projected area on the u_θ nodes
    th = u2theta(np.linspace(0.0, 1.0, Nn))
    ndf_row = ndf.D_cos(np.cos(th))
    sigma_row = ndf.sigma(th)
    ndf_t = np.tile(ndf_row, (2, 1)).astype(np.float32)
    sigma_t = np.tile(sigma_row, (2, 1)).astype(np.float32)
    ndf_tab, sigma_tab = Table2D(ndf_t), Table2D(sigma_t)
    sigma_i = ndf.sigma(theta_i)
    wi = spherical(theta_i, 0.0)  # (T, 3), φi = 0
    # VNDF density on its grid (per unit area of (u_θ, u_φ))
    ux, uy = np.meshgrid(np.linspace(0, 1, Wv), np.linspace(0, 1, Hv))  # (Hv, Wv)
    tm, pm = u2theta(ux), u2phi(uy)
    m = spherical(tm, pm)  # (Hv, Wv, 3)
    dot = np.einsum("tk,hwk->thw", wi, m)
    vndf = (
        ndf.D_cos(np.cos(tm))[None]
        * np.maximum(dot, 0.0)
        / sigma_i[:, None, None]
        * (2.0 * np.pi**2 * ux * np.sin(tm))[None]
    )
    vndf32 = vndf.astype(np.float32)[None]  # (1, T, Hv, Wv)
    warp = Table2D(vndf32, (np.zeros(1), theta_i.astype(np.float32)), warp=True)
    # ρ at the nodes of the warped square, per incidence
    sx, sy = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    s = np.broadcast_to(np.stack([sx, sy], -1), (T, n, n, 2)).reshape(-1, 2)
    ti = np.repeat(theta_i, n * n)
    u_m, _ = warp.sample(s, (np.zeros_like(ti), ti))
    m = spherical(u2theta(u_m[:, 0]), u2phi(u_m[:, 1]))
    wi_s = np.repeat(wi, n * n, axis=0)
    wim = np.einsum("ij,ij->i", wi_s, m)
    wo = 2.0 * wim[:, None] * m - wi_s
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    ok = (wo[:, 2] > 0.0) & (wim > 0.0)
    d_hat = ndf_tab.eval(u_m)
    u_wi = np.stack([theta2u(theta_i), np.full(T, 0.5)], -1)
    s_hat = np.repeat(sigma_tab.eval(u_wi), n * n)
    ok &= d_hat > 0.0
    spectral = isinstance(brdf, SpectralBRDF)
    rho = np.zeros((len(s), len(brdf.wavelengths_nm) if spectral else 3))
    if np.any(ok):
        f = brdf(wi_s[ok], wo[ok]) if spectral else brdf_rgb(brdf, wi_s[ok], wo[ok])
        rho[ok] = f * (wo[ok, 2] * 4.0 * s_hat[ok] / d_hat[ok])[:, None]
    if rho.max() > RHO_LIMIT:
        raise UsageError(
            f"brdf has energy where the NDF has almost none (ρ = f cos θo 4σ/D up to "
            f"{rho.max():.3g}, a microfacet BRDF's is a few): a diffuse term or a lobe wider "
            f"than the NDF; pass floor > 0 (a Lambertian share of the warp's NDF, e.g. 0.05) "
            f"or a wider ndf"
        )
    if spectral and flavour == "rgb":
        # each node's colour; one outside the sRGB gamut loses its negative components
        rho = np.maximum(colour_matching.linear_srgb(brdf.wavelengths_nm, rho), 0.0)
        spectral = False
    grey = not spectral and bool(np.all(rho[:, 0] == rho[:, 1]) and np.all(rho[:, 0] == rho[:, 2]))
    rho = rho.reshape(T, n, n, -1)
    if spectral:
        lum = rho.mean(axis=-1)
    else:
        lum = rho @ np.asarray(LUMINANCE_WEIGHTS) if not grey else rho[..., 0].copy()
    empty = ~np.any(lum > 0, axis=(1, 2))
    lum[empty] = 1.0
    fields = {
        "description": description,
        "jacobian": np.array([1], dtype=np.uint8),
        "theta_i": theta_i.astype(np.float32),
        "phi_i": np.zeros(1, dtype=np.float32),
        "ndf": ndf_t,
        "sigma": sigma_t,
        "vndf": vndf32,
        "luminance": lum.astype(np.float32)[None],
    }
    if flavour == "rgb":
        fields["rgb"] = np.moveaxis(rho, -1, 1).astype(np.float32)[None]  # (1, T, 3, n, n)
    elif spectral:
        fields["wavelengths"] = brdf.wavelengths_nm.astype(np.float32)
        fields["spectra"] = np.moveaxis(rho, -1, 1).astype(np.float32)[None]  # (1, T, L, n, n)
    else:
        if not grey:
            raise UsageError(
                "flavour='spectral' needs a grey or a spectral brdf (measured.SpectralBRDF): "
                "an RGB BRDF has no spectrum to write; use flavour='rgb'"
            )
        L = len(SPECTRAL_WAVELENGTHS_NM)
        fields["wavelengths"] = np.asarray(SPECTRAL_WAVELENGTHS_NM, dtype=np.float32)
        fields["spectra"] = np.repeat(rho[:, None, :, :, 0], L, axis=1).astype(np.float32)[None]
    return fields


def write_rgl(
    path,
    brdf: Callable,
    ndf,
    *,
    resolution: RGLResolution = DEFAULT_RESOLUTION,
    description: str | None = None,
    flavour: str = "rgb",
    floor: float = 0.0,
) -> None:
    """Write ``brdf(wi, wo)`` (sr⁻¹; wi, wo (M, 3) unit; returns (M,) grey or (M, 3) RGB), or
    a ``SpectralBRDF`` (one BRDF per wavelength; module docstring), to the RGL .bsdf file
    ``path``, warped by the VNDF of the isotropic microsim NDF ``ndf``
    (``microsim.measured.rgl``: what each field holds), atomically: nothing is written on an error.

    ``resolution``: an ``RGLResolution``; ``description``: the file's text (default: the
    brdf's and the NDF's repr); ``flavour``: one of ``FLAVOURS``; ``floor`` ∈ [0, 1): the
    Lambertian share of the NDF the file stores and warps by, (1 − floor) D + floor/π — 0
    (the surface's exact NDF) for a microfacet BRDF, > 0 for one with a diffuse term, which an
    exact narrow NDF leaves unrepresentable (a ``UsageError`` says so: ``RHO_LIMIT``).
    ``brdf`` is called at wi at the incidence nodes and wo reflected about each node's half
    vector; a ``BRDFTable``'s clamping beyond its last incidence carries into the file."""
    if not callable(brdf):
        raise UsageError(f"brdf must be a callable f(wi, wo) -> sr⁻¹, got {_checks.short(brdf)}")
    ndf = _check_ndf(ndf)
    if not isinstance(resolution, RGLResolution):
        raise UsageError(
            f"resolution must be an RGLResolution (e.g. RGLResolution(theta_i=32, samples=32)), "
            f"got {_checks.short(resolution)}"
        )
    if flavour not in FLAVOURS:
        raise UsageError(f"flavour must be one of {FLAVOURS}, got {flavour!r}")
    if description is None:
        description = f"microsim export: {_checks.short(brdf, 160)}; NDF {ndf!r}"
    if not isinstance(description, str):
        raise UsageError(f"description must be a str, got {_checks.short(description)}")
    floor = _checks.in_range("floor", floor, 0.0, 1.0, hi_open=True)
    blob = tensor_file_bytes(_fields(brdf, ndf, resolution, description, flavour, floor))
    with atomic_open(path, "wb") as fh:
        fh.write(blob)
