"""Colour of a spectrum: values at a few wavelengths to CIE XYZ and sRGB (colour-science, extra
``materials``: ``pip install 'microsim[materials]'``).

A spectrum v(λ) — a reflectance factor, a BRDF or the radiance it reflects for unit
irradiance — is given at increasing wavelengths λ_1 < … < λ_L (nm). Its colour under an
illuminant S (``ILLUMINANTS``; D65 by default, the white of sRGB):

    X, Y, Z = k Σ_λ v(λ) S(λ) (x̄, ȳ, z̄)(λ),   k = 1 / Σ_λ S(λ) ȳ(λ),

summed over ``GRID_NM`` (380–780 nm every 5 nm, CIE 015:2018 §7.1), x̄ ȳ z̄ the CIE 1931 2°
standard observer. Between the given wavelengths v is interpolated linearly; beyond the first
and the last it is held constant — and refused (a ``UsageError``) where that extrapolated part
would carry more than ``EXTRAPOLATED_LIMIT`` of X, Y or Z's weight (a set of wavelengths
spanning 420–680 nm is enough under D65; one at 450, 550 and 650 nm is not). The whole map is
linear: ``xyz_weights`` gives its (L, 3) matrix, so that ``xyz(v) = v @ xyz_weights``.
Normalisation: the perfect reflector (v = 1 at every wavelength) has Y = 1, its XYZ being the
illuminant's white point. Linear sRGB (IEC 61966-2-1): XYZ times the standard's matrix, no
chromatic adaptation — under D65 a flat spectrum v = c gives R = G = B = c (to 1e-4: the
standard's matrix is rounded to four digits), under illuminant A it looks orange, as an
incandescent light does in a photograph balanced for daylight. Unclipped: a colour outside the
sRGB gamut has a component below 0 or above 1. ``srgb_encode``: the standard's display curve.
"""

from __future__ import annotations

import functools

import numpy as np

from microsim.errors import EnvironmentFailure, UsageError

__all__ = [
    "OBSERVER",
    "ILLUMINANTS",
    "GRID_NM",
    "EXTRAPOLATED_LIMIT",
    "check_wavelengths",
    "xyz_weights",
    "xyz",
    "linear_srgb",
    "srgb_encode",
]

EXTRA = "pip install 'microsim[materials]'"

OBSERVER = "CIE 1931 2 Degree Standard Observer"
"""The colour-matching functions (colour-science's name)."""
ILLUMINANTS = ("D65", "A", "E")
"""Illuminants ``xyz`` accepts: CIE D65 (daylight, the white of sRGB), CIE A (incandescent,
2856 K) and E (equal energy)."""
GRID_NM = np.arange(380.0, 781.0, 5.0)
"""Wavelengths (nm) of the sum: the CIE tables' 5 nm steps over the visible."""
EXTRAPOLATED_LIMIT = 0.05
"""Largest share of X's, Y's or Z's weight (S x̄, S ȳ, S z̄ summed) that may lie beyond the given
wavelengths, where the spectrum is held constant."""


def _colour():
    try:
        import colour
    except ImportError:
        raise EnvironmentFailure(
            f"colour matching needs colour-science, an optional extra: {EXTRA}"
        ) from None
    return colour


@functools.cache
def _grid_weights(illuminant: str) -> np.ndarray:
    """(len(GRID_NM), 3): k S(λ) (x̄, ȳ, z̄)(λ) on ``GRID_NM``, the ȳ column summing to 1."""
    colour = _colour()
    shape = colour.SpectralShape(GRID_NM[0], GRID_NM[-1], GRID_NM[1] - GRID_NM[0])
    cmfs = colour.MSDS_CMFS[OBSERVER].copy().align(shape).values
    light = colour.SDS_ILLUMINANTS[illuminant].copy().align(shape).values
    w = light[:, None] * cmfs
    w = w / w[:, 1].sum()
    w.setflags(write=False)
    return w


def check_wavelengths(wavelengths_nm) -> np.ndarray:
    """``wavelengths_nm`` as float64 (L,), or a UsageError unless they are at least 2 finite
    increasing wavelengths > 0 (nm)."""
    a = np.asarray(wavelengths_nm)
    nm = a.astype(np.float64).ravel() if a.dtype.kind in "iuf" and a.ndim == 1 else None
    if nm is None or nm.size < 2 or not np.all(np.isfinite(nm) & (nm > 0)):
        raise UsageError(
            f"wavelengths_nm must be at least 2 finite wavelengths in nm > 0 (a 1-D array), "
            f"got {wavelengths_nm!r}"
        )
    if np.any(np.diff(nm) <= 0):
        raise UsageError(f"wavelengths_nm must be increasing, got {nm.tolist()}")
    return nm


def xyz_weights(wavelengths_nm, illuminant: str = "D65") -> np.ndarray:
    """(L, 3): the CIE XYZ of a spectrum given at ``wavelengths_nm`` (L increasing, nm) is
    ``values @ xyz_weights`` (module docstring: linear between them, constant beyond,
    normalised so the perfect reflector has Y = 1). A UsageError if ``illuminant`` is not one of
    ``ILLUMINANTS`` or the wavelengths leave more than ``EXTRAPOLATED_LIMIT`` of X, Y or Z to
    extrapolation."""
    if illuminant not in ILLUMINANTS:
        raise UsageError(f"illuminant must be one of {ILLUMINANTS}, got {illuminant!r}")
    nm = check_wavelengths(wavelengths_nm)
    grid = _grid_weights(illuminant)
    beyond = (GRID_NM < nm[0]) | (GRID_NM > nm[-1])
    share = grid[beyond].sum(axis=0) / grid.sum(axis=0)
    if np.any(share > EXTRAPOLATED_LIMIT):
        worst = "XYZ"[int(np.argmax(share))]
        raise UsageError(
            f"wavelengths_nm ({nm[0]:g}-{nm[-1]:g} nm) must cover the visible: beyond them "
            f"{100 * share.max():.0f} % of {worst}'s weight under {illuminant} would be "
            f"extrapolated (at most {100 * EXTRAPOLATED_LIMIT:g} %; e.g. 420-680 nm)"
        )
    # the hat function of each given wavelength on the grid: linear interpolation's weights
    hats = np.stack([np.interp(GRID_NM, nm, e) for e in np.eye(len(nm))])
    return hats @ grid


def _values(values, n: int) -> np.ndarray:
    v = np.asarray(values, dtype=np.float64)
    if v.ndim == 0 or v.shape[-1] != n:
        raise UsageError(
            f"values must have the wavelengths on their last axis ({n}), got shape {v.shape}"
        )
    if not np.all(np.isfinite(v)):
        raise UsageError("values must be finite")
    return v


def xyz(wavelengths_nm, values, illuminant: str = "D65") -> np.ndarray:
    """CIE XYZ (..., 3) of spectra ``values`` (..., L) given at ``wavelengths_nm`` (L,) nm, lit
    by ``illuminant`` (module docstring; the perfect reflector has Y = 1)."""
    w = xyz_weights(wavelengths_nm, illuminant)
    return _values(values, len(w)) @ w


def linear_srgb(wavelengths_nm, values, illuminant: str = "D65") -> np.ndarray:
    """Linear sRGB (..., 3) of spectra ``values`` (..., L) at ``wavelengths_nm`` (L,) nm lit by
    ``illuminant`` (IEC 61966-2-1's matrix on ``xyz``, no chromatic adaptation, unclipped)."""
    w = xyz_weights(wavelengths_nm, illuminant)
    return _values(values, len(w)) @ (w @ _xyz_to_srgb().T)


@functools.cache
def _xyz_to_srgb() -> np.ndarray:
    m = np.array(_colour().RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, dtype=np.float64)
    m.setflags(write=False)
    return m


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """The sRGB display curve (IEC 61966-2-1) of linear values ``x`` in [0, 1]."""
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
