"""Fitting closed-form BRDF models to a simulation (Löw eq. 29–33).

One parameter set per model is fitted to all incidences of a ``Result`` jointly, by bounded
least squares (``scipy.optimize.least_squares``, trust-region reflective) on Löw's logarithmic
metric E2 (eq. 31–33):

    E2(p) = Σ_B [ln(1 + cosθi f̄_B) − ln(1 + cosθi m_B(p))]² sinθo Δθi Δθo Δφo,

over the bins with ≥ ``min_events`` single-bounce events (the rest carry no information). The
log compresses the dynamic range, so the wide-angle scattering is not drowned by the peak.
Δθi is the spacing of the run's incidences (``np.gradient``; 1° for a single one) and Δφo the
full width of a bin in Δφ (both halves of a folded bin).

Like with like at acceptable cost: during the fit a model's bin averages m_B come from a fixed
per-bin Gauss–Legendre rule (``bin_rule``, 3 × 3 nodes in (θo, Δφ), cos-weighted, directions
precomputed); the fitted model is then evaluated once with the adaptive
``predict.bin_average`` (rtol 1e-3) for the verdict and for E1/E2 (``an.low_e1/low_e2``).

Several starts (the model's default, then scrambled Halton points within the bounds, seeded)
are run and the lowest cost is kept. Each bound of a parameter's box is either *physical*, a
constraint of the model itself (kd ≥ 0, a fraction ≤ 1, a lump exponent ≥ 0): a fit ending
there is a constrained minimum, converged; or a *search limit*, a practical end of the search
(C = 10, ior = 100, m = 0.01): a fit ending there was stopped by the box, and the best fit may
lie beyond (``Param.physical``, ``FitResult.bounds_reached``). Models (``FIT_MODELS``):

``cook-torrance``   kd/π + ks·TS(Beckmann(m), V-groove G, exact Fresnel of the scene's ior).
                    Single scattering has no diffuse term, but fitting frameworks carry one
                    (Löw §5): kd is included, bounded to [0, 1], and reported (expect ≈ 0).
``low-microfacet``  Löw eq. 15: A, B, C, kd, real ior n (as the paper).
``low-smooth``      Löw eq. 12: A, B, C, kd, real ior n; G' = 1 (Löw's choice).
``edwards``         Edwards eq. 36 with ``EdwardsParams`` (orthogonal projection, as the paper).

``fit_edwards_disk`` fits the Edwards BRDF at a single viewing direction to a histogram of
simulated half vectors on Edwards' disk (the contours of ``microsim view --what disk``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np
from scipy import optimize
from scipy.stats import qmc

from microsim import analytic as an
from microsim import checks as _checks
from microsim import vectors
from microsim.analytic.edwards import DiskPoints
from microsim.bins import Bins
from microsim.errors import UsageError
from microsim.sim.predict import bin_average

__all__ = [
    "Param",
    "BoundReached",
    "FitModel",
    "FIT_MODELS",
    "FitData",
    "FitResult",
    "BinRule",
    "bin_rule",
    "fit_model",
    "fit_all",
    "model_bin_values",
    "DiskFit",
    "fit_edwards_disk",
]


# --- parameters and models ----------------------------------------------------------------------
AT_BOUND_RTOL = 1e-5
"""A fitted parameter within this fraction of its (encoded) range from a bound is at the bound."""


@dataclass(frozen=True)
class Param:
    """A bounded parameter. ``scale``: the optimiser works on x = p ("lin"), ln p ("log",
    needs lo > 0) or ln(1 + p) ("log1p"); ``start`` is the first start's value; ``physical``:
    (lower, upper), whether each bound is a constraint of the model (kd ≥ 0) rather than a
    search limit (module docstring)."""

    name: str
    lo: float
    hi: float
    start: float
    scale: str = "lin"
    physical: tuple[bool, bool] = (False, False)

    def encode(self, p):
        return {"lin": lambda v: v, "log": np.log, "log1p": np.log1p}[self.scale](p)

    def decode(self, x):
        return {"lin": lambda v: v, "log": np.exp, "log1p": np.expm1}[self.scale](x)


@dataclass(frozen=True)
class BoundReached:
    """A fitted parameter ``param`` that ended on the ``side`` ("lower" or "upper") bound
    ``bound`` of its box; ``physical``: the bound is a constraint of the model (the fit is a
    constrained minimum there), else a search limit (the best fit may lie beyond)."""

    param: str
    bound: float
    side: str
    physical: bool


@dataclass(frozen=True)
class FitModel:
    """A fittable model: ``make(params, ior) -> brdf_fn(wi, wo)`` (sr⁻¹, isotropic).

    Optional, both or neither: ``prepare(wi, wo)``, the parameter-independent precomputation at
    the rule's fixed (wi, wo), done once per fit, and ``make_prepared(params, ior) ->
    fn(prepared)``, the values ``make(params, ior)(wi, wo)`` from it (``at`` uses them)."""

    name: str
    params: tuple[Param, ...]
    make: Callable[[Mapping[str, float], object], Callable]
    description: str
    prepare: Callable[[np.ndarray, np.ndarray], object] | None = None
    make_prepared: (
        Callable[[Mapping[str, float], object], Callable[[object], np.ndarray]] | None
    ) = None

    def __post_init__(self):
        if (self.prepare is None) != (self.make_prepared is None):
            raise UsageError(
                f"FitModel {self.name!r}: prepare and make_prepared must be given together"
            )

    def at(self, wi, wo) -> Callable[[Mapping[str, float], object], np.ndarray]:
        """``values(params, ior)``: the model's values (sr⁻¹) at the fixed pairs (wi, wo),
        with the ``prepare`` part computed once, here."""
        if self.prepare is None:
            return lambda params, ior: self.make(params, ior)(wi, wo)
        prepared = self.prepare(wi, wo)
        return lambda params, ior: self.make_prepared(params, ior)(prepared)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    def bounds_x(self) -> tuple[np.ndarray, np.ndarray]:
        return (
            np.array([p.encode(p.lo) for p in self.params]),
            np.array([p.encode(p.hi) for p in self.params]),
        )

    def decode(self, x) -> dict[str, float]:
        """Parameters from the optimiser's x, clipped into the bounds (rounding at the ends)."""
        return {p.name: float(np.clip(p.decode(v), p.lo, p.hi)) for p, v in zip(self.params, x)}

    def encode(self, params: Mapping[str, float]) -> np.ndarray:
        return np.array([p.encode(params[p.name]) for p in self.params], dtype=np.float64)

    def at_bounds(self, x, rtol: float = AT_BOUND_RTOL) -> tuple[str, ...]:
        """Names of the parameters whose optimiser value x lies within ``rtol`` of the encoded
        box's width from one of its ends (the optimum there is the bound, not a minimum)."""
        lo, hi = self.bounds_x()
        near = np.abs(np.asarray(x) - lo) <= rtol * (hi - lo)
        near |= np.abs(hi - np.asarray(x)) <= rtol * (hi - lo)
        return tuple(p.name for p, n in zip(self.params, near) if n)

    def bound_reached(self, name: str, value: float) -> BoundReached:
        """The bound of parameter ``name`` that ``value`` lies on: the nearer end of its box
        (in the optimiser's encoding)."""
        p = next(q for q in self.params if q.name == name)
        lower = abs(p.encode(value) - p.encode(p.lo)) <= abs(p.encode(p.hi) - p.encode(value))
        side = 0 if lower else 1
        return BoundReached(name, (p.lo, p.hi)[side], ("lower", "upper")[side], p.physical[side])


def _cook_torrance(p, ior):
    ndf = an.Beckmann(p["m"])

    def f(wi, wo):
        return p["kd"] / np.pi + p["ks"] * an.torrance_sparrow(wi, wo, ndf, "vgroove", ior)

    return f


def _low_microfacet(p, ior):
    def f(wi, wo):
        return an.low_microfacet(wi, wo, p["A"], p["B"], p["C"], p["kd"], p["ior"])

    return f


def _low_smooth(p, ior):
    def f(wi, wo):
        return an.low_smooth(wi, wo, p["A"], p["B"], p["C"], p["kd"], p["ior"])

    return f


def _edwards(p, ior):
    return an.EdwardsFit(an.EdwardsParams(**p), "orthogonal").f


def _edwards_points(wi, wo) -> DiskPoints:
    """The parameter-independent part of ``_edwards`` at (wi, wo)."""
    return DiskPoints.of(wi, wo, "orthogonal")


def _edwards_prepared(p, ior):
    """``_edwards`` as a function of ``_edwards_points``."""
    return an.EdwardsFit(an.EdwardsParams(**p), "orthogonal").f_at


def _edwards_params() -> tuple[Param, ...]:
    """Edwards' box (``EdwardsParams.bounds``): the fractions cd, f0, f90, k are physical at
    both ends, the lump exponents n1, n2 at 0; the radii and the exponents' 1e4 are search
    limits."""
    lo, hi = an.EdwardsParams.bounds()
    start = an.EdwardsParams(cd=0.01, f0=0.5, f90=1.0, k=0.3, r1=0.5, n1=10.0, r2=1.0, n2=1.0)
    scales = {"r1": "log", "r2": "log", "n1": "log1p", "n2": "log1p"}
    search_limits = (False, False)
    physical = {
        **dict.fromkeys(("cd", "f0", "f90", "k"), (True, True)),
        **dict.fromkeys(("n1", "n2"), (True, False)),
    }
    return tuple(
        Param(n, float(a), float(b), float(s), scales.get(n, "lin"), physical.get(n, search_limits))
        for n, a, b, s in zip(an.EdwardsParams.names(), lo, hi, start.to_vector())
    )


# Löw: A is a free amplitude (sr⁻¹); B spans "nearly flat" to "mirror-sharp" (fit in ln B);
# C > 0.05 (C ≤ 0.5 is already a very heavy tail); real ior n from a weak dielectric to a
# near-perfect reflector. These ranges are practical choices, not from the paper: search
# limits. kd, a diffuse albedo, is physical at both ends (0 ≤ kd ≤ 1).
_LOW_PARAMS = (
    Param("A", 1e-4, 1e6, 10.0, "log"),
    Param("B", 1e-2, 1e8, 100.0, "log"),
    Param("C", 0.05, 10.0, 1.5),
    Param("kd", 0.0, 1.0, 0.01, physical=(True, True)),
    Param("ior", 1.01, 100.0, 1.5, "log"),
)

FIT_MODELS: dict[str, FitModel] = {
    "cook-torrance": FitModel(
        "cook-torrance",
        (
            Param("ks", 0.0, 10.0, 1.0, physical=(True, False)),
            Param("m", 0.01, 1.5, 0.3, "log"),
            Param("kd", 0.0, 1.0, 0.01, physical=(True, True)),
        ),
        _cook_torrance,
        "kd/π + ks·TS(Beckmann m, V-groove G, exact Fresnel of the scene ior)",
    ),
    "low-microfacet": FitModel(
        "low-microfacet", _LOW_PARAMS, _low_microfacet, "Löw eq. 15 (ABC microfacet, real ior)"
    ),
    "low-smooth": FitModel(
        "low-smooth", _LOW_PARAMS, _low_smooth, "Löw eq. 12 (smooth surface, real ior, G' = 1)"
    ),
    "edwards": FitModel(
        "edwards",
        _edwards_params(),
        _edwards,
        "Edwards eq. 36 (data-fitting BRDF, orthogonal projection)",
        _edwards_points,
        _edwards_prepared,
    ),
}


# --- data and the fixed quadrature rule ---------------------------------------------------------
@dataclass(frozen=True)
class FitData:
    """What a fit sees: bin averages ``sim`` (T, Θ, Φ) sr⁻¹, event ``counts`` (T, Θ, Φ),
    incidences ``theta_i``/``phi_i`` (T,) degrees, the ``bins`` and the event threshold."""

    sim: np.ndarray
    counts: np.ndarray
    theta_i: np.ndarray
    phi_i: np.ndarray
    bins: Bins
    min_events: int = 25

    @classmethod
    def from_result(cls, result, min_events: int = 25) -> "FitData":
        return cls(
            np.asarray(result.brdf, float),
            np.asarray(result.counts),
            np.asarray(result.theta_i, float),
            np.asarray(result.phi_i, float),
            result.bins,
            int(min_events),
        )

    @property
    def used(self) -> np.ndarray:
        """(T, Θ, Φ) mask of the bins entering the fit and E1/E2."""
        return (self.counts >= self.min_events) & np.isfinite(self.sim)

    def geometry(self):
        """Broadcastable (θi, θo, Δθi, Δθo, Δφo) in degrees for ``an.low_e1/low_e2``."""
        b = self.bins
        ti = self.theta_i
        d_ti = np.ones(len(ti))  # Δθi among the incidences at the same φi
        for phi in np.unique(self.phi_i):
            sel = np.flatnonzero(self.phi_i == phi)
            if len(sel) > 1:
                d_ti[sel] = np.abs(np.gradient(ti[sel]))
        d_phi = np.diff(b.phi_edges) * (2.0 if b.folded else 1.0)
        return (
            ti[:, None, None],
            b.theta_centers[None, :, None],
            d_ti[:, None, None],
            np.diff(b.theta_edges)[None, :, None],
            d_phi[None, None, :],
        )


@dataclass(frozen=True)
class BinRule:
    """Fixed quadrature: ``directions`` (Θ, Φ, P, 3) unit wo and ``weights`` (Θ, Φ, P) summing
    to 1 per bin, so Σ_p w_p f(wi, wo_p) ≈ f̄_B."""

    directions: np.ndarray
    weights: np.ndarray

    def average(self, brdf_fn: Callable, wi) -> np.ndarray:
        """≈ bin averages (Θ, Φ) of ``brdf_fn`` for one incidence ``wi`` (3,)."""
        wo = self.directions
        f = brdf_fn(np.broadcast_to(np.asarray(wi, float), wo.shape), wo)
        return np.sum(self.weights * f, axis=-1)


def bin_rule(bins: Bins, wi, order: int = 3, phi_i: float | None = None) -> BinRule:
    """Tensor Gauss–Legendre rule with ``order`` × ``order`` nodes per bin in (θo, Δφ).

    The bin average f̄_B = ∫∫ f sinθ cosθ dθ dφ / Ω_B (docs/design.md, "Conventions") is
    approximated with the cos-weighted nodes; the weights are normalised to sum to 1 in each
    bin (a constant f is exact). Folded bins integrate Δφ ∈ [φ₁, φ₂] only (isotropic models are
    even in Δφ).
    ``phi_i`` (deg) defaults to wi's azimuth (0° at normal incidence), as in ``bin_average``.
    """
    wi = _checks.directions("wi", wi)
    if int(order) != order or not 1 <= order <= 16:
        raise UsageError(f"order must be an integer in [1, 16], got {order!r}")
    if phi_i is None:
        phi_i = float(np.degrees(np.arctan2(wi[1], wi[0]))) if np.hypot(wi[0], wi[1]) > 0 else 0.0
    x, w = np.polynomial.legendre.leggauss(int(order))
    t, p = np.radians(bins.theta_edges), np.radians(bins.phi_edges)
    tc, th = 0.5 * (t[1:] + t[:-1]), 0.5 * np.diff(t)
    pc, ph = 0.5 * (p[1:] + p[:-1]), 0.5 * np.diff(p)
    theta = (tc[:, None] + th[:, None] * x[None, :])[:, None, :, None]  # (Θ, 1, n, 1)
    phi = (pc[:, None] + ph[:, None] * x[None, :])[None, :, None, :]  # (1, Φ, 1, n)
    wt = (th[:, None] * w[None, :] * np.sin(2.0 * theta[:, 0, :, 0]) / 2.0)[:, None, :, None]
    wp = (ph[:, None] * w[None, :])[None, :, None, :]
    theta, phi = np.broadcast_arrays(theta, phi + np.radians(phi_i))
    weights = (wt * wp).reshape(bins.n_theta, bins.n_phi, -1)
    weights = weights / weights.sum(axis=-1, keepdims=True)
    dirs = vectors.spherical(theta, phi).reshape(bins.n_theta, bins.n_phi, -1, 3)
    return BinRule(dirs, weights)


# --- the least-squares problem ------------------------------------------------------------------
@dataclass(frozen=True)
class _Problem:
    """Used bins of all incidences stacked: incidence wi (K, P, 3), nodes wo (K, P, 3),
    weights (K, P), cos θi (K,), target g = ln(1 + cosθi f̄) (K,), √(Löw eq. 33 weight) (K,)."""

    wi: np.ndarray
    wo: np.ndarray
    weights: np.ndarray
    cos_i: np.ndarray
    target: np.ndarray
    sqrt_w: np.ndarray

    @classmethod
    def build(cls, data: FitData, order: int) -> "_Problem":
        used = data.used
        if not used.any():
            raise UsageError(f"no bin has >= min_events={data.min_events} events: nothing to fit")
        geo = np.broadcast_arrays(*data.geometry(), data.sim)[:5]
        ti, to, dti, dto, dpo = (g[used] for g in geo)
        wis, wos, ws = [], [], []
        for t, (th_i, ph_i) in enumerate(zip(data.theta_i, data.phi_i)):
            wi = vectors.spherical_deg(th_i, ph_i)
            rule = bin_rule(data.bins, wi, order, ph_i)
            u = used[t]
            wos.append(rule.directions[u])
            ws.append(rule.weights[u])
            wis.append(np.broadcast_to(wi, rule.directions[u].shape))
        cos_i = np.cos(np.radians(ti))
        w = np.sin(np.radians(to)) * np.radians(dti) * np.radians(dto) * np.radians(dpo)
        return cls(
            np.concatenate(wis),
            np.concatenate(wos),
            np.concatenate(ws),
            cos_i,
            np.log1p(cos_i * data.sim[used]),
            np.sqrt(w),
        )

    def residuals(self, f: np.ndarray) -> np.ndarray:
        """√weight × (ln(1 + cosθi f̄) − target) (K,) of a model's values ``f`` (K, P) sr⁻¹ at
        the nodes (wi, wo) (``FitModel.at``)."""
        fbar = np.sum(self.weights * f, axis=-1)
        return self.sqrt_w * (np.log1p(self.cos_i * np.maximum(fbar, 0.0)) - self.target)


@dataclass(frozen=True)
class FitResult:
    """A fitted model. ``params``: name → value; ``cost``: E2 (Löw eq. 33, Σ not ½Σ) under the
    fixed rule at the optimum; ``e1``/``e2``: Löw E1/E2 with the accurate bin averages
    (reports print √E); ``success``: the best start converged; ``n_starts`` run;
    ``model_values`` (T, Θ, Φ) accurate bin averages (sr⁻¹) of the fitted model;
    ``at_bounds``: the parameters that ended at a bound of their box (``FitModel.at_bounds``;
    which bound and its kind: ``bounds_reached``)."""

    name: str
    params: dict
    cost: float
    e1: float
    e2: float
    success: bool
    n_starts: int
    model_values: np.ndarray
    at_bounds: tuple[str, ...] = ()

    @property
    def bounds_reached(self) -> tuple[BoundReached, ...]:
        """The bound each parameter of ``at_bounds`` ended on, physical or a search limit."""
        model = FIT_MODELS[self.name]
        return tuple(model.bound_reached(k, self.params[k]) for k in self.at_bounds)

    @property
    def converged(self) -> bool:
        """The optimiser converged and no parameter ended at a search limit (a physical bound
        is a constrained minimum)."""
        return self.success and all(b.physical for b in self.bounds_reached)

    def __repr__(self) -> str:
        params = ", ".join(f"{k}={v:.4g}" for k, v in self.params.items())
        return (
            f"FitResult({self.name!r}, {params}; √E1 = {np.sqrt(self.e1):.3g}, √E2 = "
            f"{np.sqrt(self.e2):.3g}, {'converged' if self.converged else 'not converged'})"
        )

    def _repr_html_(self) -> str:
        from microsim.display import html_table

        on = {b.param: "physical" if b.physical else "search limit" for b in self.bounds_reached}
        rows = [[k, f"{v:.4g}", on.get(k, "")] for k, v in self.params.items()]
        caption = (
            f"fit {self.name}: √E1 = {np.sqrt(self.e1):.3g}, √E2 = {np.sqrt(self.e2):.3g} "
            f"(Löw et al. 2012, eq. 29–33); "
            f"{'converged' if self.converged else 'not converged'}, {self.n_starts} starts"
        )
        return html_table(["parameter", "value", "at a bound"], rows, caption)


def _starts(model: FitModel, n_starts: int, seed: int) -> list[np.ndarray]:
    """The model's default start, then scrambled Halton points in the (encoded) box."""
    lo, hi = model.bounds_x()
    x0 = np.clip(model.encode({p.name: p.start for p in model.params}), lo, hi)
    out = [x0]
    if n_starts > 1:
        u = qmc.Halton(d=len(lo), scramble=True, seed=seed).random(n_starts - 1)
        out += list(lo + u * (hi - lo))
    return out


def model_bin_values(
    model: FitModel,
    params: Mapping[str, float],
    ior,
    theta_i,
    phi_i,
    bins: Bins,
    rtol: float = 1e-3,
) -> np.ndarray:
    """Accurate bin averages (T, Θ, Φ) of ``model`` with ``params`` (``predict.bin_average``)."""
    fn = model.make(params, ior)
    return np.stack(
        [
            bin_average(vectors.spherical_deg(t, p), bins, fn, p, rtol).values
            for t, p in zip(np.atleast_1d(theta_i), np.atleast_1d(phi_i))
        ]
    )


def fit_model(
    name: str,
    data: FitData,
    ior=None,
    *,
    n_starts: int = 4,
    seed: int = 0,
    order: int = 3,
    rtol: float = 1e-3,
    max_nfev: int = 300,
) -> FitResult:
    """Fit ``FIT_MODELS[name]`` to ``data`` on Löw's E2 (module docstring); ``ior`` is the
    scene's material (used by ``cook-torrance``). Several starts; the lowest cost wins.
    ``max_nfev`` caps the residual evaluations per start (the finite-difference Jacobian
    costs another #params evaluations per iteration on top)."""
    if name not in FIT_MODELS:
        raise UsageError(f"name must be one of {', '.join(map(repr, FIT_MODELS))}, got {name!r}")
    if int(n_starts) != n_starts or n_starts < 1:
        raise UsageError(f"n_starts must be an integer >= 1, got {n_starts!r}")
    model = FIT_MODELS[name]
    ior = an.resolve_material(ior)
    problem = _Problem.build(data, order)
    lo, hi = model.bounds_x()
    evaluate = model.at(problem.wi, problem.wo)

    def res(x):
        return problem.residuals(evaluate(model.decode(x), ior))

    best = None
    for x0 in _starts(model, int(n_starts), seed):
        sol = optimize.least_squares(
            res,
            x0,
            bounds=(lo, hi),
            method="trf",
            x_scale="jac",
            ftol=1e-12,
            xtol=1e-12,
            gtol=1e-12,
            max_nfev=max_nfev,
        )
        if best is None or sol.cost < best.cost:
            best = sol
    params = model.decode(best.x)
    values = model_bin_values(model, params, ior, data.theta_i, data.phi_i, data.bins, rtol)
    used = data.used
    geo = [np.broadcast_to(g, data.sim.shape)[used] for g in data.geometry()]
    e1 = an.low_e1(data.sim[used], values[used], *geo)
    e2 = an.low_e2(data.sim[used], values[used], *geo)
    return FitResult(
        name,
        params,
        float(2.0 * best.cost),
        e1,
        e2,
        bool(best.success),
        int(n_starts),
        values,
        model.at_bounds(best.x),
    )


def fit_all(
    result,
    ior,
    names: Sequence[str] = tuple(FIT_MODELS),
    quick: bool = False,
    *,
    min_events: int = 25,
    seed: int = 0,
) -> dict[str, FitResult]:
    """Fit each model in ``names`` to all incidences of ``result`` jointly: name → FitResult.
    ``quick``: 2 starts of at most 60 evaluations each, instead of 4 of at most 300 (a capped
    start reports ``success = False``)."""
    data = FitData.from_result(result, min_events)
    n_starts, max_nfev = (2, 60) if quick else (4, 300)
    return {
        n: fit_model(n, data, ior, n_starts=n_starts, seed=seed, max_nfev=max_nfev) for n in names
    }


# --- Edwards' halfway disk at one viewing direction ----------------------------------------------
@dataclass(frozen=True)
class DiskFit:
    """Edwards data-fitting BRDF fitted at one viewing direction (orthogonal projection) by
    ``fit_edwards_disk``.

    ``params`` (``EdwardsParams``: cd = 0, f0 = f90 = F(θo) since at a single θo only the product
    F·p is identifiable), ``grid_uv`` (M, 2) cell centres, ``density`` (M,) simulated disk density
    per unit area (= f, Edwards eq. 24), ``cost`` (½Σ residual², residuals in standard errors)."""

    params: object
    grid_uv: np.ndarray
    density: np.ndarray
    cost: float


def fit_edwards_disk(wo, uv: np.ndarray, weight: np.ndarray, rays: int, cells: int = 40) -> DiskFit:
    """Least-squares fit of the Edwards data-fitting BRDF (Edwards et al. 2006, eq. 34–36,
    orthogonal projection) at one viewing direction ``wo`` (unit vector) to the weighted disk
    histogram of simulated half vectors (the ``microsim view --what disk`` contours).

    ``uv`` (K, 2) orthogonal-projection points of single-bounce escaping rays, ``weight`` (K,)
    their Fresnel weights, ``rays`` primary rays traced. Σw/N over a disk region equals
    ∫ f cos θi dω_i = ∫ f du dv (orthogonal: du dv = cos θi dω_i), so the histogram density per
    unit area is f itself. Cells: a square grid over [−R, R]² (R from the 99.5% radius of the
    points) keeping cells inside the disk; residuals are divided by the cells' standard errors.
    """
    wo = np.asarray(wo, dtype=np.float64)
    centre = an.disk_centre(wo)
    rad = np.linalg.norm(uv, axis=1)
    R = float(min(1.0 + np.linalg.norm(centre), max(1.5 * np.quantile(rad, 0.995), 1e-3)))
    edges = np.linspace(-R, R, cells + 1)
    s, _, _ = np.histogram2d(uv[:, 0], uv[:, 1], [edges, edges], weights=weight)
    s2, _, _ = np.histogram2d(uv[:, 0], uv[:, 1], [edges, edges], weights=weight**2)
    area = (edges[1] - edges[0]) ** 2
    mid = 0.5 * (edges[1:] + edges[:-1])
    U, V = np.meshgrid(mid, mid, indexing="ij")
    grid = np.stack([U.ravel(), V.ravel()], axis=1)
    half_diag = (edges[1] - edges[0]) / np.sqrt(2)
    inside = np.linalg.norm(grid - centre, axis=1) + half_diag <= 1.0
    dens = (s.ravel() / (rays * area))[inside]
    var = np.maximum(s2.ravel() / rays - (s.ravel() / rays) ** 2, 0.0) / (rays - 1) / area**2
    floor = np.max(weight) / (rays * area)  # one ray's worth: empty cells count
    sigma = np.sqrt(var[inside] + floor**2)
    grid = grid[inside]
    r2 = float(np.sum(weight * np.sum(uv * uv, axis=1)) / max(np.sum(weight), 1e-300))
    r1 = 1.2 * float(np.quantile(rad, 0.99)) + 1e-3
    n1 = max(r1 * r1 / max(r2, 1e-12) - 2.0, 0.0)  # E[r²] = R²/(n+2) for the lump (eq. 26)
    F0 = float(np.sum(weight) / rays)
    lo, hi = an.EdwardsParams.bounds()
    names = an.EdwardsParams.names()
    idx = [names.index(k) for k in ("k", "r1", "n1", "r2", "n2")]
    x0 = np.array([min(max(F0, 1e-3), 1.0), 0.1, min(r1, 4.0), min(n1, 1e4), min(2 * r1, 4.0), 1.0])
    lower = np.concatenate([[0.0], lo[idx]])
    upper = np.concatenate([[1.0], hi[idx]])

    def params(x):
        return an.EdwardsParams(
            cd=0.0, f0=x[0], f90=x[0], k=x[1], r1=x[2], n1=x[3], r2=x[4], n2=x[5]
        )

    def resid(x):
        return (x[0] * params(x).lumps().pdf(wo, grid) - dens) / sigma

    fit = optimize.least_squares(
        resid, np.clip(x0, lower, upper), bounds=(lower, upper), x_scale="jac", max_nfev=400
    )
    return DiskFit(params=params(fit.x), grid_uv=grid, density=dens, cost=float(fit.cost))
