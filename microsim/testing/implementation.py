"""``assert_brdf_matches_model``: is *my code* right? — a BRDF against microsim's own verified
closed form of the same model, with no rays and no noise.

Both the callable and the model (a ``microsim.analytic.models`` object such as
``TorranceSparrow(GGX(0.3), Smith(correlated=True), "aluminium")``, or any callable
``f(wi, wo)``) are bin-averaged by the same adaptive quadrature (``microsim.sim.predict``,
relative accuracy ``QUAD_RTOL`` per bin). By default the only tolerance is the quadrature's: a
bin fails when |brdf − model| > 2 q·model + q·max(model) (each average within q of its integral,
plus an absolute floor of q times the lobe's peak for bins where the model is ~0). A float32
implementation passes it (its relative rounding, ~1e-6, is 100× smaller than q); ``rtol`` widens
the relative part to max(rtol, 2q) for an implementation that approximates on purpose. This
catches an implementation bug at any level, where the surface check (``assert_brdf_agrees``)
can only resolve what the ray noise resolves.

Two further checks of the callable, which every physical BRDF passes: f ≥ 0 and finite
(``agreement.wrap_brdf``), and reciprocity f(wi, wo) = f(wo, wi) at ``RECIPROCITY_PAIRS``
random direction pairs (seeded), to relative ``reciprocity_rtol``.

A failure names the bug the numbers point at (``diagnosis.likely_cause``: the variant of the
model — a constant factor, a cosine left in, Fresnel's η and k swapped or Schlick's, G1 for G2,
separable for height-correlated Smith, α² for α, another roughness — that fits the brdf best).
Deviations are signed as in every microsim output: reference (here microsim's closed form)
minus the code under test, relative to the code under test.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from microsim import checks as _checks
from microsim.analytic.models import BRDFModel
from microsim.bins import Bins
from microsim.errors import UsageError
from microsim.sim.predict import FunctionBRDF, Predictor, predict_incidences

from .agreement import BRDFMismatch, readable_name, wrap_brdf
from .diagnosis import likely_cause

__all__ = ["assert_brdf_matches_model", "QUAD_RTOL", "RECIPROCITY_PAIRS", "RECIPROCITY_RTOL"]

QUAD_RTOL = 1e-4
"""Relative accuracy of each bin average (``predict``'s adaptive Gauss–Legendre)."""
RECIPROCITY_PAIRS = 2000
RECIPROCITY_RTOL = 1e-4
"""Default ``reciprocity_rtol``: |f(a, b) − f(b, a)| ≤ rtol · max(f(a, b), f(b, a)) at every
pair. Single precision: f(a, b) and f(b, a) round differently through the few dozen float32
operations of a microfacet BRDF (unit roundoff 2⁻²⁴ ≈ 6e-8 each, amplified near grazing where
tan²θ = (1 − cos²θ)/cos²θ), so 1e-4 leaves a correct float32 BRDF a wide margin while a
non-reciprocal one — G1 of one direction for G2, Fresnel at cos θi instead of wi·h — differs by
percents."""


def _spec(model, name: str) -> Predictor:
    if isinstance(model, BRDFModel):
        return Predictor(name, model)
    if callable(model):
        return Predictor(name, FunctionBRDF(wrap_brdf(model), symmetric=True))
    raise UsageError(
        f"model must be a microsim.analytic model or a callable f(wi, wo), got {model!r}"
    )


def _upper_directions(rng, n: int) -> np.ndarray:
    """n directions uniform over the upper hemisphere (cos θ ∈ (0, 1])."""
    z = 1.0 - rng.random(n)
    phi = 2 * np.pi * rng.random(n)
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def reciprocity_error(
    brdf, seed: int = 0, side_weight=None, floor: float = 0.0
) -> tuple[float, np.ndarray, np.ndarray]:
    """max_k |f(a_k, b_k) w(a_k) − f(b_k, a_k) w(b_k)| / max(both, ``floor`` × the largest
    value over the pairs) over ``RECIPROCITY_PAIRS`` seeded uniform pairs of upper-hemisphere
    directions, and the worst pair (a, b).

    ``side_weight``: None (w = 1: a BRDF's reciprocity) or w(directions) → (N,) for a BSDF,
    whose pairs are then uniform over the whole sphere (a lower-hemisphere direction is the
    upper one mirrored through the surface, half of each draw): Walter et al. 2007's
    generalised reciprocity f(a, b)/η_b² = f(b, a)/η_a² is w(x) = η_x², η_x the index on x's
    side."""
    rng = np.random.default_rng(seed)
    a, b = _upper_directions(rng, RECIPROCITY_PAIRS), _upper_directions(rng, RECIPROCITY_PAIRS)
    wa = wb = np.ones(RECIPROCITY_PAIRS)
    if side_weight is not None:
        a[:, 2] *= np.where(rng.random(RECIPROCITY_PAIRS) < 0.5, -1.0, 1.0)
        b[:, 2] *= np.where(rng.random(RECIPROCITY_PAIRS) < 0.5, -1.0, 1.0)
        wa, wb = side_weight(a), side_weight(b)
    fab = np.asarray(brdf(a.copy(), b.copy()), dtype=np.float64).reshape(-1) * wa
    fba = np.asarray(brdf(b.copy(), a.copy()), dtype=np.float64).reshape(-1) * wb
    larger = np.maximum(fab, fba)
    least = max(floor * np.max(larger, initial=0.0), 1e-300) if floor else 1e-300
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.abs(fab - fba) / np.maximum(larger, least)
    rel = np.where(np.isfinite(rel), rel, np.inf)
    k = int(np.argmax(rel))
    return float(rel[k]), a[k], b[k]


def _energy_ratios(bins: Bins, user, ref) -> np.ndarray:
    om = bins.projected_solid_angle()
    return (user * om).sum((1, 2)) / np.maximum((ref * om).sum((1, 2)), 1e-300)


def assert_brdf_matches_model(
    brdf,
    model,
    theta_i=(0, 30, 60, 80),
    *,
    phi_i=0.0,
    bins=(18, 19),
    name: str | None = None,
    seed: int = 0,
    rtol: float | None = None,
    reciprocity_rtol: float = RECIPROCITY_RTOL,
) -> dict:
    """Assert that the callable ``brdf(wi, wo)`` ((N, 3) unit vectors, away from the
        surface, n = +z, wi at azimuth ``phi_i``; N values in sr⁻¹, no cosine) implements ``model``
        (a ``microsim.analytic.models`` object, e.g. ``TorranceSparrow(GGX(0.3),
        Smith(correlated=True), "aluminium")``, or a callable) — module docstring for the
        tolerance, reciprocity and the diagnosis.

        ``theta_i``: incidences (degrees, < 90); ``phi_i``: their azimuth (degrees; a scalar or one
        per θi: an anisotropic model depends on it, 0 is the x–z plane); ``bins``: (n_theta, n_phi)
        or ``Bins`` (folded Δφ, as microsim's own verdicts; ``Bins(..., folded=False)`` resolves
        an anisotropic BRDF's ±Δφ asymmetry); ``name`` the brdf's name in messages (default its
        ``agreement.readable_name``); ``seed`` the reciprocity pairs'; ``rtol`` a relative tolerance
    per bin for an implementation that approximates on purpose (None: the quadrature's, module
    docstring); ``reciprocity_rtol`` the reciprocity check's (default ``RECIPROCITY_RTOL``, float32
    -safe). Returns a dict
        (``max_rel_dev``, ``energy_ratio`` per θi, ``reciprocity``) when it passes; raises
        ``BRDFMismatch`` (an AssertionError) whose message names the failing incidences, the
        energy ratio brdf/model per θi, the worst bin and the likely cause.
    """
    __tracebackhide__ = True
    if not callable(brdf):
        raise UsageError(f"brdf must be a callable f(wi, wo) -> sr⁻¹, got {brdf!r}")
    if name is not None and not isinstance(name, str):
        raise UsageError(f"name must be a string (the BRDF's name in messages), got {name!r}")
    name = name or readable_name(brdf)
    b = bins if isinstance(bins, Bins) else Bins(*bins)
    theta = np.atleast_1d(np.asarray(theta_i, dtype=np.float64))
    if theta.ndim != 1 or not np.all((theta >= 0) & (theta < 90)):
        raise UsageError(f"theta_i must be incidences in [0°, 90°), got {theta_i!r}")
    phis = np.atleast_1d(np.asarray(phi_i, dtype=np.float64))
    if phis.ndim != 1 or phis.size not in (1, theta.size) or not np.all(np.abs(phis) <= 360):
        raise UsageError(
            f"phi_i must be an azimuth in degrees in [-360, 360], or one per θi, got {phi_i!r}"
        )
    phis = np.broadcast_to(phis, theta.shape)
    if rtol is not None:
        rtol = _checks.in_range("rtol", rtol, 0.0, 1.0)
    reciprocity_rtol = _checks.in_range("reciprocity_rtol", reciprocity_rtol, 0.0, 1.0)
    specs = [Predictor("brdf", FunctionBRDF(wrap_brdf(brdf), True)), _spec(model, "model")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        vals = predict_incidences(specs, theta, phis, b, rtol=QUAD_RTOL)
    labels = [f"{t:g}°" + (f" (φi {p:g}°)" if any(phis) else "") for t, p in zip(theta, phis)]
    recip, a, bdir = reciprocity_error(brdf, seed)
    return check_bin_averages(
        Compared(vals["brdf"], vals["model"], labels, b, name, model, rtol),
        Reciprocity(recip, a, bdir, reciprocity_rtol, "a physical BRDF is symmetric"),
        lambda user, ref: likely_cause(user, specs[1].model, ref, theta, phis, b),
    )


@dataclass(frozen=True)
class Compared:
    """Bin averages (rows, Θ, Φ) of the code under test (``user``) and of the model (``ref``)
    on ``bins``, one row per ``labels`` entry (an incidence, or an incidence and a lobe), the
    brdf's ``name``, the ``model``, the check's ``rtol`` (None: the quadrature's) and what
    the code under test is called in the message (``kind``: "brdf" or "bsdf")."""

    user: np.ndarray
    ref: np.ndarray
    labels: list
    bins: Bins
    name: str
    model: object
    rtol: float | None
    kind: str = "brdf"


@dataclass(frozen=True)
class Reciprocity:
    """The worst relative reciprocity error ``error`` at the pair (``a``, ``b``), the
    ``allowed`` one and what a physical function obeys (``law``, for the message)."""

    error: float
    a: np.ndarray
    b: np.ndarray
    allowed: float
    law: str


def check_bin_averages(c: Compared, recip: Reciprocity, cause) -> dict:
    """The verdict of ``assert_brdf_matches_model`` (and of the BSDF check) on its bin
    averages: a dict (``max_rel_dev``, ``energy_ratio`` per row, ``reciprocity``) when every
    bin is within the tolerance (module docstring) and the reciprocity error within its own;
    else ``BRDFMismatch`` whose message tables the rows and names ``cause(user, ref)``
    (a ``diagnosis.Cause`` or None)."""
    __tracebackhide__ = True
    user, ref, b = c.user, c.ref, c.bins
    relative = 2 * QUAD_RTOL if c.rtol is None else max(c.rtol, 2 * QUAD_RTOL)
    allowed = relative * ref + QUAD_RTOL * ref.max(axis=(1, 2), keepdims=True)
    bad = np.abs(user - ref) > allowed
    energy = _energy_ratios(b, user, ref)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(
            user > 0, ref / np.where(user > 0, user, 1.0) - 1.0, np.where(ref > 0, np.inf, 0.0)
        )
    out = {
        "max_rel_dev": [float(np.max(np.abs(rel[t]))) for t in range(len(c.labels))],
        "energy_ratio": [float(x) for x in energy],
        "reciprocity": recip.error,
    }
    failing = [t for t in range(len(c.labels)) if bad[t].any()]
    recip_bad = recip.error > recip.allowed
    if not failing and not recip_bad:
        return out
    lines = []
    if failing:
        lines.append(
            f"{c.kind} {c.name!r} does not implement the model ({getattr(c.model, 'name', 'model')}"
            f" {getattr(c.model, 'params', dict)()!r}) at θi = "
            + ", ".join(c.labels[t] for t in failing)
            + f" (bin averages {b.n_theta} × {b.n_phi}, "
            + (f"quadrature accuracy {QUAD_RTOL:g})" if c.rtol is None else f"rtol {c.rtol:g})")
        )
        width = max(6, max(len(x) for x in c.labels))
        lines.append(
            f"  {'θi'.ljust(width)}  energy ratio {c.kind}/model   bins off   worst bin "
            f"(model − {c.kind})/{c.kind}"
        )
        for t in range(len(c.labels)):
            k = np.unravel_index(
                int(np.argmax(np.where(bad[t], np.abs(user[t] - ref[t]), -1))), bad[t].shape
            )
            worst = (
                f"θo {b.theta_centers[k[0]]:.1f}° Δφ {b.phi_centers[k[1]]:.0f}°: "
                f"model {ref[t][k]:.4g} vs {c.kind} {user[t][k]:.4g} sr⁻¹ ({100 * rel[t][k]:+.2f}%)"
                if bad[t].any()
                else "–"
            )
            lines.append(
                f"  {c.labels[t].rjust(width)}  {energy[t]:>10.4f}×  {int(bad[t].sum()):>14d}"
                f"   {worst}"
            )
        found = cause(user, ref)
        lines.append(
            f"likely cause: {found.sentence()}"
            if found is not None
            else 'no single common bug (docs/testing.md, "What a failure names") explains '
            "the difference"
        )
    if recip_bad:
        lines.append(
            f"{c.kind} {c.name!r} is not reciprocal: f(wi, wo) and f(wo, wi) differ by "
            f"{recip.error:.3g} (relative) at wi = {np.round(recip.a, 6).tolist()}, wo = "
            f"{np.round(recip.b, 6).tolist()} (allowed {recip.allowed:g}; {recip.law})"
        )
    raise BRDFMismatch("\n".join(lines), out)
