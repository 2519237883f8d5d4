"""A BSDF with transmission — a rough dielectric's f(wi, wo), wo on either side of the
surface — checked as a BRDF is, lobe by lobe.

One code path: each incidence becomes two rows, its reflected and its transmitted lobe, on
the bins of a dielectric ``Result`` (θo from the pole of the side the light leaves by, Δφ of
the direction itself; docs/dielectric.md). A lobe is a function of upper-hemisphere
directions (``analysis.glass``: z flipped for light from inside, and for the side the lobe
leaves by), so the BRDF checks' quadrature, tolerance, verdicts and diagnosis
(``diagnosis.bin_averages``' and ``likely_cause``'s ``lobes``) apply unchanged; what is
specific to a BSDF is only which rows there are, the generalised reciprocity and the
convention:

* ``convention="radiance"`` (microsim's, default): f maps incident radiance to outgoing
  radiance; its BTDF obeys Walter et al. 2007's f_t(i, o)/η_o² = f_t(o, i)/η_i² (eq. 21);
* ``convention="importance"``: the adjoint BSDF a renderer uses to transport importance
  (Mitsuba 3's ``TransportMode.Importance``, pbrt-v4's ``TransportMode::Importance``),
  f*(wi, wo) = f(wo, wi) = f(wi, wo) η_i²/η_o² on the transmitted lobe (η_i the index on wi's
  side). The checks evaluate such a BSDF as f(wo, wi), so the comparison is always in the
  radiance convention.

``assert_bsdf_matches_model``: is my code Walter et al. 2007's BSDF? (against
``WalterDielectric``, no rays; a failure names the bug: ``diagnosis``).
``assert_bsdf_agrees``: does it describe a real rough interface? (against the order 1 of
``simulate(..., transmission=True)`` on an explicit surface, the verdicts of
``analysis.glass``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from microsim.analysis.glass import LOBES, glass_models, lobe_measured
from microsim.analysis.verdicts import Prediction, Significance, verdict, verdict_kind
from microsim.analytic.dielectric import WalterDielectric
from microsim.bins import Bins
from microsim.errors import UsageError
from microsim.sim.predict import FunctionBRDF

from . import cache as _cache
from .agreement import (
    MIN_EVENTS,
    MODEL_RTOL,
    BRDFMismatch,
    _judging,
    readable_name,
    tolerance_check,
    wrap_brdf,
)
from .diagnosis import bin_averages, closest, likely_cause
from .implementation import (
    QUAD_RTOL,
    RECIPROCITY_RTOL,
    Compared,
    Reciprocity,
    check_bin_averages,
    reciprocity_error,
)

__all__ = [
    "CONVENTIONS",
    "BSDF_THETA_I",
    "RECIPROCITY_FLOOR",
    "assert_bsdf_matches_model",
    "assert_bsdf_agrees",
    "radiance_form",
]

CONVENTIONS = ("radiance", "importance")
"""``convention=``: what the BSDF under test maps (module docstring)."""
BSDF_THETA_I = (0, 45, 75, 105, 135, 180)
"""Default incidences of the BSDF checks (degrees): three from the air, three from inside the
medium (105° and 135°: beyond the critical angle of η = 1.5 for the smooth interface, 48° from
−z, where the rough interface's transmission is what is left of it)."""


def _convention(convention) -> str:
    if convention not in CONVENTIONS:
        raise UsageError(f"convention must be one of {', '.join(CONVENTIONS)}, got {convention!r}")
    return convention


def radiance_form(bsdf, convention: str = "radiance"):
    """``bsdf`` as a radiance-convention f(wi, wo): itself, or f(wo, wi) for
    ``convention="importance"`` (the adjoint BSDF, module docstring)."""
    if _convention(convention) == "radiance":
        return bsdf
    return lambda wi, wo: bsdf(wo, wi)


def _theta(theta_i) -> np.ndarray:
    """Incidences in [0, 90) (from the air) or (90, 180] (from inside), a 1-d array."""
    try:
        theta = np.atleast_1d(np.asarray(theta_i, dtype=np.float64))
    except (TypeError, ValueError):
        theta = np.array([np.nan])
    if theta.ndim != 1 or theta.size == 0 or not np.all((theta >= 0) & (theta <= 180)):
        theta = np.array([np.nan])
    if np.isnan(theta).any() or np.any(theta == 90):
        raise UsageError(
            "theta_i must be incidences in degrees, each in [0, 90) (from the air) or "
            f"(90, 180] (from inside the medium), got {theta_i!r}"
        )
    return theta


class _Rows:
    """The rows of a BSDF check: every incidence (θi, φi) with each lobe of ``LOBES``."""

    def __init__(self, theta, phi):
        self.theta = np.repeat(theta, len(LOBES))
        self.phi = np.repeat(np.broadcast_to(phi, theta.shape), len(LOBES))
        self.lobes = list(LOBES) * len(theta)

    @property
    def labels(self) -> list[str]:
        return [f"{t:g}° {lobe}" for t, lobe in zip(self.theta, self.lobes)]


RECIPROCITY_FLOOR = 1e-2
"""The BSDF checks' reciprocity error is relative to max(f(a, b)η_a², f(b, a)η_b²) or this
share of the largest such value over the pairs, whichever is larger: near the edge of
refraction η_i i·h + η_o o·h cancels, and a correct float32 BTDF (Mitsuba 3's
roughdielectric) is off its float64 value by up to 3e-4 relative at 0.2 % of the peak and
15 % at 1e-6 of it, while a non-reciprocal bug (an η² missing) is off at the peak itself."""


def _side_weight(eta: float):
    """w(x) = η_x² (η_x the index on x's side): the generalised reciprocity's weights
    (``implementation.reciprocity_error``)."""
    return lambda w: np.where(w[:, 2] < 0.0, eta * eta, 1.0)


def assert_bsdf_matches_model(
    bsdf,
    model,
    theta_i=BSDF_THETA_I,
    *,
    convention: str = "radiance",
    phi_i: float = 0.0,
    bins=(18, 19),
    name: str | None = None,
    seed: int = 0,
    rtol: float | None = None,
    reciprocity_rtol: float = RECIPROCITY_RTOL,
) -> dict:
    """Assert that the callable ``bsdf(wi, wo)`` ((N, 3) unit vectors away from the surface,
    n = +z, air above, the medium below; wi, wo on either side; N values in sr⁻¹, no cosine)
    implements ``model``: a ``WalterDielectric`` (``WalterDielectric(GGX(0.3),
    Smith(correlated=False), 1.5)``, Mitsuba's roughdielectric), both lobes at every
    incidence — ``assert_brdf_matches_model``'s tolerance (``implementation``) on each lobe.

    ``theta_i``: degrees, [0, 90) lit from the air, (90, 180] from inside the medium (180:
    normal incidence from below); ``convention``: "radiance" (default) or "importance" (module
    docstring); ``phi_i`` the incidences' azimuth, ``bins``, ``name``, ``rtol`` as
    ``assert_brdf_matches_model``'s; ``seed`` the reciprocity pairs': uniform over the
    sphere, checked against the generalised reciprocity of the convention within
    ``reciprocity_rtol`` (relative to the pair's value or ``RECIPROCITY_FLOOR`` × the peak).
    Returns the dict of ``implementation.check_bin_averages`` with ``rows`` (the rows'
    labels, "θi lobe"); a failure (``BRDFMismatch``) tables the rows and names the likely
    cause (``diagnosis``: η², Fresnel's side, the Smith form, the generic ones).
    """
    __tracebackhide__ = True
    if not callable(bsdf):
        raise UsageError(f"bsdf must be a callable f(wi, wo) -> sr⁻¹, got {bsdf!r}")
    if not isinstance(model, WalterDielectric):
        raise UsageError(
            f"model must be a microsim.analytic.WalterDielectric (a rough dielectric's closed "
            f"form), got {model!r}"
        )
    if name is not None and not isinstance(name, str):
        raise UsageError(f"name must be a string (the BSDF's name in messages), got {name!r}")
    convention = _convention(convention)
    name = name or readable_name(bsdf)
    b = bins if isinstance(bins, Bins) else Bins(*bins)
    rows = _Rows(_theta(theta_i), np.asarray(phi_i, dtype=np.float64))
    radiance = radiance_form(bsdf, convention)
    user = FunctionBRDF(wrap_brdf(radiance), True)
    values = bin_averages([user, model], rows.theta, rows.phi, b, QUAD_RTOL, rows.lobes)
    recip = reciprocity_error(radiance, seed, _side_weight(model.eta), RECIPROCITY_FLOOR)
    law = "a physical BSDF obeys f(a, b)/η_b² = f(b, a)/η_a², Walter et al. 2007, eq. 21" + (
        "" if convention == "radiance" else ", in its radiance form f(wo, wi)"
    )
    out = check_bin_averages(
        Compared(*values, rows.labels, b, name, model, rtol, kind="bsdf"),
        Reciprocity(*recip, reciprocity_rtol, law),
        lambda u, r: likely_cause(
            u, model, r, rows.theta, rows.phi, b, QUAD_RTOL, lobes=rows.lobes
        ),
    )
    return {**out, "rows": rows.labels}


def _rows_of(result) -> _Rows:
    return _Rows(np.asarray(result.theta_i, dtype=np.float64), np.asarray(result.phi_i))


def assert_bsdf_agrees(
    bsdf,
    surface_or_scene,
    material="scene",
    theta_i=None,
    *,
    convention: str = "radiance",
    phi_i=None,
    rays: int = 400_000,
    bins=None,
    alpha: float = 0.01,
    rtol: float | None = None,
    seed: int = 0,
    realisations: int | None = None,
    cache=None,
    name: str | None = None,
    min_events: int = MIN_EVENTS,
    threads: int | None = None,
) -> dict:
    """Assert that ``bsdf`` (as ``assert_bsdf_matches_model``'s, in ``convention``) agrees with
    the single scattering of the explicit surface through a dielectric interface: the order 1
    of ``simulate(..., transmission=True)``, both lobes at every incidence, judged by the
    verdicts of the glass study (``analysis.glass``: ``lobe_measured``, ``verdicts.verdict``,
    Student-t over the realisations, else the reference's ray noise), the family of rows at
    level ``alpha`` (Šidák); with ``rtol`` within that relative error
    (``agreement.tolerance_check``).

    ``surface_or_scene``, ``material`` (a real index), ``phi_i``, ``bins``, ``seed``,
    ``realisations``, ``cache``, ``min_events``, ``threads``: as ``assert_brdf_agrees``'s
    (the reference is cached the same way); ``theta_i`` may lie in (90, 180] (lit from inside;
    default: a scene's θi from both sides); ``rays`` a fixed count per incidence (no "auto"
    through an interface). Returns a dict (``verdicts``, one per judged row, ``rows``, their
    labels, ``model`` the bsdf's bin averages per row, ``reference``) when it passes; a
    failure (``BRDFMismatch``) tables the rows and says which of Walter et al. 2007's closed
    forms on the surface's ensemble NDF (``analysis.glass.GLASS_MODELS``) the bsdf is — then
    the deviation is that model's on this surface, the physics — or which bug of the nearest
    one it looks like (``diagnosis.likely_cause``).
    """
    __tracebackhide__ = True
    judging = _judging(alpha, rtol, min_events)
    if not callable(bsdf):
        raise UsageError(f"bsdf must be a callable f(wi, wo) -> sr⁻¹, got {bsdf!r}")
    if name is not None and not isinstance(name, str):
        raise UsageError(f"name must be a string (the BSDF's name in messages), got {name!r}")
    name = name or readable_name(bsdf)
    radiance = radiance_form(bsdf, convention)
    kw = dict(rays=rays, bins=bins, seed=seed, realisations=realisations, transmission=True)
    ref = _cache.resolve_reference(surface_or_scene, material, theta_i, phi_i=phi_i, **kw)
    if theta_i is None:  # a scene's incidences, from the air and from inside
        theta = ref.theta_i + tuple(180.0 - t for t in ref.theta_i)
        ref = replace(ref, theta_i=theta, phi_i=ref.phi_i * 2)
    result = _cache.cached(ref, cache=cache, threads=threads)
    rows = _rows_of(result)
    t_index = np.repeat(np.arange(len(result.theta_i)), len(LOBES))
    user = FunctionBRDF(wrap_brdf(radiance), True)
    values = bin_averages([user], rows.theta, rows.phi, result.bins, MODEL_RTOL, rows.lobes)[0]
    judged = []  # (row, verdict, passed)
    measured = [lobe_measured(result, int(t), lobe) for t, lobe in zip(t_index, rows.lobes)]
    significance = Significance(MODEL_RTOL, judging.min_events, judging.alpha, len(rows.lobes))
    for k, m in enumerate(measured):
        if not m.counts.any():  # no light leaves by this lobe (total internal reflection)
            continue
        v = verdict(
            m, Prediction(values[k], name, ensemble=m.realisations is not None), significance
        )
        if not v.n_bins:  # too few events in every bin to judge
            continue
        if judging.rtol is None:
            ok = verdict_kind(v) != "deviates"
        else:
            tol = tolerance_check(
                m.brdf, m.stderr, m.counts, values[k], m.omega, judging.rtol,
                v.p_threshold, v.realisations, judging.min_events,
            )  # fmt: skip
            v, ok = {**v, "tolerance": tol}, tol["passed"]
        judged.append((k, v, ok))
    out = {
        "verdicts": [v for _, v, _ in judged],
        "rows": [rows.labels[k] for k, _, _ in judged],
        "model": values,
        "reference": result,
    }
    failing = [k for k, _, ok in judged if not ok]
    if failing:
        lines = _agreement_lines(name, ref, result, judged, judging)
        lines += _physics_lines(ref, values, rows, failing, result.bins)
        raise BRDFMismatch("\n".join(lines), out)
    return out


def _agreement_lines(name, ref, result, judged, judging) -> list[str]:
    """The failure message's head and table: one row per judged lobe."""
    rows = _rows_of(result)
    mode = (
        f"within rtol = {judging.rtol:g} (tolerance check)"
        if judging.rtol is not None
        else "statistically indistinguishable"
    )
    bad = ", ".join(rows.labels[k] for k, _, ok in judged if not ok)
    lines = [
        f"bsdf {name!r} is not {mode} from the reference's single scattering at θi = {bad}",
        f"reference: {ref.label} through a dielectric interface (η = {ref.material}), order 1; "
        f"{int(np.max(result.rays)):,} rays per incidence, bins {result.bins.n_theta} × "
        f"{result.bins.n_phi}, seed {ref.seed}; α = {judging.alpha:g} over {len(judged)} "
        "lobe(s) (Šidák)",
        "  θi lobe               result    χ²/dof  max|z|  rel err (E)  energy dev",
    ]
    for k, v, ok in judged:
        word = ("ok" if ok else "FAIL") if judging.rtol is not None else verdict_kind(v)
        chi2 = "–" if v["chi2_dof"] is None else f"{v['chi2_dof']:.3f}"
        z = "–" if v["max_abs_z"] is None else f"{v['max_abs_z']:.2f}"
        rel = "–" if v["rel_rms"] is None else f"{v['rel_rms']:.2%}"
        dev = "–" if v["energy_dev"] is None else f"{100 * v['energy_dev']:+.2f}%"
        lines.append(f"  {rows.labels[k]:<18}  {word:<8}  {chi2:<6}  {z:<6}  {rel:<11}  {dev}")
    lines.append("signed as every microsim output: reference minus bsdf (docs/testing.md)")
    return lines


def _physics_lines(ref, values, rows: _Rows, failing, bins) -> list[str]:
    """Which of Walter et al. 2007's closed forms on the surface's ensemble NDF the bsdf is at
    the failing rows (then the deviation is the physics'), else the bug of the nearest one
    (``diagnosis.likely_cause``); nothing without an ensemble NDF."""
    if ref.ensemble_ndf is None:
        return []
    models = glass_models(ref.ensemble_ndf, float(np.real(ref.material)))
    theta, phi = rows.theta[failing], rows.phi[failing]
    lobes = [rows.lobes[k] for k in failing]
    user = values[failing]
    near = closest(user, models, theta, phi, bins, MODEL_RTOL, lobes)
    if near.is_the_model:
        return [
            f"the bsdf is {near.name} itself (within {near.misfit:.2%} relative RMS): this is "
            f"the deviation of {near.name} on this surface: the physics (Smith's masking, single "
            "scattering), not your implementation"
        ]
    cause = likely_cause(user, models[near.name], near.values, theta, phi, bins, MODEL_RTOL, lobes)
    if cause is None:
        return [
            f"the bsdf is none of {', '.join(models)} (nearest: {near.name}, {near.misfit:.2%} "
            "relative RMS) and no single common bug explains the difference"
        ]
    return [f"likely cause (against {near.name}): {cause.sentence()}"]
