"""Bin-averaged predictions of analytic BRDF models on the simulation's bins.

The simulation reports, per (θo, Δφ) bin B of ``Bins``, the bin average (docs/design.md,
"Conventions")

    f̄_B = (1/Ω_B) ∫_B f(wi, wo) cos θo dω_o,     Ω_B = ∫_B cos θo dω_o,

so every model is reduced to the same numbers before it is compared. Three ways:

``bin_average``         any vectorised ``brdf_fn(wi, wo)``: adaptive tensor Gauss–Legendre
                        quadrature per bin with an error estimate (the default, deterministic).
``bin_average_ts``      Torrance–Sparrow-type models by randomised quasi-Monte Carlo over the
                        NDF's half vectors (a cross-check; tail bins get few samples).
``bin_average_facets``  Torrance–Sparrow with the *surface's own* facets as a discrete D.

``predict`` evaluates named (model, integration rule) pairs, ``Predictor``s, for several
incidence angles: the rule says how the bin average of the model is computed — ``Quadrature``
(``bin_average`` of ``model.f``), ``QMC`` (``bin_average_ts``) or ``Facets``
(``bin_average_facets``).

Arguments come in one order: the incidence and the bins first, then the model — as the
analytic BRDFs take ``(wi, wo, ...)`` first. Incidence: ``wi`` is a unit (3,) vector with
θi < 90°; ``phi_i`` (degrees) is the azimuth from which the bins' relative azimuth
Δφ = φo − φi is measured. ``phi_i=None`` takes it from ``wi`` (0° at normal incidence), which is
what the estimator does. ``material`` is anything ``fresnel.resolve_material`` accepts (None =
mirror, a name, n, n + ik).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any, Callable, ClassVar, Iterable, Mapping, NamedTuple

import numpy as np

from microsim import checks as _checks
from microsim import vectors
from microsim.analytic.empirical import Empirical
from microsim.analytic.fresnel import fresnel_real_arithmetic, resolve_material
from microsim.analytic.masking import NoMasking, Smith, VGroove, masking_from_kind
from microsim.analytic.models import TorranceSparrow
from microsim.bins import Bins
from microsim.errors import UsageError

from .facet_sum_kernels import G_NONE, G_VGROOVE, add_facet_terms, local_terms
from .fresnel_kernels import fresnel_material

__all__ = [
    "BinAverage",
    "BinEstimate",
    "bin_average",
    "bin_average_ts",
    "bin_average_facets",
    "Predictor",
    "Quadrature",
    "QMC",
    "Facets",
    "RULES",
    "FunctionBRDF",
    "facet_model",
    "predictions",
    "predict",
    "predict_incidences",
]

_MAX_POINTS = 2**20  # directions per brdf_fn call / per facet chunk (bounds memory)
_MAX_CELLS = 2**21  # live quadrature cells; refinement stops (unconverged) beyond


class BinAverage(NamedTuple):
    """Deterministic quadrature result, arrays of shape ``bins.shape``.

    ``values``: f̄_B in sr⁻¹; ``error``: estimated absolute error of f̄_B in sr⁻¹ (|high − low|
    order, summed over the bin's cells: conservative); ``converged``: error within tolerance.
    """

    values: np.ndarray
    error: np.ndarray
    converged: np.ndarray


class BinEstimate(NamedTuple):
    """Sampling result, arrays of shape ``bins.shape``: ``values`` f̄_B and their standard
    errors ``stderr`` (sr⁻¹)."""

    values: np.ndarray
    stderr: np.ndarray


# --- incidence ---------------------------------------------------------------------------------
def _incidence(wi, phi_i) -> tuple[np.ndarray, float]:
    """Validated unit ``wi`` (3,) above the horizon and the reference azimuth in degrees."""
    wi = _checks.directions("wi", wi)
    if wi.shape != (3,):
        raise UsageError(f"wi must be one direction of shape (3,), got shape {wi.shape}")
    if not wi[2] > 1e-12:
        raise UsageError(f"wi must point above the horizon (θi < 90°), got wi_z = {wi[2]!r}")
    if phi_i is None:
        phi_i = float(np.degrees(np.arctan2(wi[1], wi[0]))) if np.hypot(wi[0], wi[1]) > 0 else 0.0
    return wi, float(phi_i)


# --- adaptive quadrature ------------------------------------------------------------------------
@dataclass(frozen=True)
class _Rule:
    """Two tensor Gauss–Legendre rules on [−1, 1]², stacked: nodes (P, 2) and weights (P, 2)
    whose first column is the low-order rule (zero on the high-order nodes) and second the high."""

    nodes: np.ndarray
    weights: np.ndarray

    @classmethod
    def of(cls, n_lo: int, n_hi: int) -> "_Rule":
        if not (isinstance(n_lo, int) and isinstance(n_hi, int) and 1 <= n_lo < n_hi <= 64):
            raise UsageError(
                f"order must be two integers 1 <= n_lo < n_hi <= 64, got {(n_lo, n_hi)!r}"
            )
        parts = []
        for n in (n_lo, n_hi):
            x, w = np.polynomial.legendre.leggauss(n)
            gx, gy = np.meshgrid(x, x, indexing="ij")
            parts.append((np.stack([gx.ravel(), gy.ravel()], axis=1), np.outer(w, w).ravel()))
        (x_lo, w_lo), (x_hi, w_hi) = parts
        weights = np.zeros((len(w_lo) + len(w_hi), 2))
        weights[: len(w_lo), 0] = w_lo
        weights[len(w_lo) :, 1] = w_hi
        return cls(np.concatenate([x_lo, x_hi]), weights)


@dataclass(frozen=True)
class _Cells:
    """Rectangles [t0, t1] × [p0, p1] in (θo, Δφ) radians, each a piece of bin ``b``."""

    t0: np.ndarray
    t1: np.ndarray
    p0: np.ndarray
    p1: np.ndarray
    b: np.ndarray

    def __len__(self) -> int:
        return len(self.b)

    def omega(self) -> np.ndarray:
        """Projected solid angle of each cell, (p1 − p0)(sin²t1 − sin²t0)/2."""
        return 0.5 * (self.p1 - self.p0) * (np.sin(self.t1) ** 2 - np.sin(self.t0) ** 2)

    def take(self, mask) -> "_Cells":
        return _Cells(self.t0[mask], self.t1[mask], self.p0[mask], self.p1[mask], self.b[mask])

    def split(self) -> "_Cells":
        """Each cell into 2 × 2 children."""
        tm, pm = 0.5 * (self.t0 + self.t1), 0.5 * (self.p0 + self.p1)
        t0 = np.concatenate([self.t0, self.t0, tm, tm])
        t1 = np.concatenate([tm, tm, self.t1, self.t1])
        p0 = np.concatenate([self.p0, pm, self.p0, pm])
        p1 = np.concatenate([pm, self.p1, pm, self.p1])
        return _Cells(t0, t1, p0, p1, np.tile(self.b, 4))


def _initial_cells(bins: Bins, symmetric: bool) -> _Cells:
    """One cell per bin; folded bins also get their mirror half [−p1, −p0] unless ``symmetric``."""
    t = np.radians(bins.theta_edges)
    p = np.radians(bins.phi_edges)
    it, ip = np.meshgrid(np.arange(bins.n_theta), np.arange(bins.n_phi), indexing="ij")
    it, ip = it.ravel(), ip.ravel()
    cells = _Cells(t[it], t[it + 1], p[ip], p[ip + 1], it * bins.n_phi + ip)
    if bins.folded and not symmetric:
        mirror = _Cells(cells.t0, cells.t1, -cells.p1, -cells.p0, cells.b)
        cells = _Cells(
            *(
                np.concatenate([a, m])
                for a, m in zip(
                    (cells.t0, cells.t1, cells.p0, cells.p1, cells.b),
                    (mirror.t0, mirror.t1, mirror.p0, mirror.p1, mirror.b),
                )
            )
        )
    return cells


def _integrate_cells(brdf_fn, wi, phi_i_rad: float, cells: _Cells, rule: _Rule):
    """Low- and high-order estimates of ∫_cell f cos θo dω_o = ∫∫ f sinθ cosθ dθ dφ, (C, 2)."""
    out = np.empty((len(cells), 2))
    per_call = max(1, _MAX_POINTS // len(rule.nodes))
    for s in range(0, len(cells), per_call):
        c = cells.take(slice(s, s + per_call))
        tc, th = 0.5 * (c.t0 + c.t1), 0.5 * (c.t1 - c.t0)
        pc, ph = 0.5 * (c.p0 + c.p1), 0.5 * (c.p1 - c.p0)
        theta = tc[:, None] + th[:, None] * rule.nodes[None, :, 0]
        phi = phi_i_rad + pc[:, None] + ph[:, None] * rule.nodes[None, :, 1]
        f = np.asarray(brdf_fn(wi, vectors.spherical(theta, phi)), dtype=np.float64)
        if f.shape != theta.shape or not np.all(np.isfinite(f)):
            raise UsageError(
                "brdf_fn(wi, wo) must return finite values of shape wo.shape[:-1]; "
                f"got shape {f.shape}" + ("" if f.shape != theta.shape else " with NaN/inf")
            )
        g = f * np.sin(theta) * np.cos(theta)
        out[s : s + len(c)] = (g @ rule.weights) * (th * ph)[:, None]
    return out


def bin_average(
    wi,
    bins: Bins,
    brdf_fn: Callable,
    phi_i: float | None = None,
    rtol: float = 1e-3,
    *,
    floor: float = 1e-6,
    symmetric: bool = True,
    order: tuple[int, int] = (4, 8),
    max_depth: int = 8,
    min_depth: int = 0,
) -> BinAverage:
    """Bin averages f̄_B (sr⁻¹) of a vectorised ``brdf_fn(wi, wo) -> sr⁻¹`` (wi (3,), wo (..., 3)).

    Quadrature variable. ∫_B f cos θo dω = ∫∫ f sinθ cosθ dθ dφ over the bin rectangle in
    (θo, Δφ), integrated by tensor Gauss–Legendre in (θ, φ). (θ, φ) is chosen over s = sin²θ,
    where the cos weight would be exact, because wo(θ, φ) is analytic in θ while in s it has
    √s and √(1 − s) branch points at both ends of the hemisphere (sin θ and cos θ); the weight
    sinθ cosθ = sin(2θ)/2 is entire, and 8 nodes integrate it to ~1e-15 even over [0, π/2].
    The result is divided by the exact Ω_B (``Bins.projected_solid_angle``).

    Adaptivity. Every cell gets an ``order`` = (n_lo, n_hi) pair of rules; |I_hi − I_lo| is the
    error estimate of I_hi (conservative: it is really the low rule's error). A bin is done
    when its summed error ≤ tol_B = max(rtol |I_B|, rtol · floor · peak · Ω_B), peak being the
    largest current f̄; otherwise each of its cells whose error exceeds its Ω-proportional
    share of tol_B is split 2 × 2, all failing cells of all bins at once (one Python loop over
    levels, none over bins). Cells still failing at ``max_depth`` (or when refining them would
    exceed ~2e6 live cells) are accepted and their bins flagged ``converged = False``;
    ``min_depth`` forces that many uniform refinements first.

    ``symmetric=True`` states that f(Δφ) = f(−Δφ) (isotropic models, relative azimuth): folded
    bins then integrate only Δφ ∈ [φ₁, φ₂]; with ``symmetric=False`` they also integrate the
    mirror half [−φ₂, −φ₁]. Unfolded bins are unaffected.
    """
    wi, phi_i = _incidence(wi, phi_i)
    rtol = _checks.in_range("rtol", rtol, 0.0, 1.0, lo_open=True)
    floor = _checks.in_range("floor", floor, 0.0, 1.0)
    max_depth = int(_checks.in_range("max_depth", max_depth, 0, 30))
    min_depth = int(_checks.in_range("min_depth", min_depth, 0, max_depth))
    rule = _Rule.of(*order)
    nb = bins.n_theta * bins.n_phi
    cells = _initial_cells(bins, symmetric)
    omega = np.bincount(cells.b, cells.omega(), minlength=nb)  # Ω of the integrated region
    acc = np.zeros((2, nb))  # accepted integral, error

    def tolerance(total):
        peak = np.max(np.abs(total) / omega)
        return np.maximum(rtol * np.abs(total), rtol * floor * peak * omega)

    for depth in range(max_depth + 1):
        est = _integrate_cells(brdf_fn, wi, np.radians(phi_i), cells, rule)
        val, err = est[:, 1], np.abs(est[:, 1] - est[:, 0])
        tol = tolerance(acc[0] + np.bincount(cells.b, val, minlength=nb))
        bin_done = acc[1] + np.bincount(cells.b, err, minlength=nb) <= tol
        share = tol[cells.b] * cells.omega() / omega[cells.b]
        accept = bin_done[cells.b] | (err <= share)
        if depth < min_depth:
            accept[:] = False
        if depth == max_depth or 4 * np.count_nonzero(~accept) > _MAX_CELLS:
            accept[:] = True
        acc += np.stack(
            [
                np.bincount(cells.b[accept], val[accept], minlength=nb),
                np.bincount(cells.b[accept], err[accept], minlength=nb),
            ]
        )
        cells = cells.take(~accept).split()
        if len(cells) == 0:
            break
    converged = acc[1] <= tolerance(acc[0]) * (1.0 + 1e-12)
    return BinAverage(
        (acc[0] / omega).reshape(bins.shape),
        (acc[1] / omega).reshape(bins.shape),
        converged.reshape(bins.shape),
    )


# --- Torrance–Sparrow by sampling half vectors --------------------------------------------------
def _reflection_terms(wi, h, cos_i: float, eta, masking):
    """wo = 2(wi·h)h − wi and x = F(wi·h) G(wi, wo, h) (wi·h)⁺/(cos θi h_z) for unit h (N, 3),
    G of the ``masking`` object, F in the estimator's real arithmetic
    (``fresnel_real_arithmetic``: ``fresnel`` to 1e-12, each value independent of its array
    position, ~10× faster on the millions of half vectors of a facet sum).

    x is what one half vector contributes to ∫_B f cos θo dω_o (see ``bin_average_ts``); it is 0
    where wi·h ≤ 0, wo is below the horizon (G = 0) or h_z = 0.
    """
    wih = h @ wi
    wo = vectors.normalize(2.0 * wih[:, None] * h - wi)
    wi_b = np.broadcast_to(wi, wo.shape)
    g = masking.g2_cosines(wi_b, wo, h[:, 2], vectors.dot(wi_b, h), vectors.dot(wo, h))
    hz = h[:, 2]
    ok = (wih > 0.0) & (hz > 0.0) & (wo[:, 2] > 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = fresnel_real_arithmetic(np.clip(wih, 0.0, 1.0), eta) * g * wih / (cos_i * hz)
    return wo, np.where(ok, x, 0.0)


def bin_average_ts(
    wi,
    bins: Bins,
    ndf,
    shadowing: str = "vgroove",
    material=None,
    phi_i: float | None = None,
    n: int = 2**20,
    *,
    replicates: int = 16,
    seed: int = 0,
) -> BinEstimate:
    """Torrance–Sparrow bin averages by randomised quasi-Monte Carlo over half vectors (sr⁻¹).

    Identity. With f = F G D/(4 cos θi cos θo) (Mikkelsen 2009, eq. 13/18) and the Jacobian
    dω_o = 4 (wo·h) dω_h of wo = 2(wi·h)h − wi (Mikkelsen 2009, eq. 15; wo·h = wi·h):

        ∫_B f cos θo dω_o = ∫ F G D(h) (wi·h) / (cos θi) 1(wo(h) ∈ B) dω_h
                          = E_{h ~ D(h) h_z} [ F(wi·h) G(wi, wo, h) (wi·h)/(cos θi h_z) 1(wo ∈ B) ],

    the cos θo of the weight cancelling the 1/cos θo of f and 4(wo·h) cancelling the 4.
    h is drawn with ``ndf.sample`` from scrambled Sobol points: ``replicates`` independent
    scramblings (seeded from ``seed``) of n/replicates points each (a power of 2); the value is
    their mean and ``stderr`` their standard deviation / √replicates (randomised QMC).
    Tail bins get few samples: use this to cross-check ``bin_average``, not instead of it.
    """
    wi, phi_i = _incidence(wi, phi_i)
    masking, eta = masking_from_kind(shadowing, ndf), resolve_material(material)
    return _half_vector_qmc(wi, phi_i, bins, ndf, masking, eta, n, replicates, seed)


def _half_vector_qmc(wi, phi_i, bins, ndf, masking, eta, n, replicates, seed) -> BinEstimate:
    """``bin_average_ts`` with h ~ ``ndf`` and G of ``masking`` (validated incidence)."""
    replicates = int(_checks.in_range("replicates", replicates, 2, 2**12))
    per = int(n) // replicates
    if int(n) != n or per < 1 or per & (per - 1):
        raise UsageError(
            f"n must be an integer with n/replicates a power of 2, got n={n!r}, "
            f"replicates={replicates}"
        )
    nb = bins.n_theta * bins.n_phi
    omega = bins.projected_solid_angle().ravel()
    sums = np.zeros((replicates, nb))
    for r, child in enumerate(np.random.SeedSequence(seed).spawn(replicates)):
        from scipy.stats import qmc  # ~1 s to import: only for the QMC path

        sobol = qmc.Sobol(d=2, scramble=True, seed=np.random.default_rng(child))
        for s in range(0, per, _MAX_POINTS):
            u = sobol.random(min(_MAX_POINTS, per - s))
            h = ndf.sample(u[:, 0], u[:, 1])
            wo, x = _reflection_terms(wi, h, wi[2], eta, masking)
            idx = bins.locate(wo, phi_i)
            keep = (idx >= 0) & (x > 0.0)
            sums[r] += np.bincount(idx[keep], x[keep], minlength=nb)
    vals = sums / (per * omega)
    return BinEstimate(
        vals.mean(axis=0).reshape(bins.shape),
        (vals.std(axis=0, ddof=1) / np.sqrt(replicates)).reshape(bins.shape),
    )


# --- Torrance–Sparrow with the surface's own facets ---------------------------------------------
def _rotate_z(normals: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """normals (K, 3) rotated about z by angles psi (K, J): (K, J, 3)."""
    c, s = np.cos(psi), np.sin(psi)
    nx, ny, nz = (normals[:, i, None] for i in range(3))
    return np.stack([c * nx - s * ny, s * nx + c * ny, np.broadcast_to(nz, psi.shape)], axis=-1)


def _merge_tilts(normals: np.ndarray, weights: np.ndarray, decimals: int = 12):
    """One normal (sin θ, 0, cos θ) per distinct tilt θ (rounded to ``decimals`` radians) with
    the summed weight: under azimuth averaging only the tilt matters, and merging the faces
    of a groove (equal tilts) keeps the facets that ``stderr`` treats as independent distinct."""
    theta = np.round(np.arctan2(np.hypot(normals[:, 0], normals[:, 1]), normals[:, 2]), decimals)
    tilts, inv = np.unique(theta, return_inverse=True)
    w = np.bincount(inv.ravel(), weights)
    return vectors.spherical(tilts, 0.0), w


def bin_average_facets(
    wi,
    bins: Bins,
    normals,
    weights=None,
    shadowing: str = "vgroove",
    material=None,
    phi_i: float | None = None,
    azimuths: int | None = None,
    *,
    smith_ndf=None,
    seed: int = 0,
) -> BinEstimate:
    """Torrance–Sparrow bin averages with the surface's own facet normals as D (sr⁻¹).

    Discrete NDF: the facets' projected-area fractions a_k = weights_k/Σ weights (weights =
    facet area × n_z) give the pdf D(h) h_z = Σ_k a_k δ(h − n_k), and the half-vector identity
    of ``bin_average_ts`` becomes an exact finite sum:

        ∫_B f cos θo dω_o = Σ_k a_k F(wi·n_k) G(wi, wo_k, n_k) (wi·n_k)/(cos θi n_kz) 1(wo_k ∈ B),

    wo_k = 2(wi·n_k)n_k − wi (Mikkelsen 2009, eq. 9 read facet by facet: facet k intercepts the
    fraction a_k (wi·n_k)/(n_kz cos θi) of the incident flux). G: "vgroove" is local
    (Mikkelsen 2009, eq. 25); "smith"/"smith-correlated" use Λ of ``smith_ndf`` (default
    ``Empirical(normals, weights)``, isotropic); "none" keeps only the χ⁺ conditions.

    ``azimuths=J`` averages the facet set over a uniform rotation ψ about z (V-groove surfaces,
    ``Surface.azimuth_average``: the isotropic V-cavity). Choice: each facet is replaced by J
    copies at ψ_kj = 2π(j + u_k)/J with one uniform offset u_k per facet (stratified and
    randomised, seeded by ``seed``): unbiased for every J, with an azimuthal error that averages
    out over facets and is included in ``stderr``. Only tilts matter then, so facets of equal
    tilt (the faces of a groove) are first merged into one with their summed weight.
    Take J so that the reflected directions of
    one facet, which move by up to ~2 θ_k · 2π/J between copies, sample each bin they cross
    several times (J ≳ 4 · 2π · 2θ_max / bin width).

    ``stderr``: the (merged) facets are treated as independent draws from D h_z — exact for
    i.i.d. normals, conservative for stratified ones (e.g. quantile groove tilts) — so with X_kB the
    (azimuth-averaged) contribution of facet k to bin B, Var(I_B) = Σ_k a_k² (X_kB − I_B)².
    Memory is bounded by processing ~1e6 (facet, azimuth) pairs at a time.
    """
    wi, phi_i = _incidence(wi, phi_i)
    masking, eta = masking_from_kind(shadowing, smith_ndf), resolve_material(material)
    nrm, w = _facet_set(normals, weights)
    if isinstance(masking, Smith) and masking.ndf is None:
        masking = Smith(Empirical(nrm, w), masking.correlated)
    return _facet_sum(wi, phi_i, bins, nrm, w, masking, eta, azimuths, seed)


def _facet_set(normals, weights) -> tuple[np.ndarray, np.ndarray]:
    """Validated facet normals (N, 3) and weights (N,) (None: equal)."""
    nrm = _checks.directions("normals", normals)
    if nrm.ndim != 2 or len(nrm) == 0 or np.any(nrm[:, 2] <= 0.0):
        raise UsageError("normals must be a non-empty (N, 3) array of unit vectors with n_z > 0")
    w = np.ones(len(nrm)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (len(nrm),) or not np.all(np.isfinite(w)) or np.any(w < 0) or not w.sum() > 0:
        raise UsageError(f"weights must be {len(nrm)} finite values >= 0 with a positive sum")
    return nrm, w


def _facet_sum(wi, phi_i, bins, nrm, w, masking, eta, azimuths, seed) -> BinEstimate:
    """``bin_average_facets`` on a validated incidence and facet set, G of ``masking``: the
    (facet, azimuth) pairs' terms compiled where G depends on a pair's cosines alone
    (V-groove, none: ``facet_sum_kernels.local_terms``), from NumPy otherwise (Smith's Λ of
    an NDF); their sums compiled (``facet_sum_kernels.add_facet_terms``)."""
    J = 1 if azimuths is None else int(_checks.in_range("azimuths", azimuths, 1, 2**16))
    if azimuths is not None:
        nrm, w = _merge_tilts(nrm, w)
    a = w / w.sum()
    rng = np.random.default_rng(seed)
    nb = bins.n_theta * bins.n_phi
    total, s1, s2 = np.zeros(nb), np.zeros(nb), np.zeros(nb)  # Σ a X, Σ a² X, Σ a² X²
    acc, touched = np.zeros(nb), np.empty(nb, dtype=np.int64)
    g_mode = {VGroove: G_VGROOVE, NoMasking: G_NONE}.get(type(masking))
    wi = np.ascontiguousarray(wi, dtype=np.float64)
    per_chunk = max(1, _MAX_POINTS // J)
    for s in range(0, len(nrm), per_chunk):
        n_k, a_k = nrm[s : s + per_chunk], np.ascontiguousarray(a[s : s + per_chunk])
        u = rng.random(len(n_k)) if J > 1 else np.zeros(len(n_k))  # azimuth offsets u_k
        if g_mode is not None:
            x, idx = np.empty(len(n_k) * J), np.empty(len(n_k) * J, dtype=np.int64)
            local_terms(
                np.ascontiguousarray(n_k, dtype=np.float64), u, J, wi, fresnel_material(eta),
                g_mode, bins.kernel_grid(phi_i), x, idx,
            )  # fmt: skip
        else:
            h = n_k
            if J > 1:
                psi = 2.0 * np.pi * (np.arange(J)[None, :] + u[:, None]) / J
                h = _rotate_z(n_k, psi).reshape(-1, 3)
            wo, x = _reflection_terms(wi, h, wi[2], eta, masking)
            idx = bins.locate(wo, phi_i)
        add_facet_terms(x, idx, J, a_k, acc, touched, total, s1, s2)
    var = np.maximum(s2 - 2.0 * total * s1 + total**2 * np.sum(a * a), 0.0)
    omega = bins.projected_solid_angle().ravel()
    shape = bins.shape
    return BinEstimate((total / omega).reshape(shape), (np.sqrt(var) / omega).reshape(shape))


# --- models and their integration rules -------------------------------------------------------
@dataclass(frozen=True)
class Quadrature:
    """Integrate ``model.f`` per bin by adaptive Gauss–Legendre quadrature (``bin_average``,
    to ``predict``'s ``rtol``; half a folded bin when ``model.symmetric``). Any model."""


@dataclass(frozen=True)
class QMC:
    """Randomised QMC over ``n`` half vectors h ~ D(h) h_z in ``replicates`` scramblings seeded
    by ``seed`` (``bin_average_ts``): for a ``TorranceSparrow`` model, a cross-check of
    ``Quadrature`` (tail bins get few samples)."""

    n: int = 2**20
    replicates: int = 16
    seed: int = 0

    def __post_init__(self):
        object.__setattr__(self, "n", int(_checks.in_range("n", self.n, 2, 2**40)))


@dataclass(frozen=True, eq=False)
class Facets:
    """The exact finite sum over a facet set (``bin_average_facets``) for a ``TorranceSparrow``
    model whose D is those facets' (``facet_model``): its masking and material, these
    ``normals`` (N, 3), projected-area ``weights`` (None: equal) and ``azimuths`` copies
    (their offsets seeded by ``seed``).

    Provenance (read by ``compare.attach_models``): ``fingerprints``, the sorted fingerprints
    of the surfaces the facets come from; ``ensemble``, the name of the ensemble prediction this
    tile model is paired with; ``continuum``, True when the facets stand for a continuum of
    tilts rather than a traced tile. Compared by identity (holds arrays)."""

    normals: Any
    weights: Any = None
    azimuths: int | None = None
    seed: int = 0
    fingerprints: tuple[str, ...] | None = None
    ensemble: str | None = None
    continuum: bool = False

    def __repr__(self) -> str:
        shape = " × ".join(map(str, np.shape(self.normals)))
        return f"Facets(<{shape} normals>, azimuths={self.azimuths!r})"


RULES = (Quadrature, QMC, Facets)
"""The integration rules, each a frozen dataclass."""


@dataclass(frozen=True, eq=False)
class FunctionBRDF:
    """A vectorised ``fn(wi, wo)`` (sr⁻¹) as a model; ``symmetric``: f is unchanged by
    mirroring wo about the plane of incidence (as ``BRDFModel``)."""

    fn: Callable
    symmetric: bool = False
    source: ClassVar[str] = "a function f(wi, wo)"

    def f(self, wi, wo):
        return self.fn(wi, wo)

    def params(self) -> dict:
        return {"fn": self.fn, "symmetric": self.symmetric}


def facet_model(normals, weights=None, masking="vgroove", material=None) -> TorranceSparrow:
    """``TorranceSparrow`` with D the facets' histogram (``Empirical(normals, weights)``), for
    the ``Facets`` rule; ``masking``: an object or a shadowing name (Smith: the facets' Λ)."""
    nrm, w = _facet_set(normals, weights)
    return TorranceSparrow(Empirical(nrm, w), masking, material)


@dataclass(frozen=True, eq=False)
class Predictor:
    """A named model to predict and the rule computing its bin averages: ``model`` any
    ``BRDFModel`` (``f(wi, wo)``); ``rule`` one of ``RULES`` (``QMC`` and ``Facets`` need a
    ``TorranceSparrow``). Compared by identity."""

    name: str
    model: Any
    rule: Quadrature | QMC | Facets = Quadrature()

    def __post_init__(self):
        if not isinstance(self.rule, RULES):
            raise UsageError(
                f"rule must be Quadrature(), QMC(n) or Facets(normals, ...), got {self.rule!r}"
            )
        if isinstance(self.rule, Quadrature):
            if not callable(getattr(self.model, "f", None)):
                raise UsageError(
                    f"model must be a BRDFModel (f(wi, wo), params(), source), got {self.model!r}"
                )
        elif not isinstance(self.model, TorranceSparrow):
            raise UsageError(
                f"model must be a TorranceSparrow for {type(self.rule).__name__}(), "
                f"got {self.model!r}"
            )

    @classmethod
    def facets(
        cls,
        name: str,
        normals,
        weights=None,
        masking="vgroove",
        material=None,
        azimuths: int | None = None,
        **provenance,
    ) -> "Predictor":
        """``facet_model`` of the facets with the ``Facets`` rule (``provenance``: its
        ``fingerprints``, ``ensemble``, ``continuum``)."""
        model = facet_model(normals, weights, masking, material)
        return cls(name, model, Facets(normals, weights, azimuths, **provenance))

    def bin_values(self, wi, bins: Bins, phi_i: float, rtol: float) -> np.ndarray:
        """f̄_B (sr⁻¹, ``bins.shape``) at one incidence (quadrature warns when a bin misses
        ``rtol``)."""
        rule, model = self.rule, self.model
        if isinstance(rule, Quadrature):
            symmetric = bool(getattr(model, "symmetric", False))
            res = bin_average(wi, bins, model.f, phi_i, rtol, symmetric=symmetric)
            if not res.converged.all():
                warnings.warn(
                    f"model {self.name!r}: {int((~res.converged).sum())} bins did not "
                    f"reach rtol={rtol} (max error {res.error.max():.3g} sr^-1)",
                    RuntimeWarning,
                    stacklevel=3,
                )
            return res.values
        wi, phi_i = _incidence(wi, phi_i)
        eta = resolve_material(model.material)
        if isinstance(rule, QMC):
            return _half_vector_qmc(
                wi, phi_i, bins, model.ndf, model.masking, eta, rule.n, rule.replicates, rule.seed
            ).values
        nrm, w = _facet_set(rule.normals, rule.weights)
        return _facet_sum(
            wi, phi_i, bins, nrm, w, model.masking, eta, rule.azimuths, rule.seed
        ).values


def predictions(models) -> list[Predictor]:
    """``models`` as a list of ``Predictor``: an iterable of them, or a mapping name → a
    model, a (model, rule) pair or a ``Predictor``."""
    if isinstance(models, Mapping):
        out = []
        for name, m in models.items():
            if isinstance(m, Predictor):
                out.append(m)
            elif isinstance(m, tuple) and len(m) == 2:
                out.append(Predictor(str(name), *m))
            else:
                out.append(Predictor(str(name), m))
        return out
    out = list(models)
    for m in out:
        if not isinstance(m, Predictor):
            raise UsageError(
                f"models: a list must hold Predictors (pass model objects as a mapping "
                f"name → model or (model, rule)), got {m!r}"
            )
    return out


def predict(
    models,
    theta_i: Iterable[float],
    bins: Bins,
    phi_i: float = 0.0,
    rtol: float = 1e-3,
) -> dict[str, np.ndarray]:
    """Bin averages (sr⁻¹) of every model for incidence angles ``theta_i`` (degrees, < 90)
    at azimuth ``phi_i`` (degrees): name → array (len(theta_i), n_theta, n_phi).

    ``models``: ``Predictor``s, or a mapping name → model, (model, rule) or ``Predictor``
    (``predictions``). Quadrature models warn (RuntimeWarning) when a bin misses ``rtol``.
    """
    models = predictions(models)
    names = [m.name for m in models]
    if len(set(names)) != len(names):
        raise UsageError(f"model names must be unique, got {names}")
    thetas = np.atleast_1d(np.asarray(theta_i, dtype=np.float64))
    for t in thetas:
        _checks.in_range("theta_i", t, 0.0, 90.0, hi_open=True)
    out = {}
    for m in models:
        out[m.name] = np.stack(
            [m.bin_values(vectors.spherical_deg(t, phi_i), bins, phi_i, rtol) for t in thetas]
        )
    return out


def predict_incidences(
    models, theta_i, phi_i, bins: Bins, rtol: float = 1e-3
) -> dict[str, np.ndarray]:
    """``predict`` at incidences (θi, φi) given pairwise (degrees; ``phi_i`` one per θi or a
    scalar): name → array (T, n_theta, n_phi), the incidences in the given order."""
    models = predictions(models)
    thetas = np.atleast_1d(np.asarray(theta_i, dtype=np.float64))
    phis = np.broadcast_to(np.asarray(phi_i, dtype=np.float64), thetas.shape)
    out = {m.name: np.empty((len(thetas),) + bins.shape) for m in models}
    for phi in np.unique(phis):
        sel = np.flatnonzero(phis == phi)
        for name, values in predict(models, thetas[sel], bins, float(phi), rtol).items():
            out[name][sel] = values
    return out
