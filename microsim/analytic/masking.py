"""Shadowing–masking terms as objects: ``VGroove()``, ``Smith(ndf, correlated)``, ``NoMasking()``.

Each wraps the functions of ``shadowing`` (no physics of its own) and names the ``shadowing``
string the BRDF functions take (``kind``), so ``TorranceSparrow(ndf, Smith(correlated=True))``
is ``torrance_sparrow(wi, wo, ndf, "smith-correlated")``. Conventions as in ``shadowing``:
unit directions (..., 3) pointing away from the surface, n = +z, h the microfacet normal;
G1, G2 dimensionless in [0, 1]. A ``Smith()`` without an NDF is bound to the microsurface's
own NDF by the model that uses it (``TorranceSparrow``); on its own it needs one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from microsim.errors import UsageError

from .shadowing import SHADOWING_KINDS, shadowing_g, smith_g1, smith_g2, vgroove_g, vgroove_g1

__all__ = ["Masking", "VGroove", "Smith", "NoMasking", "MASKING_CLASSES", "masking_from_kind"]


@runtime_checkable
class Masking(Protocol):
    """A shadowing–masking term: ``kind`` (one of ``SHADOWING_KINDS``), ``g1(w, h)`` and
    ``g2(wi, wo, h)`` (dimensionless), ``source`` (paper and equation)."""

    kind: str
    source: str

    def g1(self, w, h): ...

    def g2(self, wi, wo, h): ...


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
        return vgroove_g1(w, h)

    def g2(self, wi, wo, h):
        return vgroove_g(wi, wo, h)


@dataclass(frozen=True)
class Smith:
    """Smith masking G1 = χ⁺(w·h)/(1 + Λ(w)) of ``ndf``; G2 separable G1(wi)G1(wo) or, with
    ``correlated``, height-correlated χ⁺χ⁺/(1 + Λ(wi) + Λ(wo)) (Smith 1967; Heitz 2014):
    ``smith_g1`` / ``smith_g2``. ``ndf=None``: the NDF of the model using it."""

    ndf: Any = None
    correlated: bool = False
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
        return smith_g1(w, h, self._ndf())

    def g2(self, wi, wo, h):
        return smith_g2(wi, wo, h, self._ndf(), correlated=self.correlated)


@dataclass(frozen=True)
class NoMasking:
    """No shadowing or masking: G1 = χ⁺(w·h), G2 = χ⁺(wi·h) χ⁺(wo·h) (``shadowing="none"``)."""

    name: ClassVar[str] = "NoMasking"
    kind: ClassVar[str] = "none"
    params_doc: ClassVar[str] = "none; only the χ⁺ back-facing conditions"
    source: ClassVar[str] = "Torrance & Sparrow 1967 without G (reference case)"
    functions: ClassVar[tuple[str, ...]] = ("shadowing_g",)

    def g1(self, w, h):
        return shadowing_g(w, w, h, None, "none")  # χ⁺(w·h)²

    def g2(self, wi, wo, h):
        return shadowing_g(wi, wo, h, None, "none")


MASKING_CLASSES = (VGroove, Smith, NoMasking)


def masking_from_kind(kind: str, ndf=None):
    """The masking object of a ``shadowing`` string (``SHADOWING_KINDS``)."""
    if kind not in SHADOWING_KINDS:
        raise UsageError(
            f"shadowing must be one of {', '.join(map(repr, SHADOWING_KINDS))}, got {kind!r}"
        )
    if kind == "vgroove":
        return VGroove()
    if kind == "none":
        return NoMasking()
    return Smith(ndf, correlated=(kind == "smith-correlated"))
