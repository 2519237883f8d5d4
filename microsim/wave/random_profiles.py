"""Periodic random 1D profiles: a Gaussian or ABC spectrum sampled on N points per period,
for the grating solvers (``wave.gratings.SampledGrating``; RCW through SCATMECH's
``Generic_Grating``, ``wave.fullwave``).

The spectra are those of ``surfaces.heightfields`` in their 1D (profile) form, normalised so
that ∫ S(f) df = σ² over −∞ < f < ∞ (S in µm³, f in cycles per µm):
* Gaussian, autocorrelation σ² exp(−x²/ℓ²) as the 2D fields': S(f) = √π σ² ℓ exp(−π² ℓ² f²)
  (the 2D field's PSD integrated over f_y: a line cut of the 2D field has this spectrum);
  rms slope √2 σ/ℓ;
* ABC (Church et al. 1989; Löw et al. 2012, eq. 7–8, the profile form): S(f) =
  a/(1 + B² f²)^((C+1)/2), a = σ² B Γ((C+1)/2)/(√π Γ(C/2)) (eq. 8), C > 0. (A line cut of
  the 2D ABC field of exponent C has this form with C − 1.)

Synthesis as the 2D fields' (``heightfields.synthesize``): the profile is a 1 × N grid, whose
single f_y cell has width 1/dx, so its 2D spectrum is S·dx; with ``exact_amplitude`` (the
default) every Fourier mode f_k = k/Λ, 0 < |k| ≤ N/2, has exactly the power S(f_k)/Λ and a
random phase, so the samples' variance is Σ_k S(f_k)/Λ (σ² less what the period and the
Nyquist band 1/(2dx) leave out); the piecewise-linear profile through the samples is what
every solver sees (its rms: ``SampledGrating.rms_height``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import gammaln

from microsim.checks import integer, positive
from microsim.errors import UsageError
from microsim.surfaces.heightfields import psd_grid, synthesize

from .gratings import SampledGrating

__all__ = ["SPECTRA", "RandomProfile", "gaussian_profile_psd", "abc_profile_psd", "random_grating"]

SPECTRA = ("gaussian", "abc")


def gaussian_profile_psd(f, sigma: float, corr_len: float):
    """S(f) = √π σ² ℓ exp(−π² ℓ² f²) (µm³; module docstring)."""
    f = np.asarray(f, dtype=np.float64)
    return np.sqrt(np.pi) * sigma**2 * corr_len * np.exp(-((np.pi * corr_len * f) ** 2))


def abc_profile_psd(f, sigma: float, B: float, C: float):
    """S(f) = a/(1 + B² f²)^((C+1)/2), a = σ² B Γ((C+1)/2)/(√π Γ(C/2)) (µm³; Löw et al. 2012,
    eq. 7–8)."""
    f = np.asarray(f, dtype=np.float64)
    a = sigma**2 * B * np.exp(gammaln(0.5 * (C + 1.0)) - gammaln(0.5 * C)) / np.sqrt(np.pi)
    return a / (1.0 + (B * f) ** 2) ** (0.5 * (C + 1.0))


@dataclass(frozen=True)
class RandomProfile:
    """One periodic random profile (module docstring): ``spectrum`` "gaussian" (``corr_len`` ℓ)
    or "abc" (``B`` in µm, ``C`` > 0); ``sigma`` σ and ``period`` Λ in µm; ``n`` samples per
    period; ``seed``; ``exact_amplitude`` as ``surfaces.heightfields.gaussian``'s."""

    spectrum: str
    period: float
    sigma: float
    corr_len: float | None = None
    B: float | None = None
    C: float | None = None
    n: int = 64
    seed: int = 0
    exact_amplitude: bool = True

    def __post_init__(self):
        if self.spectrum not in SPECTRA:
            raise UsageError(f"spectrum must be one of {SPECTRA}, got {self.spectrum!r}")
        object.__setattr__(self, "period", positive("period", self.period))
        object.__setattr__(self, "sigma", positive("sigma", self.sigma))
        object.__setattr__(self, "n", integer("n", self.n, 4, 4096, " (samples per period)"))
        object.__setattr__(self, "seed", integer("seed", self.seed, 0))
        if self.spectrum == "gaussian":
            ell = positive("corr_len", self.corr_len)
            object.__setattr__(self, "corr_len", ell)
            if ell < self.period / self.n:
                raise UsageError(
                    f"corr_len = {ell:g} is shorter than the sample step {self.period / self.n:g}"
                )
        else:
            object.__setattr__(self, "B", positive("B", self.B))
            object.__setattr__(self, "C", positive("C", self.C))

    def psd(self, f):
        """The profile spectrum S(f) (µm³)."""
        if self.spectrum == "gaussian":
            return gaussian_profile_psd(f, self.sigma, self.corr_len)
        return abc_profile_psd(f, self.sigma, self.B, self.C)


def random_grating(profile: RandomProfile, material="aluminium") -> SampledGrating:
    """The ``SampledGrating`` of one realisation of ``profile`` on ``material``."""
    dx = profile.period / profile.n
    S, _, _ = psd_grid(profile.psd, (1, profile.n), dx)
    rng = np.random.default_rng(profile.seed)
    h = synthesize(S * dx, dx, rng, profile.exact_amplitude)[0]
    return SampledGrating(profile.period, tuple(h.tolist()), material)
