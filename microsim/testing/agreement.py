"""``assert_brdf_agrees``: does a BRDF agree with an explicit surface that has this NDF?

The BRDF under test is bin-averaged exactly as microsim bin-averages its own models
(``microsim.sim.predict``: adaptive Gauss–Legendre quadrature of f cos θo over each (θo, Δφ)
bin, divided by the bin's projected solid angle Ω_B, relative accuracy 1e-3) and compared with
the cached reference simulation (``microsim.testing.cache``) by the verdict machinery
(``microsim.analysis.verdicts.verdict``), one verdict per incidence, the family of incidences
kept at level α by Šidák's correction.

Which noise the BRDF is judged against:

* one V-groove surface (a scene with ``realisations = 1``, e.g. the stratified V-grooves of
  the catalogue scene ``vgroove-ggx-0.3``): reference "one-tile", as ``microsim run`` judges an
  ensemble model on one tile. The tile's departure from its ensemble is computed without rays
  (Torrance–Sparrow with the tile's own facets against the same form with the ensemble NDF,
  both with the V-groove G: ``verdicts.tile_departure``) and each bin's deviation is
  discounted by it before the χ² and max-|z| tests against ray noise. A BRDF of the ensemble
  — Torrance–Sparrow with D and the V-groove G (Mikkelsen 2009, eq. 13, 25) — then passes at
  any ray count; the departure (tilt quantisation, empirical tilt CDF within 1/(2n) of D's,
  and the missing tail beyond the 1 − 1/(2n) quantile for stratified grooves) is reported as
  the verdict's ``tile_departure``. A deviation the departure explains is "inconclusive" and
  passes;
* one tile of another surface (a heightfield, ``realisations = 1``): reference "ray-noise" —
  the BRDF is compared with the traced tile itself within the simulation's ray noise (its
  departure from the ensemble is not computable); a surface read from a file is judged the
  same way as the object it is (reference "this-tile", ``verdicts.judged_as_tile``);
* several realisations (a random scene, ``realisations = R ≥ 2``): the BRDF is judged as a
  model of the *ensemble* (reference "realisations": Student-t tests over the R tiles'
  BRDFs), because each tile is one draw of the random surface.

``rtol`` turns the test into a tolerance check (module function ``tolerance_check``).

The physics' own error (``physics_error``, module ``physics``): microsim's Torrance–Sparrow
with the surface's ensemble NDF and height-correlated Smith G judged by the same code path
(``_judge``) against the same reference, so that a failure message can say whether a correct
BRDF of that distribution could pass at each failing incidence.
"""

from __future__ import annotations

import hashlib
import warnings
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from microsim.analysis import incidence
from microsim.analysis.markdown import percent
from microsim.analysis.verdicts import (
    Measured,
    Prediction,
    Significance,
    departure_of,
    realisations_at,
    tile_departure,
    verdict,
    verdict_kind,
)
from microsim.analytic.brdf import TorranceSparrow
from microsim.analytic.masking import Smith, VGroove
from microsim.analytic.ndf import Beckmann
from microsim.errors import UsageError
from microsim.sim.compare import attach_models, default_models, departure_models, realised_m
from microsim.sim.predict import FunctionBRDF, Predictor, predict_incidences
from microsim.sim.tallies import stderr_dof
from microsim.stats import energy_set, norm_isf, sidak, t_isf

from .cache import (
    AUTO_MAX_RAYS,
    AUTO_TARGET,
    Reference,
    cache_dir,
    cached,
    derived,
    resolve_reference,
)
from .diagnosis import closest, likely_cause, lobe_width_deg
from .physics import PHYSICS_MODEL, PhysicsError, physics_lines, physics_model
from .returns import real_values

__all__ = [
    "MIN_EVENTS",
    "assert_brdf_agrees",
    "physics_error",
    "Agreement",
    "BRDFMismatch",
    "tolerance_check",
    "MODEL_RTOL",
    "wrap_brdf",
]

MIN_EVENTS = 100
"""Single-bounce events a reference bin needs to enter the tests here (the project's verdicts
default to ``microsim.stats.MIN_EVENTS`` = 25). z = (m − f̄)/se uses the bin's *own* standard
error; with a few dozen events a downward fluctuation lowers f̄ and se together and |z| is
heavy-tailed: the one false alarm of example (a) in 12 seeds at 25 events was a 44-event bin
at θo 1.5° (z = 5.9). With ≥ 100 events the relative error of se is ≤ 7 %."""
MODEL_RTOL = 1e-3
"""Relative accuracy of the bin-averaging quadrature, added to σ in quadrature (as for
microsim's own models)."""


class Agreement(dict):
    """What ``assert_brdf_agrees`` found (a dict): ``verdicts`` (one verdict dict per
    incidence, ``microsim.analysis.verdicts.VERDICT_SCHEMA``, plus ``tolerance`` entries in
    rtol mode), ``passed`` (bool), ``failing`` (θi list) and ``failing_incidences`` ((θi, φi)
    list), ``model`` (T, Θ, Φ) the BRDF's bin averages, ``reference`` (the Result), ``chart``
    (path or None), ``message``, ``physics`` (on a failure over a surface with an ensemble
    NDF: one ``PhysicsError`` per failing incidence, a tuple; else None)."""


class BRDFMismatch(AssertionError):
    """Raised by ``assert_brdf_agrees`` when the BRDF fails: an ``AssertionError`` whose
    message is the report and whose ``agreement`` holds the numbers (``Agreement``)."""

    def __init__(self, message: str, agreement: Agreement):
        super().__init__(message)
        self.agreement = agreement


def wrap_brdf(brdf):
    """``brdf(wi, wo)`` over (N, 3) arrays as the ``brdf_fn(wi (3,), wo (..., 3))`` that
    ``predict.bin_average`` calls: wi is broadcast to wo's rows (a copy, so the callable may
    write into it), the result must hold one real, finite value ≥ 0 per pair."""

    def fn(wi, wo):
        shape = wo.shape[:-1]
        wo2 = np.ascontiguousarray(wo.reshape(-1, 3))
        wi2 = np.ascontiguousarray(np.broadcast_to(wi, wo2.shape))
        f = real_values(brdf(wi2, wo2), "brdf(wi, wo) must return", "(N,)")
        if f.size != len(wo2) or (f.ndim > 1 and f.shape != (len(wo2), 1)):
            raise UsageError(
                f"brdf(wi, wo) must return one value per direction pair, shape ({len(wo2)},); "
                f"got shape {f.shape} for wi, wo of shape ({len(wo2)}, 3)"
            )
        f = f.reshape(shape)
        if not np.all(np.isfinite(f)) or np.any(f < 0):
            bad = ~(np.isfinite(f) & (f >= 0))
            k = np.argwhere(bad)[0]
            raise AssertionError(
                f"brdf returned {int(bad.sum())} non-finite or negative value(s), e.g. "
                f"{f[tuple(k)]!r} at wi = {np.round(wi, 6).tolist()}, "
                f"wo = {np.round(wo[tuple(k)], 6).tolist()}: a BRDF is finite and >= 0"
            )
        return f

    return fn


def readable_name(f) -> str:
    """A BRDF callable's name for messages and chart files: its ``__qualname__`` with
    ``.<locals>`` dropped ("make_ggx.f", not "make_ggx.<locals>.f") and ``<lambda>`` as
    "lambda", other characters than letters, digits, '-', '_', '.' as '_', at most 60."""
    q = getattr(f, "__qualname__", None) or type(f).__name__
    q = q.replace(".<locals>", "").replace("<lambda>", "lambda")
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in q)[:60]


class _KnownModel(NamedTuple):
    """A model microsim knows by ``name``: a catalogue model of the reference's surfaces
    (``source`` "catalogue") or the physics model ("physics"). Its bin averages depend on the
    reference's surfaces, material, incidences and bins alone, so they are kept in the
    testing cache (``cache.derived``); ``build()`` makes its ``Predictor`` on a miss only (a
    catalogue model needs the surfaces' meshes)."""

    name: str
    source: str
    build: Callable[[], Predictor]


def _brdf_spec(brdf, ref, symmetric: bool, label) -> Predictor | _KnownModel:
    """The BRDF under test: a callable's ``Predictor``, or a catalogue model name's
    ``_KnownModel``; its ``name`` is the BRDF's name in messages."""
    if isinstance(brdf, str):
        return _KnownModel(brdf, "catalogue", lambda: _catalogue_model(brdf, ref))
    if callable(brdf):
        name = label or readable_name(brdf)
        return Predictor(name, FunctionBRDF(wrap_brdf(brdf), symmetric=symmetric))
    raise UsageError(f"brdf must be a callable f(wi, wo) -> sr⁻¹ or a model name, got {brdf!r}")


def _catalogue_model(name: str, ref) -> Predictor:
    """The ``Predictor`` of the reference surfaces' catalogue model ``name``
    (``compare.default_models``); UsageError listing them for another name."""
    specs = {s.name: s for s in default_models(list(ref.surfaces), ref.material)}
    if name not in specs:
        raise UsageError(
            f"brdf must be a callable f(wi, wo) or one of this surface's catalogue models "
            f"{', '.join(specs)}, got {name!r}"
        )
    return specs[name]


def _model_values(spec, ref, result, incidences: list[int], cache) -> np.ndarray:
    """(len(incidences), Θ, Φ) bin averages of ``spec`` at those of the reference's
    incidences: a callable's computed, a ``_KnownModel``'s from the testing cache (computed
    once per cache; ``cache.derived``)."""
    if isinstance(spec, Predictor):
        return _bin_averages(spec, result, incidences)
    what = {
        "model": spec.name,
        "source": spec.source,
        "ndf": repr(ref.ensemble_ndf),
        "quadrature_rtol": MODEL_RTOL,
        "incidences": incidences,
    }
    shape = (len(incidences), result.bins.n_theta, result.bins.n_phi)
    return derived(
        ref, what, shape, lambda: _bin_averages(spec.build(), result, incidences), cache=cache
    )


def _bin_averages(spec: Predictor, result, incidences: list[int]) -> np.ndarray:
    """(len(incidences), Θ, Φ) bin averages of ``spec`` at those of the reference's
    incidences, on its bins."""
    th, ph = result.theta_i[incidences], result.phi_i[incidences]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # unconverged bins: rare, in σ anyway
        return predict_incidences([spec], th, ph, result.bins, rtol=MODEL_RTOL)[spec.name]


def _one_tile_departure(ref, result, cache) -> np.ndarray | None:
    """(T, Θ, Φ) relative departure of the one traced tile's BRDF from its ensemble's, where it
    is computable without rays (``compare.departure_models``: V-grooves;
    ``verdicts.tile_departure``), else None. It depends on the surface, material, incidences
    and bins only, so it is kept in the testing cache (``cache.derived``)."""

    def compute():
        pair = departure_models(list(ref.surfaces), ref.material)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # as _bin_averages
            return tile_departure(attach_models(result, pair, rtol=MODEL_RTOL)) if pair else None

    what = {"tile_departure": "verdicts.tile_departure", "quadrature_rtol": MODEL_RTOL}
    shape = (len(result.theta_i), result.bins.n_theta, result.bins.n_phi)
    return derived(ref, what, shape, compute, cache=cache)


def _used_bins(sim, se, cnt, mod, min_events: int) -> tuple[np.ndarray, np.ndarray]:
    """(used bins: ≥ ``min_events`` events, finite, f̄ > 0, σ > 0; σ = √(se² + (1e-3 m)²))."""
    with np.errstate(invalid="ignore"):
        sigma = np.sqrt(se**2 + (MODEL_RTOL * mod) ** 2)
        used = (cnt >= min_events) & np.isfinite(sim) & np.isfinite(mod) & (sigma > 0) & (sim > 0)
    return used, sigma


def _energy_deviation(sim, sigma, mod, om, used) -> tuple[float, float]:
    """(d, se_d): d = Σ_E Ω (f̄ − m)/Σ_E Ω m over the model's energy set E (90 % of its energy
    in the ``used`` bins), se_d = √(Σ_E Ω² σ²)/Σ_E Ω m its standard error from the bins' σ."""
    E = energy_set(np.where(used, mod * om, 0.0)).reshape(sim.shape)
    norm = np.sum(om[E] * mod[E])
    d = float(np.sum(om[E] * (sim[E] - mod[E])) / norm)
    return d, float(np.sqrt(np.sum((om[E] * sigma[E]) ** 2)) / norm)


def tolerance_check(
    sim,
    stderr,
    counts,
    model,
    omega,
    rtol: float,
    p_threshold: float,
    realisations: int = 1,
    min_events: int = MIN_EVENTS,
) -> dict:
    """Is the model within ``rtol`` (relative) of the reference, beyond its noise?

    H0: |m_B − f_B| ≤ rtol · m_B in every bin (f the true bin average). Two tests, each at
    ``p_threshold``, both conservative under H0:

    * per bin: excess z_B = max(|m_B − f̄_B| − rtol m_B, 0)/σ_B, σ_B² = se_B² + (1e-3 m_B)²;
      rejects when max_U z_B ≥ the two-sided normal quantile at Šidák(p_threshold, |U|)
      (Student t_{R−1} with R ≥ 2 realisations);
    * energy: d = Σ_E Ω (f̄ − m)/Σ_E Ω m over the model's energy set E (90 % of its energy
      in the used bins), se_d = √(Σ_E Ω² se²)/Σ_E Ω m; rejects when |d| − rtol ≥ q se_d with q
      the two-sided quantile at p_threshold.

    Used bins U as the verdicts' (≥ ``min_events`` events, finite, f̄ > 0). Returns ``passed``,
    ``max_excess_z``, ``z_threshold``, ``energy_dev``, ``energy_se``, ``energy_threshold``.
    """
    sim, se, cnt, mod, om = (
        np.asarray(a, dtype=np.float64) for a in (sim, stderr, counts, model, omega)
    )
    used, sigma = _used_bins(sim, se, cnt, mod, min_events)
    n_bins = int(used.sum())
    if n_bins == 0:
        return {
            "passed": False,
            "max_excess_z": None,
            "z_threshold": None,
            "energy_dev": None,
            "energy_se": None,
            "energy_threshold": None,
        }
    excess = np.maximum(np.abs(mod[used] - sim[used]) - rtol * mod[used], 0.0) / sigma[used]
    q_bin = sidak(p_threshold, n_bins)
    if realisations >= 2:
        z_thr = float(t_isf(0.5 * q_bin, realisations - 1))
        q_e = float(t_isf(0.5 * p_threshold, realisations - 1))
    else:
        z_thr = float(norm_isf(0.5 * q_bin))
        q_e = float(norm_isf(0.5 * p_threshold))
    d, se_d = _energy_deviation(sim, sigma, mod, om, used)
    passed = bool(excess.max() < z_thr and abs(d) - rtol < q_e * se_d)
    return {
        "passed": passed,
        "max_excess_z": float(excess.max()),
        "z_threshold": z_thr,
        "energy_dev": d,
        "energy_se": se_d,
        "energy_threshold": rtol + q_e * se_d,
    }


def _num(x, fmt="{:.3g}") -> str:
    return "–" if x is None else fmt.format(x)


def _worst_bins(result, model, t: int, min_events: int, k: int = 3) -> list[str]:
    """The ``k`` used bins of largest |z| at incidence ``t``: θo, Δφ, model vs reference."""
    sim, se, cnt, mod = result.brdf[t], result.stderr[t], result.counts[t], model[t]
    with np.errstate(invalid="ignore", divide="ignore"):
        sigma = np.sqrt(se**2 + (MODEL_RTOL * mod) ** 2)
        used = (cnt >= min_events) & np.isfinite(sim) & (sigma > 0) & (sim > 0)
        z = np.where(used, (sim - mod) / np.where(used, sigma, 1.0), 0.0)
    order = np.argsort(-np.abs(z).ravel())[:k]
    tc, pc = result.bins.theta_centers, result.bins.phi_centers
    out = []
    for f in order:
        i, j = np.unravel_index(f, z.shape)
        if not used[i, j]:
            continue
        out.append(
            f"θo {tc[i]:.1f}° Δφ {pc[j]:.0f}°: brdf {mod[i, j]:.4g} vs reference "
            f"{sim[i, j]:.4g} ± {se[i, j]:.2g} sr⁻¹ ({100 * (sim[i, j] / mod[i, j] - 1):+.1f}%, "
            f"z = {z[i, j]:+.1f})"
        )
    return out


def _energy_ratio(bins, numerator, denominator) -> float | None:
    """Σ Ω⊥ numerator / Σ Ω⊥ denominator over the (Θ, Φ) ``bins`` where both are finite: the
    ratio of their albedos (None where the denominator carries no energy)."""
    om = bins.projected_solid_angle()
    ok = np.isfinite(numerator) & np.isfinite(denominator)
    den = (denominator * om)[ok].sum()
    return None if den <= 0 else float((numerator * om)[ok].sum() / den)


def _diagnosis(result, model, t: int, min_events: int) -> str | None:
    """For a surface without an ensemble NDF (no closed form to fit variants of): a ratio
    brdf/reference that is the same in every well-measured bin (a normalisation error: a
    constant factor), else a lobe wider or narrower than the reference's (a roughness error?).
    None when neither shows."""
    ref, mod, cnt = result.brdf[t], model[t], result.counts[t]
    used = (cnt >= min_events) & np.isfinite(ref) & (ref > 0) & np.isfinite(mod)
    if used.sum() >= 3:
        w = np.where(used, ref * result.bins.projected_solid_angle(), 0.0)
        r = np.where(used, mod / np.where(used, ref, 1.0), 0.0)
        mean = (w * r).sum() / w.sum()
        spread = np.sqrt((w * (r - mean) ** 2).sum() / w.sum())
        if mean > 0 and abs(mean - 1.0) > 0.1 and spread < 0.1 * mean:
            return (
                f"brdf/reference ≈ {mean:.3g} in every bin (spread {spread / mean:.1%}): "
                "a constant factor — a normalisation error?"
            )
    width_ref, width_mod = lobe_width_deg(result.bins, ref), lobe_width_deg(result.bins, mod)
    if np.isfinite(width_ref) and np.isfinite(width_mod) and width_ref > 0:
        change = width_mod / width_ref - 1.0
        if abs(change) > 0.05:
            return (
                f"lobe {abs(change):.0%} {'wider' if change > 0 else 'narrower'} than the "
                f"reference's (RMS angle {width_mod:.1f}° vs {width_ref:.1f}°): roughness?"
            )
    return None


def _correct_models(ref: Reference) -> dict:
    """The closed forms a correct BRDF of the reference's ensemble NDF may implement (catalogue
    names → models): Torrance–Sparrow with the surface's own exact G where it has one, and
    with Smith's G, height-correlated and separable."""
    ndf, material = ref.ensemble_ndf, ref.material
    models = {}
    if ref.exact_shadowing == "vgroove":
        models["ts-vgroove"] = TorranceSparrow(ndf, VGroove(), material)
    models[PHYSICS_MODEL] = physics_model(ndf, material).model
    models["ts-smith"] = TorranceSparrow(ndf, Smith(correlated=False), material)
    return models


def _realised_lines(ref: Reference, result, judging: "_Judging", failing, with_phi, cache):
    """For a Beckmann ensemble (Gaussian and ABC heightfields): the m its tiles realise when it
    differs from the nominal one, and the physics model at that m judged at the failing
    incidences — a BRDF of the nominal m departs from these tiles by the difference alone."""
    ndf = ref.ensemble_ndf
    if type(ndf) is not Beckmann or ref.exact_shadowing is not None:
        return []
    m = realised_m(ref.surfaces)
    if abs(m / ndf.m - 1.0) < 1e-3:
        return []
    model = physics_model(Beckmann(m), ref.material).model
    judged = _judge(
        Predictor(f"{PHYSICS_MODEL} at m = {m:.4g}", model), ref, result, judging, cache, failing
    )
    agrees = [t for t in failing if t not in judged.failing]
    where = "; ".join(
        f"{word} at {', '.join(_at(result, t, with_phi) for t in ts)}"
        for word, ts in (("passes", agrees), ("fails", judged.failing))
        if ts
    )
    return [
        f"the surface's tiles realise m = {m:.4g}, not the nominal {ndf.m:g} "
        f"({m / ndf.m - 1.0:+.2%}: their own facet slopes, Surface.stats()), so a BRDF of the "
        f"nominal m departs from them by that alone; {PHYSICS_MODEL} at the realised m {where}"
    ]


DIAGNOSIS_RTOL = 1e-3
"""Relative accuracy of the correct models' and their variants' bin averages in the failure
message's diagnosis: that of the brdf's own (``predict``'s default)."""


def _cause_lines(ref: Reference, result, judged: "_Judged", physics, with_phi: bool) -> list[str]:
    """What the failing incidences' deviation looks like: the brdf is one of the correct closed
    forms itself (its deviation is that model's), or the variant of the nearest one that fits
    it (``diagnosis.likely_cause``); for a surface without an ensemble NDF, the ratio to the
    reference per incidence (``_diagnosis``)."""
    name, values, verdicts, failing = judged
    physics_fails = {(r.theta_i, r.phi_i) for r in physics or () if not r.holds}
    if ref.ensemble_ndf is None or not ref.ensemble_ndf.isotropic:
        lines = []
        for t in failing:
            if (verdicts[t]["theta_i"], verdicts[t]["phi_i"]) in physics_fails:
                continue  # a roughness or scale hint would blame the brdf for the physics' error
            hint = _diagnosis(result, values, t, verdicts[t]["min_events"])
            if hint:
                lines.append(f"at {_at(result, t, with_phi)}: {hint}")
        return lines
    theta, phi = result.theta_i[failing], result.phi_i[failing]
    user = values[failing]
    models = _correct_models(ref)
    near = closest(user, models, theta, phi, result.bins, DIAGNOSIS_RTOL)
    if near.is_the_model:
        devs = ", ".join(
            f"{percent(verdicts[t]['energy_dev'], 3, signed=True, unit=' %')} at "
            f"{_at(result, t, with_phi)}"
            for t in failing
        )
        return [
            f"the brdf is {near.name} itself (within {near.misfit:.2%} relative RMS): this is "
            f"the deviation of {near.name} on this surface ({devs}, energy): the physics, not "
            "your implementation"
        ]
    # the nearest correct model first; the others only if no variant of it explains the brdf
    others = [name for name in models if name != near.name]
    for name in (near.name, *others):
        known = near.values if name == near.name else None
        cause = likely_cause(user, models[name], known, theta, phi, result.bins, DIAGNOSIS_RTOL)
        if cause is not None:
            break
    else:
        return [
            f"the brdf is none of {', '.join(models)} (nearest: {near.name}, "
            f"{near.misfit:.2%} relative RMS) and no single common bug explains the difference"
        ]
    return [f"likely cause (against {name}): {cause.sentence()}"]


def _chart(result, model, name, verdicts, t: int, where: Path, key: str) -> str:
    """Hemisphere chart (``analysis.charts.hemisphere_maps``) of incidence ``t``; its path.
    The file name holds the reference key and a hash of the model's bin averages and the
    verdicts' settings, so a chart already written for the same numbers is reused."""
    h = hashlib.sha1(np.ascontiguousarray(model, dtype=np.float64).tobytes())
    h.update(
        repr([(v["alpha"], v["n_tests"], v["min_events"], v["agrees"]) for v in verdicts]).encode()
    )
    digest = h.hexdigest()
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in name)[:60]
    phi = f"-phi{result.phi_i[t]:g}" if any(result.phi_i) else ""
    path = where / f"{safe}-{key}-{digest[:10]}-theta{result.theta_i[t]:g}{phi}.png"
    if path.is_file():
        return str(path)
    try:
        from microsim.analysis import charts  # Figure + FigureCanvasAgg: no pyplot, no GUI

        where.mkdir(parents=True, exist_ok=True)
        charts.hemisphere_maps(
            result, {name: model}, verdicts, path, t_index=t, scene_name=f"brdf {name}"
        )
        return str(path)
    except Exception as e:  # a chart is a convenience: never hide the verdict behind it
        return f"(chart not written: {type(e).__name__}: {e})"


def symmetric_keyword(symmetric, isotropic=None) -> bool:
    """The checked ``symmetric`` flag (the callable is symmetric in Δφ); ``isotropic``, its
    older name, still sets it with a DeprecationWarning."""
    if isotropic is not None:
        warnings.warn(
            "isotropic= is deprecated: it means symmetric= (f(Δφ) = f(−Δφ))",
            DeprecationWarning,
            stacklevel=3,
        )
        symmetric = isotropic
    if not isinstance(symmetric, bool):
        raise UsageError(f"symmetric must be True or False, got {symmetric!r}")
    return symmetric


def assert_brdf_agrees(
    brdf,
    surface_or_scene,
    material="scene",
    theta_i=None,
    *,
    phi_i=None,
    rays="auto",
    bins=None,
    alpha: float = 0.01,
    rtol: float | None = None,
    seed: int = 0,
    target: float = AUTO_TARGET,
    max_rays: int = AUTO_MAX_RAYS,
    realisations: int | None = None,
    cache=None,
    symmetric: bool = False,
    name: str | None = None,
    min_events: int = MIN_EVENTS,
    isotropic: bool | None = None,
    chart_dir=None,
    threads: int | None = None,
) -> Agreement:
    """Assert that ``brdf`` agrees with the explicit surface (module docstring).

    ``brdf``: a callable ``f(wi, wo)`` with ``wi``, ``wo`` float64 arrays of shape (N, 3) —
    unit vectors pointing away from the surface (towards the light, towards the viewer), z the
    macro normal, wi at the incidence azimuth φi (0: in the x–z plane) — returning N values
    in sr⁻¹ (one scalar
    per pair; the cosine factor is *not* included); or the name of one of the surface's
    catalogue models (``microsim.sim.compare.default_models``: "ts-vgroove", "ts-smith",
    "ts-smith-corr", "ts-facets", …).

    ``surface_or_scene``: a scene file or catalogue name ("vgroove-ggx-0.3"), a ``Scene``, a
    ``Surface`` or a sequence of Surfaces; ``material`` ("scene": the scene's; else a name, n,
    n + ik or None for a mirror), ``theta_i`` and ``phi_i`` (degrees; default the scene's
    incidences — every θi at each of its φi —; for a Surface φi defaults to 0; ``phi_i`` a
    scalar or one per θi, in the surface frame), ``bins``
    (``Bins`` or (n_theta, n_phi); default the scene's), ``rays`` (per incidence, or "auto":
    until the reference's energy-weighted relative standard error is ≤ ``target``, at most
    ``max_rays``; ``microsim.testing.cache.reference``), ``seed``, ``realisations`` (overrides
    a scene's count), ``cache`` (directory, or False for no cache) as
    ``microsim.testing.reference``. ``symmetric=True`` states that the
    callable is symmetric in the relative azimuth, f(Δφ) = f(−Δφ) (isotropic BRDFs): the
    folded bins are then integrated over Δφ ≥ 0 only, half the evaluations (as microsim does
    for its isotropic models); by default both halves are integrated, exact for any callable.
    (``isotropic=`` is the deprecated name of ``symmetric=``.)
    ``name``: the BRDF's name in the message and chart (default ``readable_name(brdf)``).
    ``min_events``: single-bounce events a bin needs to be tested (default ``MIN_EVENTS`` =
    100, see there).

    Statistical mode (``rtol=None``): no incidence's verdict may deviate at family level
    ``alpha`` (Šidák over the incidences), judged as ``microsim run`` judges an ensemble model:
    t tests over the realisations for R ≥ 2; for one V-groove tile, χ² and max-|z| tests of
    the excess over the tile's computed departure from its ensemble (a BRDF of the ensemble
    passes at any ray count; a deviation within that departure is "inconclusive" and passes,
    the verdict says so); for one tile of another surface, χ² and max-|z| tests against ray
    noise (the reference is the tile itself). Tolerance mode (``rtol`` = a relative
    error, e.g. 0.05): every incidence must pass ``tolerance_check`` at the same levels —
    agreement within rtol rather than statistical indistinguishability.

    On failure raises AssertionError with a table (incidences; χ²/dof, max |z|,
    energy-weighted relative error rel_rms, energy deviation, θo ranges of deviation), the
    physics' own error at each failing incidence (``physics_error``; where the surface has
    an ensemble NDF), the worst bins of each failing incidence, and the path of a hemisphere
    chart of the worst incidence (written under ``chart_dir``, default ``<cache>/charts``).
    Returns the ``Agreement`` when it passes. Bad arguments raise UsageError naming the parameter.
    """
    __tracebackhide__ = True
    judging = _judging(alpha, rtol, min_events)
    if not (callable(brdf) or isinstance(brdf, str)):
        raise UsageError(f"brdf must be a callable f(wi, wo) -> sr⁻¹ or a model name, got {brdf!r}")
    symmetric = symmetric_keyword(symmetric, isotropic)
    if name is not None and not isinstance(name, str):
        raise UsageError(f"name must be a string (the BRDF's name in messages), got {name!r}")
    ref = resolve_reference(
        surface_or_scene,
        material,
        theta_i,
        phi_i=phi_i,
        rays=rays,
        bins=bins,
        seed=seed,
        target=target,
        max_rays=max_rays,
        realisations=realisations,
    )
    result = cached(ref, cache=cache, threads=threads)
    judged = _judge(_brdf_spec(brdf, ref, symmetric, name), ref, result, judging, cache)
    failing = judged.failing
    out = Agreement(
        verdicts=judged.verdicts,
        passed=not failing,
        failing=[float(result.theta_i[t]) for t in failing],
        failing_incidences=[(float(result.theta_i[t]), float(result.phi_i[t])) for t in failing],
        model=judged.values,
        reference=result,
        chart=None,
        message="",
        physics=None,
    )
    if not failing:
        return out
    worst = max(failing, key=lambda t: judged.verdicts[t]["chi2_dof"] or 0.0)
    where = (
        Path(chart_dir)
        if chart_dir is not None
        else (cache_dir(cache if cache is not False else None) / "charts")
    )
    out["chart"] = _chart(
        result, judged.values, judged.name, judged.verdicts, worst, where, ref.key()[:10]
    )
    out["physics"] = _physics_errors(ref, result, judging, failing, cache, judged.values)
    out["message"] = _message(judged, ref, result, judging, out["chart"], out["physics"], cache)
    raise BRDFMismatch(out["message"], out)


class _Judging(NamedTuple):
    """How a model is judged against the reference: the family level ``alpha`` (Šidák over
    the incidences), ``rtol`` (None: statistically; else the tolerance check) and the
    ``min_events`` a bin needs."""

    alpha: float
    rtol: float | None
    min_events: int


def _judging(alpha, rtol, min_events) -> _Judging:
    """The checked judging arguments of ``assert_brdf_agrees`` and ``physics_error``."""
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float)) or not 0 < alpha < 1:
        raise UsageError(f"alpha must lie in (0, 1), got {alpha!r}")
    if rtol is not None and (
        isinstance(rtol, bool) or not isinstance(rtol, (int, float)) or not 0 < rtol < 1
    ):
        raise UsageError(f"rtol must be None or a relative error in (0, 1), got {rtol!r}")
    if isinstance(min_events, bool) or not isinstance(min_events, int) or min_events < 1:
        raise UsageError(f"min_events must be an integer >= 1, got {min_events!r}")
    return _Judging(alpha, None if rtol is None else float(rtol), min_events)


class _Judged(NamedTuple):
    """A model judged at some of the reference's incidences: its ``name``, its bin averages
    ``values`` (one (Θ, Φ) array per judged incidence), their ``verdicts`` (with
    ``tolerance`` in rtol mode), and ``failing``, the indices t of the incidences where it
    fails."""

    name: str
    values: np.ndarray
    verdicts: list
    failing: list[int]


def _judge(spec, ref: Reference, result, judging: _Judging, cache, incidences=None) -> _Judged:
    """Judge ``spec`` (a ``Predictor`` or ``_KnownModel``) against the reference ``result`` at
    the incidence indices ``incidences`` (default all of them), each verdict within the family
    of all the reference's incidences (``assert_brdf_agrees``' docstring says how); ``cache``
    the testing cache's argument."""
    T = len(result.theta_i)
    incidences = list(range(T)) if incidences is None else list(incidences)
    values = _model_values(spec, ref, result, incidences, cache)
    omega = result.bins.projected_solid_angle()
    per = result.brdf_realisations
    R = 1 if per is None else int(per.shape[0])
    departure = _one_tile_departure(ref, result, cache) if R == 1 else None
    dof = stderr_dof(result) if R == 1 else None  # of result.stderr: ray noise alone
    alpha, rtol, min_events = judging
    verdicts, failing = [], []
    for model, t in zip(values, incidences):
        real_t, strata_t = realisations_at(result, t) if R >= 2 else (None, None)
        dep_t = None if departure is None else departure_of(departure[t], model)
        v = verdict(
            Measured.of(
                result,
                t,
                omega=omega,
                realisations=real_t,
                dof=None if dof is None else dof[t],
                strata=strata_t,
            ),
            Prediction(model, spec.name, ensemble=R >= 2 or departure is not None, departure=dep_t),
            Significance(MODEL_RTOL, min_events, alpha, T),
        )
        if rtol is not None:
            tolerance = tolerance_check(
                result.brdf[t],
                result.stderr[t],
                result.counts[t],
                model,
                omega,
                rtol,
                v.p_threshold,
                v.realisations,
                min_events,
            )
            v = {**v, "tolerance": tolerance}
            ok = tolerance["passed"]
        else:
            ok = verdict_kind(v) != "deviates"
        verdicts.append(v)
        if not ok:
            failing.append(t)
    return _Judged(spec.name, values, verdicts, failing)


def _physics_errors(ref: Reference, result, judging: _Judging, incidences, cache, brdf_values=None):
    """The physics model (``physics.physics_model``) judged as the brdf is at the incidence
    indices ``incidences``: one ``PhysicsError`` each (a tuple), with the brdf's energy over
    the model's where ``brdf_values`` (T, Θ, Φ) are given; None without an ensemble NDF.
    ``cache``: the testing cache's argument (the model's bin averages are kept there)."""
    if ref.exact_shadowing is not None:  # V-grooves, flat: their own G is exact, not Smith's
        return None
    spec = physics_model(ref.ensemble_ndf, ref.material)
    if spec is None:
        return None
    known = _KnownModel(spec.name, "physics", lambda: spec)
    judged = _judge(known, ref, result, judging, cache, incidences)
    records = []
    for t, model, v in zip(incidences, judged.values, judged.verdicts):
        holds = t not in judged.failing
        if judging.rtol is None:
            word = verdict_kind(v)
        else:
            word = f"{'within' if holds else 'beyond'} rtol = {judging.rtol:g}"
        records.append(
            PhysicsError(
                theta_i=float(result.theta_i[t]),
                phi_i=float(result.phi_i[t]),
                model=judged.name,
                ndf=repr(ref.ensemble_ndf),
                holds=holds,
                result=word,
                energy_dev=v["energy_dev"],
                energy_se=_energy_se(v, result, t, model, judging.min_events),
                rel_rms=v["rel_rms"],
                verdict={k: x for k, x in v.items() if k != "tolerance"},
                tolerance=v.get("tolerance"),
                brdf_energy_ratio=None
                if brdf_values is None
                else _energy_ratio(result.bins, brdf_values[t], model),
            )
        )
    return tuple(records)


def _energy_se(v, result, t: int, model, min_events: int) -> float | None:
    """The standard error of verdict ``v``'s energy deviation at incidence ``t``: the
    realisations' (the verdict's ``energy_dev_se``), else the reference's ray noise
    (``_energy_deviation``)."""
    if v["energy_dev_se"] is not None or v["energy_dev"] is None:
        return v["energy_dev_se"]
    sim, se, cnt = result.brdf[t], result.stderr[t], result.counts[t]
    used, sigma = _used_bins(sim, se, cnt, model, min_events)
    return _energy_deviation(sim, sigma, model, result.bins.projected_solid_angle(), used)[1]


def physics_error(
    surface_or_scene,
    material="scene",
    theta_i=None,
    *,
    phi_i=None,
    rays="auto",
    bins=None,
    alpha: float = 0.01,
    rtol: float | None = None,
    seed: int = 0,
    target: float = AUTO_TARGET,
    max_rays: int = AUTO_MAX_RAYS,
    realisations: int | None = None,
    cache=None,
    min_events: int = MIN_EVENTS,
    threads: int | None = None,
) -> tuple[PhysicsError, ...]:
    """The physics' own error at every incidence of the reference: microsim's Torrance–Sparrow
    with the surface's ensemble NDF and height-correlated Smith G (``physics.PHYSICS_MODEL``)
    judged against the reference exactly as ``assert_brdf_agrees`` judges a BRDF (the same
    arguments, the same cached reference). One ``PhysicsError`` per incidence, in the
    reference's order; where ``holds`` is False a correct BRDF of that D with Smith's G fails
    too. A surface without an ensemble NDF (a file heightfield, the flat mirror, oriented
    V-grooves) is a UsageError naming ``surface_or_scene``."""
    judging = _judging(alpha, rtol, min_events)
    ref = resolve_reference(
        surface_or_scene,
        material,
        theta_i,
        phi_i=phi_i,
        rays=rays,
        bins=bins,
        seed=seed,
        target=target,
        max_rays=max_rays,
        realisations=realisations,
    )
    if ref.ensemble_ndf is None or ref.exact_shadowing is not None:
        raise UsageError(
            f"surface_or_scene: {ref.label} has no ensemble NDF (a file heightfield, the flat "
            "mirror or oriented V-grooves) or an exact masking of its own (V-grooves: the "
            "V-groove G), so no Smith model of it to judge"
        )
    result = cached(ref, cache=cache, threads=threads)
    return _physics_errors(ref, result, judging, range(len(result.theta_i)), cache)


def _failing_text(verdicts, with_phi: bool) -> str:
    return incidence.grouped(verdicts) if with_phi else incidence.where(verdicts, False)


def _at(result, t: int, with_phi: bool) -> str:
    return incidence.label(float(result.theta_i[t]), float(result.phi_i[t]), with_phi)


def _message(judged: _Judged, ref, result, judging: _Judging, chart, physics, cache) -> str:
    """The failure message (docs/testing.md, "The failure message"): ``judged`` the brdf at
    every incidence, ``physics`` the ``PhysicsError`` records of its failing incidences (or
    None), ``cache`` the testing cache's argument."""
    name, model, verdicts, failing = judged
    alpha, rtol = judging.alpha, judging.rtol
    with_phi = incidence.several_azimuths(verdicts)
    rays = np.asarray(result.rays)
    rays_txt = (
        f"{int(rays.min()):,}"
        if rays.min() == rays.max()
        else f"{int(rays.min()):,}–{int(rays.max()):,}"
    )
    v0 = verdicts[0]
    against = {
        "ray-noise": "the reference's ray noise",
        "this-tile": "the reference's ray noise (a measured surface, judged as itself)",
        "realisations": f"the scatter of {v0['realisations']} realisations (t tests)",
        "one-tile": "the reference's ray noise beyond the tile's computed departure from its "
        "ensemble",
    }[v0["reference"]]
    mode = (
        f"within rtol = {rtol:g} (tolerance check)"
        if rtol is not None
        else "statistically indistinguishable"
    )
    head = (
        f"brdf {name!r} is not {mode} from the reference at θi = "
        f"{_failing_text([verdicts[t] for t in failing], with_phi)}\n"
        f"reference: {ref.label}; {rays_txt} rays per incidence, bins {result.bins.n_theta} × "
        f"{result.bins.n_phi}, seed {ref.seed}; judged against {against}; α = {alpha:g} over "
        f"{len(verdicts)} incidence(s) (Šidák)"
    )
    cols = [
        "θi",
        "result",
        "χ²/dof",
        "max|z|",
        "rel err (E)",
        "energy dev",
        "energy ratio",
        "deviating θo",
    ]
    if rtol is not None:
        cols[3] = "excess z/thr"
    if with_phi:
        cols.insert(1, "φi")
    rows = [cols]
    for t, v in enumerate(verdicts):
        ok = t not in failing
        dev = ", ".join(f"{a:g}–{b:g}°" for a, b in v["deviations"]) or "–"
        if rtol is not None:
            tol = v["tolerance"]
            zcol = f"{_num(tol['max_excess_z'], '{:.2f}')}/{_num(tol['z_threshold'], '{:.2f}')}"
        else:
            zcol = _num(v["max_abs_z"], "{:.2f}")
        energy = v["energy_dev"]
        rows.append(
            [
                f"{v['theta_i']:g}°",
                *([f"{v['phi_i']:g}°"] if with_phi else []),
                ("ok" if ok else "FAIL") if rtol is not None else verdict_kind(v),
                _num(v["chi2_dof"], "{:.3f}"),
                zcol,
                _num(v["rel_rms"], "{:.2%}"),
                "–" if energy is None else f"{100 * energy:+.2f}%",
                _num(_energy_ratio(result.bins, model[t], result.brdf[t]), "{:.3f}×"),
                dev,
            ]
        )
    widths = [max(len(r[i]) for r in rows) for i in range(len(cols))]
    table = "\n".join(
        "  " + "  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows
    )
    lines = [
        head,
        table,
        "signed as every microsim output: reference minus brdf. energy dev = "
        "Σ Ω (reference − brdf)/Σ Ω brdf over the bins carrying 90 % "
        "of the brdf's energy; worst bins' % = reference/brdf − 1, z = (reference − brdf)/σ; "
        "rel err (E) = energy-weighted RMS of (reference − brdf)/"
        "reference over the reference's 90 % energy bins; energy ratio = Σ Ω⊥ brdf / "
        "Σ Ω⊥ reference over the hemisphere (the brdf's albedo over the reference's)",
    ]
    lines += _cause_lines(ref, result, judged, physics, with_phi)
    lines += physics_lines(physics or (), lambda r: incidence.label(r.theta_i, r.phi_i, with_phi))
    lines += _realised_lines(ref, result, judging, failing, with_phi, cache)
    for t in failing:
        wb = _worst_bins(result, model, t, verdicts[t]["min_events"])
        if wb:
            lines.append(f"worst bins at {_at(result, t, with_phi)}:")
            lines += [f"  {w}" for w in wb]
    lines.append(f"hemisphere chart: {chart}")
    return "\n".join(lines)
