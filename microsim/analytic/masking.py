"""Shadowing–masking terms G as objects: ``VGroove()``, ``Smith(ndf, correlated)``, ``NoMasking()``.

The V-groove G (Mikkelsen 2009, eq. 25) lives here; Smith's G comes from the NDF's Λ
(``shadowing``). Each object names the ``shadowing`` string the BRDF functions take (``kind``),
so ``TorranceSparrow(ndf, Smith(correlated=True))`` is ``torrance_sparrow(wi, wo, ndf,
"smith-correlated")``; ``masking_from_kind`` is the one parser of those strings. Conventions as
in ``shadowing``: unit directions (..., 3) pointing away from the surface, n = +z, h the
microfacet normal; G1, G2 dimensionless in [0, 1]. A ``Smith()`` without an NDF is bound to the
microsurface's own NDF by the model that uses it (``TorranceSparrow``); on its own it needs one.

``g2_cosines(wi, wo, cos_h, wih, woh)`` is G2 from precomputed cosines h_z, wi·h, wo·h on
validated unit arrays (the BRDFs and the bin averages call it at their half vectors).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from microsim import checks as _checks
from microsim import vectors
from microsim.errors import UsageError
from microsim.jit import compiled, vector_inlined

__all__ = [
    "Masking",
    "VGroove",
    "Smith",
    "NoMasking",
    "MASKING_CLASSES",
    "SHADOWING_KINDS",
    "masking_from_kind",
    "vgroove_g",
    "vgroove_g1",
    "vgroove_g1_cosines",
    "shadowing_g",
]

SHADOWING_KINDS = ("vgroove", "smith", "smith-correlated", "none")
"""Allowed values of the ``shadowing`` argument (``masking_from_kind``)."""


@runtime_checkable
class Masking(Protocol):
    """A shadowing–masking term: ``kind`` (one of ``SHADOWING_KINDS``), ``g1(w, h)``,
    ``g2(wi, wo, h)`` and ``g2_cosines(wi, wo, cos_h, wih, woh)`` (dimensionless), ``source``
    (paper and equation)."""

    kind: str
    source: str

    def g1(self, w, h): ...

    def g2(self, wi, wo, h): ...

    def g2_cosines(self, wi, wo, cos_h, wih, woh): ...


def _unit_triple(wi, wo, h):
    wi = _checks.directions("wi", wi)
    wo = _checks.directions("wo", wo)
    h = _checks.directions("h", h)
    _checks.broadcast({"wi": wi, "wo": wo, "h": h})
    return wi, wo, h


def _unit_pair(w, h):
    w = _checks.directions("w", w)
    h = _checks.directions("h", h)
    _checks.broadcast({"w": w, "h": h})
    return w, h


@vector_inlined
def vgroove_g1_cosines(cos_w, w_dot_h, cos_h):
    """min(1, 2(n·h)(n·w)/(w·h)) χ⁺(w·h) χ⁺(n·w) from the three cosines n·w, w·h, n·h
    (Mikkelsen 2009, eq. 25), for one direction: the formula of every V-groove G here and in
    the compiled facet sums (``sim.facet_sum_kernels``)."""
    if not (w_dot_h > 0.0 and cos_w > 0.0):
        return 0.0
    return min(max(2.0 * cos_h * cos_w / w_dot_h, 0.0), 1.0)


@compiled
def _vgroove_g1_fill(cos_w, w_dot_h, cos_h, out):
    for i in range(len(out)):
        out[i] = vgroove_g1_cosines(cos_w[i], w_dot_h[i], cos_h[i])


def _vgroove_g1(cos_w, w_dot_h, cos_h):
    """``vgroove_g1_cosines`` of broadcast arrays of the three cosines."""
    args = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (cos_w, w_dot_h, cos_h)))
    out = np.empty(args[0].shape)
    _vgroove_g1_fill(*(np.ascontiguousarray(a).reshape(-1) for a in args), out.reshape(-1))
    return out


@dataclass(frozen=True)
class VGroove:
    """V-groove masking G1 = min(1, 2(n·h)(n·w)/(w·h)) χ⁺(w·h), G2 = min(G1(wi), G1(wo))
    (Mikkelsen 2009, eq. 25; Blinn 1977): ``vgroove_g1`` / ``vgroove_g``."""

    name: ClassVar[str] = "VGroove"
    kind: ClassVar[str] = "vgroove"
    params_doc: ClassVar[str] = "none; g1(w, h), g2(wi, wo, h)"
    source: ClassVar[str] = "Mikkelsen 2009, eq. 25 (Blinn 1977)"
    functions: ClassVar[tuple[str, ...]] = ("vgroove_g", "vgroove_g1")

    def g1(self, w, h):
        w, h = _unit_pair(w, h)
        return _vgroove_g1(w[..., 2], vectors.dot(w, h), h[..., 2])

    def g2(self, wi, wo, h):
        wi, wo, h = _unit_triple(wi, wo, h)
        return self.g2_cosines(wi, wo, h[..., 2], vectors.dot(wi, h), vectors.dot(wo, h))

    def g2_cosines(self, wi, wo, cos_h, wih, woh):
        return np.minimum(_vgroove_g1(wi[..., 2], wih, cos_h), _vgroove_g1(wo[..., 2], woh, cos_h))


@dataclass(frozen=True)
class Smith:
    """Smith masking G1 = χ⁺(w·h)/(1 + Λ(w)) of ``ndf``; G2 separable G1(wi)G1(wo) or, with
    ``correlated``, height-correlated χ⁺χ⁺/(1 + Λ(wi) + Λ(wo)) (Smith 1967; Heitz 2014):
    ``smith_g1`` / ``smith_g2``. ``ndf=None``: the NDF of the model using it. ``lambda_method``:
    how Λ is evaluated, the NDF's ``smith_lambda`` method ("auto"; Beckmann's "walter2007" is
    the rational G1 a renderer such as Mitsuba 3 uses)."""

    ndf: Any = None
    correlated: bool = False
    lambda_method: str = "auto"
    name: ClassVar[str] = "Smith"
    params_doc: ClassVar[str] = (
        "ndf (None: the model's own), correlated=False|True; closed Λ for Beckmann/GGX, "
        "projected-area identity otherwise"
    )
    source: ClassVar[str] = "Smith 1967; Heitz 2014 (separable / height-correlated Smith)"
    functions: ClassVar[tuple[str, ...]] = ("smith_g1", "smith_g2", "smith_lambda")

    def __post_init__(self):
        if not isinstance(self.correlated, (bool, np.bool_)):
            raise UsageError(f"correlated must be True or False, got {self.correlated!r}")
        object.__setattr__(self, "correlated", bool(self.correlated))

    @property
    def kind(self) -> str:
        return "smith-correlated" if self.correlated else "smith"

    def _ndf(self):
        if self.ndf is None:
            raise UsageError("Smith() needs an ndf for g1/g2 on its own: use Smith(ndf, ...)")
        return self.ndf

    def g1(self, w, h):
        return self._ndf().G1(w, h, self.lambda_method)

    def g2(self, wi, wo, h):
        wi, wo, h = _unit_triple(wi, wo, h)
        return self.g2_cosines(wi, wo, h[..., 2], vectors.dot(wi, h), vectors.dot(wo, h))

    def g2_cosines(self, wi, wo, cos_h, wih, woh):
        return self._ndf().smith_g2_dots(wi, wo, wih, woh, self.correlated, self.lambda_method)


@dataclass(frozen=True)
class NoMasking:
    """No shadowing or masking: G1 = χ⁺(w·h), G2 = χ⁺(wi·h) χ⁺(wo·h) (``shadowing="none"``)."""

    name: ClassVar[str] = "NoMasking"
    kind: ClassVar[str] = "none"
    params_doc: ClassVar[str] = "none; only the χ⁺ back-facing conditions"
    source: ClassVar[str] = "Torrance & Sparrow 1967 without G (reference case)"
    functions: ClassVar[tuple[str, ...]] = ("shadowing_g",)

    def g1(self, w, h):
        return self.g2(w, w, h)  # χ⁺(w·h)²

    def g2(self, wi, wo, h):
        wi, wo, h = _unit_triple(wi, wo, h)
        return self.g2_cosines(wi, wo, h[..., 2], vectors.dot(wi, h), vectors.dot(wo, h))

    def g2_cosines(self, wi, wo, cos_h, wih, woh):
        return ((wih > 0.0) & (woh > 0.0)).astype(np.float64)


MASKING_CLASSES = (VGroove, Smith, NoMasking)


def masking_from_kind(kind: str, ndf=None):
    """The masking object of a ``shadowing`` string (``SHADOWING_KINDS``); Smith kinds are
    bound to ``ndf``. The one place a shadowing string is read."""
    if kind not in SHADOWING_KINDS:
        raise UsageError(
            f"shadowing must be one of {', '.join(map(repr, SHADOWING_KINDS))}, got {kind!r}"
        )
    if kind == "vgroove":
        return VGroove()
    if kind == "none":
        return NoMasking()
    return Smith(ndf, correlated=(kind == "smith-correlated"))


# --- the free functions, kept for callers of the string form ----------------------------------
def vgroove_g1(w, h):
    """One-sided V-groove masking min(1, 2(n·h)(n·w)/(w·h)) χ⁺(w·h) (Mikkelsen 2009, eq. 25):
    ``VGroove().g1``."""
    return VGroove().g1(w, h)


def vgroove_g(wi, wo, h):
    """V-groove shadowing–masking min(1, 2(n·h)(n·wo)/(wo·h), 2(n·h)(n·wi)/(wi·h)) with χ⁺
    conditions (Mikkelsen 2009, eq. 25, Blinn 1977); 0 where wi·h ≤ 0 or wo·h ≤ 0:
    ``VGroove().g2``."""
    return VGroove().g2(wi, wo, h)


def shadowing_g(wi, wo, h, ndf, shadowing: str):
    """G(wi, wo, h) of the model named by ``shadowing``: "vgroove" (Mikkelsen 2009, eq. 25),
    "smith" (separable), "smith-correlated" (height-correlated) or "none" (χ⁺(wi·h)χ⁺(wo·h)
    only); ``ndf`` is used by the Smith models only: ``masking_from_kind(shadowing, ndf).g2``
    without the Smith NDF check."""
    masking = masking_from_kind(shadowing, ndf)
    wi, wo, h = _unit_triple(wi, wo, h)
    return masking.g2_cosines(wi, wo, h[..., 2], vectors.dot(wi, h), vectors.dot(wo, h))
