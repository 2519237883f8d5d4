"""The verdict record: ``Verdict``, the fields of one verdict (``VERDICT_SCHEMA``, each
with what it means; docs/verdicts.md) as a frozen record that is also the read-only dict
verdicts.json holds, and the reader of such dicts (``Verdict.from_json``, checked by
``validate_verdict``). How a verdict is reached is ``analysis.verdicts``."""

from __future__ import annotations

from dataclasses import dataclass
from dataclasses import fields as dataclass_fields
from types import SimpleNamespace
from typing import Iterable, Mapping

import numpy as np

from microsim.errors import UsageError

from .json_record import JsonRecord

__all__ = [
    "VERDICT_SCHEMA",
    "REFERENCES",
    "Verdict",
    "as_verdicts",
    "validate_verdict",
]

_NUM = (int, float)
_OPT_NUM = (int, float, type(None))
_OPT_INT = (int, type(None))

# name → (allowed Python types, description). Floats that cannot be defined (no used bins,
# dof ≤ 0) are null. ``validate_verdict`` checks keys, types and the simple invariants.
VERDICT_SCHEMA: dict = {
    "theta_i": (_NUM, "incidence polar angle θi, degrees"),
    "phi_i": (_NUM, "incidence azimuth φi in the surface frame, degrees"),
    "model": ((str,), "model name"),
    "params": ((dict,), "model parameters (name → JSON value); fitted values for fitted models"),
    "fitted": ((bool,), "True if the parameters were fitted to this simulation"),
    "n_params": ((int,), "number of fitted parameters k (0 unless fitted)"),
    "n_bins": (
        (int,),
        "used bins U: ≥ min_events single-bounce events, finite sim/stderr/model, σ > 0",
    ),
    "min_events": ((int,), "event threshold for a used bin"),
    "chi2": (
        _NUM,
        "Σ_U z², z = (sim − model)/σ, σ² = stderr² + (model_rtol·model)² (decides only for "
        "'ray-noise', 'one-tile' and 'this-tile'; descriptive for 'realisations')",
    ),
    "dof": ((int,), "n_bins − n_params"),
    "chi2_dof": (_OPT_NUM, "chi2/dof (null if dof ≤ 0)"),
    "p_value": (_OPT_NUM, "P(χ²_dof ≥ chi2) (null if dof ≤ 0)"),
    "max_abs_z": (_OPT_NUM, "max_U |z| (null if no used bins)"),
    "rel_rms": (
        _OPT_NUM,
        "energy-weighted relative RMS error over the energy set E (the fewest "
        "used bins, by decreasing sim·Ω, reaching 90% of Σ_U sim·Ω): "
        "√(Σ_E sim·Ω·((sim − model)/sim)² / Σ_E sim·Ω)",
    ),
    "energy_bins": ((int,), "number of bins in the energy set E"),
    "alpha": (_NUM, "family significance level α of the run"),
    "n_tests": ((int,), "number of (incidence, model) verdicts in the family"),
    "alpha_eff": (_NUM, "Šidák(α, n_tests) = 1 − (1 − α)^(1/n_tests) for this verdict"),
    "p_threshold": (_NUM, "the χ² test rejects when p_value < Šidák(alpha_eff, 2)"),
    "z_threshold": (
        _OPT_NUM,
        "the max-|z| test rejects when max_abs_z ≥ this two-sided normal "
        "quantile at Šidák(Šidák(alpha_eff, 2), n_bins)",
    ),
    "model_rtol": (_NUM, "relative quadrature error of the model added to σ in quadrature"),
    "agrees": (
        (bool,),
        "conclusive agreement: 'ray-noise'/'one-tile'/'this-tile': p_value ≥ p_threshold and "
        "max_abs_z < z_threshold; 'realisations': energy_p ≥ p_threshold and max_abs_t < "
        "t_threshold (false if n_bins = 0 or dof ≤ 0): statistically indistinguishable at the "
        "run's precision",
    ),
    "deviations": (
        (list,),
        "[θo_lo, θo_hi] ranges in degrees of bins with |z| > 5 and "
        "|sim − model|/sim > 0.05 at any Δφ, adjacent θo bins merged",
    ),
    "max_rel_dev": (
        _OPT_NUM,
        "signed (sim − model)/sim of largest magnitude over E ∪ deviating bins (null if empty; "
        "negative: the model is too bright there)",
    ),
    "worst_bin": ((list, type(None)), "[θo, Δφ] bin centre (degrees) of max_rel_dev"),
    "reference": (
        (str,),
        "what the tests compare against (module docstring): 'ray-noise' (χ² and max-|z|), "
        "'realisations' (t tests over the R realisations), 'one-tile' (ensemble model, one "
        "realisation: ray-noise tests, and the excess over the tile's departure from its ensemble "
        "where that is computable; a rejection it explains is inconclusive), 'this-tile' "
        "(any model of a measured surface, judged as a model of that tile: ray-noise tests)",
    ),
    "conclusive": (
        (bool,),
        "False only for a 'one-tile' rejection that the tile's departure from its ensemble "
        "explains (or, where the departure is not computable, any 'one-tile' rejection), or "
        "a verdict without a bin or degree of freedom to test (n_bins = 0 or dof ≤ 0)",
    ),
    "realisations": ((int,), "number of realisations R the verdict used (1 unless 'realisations')"),
    "tile_departure": (
        _OPT_NUM,
        "'one-tile' with a computable departure only (else null): energy-weighted relative RMS "
        "√(Σ_E sim·Ω·(δ/model)² / Σ_E sim·Ω) of the tile's departure δ from its ensemble",
    ),
    "departure_max_abs_z": (
        _OPT_NUM,
        "'one-tile' with a computable departure only (else null): max_U of the excess "
        "max(|sim − model| − δ, 0)/σ; with its χ² it decides between 'deviates' and "
        "'inconclusive' against the same thresholds",
    ),
    "energy_dev": (
        _OPT_NUM,
        "relative energy deviation Σ_E Ω (sim − model)/Σ_E Ω model over the model's energy set "
        "(mean over realisations for 'realisations'); null if the set is empty",
    ),
    "energy_dev_se": (
        _OPT_NUM,
        "standard error of energy_dev from the realisations' scatter, s_d/√R, or the "
        "stratified estimate when the realisations are strata of the ensemble "
        "('realisations' only, else null)",
    ),
    "energy_p": (
        _OPT_NUM,
        "two-sided Student-t p-value of energy_dev on realisation_dof dof ('realisations' "
        "only); the energy test rejects when energy_p < p_threshold",
    ),
    "max_abs_t": (_OPT_NUM, "max_U |t_B| over the realisations ('realisations' only)"),
    "t_threshold": (
        _OPT_NUM,
        "two-sided t quantile on realisation_dof dof at Šidák(p_threshold, n_bins): the shape "
        "test rejects when max_abs_t ≥ this ('realisations' only)",
    ),
    "realisation_dof": (
        _OPT_INT,
        "degrees of freedom of the realisations' standard errors: R − 1, or for realisations "
        "drawn one per stratum of the ensemble the collapsed-strata value ('realisations' "
        "only, else null)",
    ),
}

REFERENCES = ("ray-noise", "realisations", "one-tile", "this-tile")


@dataclass(frozen=True, eq=False)
class Verdict(JsonRecord):
    """One verdict (module docstring; every field documented in ``VERDICT_SCHEMA``), read by
    attribute. It is also a read-only dict of the same fields in the same order — what
    verdicts.json holds — so ``v["rel_rms"]``, ``json.dumps(v)`` and ``==`` with its JSON
    form keep working; ``from_json`` reads one back, checked."""

    theta_i: float
    phi_i: float
    model: str
    params: dict
    fitted: bool
    n_params: int
    n_bins: int
    min_events: int
    chi2: float
    dof: int
    chi2_dof: float | None
    p_value: float | None
    max_abs_z: float | None
    rel_rms: float | None
    energy_bins: int
    alpha: float
    n_tests: int
    alpha_eff: float
    p_threshold: float
    z_threshold: float | None
    model_rtol: float
    agrees: bool
    deviations: list
    max_rel_dev: float | None
    worst_bin: list | None
    reference: str
    conclusive: bool
    realisations: int
    energy_dev: float | None
    energy_dev_se: float | None
    energy_p: float | None
    max_abs_t: float | None
    t_threshold: float | None
    tile_departure: float | None
    departure_max_abs_z: float | None
    realisation_dof: int | None

    @property
    def kind(self) -> str:
        """ "agrees", "deviates" or "inconclusive" (``verdict_kind``)."""
        if self.agrees:
            return "agrees"
        return "deviates" if self.conclusive else "inconclusive"

    @classmethod
    def from_json(cls, d: Mapping) -> "Verdict":
        """A verdict read back from verdicts.json, checked (``validate_verdict``); the fields
        an older file lacks read as ``OLDER_DEFAULTS`` (a ray-noise verdict, no realisation
        tests)."""
        if isinstance(d, cls):
            return d
        return cls(**validate_verdict({**cls.OLDER_DEFAULTS, **d}))


_VERDICT_FIELDS = tuple(f.name for f in dataclass_fields(Verdict))


Verdict.OLDER_DEFAULTS = {  # the fields verdicts.json did not always hold, as they were before
    "reference": "ray-noise",
    "conclusive": True,
    "realisations": 1,
    **dict.fromkeys(_VERDICT_FIELDS[_VERDICT_FIELDS.index("energy_dev") :]),
}


def as_verdicts(verdicts: Iterable[Mapping]) -> list[Verdict]:
    """``verdicts`` as ``Verdict`` records (``Verdict.from_json`` for the dicts of a file)."""
    return [Verdict.from_json(v) for v in verdicts]


def validate_verdict(d) -> dict:
    """Check a verdict dict against ``VERDICT_SCHEMA`` (keys, types, invariants); return it.
    Raises ValueError naming the offending key."""
    if not isinstance(d, Mapping):
        raise UsageError(f"verdict must be a dict, got {type(d).__name__}")
    missing = [k for k in VERDICT_SCHEMA if k not in d]
    if missing:
        raise UsageError(f"verdict is missing keys {missing}")
    extra = [k for k in d if k not in VERDICT_SCHEMA]
    if extra:
        raise UsageError(f"verdict has unknown keys {extra}")
    for key, (types, _) in VERDICT_SCHEMA.items():
        v = d[key]
        if isinstance(v, bool) and bool not in types:
            raise UsageError(f"verdict[{key!r}] must be of type {types}, got bool")
        if not isinstance(v, types):
            raise UsageError(f"verdict[{key!r}] must be of type {types}, got {type(v).__name__}")
        if isinstance(v, float) and not np.isfinite(v):
            raise UsageError(f"verdict[{key!r}] must be finite or null, got {v!r}")
    _check_invariants(SimpleNamespace(**d))
    return d


def _check_invariants(v) -> None:
    """The relations between a verdict's fields (``v``: its fields by attribute, types
    checked); a UsageError naming the field that breaks one."""
    if v.n_bins < 0 or v.dof != v.n_bins - v.n_params:
        raise UsageError("verdict's dof must equal n_bins - n_params with n_bins >= 0")
    if v.p_value is not None and not 0.0 <= v.p_value <= 1.0:
        raise UsageError(f"verdict's p_value must lie in [0, 1], got {v.p_value}")
    for r in v.deviations:
        if not (isinstance(r, list) and len(r) == 2 and 0.0 <= r[0] < r[1] <= 90.0):
            raise UsageError(f"verdict's deviations entries must be [lo, hi] in [0, 90], got {r}")
    if v.worst_bin is not None and len(v.worst_bin) != 2:
        raise UsageError("verdict's worst_bin must be [θo, Δφ] or null")
    if v.reference not in REFERENCES:
        raise UsageError(f"verdict's reference must be one of {REFERENCES}, got {v.reference!r}")
    if v.agrees and not v.conclusive:
        raise UsageError("verdict's agrees can be true only for a conclusive verdict")
    if not v.conclusive and v.reference != "one-tile" and v.dof > 0:
        raise UsageError(
            "only a 'one-tile' verdict, or one without a degree of freedom, can be inconclusive"
        )
    if (v.realisations >= 2) != (v.reference == "realisations"):
        raise UsageError("verdict's realisations >= 2 iff reference is 'realisations'")
