"""A BRDF at several wavelengths: one microsim BRDF per wavelength — the ``Result`` of a run at
each wavelength's material, or a closed form there — for colour pictures
(``analysis.pictures.appearance_colour``) and the RGL export (``write_rgl``).

``SpectralBRDF(wavelengths_nm, brdfs)``: ``wavelengths_nm`` (L,) increasing, nm; ``brdfs``
one per wavelength, each a callable ``f(wi, wo)`` → (M,) sr⁻¹ (e.g. ``TorranceSparrow(ndf,
masking, ("gold", nm)).f``) or a ``Result`` (evaluated anywhere through
``BRDFTable.from_result``: its simulated bin averages, log-linear between bin centres and
incidences). Called with unit wi, wo (M, 3) it returns every wavelength's value (M, L);
``rgb`` gives their colour (``analytic.colour_matching``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from microsim import checks as _checks
from microsim.analytic import colour_matching
from microsim.errors import UsageError
from microsim.sim.result import Result

from .table import BRDFTable

__all__ = ["SpectralBRDF"]


@dataclass(frozen=True, eq=False)
class SpectralBRDF:
    """``brdfs`` (callables or ``Result``s, module docstring) at ``wavelengths_nm`` (nm,
    increasing, at least 2)."""

    wavelengths_nm: np.ndarray
    brdfs: tuple

    def __post_init__(self):
        nm = colour_matching.check_wavelengths(self.wavelengths_nm)
        brdfs = tuple(self.brdfs) if isinstance(self.brdfs, (list, tuple)) else None
        if brdfs is None or len(brdfs) != len(nm):
            raise UsageError(
                f"brdfs must be a list of one BRDF per wavelength ({len(nm)}), got "
                f"{_checks.short(self.brdfs)}"
            )
        for lam, b in zip(nm, brdfs):
            if not (isinstance(b, Result) or callable(b)):
                raise UsageError(
                    f"brdfs at {lam:g} nm must be a callable f(wi, wo) -> sr⁻¹ or a microsim "
                    f"Result, got {_checks.short(b)}"
                )
        nm.setflags(write=False)
        object.__setattr__(self, "wavelengths_nm", nm)
        object.__setattr__(self, "brdfs", brdfs)

    @functools.cached_property
    def functions(self) -> tuple:
        """Each of ``brdfs`` as a callable f(wi, wo) → (M,): a ``Result`` through its
        ``BRDFTable`` (made on first use; an anisotropic result's is refused there)."""
        return tuple(BRDFTable.from_result(b).f if isinstance(b, Result) else b for b in self.brdfs)

    def __repr__(self) -> str:
        nm = self.wavelengths_nm
        return f"SpectralBRDF({len(nm)} wavelengths {nm[0]:g}-{nm[-1]:g} nm)"

    def __call__(self, wi, wo) -> np.ndarray:
        """f(wi, wo) sr⁻¹ at every wavelength, (M, L), for unit wi, wo (M, 3); a UsageError
        naming the wavelength whose BRDF returns another shape or a value not finite and >= 0."""
        out = np.empty((len(wi), len(self.wavelengths_nm)))
        for k, (lam, f) in enumerate(zip(self.wavelengths_nm, self.functions)):
            v = np.asarray(f(wi, wo), dtype=np.float64)
            if v.shape != (len(wi),):
                raise UsageError(
                    f"brdfs at {lam:g} nm: f(wi, wo) must return shape {(len(wi),)} (one value "
                    f"per direction pair), got {v.shape}"
                )
            if not np.all(np.isfinite(v) & (v >= 0)):
                raise UsageError(f"brdfs at {lam:g} nm: f(wi, wo) must be finite and >= 0")
            out[:, k] = v
        return out

    def rgb(self, wi, wo, illuminant: str = "D65") -> np.ndarray:
        """Linear sRGB (M, 3) of f(wi, wo) under ``illuminant`` (``colour_matching``)."""
        return colour_matching.linear_srgb(self.wavelengths_nm, self(wi, wo), illuminant)
