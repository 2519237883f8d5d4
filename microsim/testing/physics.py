"""The physics' own error: how far microsim's own single-scattering Smith model is from a
reference surface, so that a failing BRDF can be told apart from a failing physics model.

A BRDF of the surface's distribution is at best Torrance–Sparrow with that D and Smith's
masking (Mikkelsen 2009, eq. 13; height-correlated G2, Heitz 2014). On a surface where
Smith's masking or single scattering does not hold at some incidence, a *correct* BRDF fails
there too. ``PHYSICS_MODEL`` — that closed form with the reference's ensemble NDF — is judged
against the same reference by the same verdict machinery as the BRDF under test
(``agreement.physics_error``); a ``PhysicsError`` record holds its result at one incidence,
and ``physics_lines`` words it for a failure message. ``PHYSICS_REFERENCES`` names, per
distribution, the catalogue scenes to check a BRDF of that distribution against.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping

from microsim.analysis.json_record import JsonRecord
from microsim.analysis.verdict_record import Verdict
from microsim.analytic.models import TorranceSparrow
from microsim.sim.predict import Predictor
from microsim.sim.result import FrozenDict

__all__ = ["PHYSICS_MODEL", "PHYSICS_REFERENCES", "PhysicsError", "physics_model", "physics_lines"]

PHYSICS_MODEL = "ts-smith-corr"
"""The physics model's name, as in the catalogue (``microsim.sim.compare.default_models``)."""

PHYSICS_REFERENCES = MappingProxyType(
    {
        "beckmann": ("gaussian-m0.3",),
        "ggx": ("ggx-transform-0.3", "ggx-mixture-0.3"),
        "student-t": ("student-t-3-0.3",),
    }
)
"""Distribution name → the catalogue scenes (``microsim/scenes/``) to check a BRDF of it against
(docs/testing.md, "Which reference for which BRDF")."""


@dataclass(frozen=True, eq=False)
class PhysicsError(JsonRecord):
    """The physics model at one incidence, judged against the reference as the BRDF is:
    ``model`` (``PHYSICS_MODEL``) with the ensemble NDF ``ndf`` (its repr); ``holds`` — it
    passes the check the BRDF must pass (statistical: its verdict does not deviate;
    tolerance: within ``rtol``) —, ``result`` its word (agrees, deviates, inconclusive; in
    tolerance mode "within/beyond rtol = …"); ``energy_dev`` Σ Ω (reference − model)/Σ Ω
    model over the model's 90 % energy bins (the verdict's) ± ``energy_se`` (the
    realisations' scatter, else the reference's ray noise), ``rel_rms`` the verdict's
    energy-weighted relative RMS error; ``verdict`` the whole verdict, ``tolerance`` in rtol
    mode the ``agreement.tolerance_check`` (a read-only dict; else None);
    ``brdf_energy_ratio`` Σ Ω⊥ brdf / Σ Ω⊥ model over the hemisphere when a BRDF was judged
    (None from ``physics_error``)."""

    theta_i: float
    phi_i: float
    model: str
    ndf: str
    holds: bool
    result: str
    energy_dev: float | None
    energy_se: float | None
    rel_rms: float | None
    verdict: Verdict
    tolerance: Mapping | None = None
    brdf_energy_ratio: float | None = None

    def __post_init__(self) -> None:
        if self.tolerance is not None:
            object.__setattr__(self, "tolerance", FrozenDict(self.tolerance))
        super().__post_init__()

    _nested = {"verdict": Verdict}


def physics_model(ensemble_ndf, material) -> Predictor | None:
    """``PHYSICS_MODEL`` for a surface of ``ensemble_ndf`` in ``material``: Torrance–Sparrow
    with that D and height-correlated Smith G; None without an ensemble NDF."""
    if ensemble_ndf is None:
        return None
    return Predictor(PHYSICS_MODEL, TorranceSparrow(ensemble_ndf, "smith-correlated", material))


def _percent(x) -> str:
    return "–" if x is None else f"{100 * x:+.2f}%"


def physics_lines(records, at) -> list[str]:
    """The failure message's lines on the physics' own error: what the physics model is, then
    per record (one per failing incidence; ``at(record)`` its incidence label) its deviation
    and verdict, the brdf's energy relative to it and what the user can conclude."""
    if not records:
        return []
    r0 = records[0]
    lines = [
        f"Smith's own error: {r0.model} = Torrance–Sparrow with the surface's ensemble NDF "
        f"D = {r0.ndf} and height-correlated Smith G (Mikkelsen 2009, eq. 13; Heitz 2014), "
        "judged against the same reference in the same way as the brdf"
    ]
    for r in records:
        se = "" if r.energy_se is None else f" ± {100 * r.energy_se:.2f}%"
        rel = "–" if r.rel_rms is None else f"{r.rel_rms:.2%}"
        ratio = "–" if r.brdf_energy_ratio is None else f"{r.brdf_energy_ratio:.3f}×"
        if r.holds:
            why = "Smith holds here, so the deviation is the brdf's"
        else:
            why = (
                f"a correct {r.ndf} with Smith's G cannot pass here: the deviation is the "
                "physics' (Smith's masking / single scattering), not necessarily the brdf's"
            )
        lines += [
            f"at {at(r)}: Smith's own error here: {r.model} deviates from the reference by "
            f"{_percent(r.energy_dev)}{se} (rel err {rel}) — its verdict {r.result}",
            f"  brdf/{r.model} energy ratio {ratio}; {why}",
        ]
    return lines
