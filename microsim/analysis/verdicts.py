"""Verdicts: is a closed-form model statistically indistinguishable from the simulation?

One verdict compares, for ONE incidence θi and ONE model, the simulated bin averages f̄_B
(sr⁻¹, ``Result.brdf[t]``) with the model's bin averages m_B over the (θo, Δφ) bins
(docs/design.md, "Verdicts"). Sign convention, as in every output: simulation minus model
(z, max_rel_dev, energy_dev are negative where the model is too bright). Definitions (all
documented again in ``VERDICT_SCHEMA``):

* Used bins U: ≥ ``min_events`` single-bounce events, and sim, stderr, model finite, σ_B > 0.
* σ_B² = se_B² + (model_rtol · m_B)²: the simulation's standard error and, in quadrature, the
  model's own quadrature error (``predict.bin_average`` converges to relative ``rtol``).
  z_B = (f̄_B − m_B)/σ_B; where se_B comes with finite degrees of freedom ν_B (``Measured.dof``,
  ``sim.tallies.stderr_dof``: a paired-strata error has as many as the bin's discordant
  pairs) z_B is Student t on ν_B (σ/se)⁴ dof (Satterthwaite) and is replaced by the normal
  deviate of the same two-sided p, so that both tests below keep their level.
* χ² = Σ_U z², dof = |U| − k (k = number of fitted parameters, 0 for a prescribed model),
  p = P(χ²_dof ≥ χ²).
* Agreement is a family of two tests per (incidence, model): the χ² test and the max-|z| test
  (two-sided, Šidák over the |U| bins). With α_eff = Šidák(α, n_tests) for the whole run, each
  of the two is run at Šidák(α_eff, 2), so that under the null hypothesis "model = truth" the
  verdict says "deviates" with probability ≤ α_eff (exactly α_eff for independent tests).
* rel_rms over the energy set E ⊂ U: the fewest used bins, taken in order of decreasing
  f̄_B Ω_B, whose Σ f̄ Ω reaches 90 % of Σ_U f̄ Ω; energy-weighted:
  rel_rms = √(Σ_E f̄Ω ((f̄ − m)/f̄)² / Σ_E f̄Ω). For m = f̄(1 + ε) it is |ε| exactly.
* deviations: θo ranges of bins with |z| > 5 and |f̄ − m|/f̄ > 5 % (any Δφ), adjacent θo bins
  merged. max_rel_dev: the signed (f̄ − m)/f̄ of largest magnitude over E ∪ deviating bins
  (noisy far-tail bins of a model that agrees there are not reported as "worst").

Limitation: bins are selected by the *simulation's* event count, so a model predicting a lobe
where the simulation has (almost) no events is not tested there.

Reference of the test (``reference``), by what the model describes:

* ``"ray-noise"``: a model of the traced facets themselves (``ts-facets``, listed in
  ``info.realisation_models``) or a standalone ``verdict`` call: f̄ differs from m by ray
  noise only, the χ² and max-|z| tests above are exact. Always ``conclusive``.
* ``"realisations"``: a model of the *ensemble* (nominal/realised Beckmann, V-groove closed
  forms, fitted models) with R ≥ 2 realisations f_r (``Result.brdf_realisations``). Each tile
  is one draw of the random surface, and its BRDF mean f_r (ray noise included) is an i.i.d.
  draw around the ensemble BRDF; the bins of one tile are strongly correlated (a tile's lobe is
  wider or narrower as a whole), so a χ² over bins with a per-bin variance from R tiles (R − 1
  dof) is anti-conservative. The two tests of the family are instead, each at
  Šidák(alpha_eff, 2):
    - energy: d_r = Σ_E Ω (f_r − m) / Σ_E Ω m over the *model's* energy set E (chosen from m,
      not from the data, so the d_r stay i.i.d.): Student's t = d̄ / √(s_d²/R + rtol²) on R − 1
      dof (one number per tile absorbs every correlation between bins);
    - shape: per bin t_B = (f̄_B − m_B)/√(s_B²/R + (rtol m_B)²) with s_B the realisations'
      standard deviation, max_U |t_B| against the two-sided t_{R−1} quantile at
      Šidák(·, |U|) (conservative for positively correlated bins).
  Fitted models are judged the same way (their fit pulls m towards f̄: conservative).
  Always ``conclusive``; with R = 2 the t_1 quantiles are wide and the power is low.
* ``"one-tile"``: an ensemble model and one realisation. The ray-noise tests are run; their
  agreement is conclusive (the model is within ray noise of a tile). A rejection alone cannot
  separate the tile's departure from its ensemble from a model error. Where that departure is
  computable without rays (``tile_departure``: V-grooves, whose exact G is a function of the
  facets alone, so TS with the tile's facets and with the ensemble NDF, both with the V-groove
  G, differ by the tile's NDF quantisation only), each bin's deviation is discounted by it:
  the excess e_B = max(|f̄_B − m_B| − δ_B, 0)/σ_B goes through the same χ² and max-|z| tests.
  Under "model = ensemble" |f̄ − m| ≤ |noise| + δ, so e_B ≤ |z_B of the noise| and both
  tests keep at most their nominal false-alarm rate (tests/test_calibration.py measures it).
  A rejection of the excess is a resolved model error ("deviates"); a rejection of the plain
  tests only is ``conclusive`` = False, ``agrees`` = False ("inconclusive"), reported with
  the model's rel_rms and the departure's (``tile_departure``). Without a computable departure
  (heightfields: a tile's masking also departs from the ensemble's) a rejection is always
  inconclusive.

* ``"this-tile"``: every model on a *measured* surface (``judged_as_tile``: a surface read
  from a file, ``kind = "file"``). The traced tile is then not a draw of an ensemble but the
  object of study: the question is which model describes *this* surface and by how much each
  misses it. Its models are built from the tile itself (Beckmann at the tile's realised rms
  slope, its own facets, fits to its BRDF), so f̄ differs from a model that describes the
  tile by ray noise only: the χ² and max-|z| tests above decide, and agreement and deviation
  are both ``conclusive`` (the same tests, and false-alarm rate, as ``"ray-noise"``).

Whatever the reference, a verdict without a bin to test (none holds ``min_events`` events, or
no degree of freedom is left after the fitted parameters: dof ≤ 0) is inconclusive: there is
no evidence either way (a lobe too narrow, or light too faint, for the rays traced).

``agrees`` is True only for a conclusive agreement; a verdict "deviates" iff ``conclusive`` and
not ``agrees``. The false-alarm rate and power are measured in tests/test_calibration.py.
"""

from __future__ import annotations

from typing import Iterable, Mapping, NamedTuple

import numpy as np

from microsim import checks as _checks
from microsim.analysis import incidence
from microsim.analysis.markdown import percent
from microsim.analysis.verdict_record import (
    VERDICT_SCHEMA,
    Verdict,
    as_verdicts,
    validate_verdict,
)
from microsim.errors import UsageError
from microsim.sim.tallies import stderr_dof
from microsim.stats import (
    ENERGY_FRACTION,
    MIN_EVENTS,
    chi2_sf,
    energy_set,
    norm_isf,
    sidak,
    stratified_mean,
    t_isf,
    t_sf,
)

__all__ = [
    "VERDICT_SCHEMA",
    "Verdict",
    "as_verdicts",
    "verdict",
    "Measured",
    "Prediction",
    "realisation_strata",
    "realisations_at",
    "Significance",
    "verdict_kind",
    "verdict_symbol",
    "inconclusive_reason",
    "verdicts_for_result",
    "VerdictList",
    "tile_departure",
    "departure_of",
    "judged_as_tile",
    "MEASURED_KINDS",
    "validate_verdict",
    "summary_row",
    "sidak",
    "energy_set",
    "Z_DEVIATION",
    "REL_DEVIATION",
    "ENERGY_FRACTION",
]

Z_DEVIATION = 5.0  # |z| beyond which a bin counts as a deviation ...
REL_DEVIATION = 0.05  # ... if its relative error also exceeds this


def _merge_ranges(flag_theta: np.ndarray, theta_edges: np.ndarray) -> list[list[float]]:
    """[lo, hi] degree ranges of runs of True in ``flag_theta`` (one per θo bin)."""
    out, start = [], None
    for i, f in enumerate(list(flag_theta) + [False]):
        if f and start is None:
            start = i
        elif not f and start is not None:
            out.append([float(theta_edges[start]), float(theta_edges[i])])
            start = None
    return out


def _opt(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


class Measured(NamedTuple):
    """One incidence's measured bin-averaged BRDF, by any method (ray tracer, Kirchhoff
    solver): ``brdf`` f̄ and ``stderr`` (Θ, Φ) sr⁻¹, ``counts`` (Θ, Φ) events per bin,
    ``omega`` (Θ, Φ) projected solid angles sr, ``theta_edges`` (Θ+1,) and ``phi_edges``
    (Φ+1,, None: the folded grid of ``Bins``) degrees; ``realisations`` (R, Θ, Φ) the BRDFs of
    R tiles of equal rays (sr⁻¹, their mean is ``brdf``) or None; ``theta_i``, ``phi_i``
    degrees; ``dof`` (Θ, Φ) the degrees of freedom of ``stderr`` (``sim.tallies.stderr_dof``)
    or None: exact; ``strata`` (R,) the stratum of each realisation when they were drawn one
    per stratum of the ensemble (``realisation_strata``), else None (i.i.d.); ``object_tile``:
    the traced tile is itself the object of study (a measured surface, ``judged_as_tile``):
    every model is judged as a model of it, against ray noise (reference "this-tile")."""

    brdf: np.ndarray
    stderr: np.ndarray
    counts: np.ndarray
    omega: np.ndarray
    theta_edges: np.ndarray
    phi_edges: np.ndarray | None = None
    realisations: np.ndarray | None = None
    theta_i: float = 0.0
    phi_i: float = 0.0
    dof: np.ndarray | None = None
    strata: np.ndarray | None = None
    object_tile: bool = False

    @classmethod
    def of(cls, result, t: int, **replace) -> "Measured":
        """Incidence ``t`` of a ``Result`` (``replace``: fields to take from elsewhere, e.g.
        another ``stderr``); ``object_tile`` when it traced a measured surface
        (``judged_as_tile``)."""
        fields = {
            "brdf": result.brdf[t],
            "stderr": result.stderr[t],
            "counts": result.counts[t],
            "omega": result.bins.projected_solid_angle(),
            "theta_edges": result.theta_edges,
            "phi_edges": result.phi_edges,
            "theta_i": float(result.theta_i[t]),
            "phi_i": float(result.phi_i[t]),
            "object_tile": judged_as_tile(result),
        }
        return cls(**{**fields, **replace})


class Prediction(NamedTuple):
    """The model's side of a verdict: ``values`` m (Θ, Φ) sr⁻¹ on the same bins, ``name``,
    ``params`` (name → value, recorded), ``fitted`` with ``n_params`` fitted parameters (they
    reduce the dof); ``ensemble``: the model describes the random surface's ensemble, not the
    traced facets (then realisations, or one tile's ``departure`` (Θ, Φ) sr⁻¹ ≥ 0 from its
    ensemble, ``tile_departure``, choose the reference; module docstring)."""

    values: np.ndarray
    name: str = "model"
    params: Mapping | None = None
    fitted: bool = False
    n_params: int = 0
    ensemble: bool = False
    departure: np.ndarray | None = None


class Significance(NamedTuple):
    """How a verdict tests: ``model_rtol`` the model's own relative quadrature error (added
    to σ in quadrature), ``min_events`` per used bin, ``alpha`` the false-alarm rate of the
    whole family of ``n_tests`` verdicts (Šidák)."""

    model_rtol: float = 1e-3
    min_events: int = MIN_EVENTS
    alpha: float = 0.01
    n_tests: int = 1


_TEST_FIELDS = (
    "energy_dev_se",
    "energy_p",
    "max_abs_t",
    "t_threshold",
    "tile_departure",
    "departure_max_abs_z",
    "realisation_dof",
)
"""The fields of the realisation and tile-departure tests: null for a verdict without them."""


def verdict(
    measured: Measured, prediction: Prediction, significance: Significance = Significance()
) -> Verdict:
    """Verdict of one model at one incidence (module docstring; fields in ``VERDICT_SCHEMA``):
    ``prediction`` against ``measured``, tested as ``significance`` says."""
    m, p = measured, prediction
    model_rtol, min_events, alpha, n_tests = significance
    theta_edges, theta_i = m.theta_edges, m.theta_i
    name, params, fitted, n_params, ensemble = p.name, p.params, p.fitted, p.n_params, p.ensemble
    a = _inputs_of(m, p, significance)
    alpha_eff = sidak(alpha, n_tests)
    alpha_each = sidak(alpha_eff, 2)
    used, sigma = _used_bins(a, model_rtol, min_events)
    n_bins = int(used.sum())
    dof = n_bins - int(n_params)
    z_thr = float(norm_isf(0.5 * sidak(alpha_each, n_bins))) if n_bins else None
    normal = _normal_equivalent(a, sigma)
    ray = _noise_tests(a.sim - a.mod, sigma, used, dof, alpha_each, z_thr, normal)
    Em = energy_set(np.where(used, a.mod * a.om, 0.0)).reshape(a.shape)
    energy = np.where(used, a.sim * a.om, 0.0)
    E = energy_set(energy).reshape(a.shape)
    out = {"energy_dev": _energy_dev(a.sim, a.mod, a.om, Em), **dict.fromkeys(_TEST_FIELDS)}
    z_dev = ray.z
    if m.object_tile:
        reference, n_real = "this-tile", 1
        agrees, conclusive = ray.ok, True
    elif a.F is not None:
        reference, n_real = "realisations", len(a.F)
        agrees, tests = _realisation_tests(a, used, Em, dof, model_rtol, alpha_each)
        out.update(tests)
        conclusive = True
    elif ensemble:
        reference, n_real = "one-tile", 1
        agrees, conclusive = ray.ok, ray.ok
        if a.dep is not None:
            excess = np.maximum(np.abs(a.sim - a.mod) - a.dep, 0.0)
            tile = _noise_tests(excess, sigma, used, dof, alpha_each, z_thr, normal)
            z_dev = tile.z
            out.update(
                tile_departure=_weighted_rms(energy, a.dep / np.where(used, a.mod, 1.0), E),
                departure_max_abs_z=tile.max_abs_z,
            )
            conclusive = ray.ok or not tile.ok
    else:
        reference, n_real = "ray-noise", 1
        agrees, conclusive = ray.ok, True
    if dof <= 0:  # no bin (or no degree of freedom) to test: no evidence either way
        agrees, conclusive = False, False
    rel = np.where(used, (a.sim - a.mod) / np.where(used, a.sim, 1.0), 0.0)
    dev = used & (np.abs(z_dev) > Z_DEVIATION) & (np.abs(rel) > REL_DEVIATION)
    max_rel_dev, worst = _worst_bin(rel, E | dev, theta_edges, a.phi_edges)
    return Verdict(
        theta_i=float(theta_i),
        phi_i=float(m.phi_i),
        model=str(name),
        params=_jsonable_params(params),
        fitted=bool(fitted),
        n_params=int(n_params),
        n_bins=n_bins,
        min_events=int(min_events),
        chi2=ray.chi2,
        dof=int(dof),
        chi2_dof=ray.chi2 / dof if dof > 0 else None,
        p_value=ray.p_value,
        max_abs_z=ray.max_abs_z,
        rel_rms=_weighted_rms(energy, rel, E),
        energy_bins=int(E.sum()),
        alpha=float(alpha),
        n_tests=int(n_tests),
        alpha_eff=alpha_eff,
        p_threshold=alpha_each,
        z_threshold=z_thr,
        model_rtol=float(model_rtol),
        agrees=bool(agrees),
        deviations=_merge_ranges(dev.any(axis=1), theta_edges),
        max_rel_dev=max_rel_dev,
        worst_bin=worst,
        reference=reference,
        conclusive=bool(conclusive),
        realisations=int(n_real),
        **out,
    )


class _Inputs(NamedTuple):
    """The arrays of one verdict, float64 and shape-checked (``_inputs_of``): sim, se,
    counts, model, Ω (Θ, Φ); the φ edges; the R ≥ 2 realisations F (R, Θ, Φ) or None; the
    tile's departure δ (Θ, Φ, sr⁻¹) or None; se_t = √(s_B²/R + (rtol·m)²) with F, else None
    (with ``strata``, the stratified variance of the mean, ``stats.stratified_mean``, in place
    of s_B²/R); ``real_dof`` the degrees of freedom of that variance (R − 1, or stratified)."""

    sim: np.ndarray
    se: np.ndarray
    cnt: np.ndarray
    mod: np.ndarray
    om: np.ndarray
    phi_edges: np.ndarray
    F: np.ndarray | None
    dep: np.ndarray | None
    se_t: np.ndarray | None
    nu: np.ndarray | None
    strata: np.ndarray | None = None
    real_dof: int | None = None

    @property
    def shape(self) -> tuple:
        return self.sim.shape


def _inputs_of(m: Measured, p: Prediction, s: Significance) -> _Inputs:
    """The arrays of one verdict from its three argument groups, converted and checked:
    one-line UsageErrors naming the argument. On a measured surface (``object_tile``) no model
    is an ensemble's: realisations and departure are not used."""
    ensemble = p.ensemble and not m.object_tile
    model_rtol, min_events, n_params = s.model_rtol, s.min_events, p.n_params
    sim, se, cnt, mod, om = (
        np.asarray(x, dtype=np.float64) for x in (m.brdf, m.stderr, m.counts, p.values, m.omega)
    )
    shape = sim.shape
    if sim.ndim != 2 or any(x.shape != shape for x in (se, cnt, mod, om)):
        raise UsageError(
            "sim, stderr, counts, model and omega must be (Θ, Φ) arrays of one shape, "
            f"got {[x.shape for x in (sim, se, cnt, mod, om)]}"
        )
    theta_edges = np.asarray(m.theta_edges, dtype=np.float64)
    if theta_edges.shape != (shape[0] + 1,):
        raise UsageError(f"theta_edges must have shape ({shape[0] + 1},), got {theta_edges.shape}")
    phi_edges = m.phi_edges
    if phi_edges is None:
        from microsim.bins import Bins

        phi_edges = Bins(shape[0], shape[1], folded=True).phi_edges
    phi_edges = np.asarray(phi_edges, dtype=np.float64)
    if phi_edges.shape != (shape[1] + 1,):
        raise UsageError(f"phi_edges must have shape ({shape[1] + 1},), got {phi_edges.shape}")
    _checks.in_range("model_rtol", model_rtol, 0.0, 1.0)
    if int(min_events) != min_events or min_events < 1:
        raise UsageError(f"min_events must be an integer >= 1, got {min_events!r}")
    if int(n_params) != n_params or n_params < 0:
        raise UsageError(f"n_params must be an integer >= 0, got {n_params!r}")
    F = se_t = None
    if ensemble and m.realisations is not None:
        F = np.asarray(m.realisations, dtype=np.float64)
        if F.ndim != 3 or F.shape[1:] != shape:
            raise UsageError(
                f"realisations must be an (R, {shape[0]}, {shape[1]}) array, got {F.shape}"
            )
        F = F if len(F) >= 2 else None
    strata = real_dof = None
    if F is not None and m.strata is not None:
        strata = np.asarray(m.strata)
        st = stratified_mean(F, strata)
        with np.errstate(invalid="ignore", over="ignore"):
            se_t = np.sqrt(st.var + (model_rtol * mod) ** 2)
        real_dof = st.dof
    elif F is not None:
        with np.errstate(invalid="ignore", over="ignore"):
            se_t = np.sqrt(np.std(F, axis=0, ddof=1) ** 2 / len(F) + (model_rtol * mod) ** 2)
        real_dof = len(F) - 1
    dep = None
    if ensemble and F is None and p.departure is not None:
        dep = np.asarray(p.departure, dtype=np.float64)
        if dep.shape != shape or not np.all(dep >= 0):  # NaN fails too
            raise UsageError(
                f"departure must be a non-negative {shape} array (sr⁻¹), got shape {dep.shape}"
            )
    nu = m.dof
    if nu is not None:
        nu = np.asarray(nu, dtype=np.float64)
        if nu.shape != shape or not np.all(nu >= 1):  # NaN fails too
            raise UsageError(f"dof must be a {shape} array of degrees of freedom >= 1")
    return _Inputs(sim, se, cnt, mod, om, phi_edges, F, dep, se_t, nu, strata, real_dof)


def _used_bins(a: _Inputs, model_rtol: float, min_events: int) -> tuple[np.ndarray, np.ndarray]:
    """(used bins U, σ = √(se² + (model_rtol·m)²)) of the module docstring."""
    with np.errstate(invalid="ignore", over="ignore"):
        sigma = np.sqrt(a.se**2 + (model_rtol * a.mod) ** 2)
        used = (
            (a.cnt >= min_events)
            & np.isfinite(a.sim)
            & np.isfinite(a.mod)
            & np.isfinite(a.se)
            & (sigma > 0)
            & (a.sim > 0)
        )
        if a.F is not None:
            used &= np.all(np.isfinite(a.F), axis=0) & (a.se_t > 0)
    return used, sigma


def _normal_equivalent(a: _Inputs, sigma):
    """z ↦ its normal equivalent where σ's standard error has finite degrees of freedom ν
    (``a.nu``), else None. A ratio diff/σ whose σ² is estimated on ν dof is Student t, not
    normal: with few discordant pairs a bin's error is itself noisy, and normal quantiles
    would then call far too many bins deviating. σ² = se² + (rtol·m)² with the model's part
    exact has ν_σ = ν (σ/se)⁴ (Satterthwaite), and z keeps the two-sided p of t on ν_σ dof:
    z' = sign(z) Φ⁻¹(1 − F_t(|z|; ν_σ))."""
    if a.nu is None:
        return None
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        nu = a.nu * (sigma / np.where(a.se > 0, a.se, np.inf)) ** 4

    def convert(z):
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            p = t_sf(np.abs(z), nu)
            return np.where(p > 0, np.sign(z) * norm_isf(p), z)

    return convert


class _NoiseTests(NamedTuple):
    """The χ² and max-|z| tests of one verdict: the z-scores (Θ, Φ), χ², its p-value, max |z|
    (None when undefined) and whether both pass (``ok``)."""

    z: np.ndarray
    chi2: float
    p_value: float | None
    max_abs_z: float | None
    ok: bool


def _noise_tests(diff, sigma, used, dof, alpha_each, z_thr, normal=None) -> _NoiseTests:
    """χ² and max-|z| tests of z = diff/σ over the used bins (each at ``alpha_each``);
    ``normal``: z ↦ its normal equivalent (``_normal_equivalent``) or None."""
    z = np.where(used, diff / np.where(used, sigma, 1.0), 0.0)
    if normal is not None:
        z = np.where(used, normal(z), 0.0)
    chi2 = float(np.sum(z**2))
    p_value = float(chi2_sf(chi2, dof)) if dof > 0 else None
    max_abs_z = float(np.max(np.abs(z))) if used.any() else None
    ok = bool(dof > 0 and p_value >= alpha_each and max_abs_z < z_thr)
    return _NoiseTests(z, chi2, p_value, max_abs_z, ok)


def _energy_dev(sim, mod, om, Em) -> float | None:
    """Σ_E Ω (sim − m) / Σ_E Ω m over the model's energy set E (None if E is empty)."""
    if not Em.any():
        return None
    return float(np.sum(om[Em] * (sim[Em] - mod[Em])) / np.sum(om[Em] * mod[Em]))


def _realisation_tests(a: _Inputs, used, Em, dof, model_rtol, alpha_each) -> tuple[bool, dict]:
    """The energy and shape t tests over R ≥ 2 realisations (module docstring): (whether both
    pass, the verdict fields they fill)."""
    if not (used.any() and Em.any() and dof > 0):
        return False, {}
    R, nu = len(a.F), a.real_dof
    norm = np.sum(a.om[Em] * a.mod[Em])
    d = np.sum(a.om[Em] * (a.F[:, Em] - a.mod[Em]), axis=1) / norm
    if a.strata is None:
        d_mean, se_d, f_mean = d.mean(), float(d.std(ddof=1) / np.sqrt(R)), a.F.mean(axis=0)
    else:
        sd = stratified_mean(d, a.strata)
        d_mean, se_d = sd.mean, float(np.sqrt(sd.var))
        f_mean = stratified_mean(a.F, a.strata).mean
    energy_p = float(2.0 * t_sf(abs(d_mean) / np.sqrt(se_d**2 + model_rtol**2), nu))
    max_abs_t = float((np.abs(f_mean[used] - a.mod[used]) / a.se_t[used]).max())
    t_thr = float(t_isf(0.5 * sidak(alpha_each, int(used.sum())), nu))
    fields = dict(
        energy_dev=float(d_mean),
        energy_dev_se=se_d,
        energy_p=energy_p,
        max_abs_t=max_abs_t,
        t_threshold=t_thr,
        realisation_dof=int(nu),
    )
    return bool(energy_p >= alpha_each and max_abs_t < t_thr), fields


def _weighted_rms(energy, rel, E) -> float | None:
    """√(Σ_E e·rel² / Σ_E e): the energy-weighted RMS of ``rel`` over the set E."""
    if not E.any():
        return None
    ew = energy[E]
    return _opt(np.sqrt(np.sum(ew * rel[E] ** 2) / ew.sum()))


def _worst_bin(rel, cand, theta_edges, phi_edges) -> tuple[float | None, list | None]:
    """(signed rel of largest magnitude over ``cand``, its [θo, Δφ] bin centre)."""
    if not cand.any():
        return None, None
    flat = np.flatnonzero(cand.ravel())
    k = flat[np.argmax(np.abs(rel.ravel()[flat]))]
    it, ip = np.unravel_index(k, rel.shape)
    return float(rel.ravel()[k]), [
        float(0.5 * (theta_edges[it] + theta_edges[it + 1])),
        float(0.5 * (phi_edges[ip] + phi_edges[ip + 1])),
    ]


def verdict_kind(v: Mapping) -> str:
    """ "agrees", "deviates" or "inconclusive" (an ensemble model on one realisation whose
    deviation the tile's own departure from the ensemble may explain; module docstring): the
    one rule every output — run, report, index, charts, sweep, testing — words verdicts by."""
    if v["agrees"]:
        return "agrees"
    return "deviates" if v.get("conclusive", True) else "inconclusive"


def verdict_symbol(v: Mapping) -> str:
    """One verdict (a ``Verdict`` or its dict) in the symbols of the run's table and the
    index: "✓", "✗ 20%" (its energy-weighted relative RMS error) or "?" — followed, when the
    tile's departure from its ensemble is known, by both sizes: "? 2% (tile departs 3%)"."""
    v = Verdict.from_json(v)
    if v.kind == "agrees":
        return "✓"
    if v.kind == "deviates":
        return f"✗ {percent(v.rel_rms)}" if v.rel_rms is not None else "✗"
    if v.tile_departure is None or v.rel_rms is None:
        return "?"
    return f"? {percent(v.rel_rms)} (tile departs {percent(v.tile_departure)})"


def inconclusive_reason(v: Mapping) -> str:
    """Why an inconclusive verdict (a ``Verdict`` or its dict) is one, in words
    (``verdict_kind`` "inconclusive")."""
    v = Verdict.from_json(v)
    if v.dof <= 0:
        if v.n_bins == 0:
            return f"no bin holds {v.min_events} events: nothing to test"
        held = f"{v.n_bins} bin{'s' if v.n_bins > 1 else ''} hold{'' if v.n_bins > 1 else 's'}"
        return (
            f"{held} {v.min_events} events, no more than the {v.n_params} fitted parameters: "
            f"nothing to test"
        )
    if v.tile_departure is None or v.rel_rms is None:
        return "one realisation cannot separate tile scatter from model error"
    return (
        f"its deviation (rel RMS {percent(v.rel_rms)}) is explained by the tile's own "
        f"departure from its ensemble ({percent(v.tile_departure)}) and ray noise"
    )


def _jsonable_params(params: Mapping | None) -> dict:
    """Parameters as plain JSON values (numbers, strings, lists; complex → [re, im])."""

    def conv(v):
        if isinstance(v, (bool, str)) or v is None:
            return v
        if isinstance(v, (complex, np.complexfloating)):
            return [float(np.real(v)), float(np.imag(v))]
        if isinstance(v, (int, float, np.integer, np.floating)):
            return v.item() if isinstance(v, np.generic) else v
        if isinstance(v, np.ndarray):
            return [conv(x) for x in v.tolist()]
        if isinstance(v, (list, tuple)):
            return [conv(x) for x in v]
        if isinstance(v, Mapping):
            return {str(k): conv(x) for k, x in v.items()}
        return repr(v)

    return {str(k): conv(v) for k, v in dict(params or {}).items()}


def verdicts_for_result(
    result,
    fitted=None,
    *,
    params: Mapping | None = None,
    model_rtol: float = 1e-3,
    min_events: int = MIN_EVENTS,
    alpha: float = 0.01,
) -> list[dict]:
    """Verdicts for every incidence × model of ``result.models`` (prescribed models) and of
    ``fitted`` (an iterable or name → mapping of ``fits.FitResult``; their ``model_values`` are
    compared and their parameter count reduces the dof). ``params``: optional name → parameter
    dict for the prescribed models (default ``result.info.model_params``).
    The family size n_tests = #incidences × #models (prescribed + fitted). On a measured
    surface (``judged_as_tile``) every model is judged as a model of the traced tile, against
    ray noise ("this-tile"); otherwise models in ``info.realisation_models`` are judged against
    ray noise, the others as ensemble models over ``result.brdf_realisations`` (finite rows;
    "one-tile" without them)."""
    fits = list(fitted.values()) if isinstance(fitted, Mapping) else list(fitted or [])
    params = dict((result.info.model_params or {}) if params is None else params)
    entries = [
        (name, values, params.get(name, {}), False, 0) for name, values in result.models.items()
    ]
    entries += [(f.name, f.model_values, f.params, True, len(f.params)) for f in fits]
    names = [e[0] for e in entries]
    if len(set(names)) != len(names):
        raise UsageError(f"model names must be unique across prescribed and fitted, got {names}")
    T = len(result.theta_i)
    n_tests = max(1, T * len(entries))
    omega = result.bins.projected_solid_angle()
    rel_departure = tile_departure(result)
    # models of the realised surfaces themselves (``ts-facets``), and every model of a measured
    # surface, differ from the simulation by ray noise only; ensemble models also by the
    # tile-to-tile scatter (``result.stderr``)
    own = set(names) if judged_as_tile(result) else set(result.info.realisation_models)
    ray_err = result.stderr_ray if result.stderr_ray is not None else result.stderr
    ray_dof = stderr_dof(result)  # of ray_err; ``result.stderr`` with realisations: none
    out = []
    for t in range(T):
        for name, values, p, is_fit, k in entries:
            ray = name in own or result.stderr_ray is None
            stderr, dof = (ray_err, ray_dof) if ray else (result.stderr, None)
            real_t = strata_t = None
            if name not in own:
                real_t, strata_t = realisations_at(result, t)
            values = np.asarray(values)
            if values.shape != result.brdf.shape:
                raise UsageError(
                    f"model {name!r} has shape {values.shape}, expected {result.brdf.shape}"
                )
            departure = None
            if rel_departure is not None and name not in own:
                departure = departure_of(rel_departure[t], values[t])
            out.append(
                verdict(
                    Measured.of(
                        result,
                        t,
                        stderr=stderr[t],
                        omega=omega,
                        realisations=real_t,
                        dof=None if dof is None else dof[t],
                        strata=strata_t,
                    ),
                    Prediction(values[t], name, p, is_fit, k, name not in own, departure),
                    Significance(model_rtol, min_events, alpha, n_tests),
                )
            )
    return VerdictList(out)


MEASURED_KINDS = ("file",)
"""Surface kinds given as data rather than generated (a heightfield file, a measured scan):
their traced tile is the object of study, not a draw of an ensemble (``judged_as_tile``)."""


def judged_as_tile(result) -> bool:
    """Whether ``result`` traced a measured surface (its recorded ``surface`` kind is one of
    ``MEASURED_KINDS``): every model is then a model of that tile and is judged against its
    ray noise, conclusively either way (reference "this-tile", module docstring)."""
    return (result.info.surface or {}).get("kind") in MEASURED_KINDS


def realisation_strata(result) -> np.ndarray | None:
    """The stratum of each realisation of ``result`` when its generator drew them one per
    stratum of the ensemble (the surface's nominal ``patch``: the Student-t mixture's Beckmann
    patches, ``surfaces.student_t_mixture``), else None (i.i.d. realisations)."""
    metas = result.info.realisations
    if isinstance(metas, (int, np.integer)) or not metas or len(metas) < 2:
        return None
    patches = [(m.get("nominal") or {}).get("patch") for m in metas]
    return None if any(p is None for p in patches) else np.asarray(patches)


def realisations_at(result, t: int) -> tuple:
    """(F, strata) of incidence ``t``: the BRDFs (R, Θ, Φ) of the realisations traced there
    and their strata (``realisation_strata``, when at least two are present), or (None, None)
    for a result of one realisation."""
    per = result.brdf_realisations
    if per is None:
        return None, None
    traced = result.realisations_traced(t)
    strata = realisation_strata(result)
    if strata is not None and len(np.unique(strata[traced])) < 2:
        strata = None
    return per[traced, t], None if strata is None else strata[traced]


class VerdictList(list):
    """The verdicts of a result (a plain list of verdict dicts) that a notebook shows as a
    model × θi table in the symbols of every output (``verdict_symbol``)."""

    def _repr_html_(self) -> str:
        from microsim.display import html_table

        def label(v: Verdict) -> str:
            return v.model + (" (fit)" if v.fitted else "")

        verdicts = as_verdicts(self)
        models = list(dict.fromkeys(map(label, verdicts)))
        incidences = list(dict.fromkeys(incidence.key(v) for v in verdicts))
        cell = {(label(v), incidence.key(v)): v for v in verdicts}
        rows = [
            [m] + [verdict_symbol(cell[m, i]) if (m, i) in cell else "–" for i in incidences]
            for m in models
        ]
        caption = "✓ agrees · ✗ deviates (its relative RMS error) · ? inconclusive"
        with_phi = incidence.several_azimuths(self)
        header = ["model"] + [incidence.label(t, p, with_phi) for t, p in incidences]
        return html_table(header, rows, caption)


def tile_departure(result) -> np.ndarray | None:
    """|r| (T, Θ, Φ), r = m_tile/m_ensemble − 1: the relative departure of the traced tile's
    BRDF from its ensemble's, computed without rays from the two models named by
    ``info.tile_departure`` ({"tile": facet model, "ensemble": the same closed form with
    the ensemble NDF}, recorded by ``sim.compare.attach_models``); 0 where the ensemble model
    is 0 and the tile's too, ∞ where only the tile's is. None if not recorded, or if the
    result has several realisations (their scatter is measured instead)."""
    pair = result.info.tile_departure
    if not pair or getattr(result, "brdf_realisations", None) is not None:
        return None
    names = (pair.get("tile"), pair.get("ensemble"))
    if any(name not in result.models for name in names):
        return None
    tile, ens = (np.asarray(result.models[name], dtype=np.float64) for name in names)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(ens > 0, np.abs(tile / np.where(ens > 0, ens, 1.0) - 1.0), np.inf)
    r = np.where((ens == 0) & (tile == 0), 0.0, r)
    return r


def departure_of(rel: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The ``departure`` argument of ``verdict`` for a model's bin values (sr⁻¹) from the
    tile's relative departure ``rel`` (``tile_departure``): rel·|values| with 0·∞ = 0 (a bin
    the model gives no light has no departure)."""
    with np.errstate(invalid="ignore", over="ignore"):
        out = rel * np.abs(np.asarray(values, dtype=np.float64))
    return np.where(np.isnan(out) & (rel >= 0), 0.0, out)


def summary_row(verdicts: Iterable[Mapping]) -> dict[str, str]:
    """One line per model (in order of appearance) for the index table: "agrees" if every
    incidence agrees conclusively; incidences with an inconclusive verdict are listed as
    "inconclusive at θi=…" (after "; " when others deviate); else e.g.
    "deviates at θi=80°: rel RMS 12% at θi=80°, worst +35% at θo 84°
    (θi=80°)" (the largest rel_rms and |max_rel_dev| over the deviating incidences)."""
    verdicts = as_verdicts(verdicts)
    with_phi = incidence.several_azimuths(verdicts)

    def at(v):
        return incidence.label(*incidence.key(v), with_phi).replace(" = ", "=")

    by_model: dict[str, list] = {}
    for v in verdicts:
        by_model.setdefault(v.model, []).append(v)
    out = {}
    for name, vs in by_model.items():
        bad = [v for v in vs if v.kind == "deviates"]
        unsure = [v for v in vs if v.kind == "inconclusive"]
        if not bad and not unsure:
            out[name] = "agrees"
            continue
        note = ""
        if unsure:
            where = incidence.grouped(unsure) if with_phi else incidence.where(unsure, False)
            note = f"inconclusive at θi={where} ({inconclusive_reason(unsure[-1])})"
        if not bad:
            out[name] = note
            continue
        parts = [
            f"deviates at θi={incidence.grouped(bad) if with_phi else incidence.where(bad, False)}"
        ]
        rms = [v for v in bad if v.rel_rms is not None]
        if rms:
            r = max(rms, key=lambda v: v.rel_rms)
            parts.append(f"rel RMS {percent(r.rel_rms, 3)} at {at(r)}")
        worst = [v for v in bad if v.max_rel_dev is not None]
        if worst:
            w = max(worst, key=lambda v: abs(v.max_rel_dev))
            theta_o, dphi = w.worst_bin
            parts.append(
                f"worst {percent(w.max_rel_dev, 3, signed=True)} at θo {theta_o:g}°, "
                f"Δφ {dphi:g}° ({at(w)})"
            )
        out[name] = parts[0] + (": " + ", ".join(parts[1:]) if len(parts) > 1 else "")
        out[name] += f"; {note}" if note else ""
    return out
