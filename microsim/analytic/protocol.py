"""The model protocol of the closed-form BRDFs (``models``): ``BRDFModel`` (``f(wi, wo)``,
``params()``, ``source``), ``SampleableBRDF`` (adds ``sample`` and ``pdf``), the sample record
``BRDFSample`` and ``ModelBase``, the parts every model class shares. The conventions are in
the ``models`` module docstring.
"""

from __future__ import annotations

from dataclasses import fields
from typing import ClassVar, NamedTuple, Protocol, runtime_checkable

import numpy as np

__all__ = ["BRDFModel", "SampleableBRDF", "BRDFSample", "ModelBase"]


@runtime_checkable
class BRDFModel(Protocol):
    """A closed-form BRDF: ``f(wi, wo)`` (sr⁻¹), ``params()`` and ``source``."""

    source: str

    def f(self, wi, wo): ...

    def params(self) -> dict: ...


@runtime_checkable
class SampleableBRDF(BRDFModel, Protocol):
    """A ``BRDFModel`` with an importance sampler: ``sample(wo, u1, u2)`` → (wi, pdf, ...) and
    its density ``pdf(wi, wo)`` (sr⁻¹, whole sphere of wi)."""

    def sample(self, wo, u1, u2): ...

    def pdf(self, wi, wo): ...


class BRDFSample(NamedTuple):
    """A sampled incident direction ``wi`` (..., 3) and its solid-angle density ``pdf`` (sr⁻¹)."""

    wi: np.ndarray
    pdf: np.ndarray


_N = np.array([0.0, 0.0, 1.0])


class ModelBase:
    """Shared parts: ``params()`` from the dataclass fields, the construction check."""

    name: ClassVar[str]
    params_doc: ClassVar[str]
    source: ClassVar[str]
    functions: ClassVar[tuple[str, ...]]
    symmetric: ClassVar[bool] = True

    def params(self) -> dict:
        """The model's parameters, name → value (its dataclass fields)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def __post_init__(self):
        self.f(_N, _N)  # one evaluation validates the parameters
