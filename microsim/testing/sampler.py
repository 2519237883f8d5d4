"""Pearson χ² goodness of fit of an importance sampler against its own pdf.

The harness microsim uses for its own samplers (docs/design.md, "Tests"), public: draw N
directions, count them in cells of the sphere, integrate the pdf over the same cells, and
test the counts with Pearson's χ² (cells whose expected count is below ``min_expected``
pooled into one; Šidák's correction for a family of tests). Mitsuba 3 and pbrt-v4 ship the
same kind of test for their BSDF samplers. Beside the counts it checks what a renderer's
sampler returns with each direction — its pdf value and its weight f·|cos θ|/pdf — and on a
failure fits the misfit against the usual bugs (a constant, a cos θ, the half-vector
Jacobian) to name the likely one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from microsim import checks as _checks
from microsim import vectors
from microsim.errors import UsageError
from microsim.stats import chi2_sf, sidak

from .returns import real_values

__all__ = ["pearson_chi2", "assert_sampler_matches", "SamplerCheck", "FLOAT32_RTOL"]

FLOAT32_RTOL = 1e-3
"""Default ``pdf_rtol`` and ``weight_rtol`` of ``assert_sampler_matches``: single precision
with room for cancellation. A float32 operation rounds by at most u = 2⁻²⁴ ≈ 6·10⁻⁸
(relative); a pdf or weight through a dozen operations is within ≈ 12u ≈ 7·10⁻⁷, and the
sampler's value and the one recomputed from ``pdf(w)`` (or ``brdf(w)``) round independently,
at a direction itself rounded to float32: ≈ 2·10⁻⁶ apart (Mitsuba 3's GGX sampler and its pdf
differ by ~10⁻⁶). Where a difference cancels — 1 − cos²θ as θ → 0 (sin²θ), |wo·h| near
grazing, D's slope ~1/α at small roughness α — the relative error grows by that factor's
inverse; 10⁻³ allows an amplification of ~500 and stays 100× below what a bug changes (a pdf
× 0.5, a missing Jacobian 1/(4|wo·h|), a cos θ too many: tens of % over most samples)."""

_UNIT_TOL = 1e-5  # | |w| − 1 | of a sampled direction: float32 directions are a few ulp off
_FILLED = 20.0  # the cause fit uses cells expecting at least this many samples


def pearson_chi2(observed, expected, min_expected: float = 5.0):
    """Return (statistic, dof, p-value) of Pearson's χ² test.

    ``expected`` must sum to the same total as ``observed`` (the caller integrates the pdf over
    each cell and multiplies by the sample count; any probability outside the cells belongs in
    one extra cell). Cells with expected count < ``min_expected`` are pooled into one cell.
    Counts that are not finite numbers >= 0 raise a UsageError naming the argument.
    """
    obs = _counts("observed", observed)
    exp = _counts("expected", expected)
    min_expected = _checks.positive("min_expected", min_expected)
    if obs.shape != exp.shape:
        raise UsageError(
            f"observed and expected must have the same number of cells, got {obs.size} and "
            f"{exp.size}"
        )
    small = exp < min_expected
    if small.any():
        obs = np.append(obs[~small], obs[small].sum())
        exp = np.append(exp[~small], exp[small].sum())
        if exp[-1] == 0:
            if obs[-1] > 0:  # samples where the pdf says none can be: certain failure
                return np.inf, max(len(exp) - 2, 1), 0.0
            obs, exp = obs[:-1], exp[:-1]
    stat = float(np.sum((obs - exp) ** 2 / exp))
    dof = len(exp) - 1
    return stat, dof, float(chi2_sf(stat, dof))


def _counts(name: str, value) -> np.ndarray:
    """``value`` flattened to float64 counts, or a UsageError naming ``name`` unless every one
    is a finite number >= 0."""
    c = real_values(value, f"{name} must be", "(cells,)").ravel()
    if not np.all(np.isfinite(c) & (c >= 0)):
        raise UsageError(f"{name} must be finite counts >= 0, got {_checks.short(value)}")
    return c


class SamplerCheck(dict):
    """The numbers of one ``assert_sampler_matches`` run (a dict): chi2, dof, p_value,
    p_threshold, n, outside (rejected samples, in no direction cell: NaN or non-unit
    directions, returned pdf value or weight 0), cells, quad_chi2, weights_checked (samples
    whose weight was compared with ``brdf``; 0 without it)."""


# --- what the sampler returned ---------------------------------------------------------------
@dataclass(frozen=True)
class _Draw:
    """One call of ``sample``: directions (m, 3) and, if returned, pdf values and weights (m,)."""

    w: np.ndarray
    pdf_values: np.ndarray | None
    weights: np.ndarray | None

    @property
    def rejected(self) -> np.ndarray:
        """Samples the sampler rejected: NaN or non-unit directions, pdf value or weight 0."""
        with np.errstate(invalid="ignore"):
            norm = np.linalg.norm(self.w, axis=1)
            out = ~(np.isfinite(norm) & (np.abs(norm - 1.0) < _UNIT_TOL))
        for v in (self.pdf_values, self.weights):
            if v is not None:
                out |= v == 0.0
        return out


def _draw(sample, m: int, rng) -> _Draw:
    """Call ``sample`` on m uniform pairs; UsageError unless it returned directions (m, 3),
    optionally with pdf values (m,) and weights (m,)."""
    out = sample(rng.random(m), rng.random(m))
    extra = ()
    if isinstance(out, tuple):
        if len(out) not in (2, 3):
            raise UsageError(
                "sample must return directions (n, 3), (directions, pdf) or "
                f"(directions, pdf, weight); got a tuple of {len(out)}"
            )
        out, *extra = out
    w = real_values(out, "sample(u1, u2) must return directions as", f"({m}, 3)")
    if w.shape != (m, 3):
        raise UsageError(f"sample(u1, u2) must return directions of shape ({m}, 3), got {w.shape}")
    values = []
    for what, v in zip(("pdf values", "weights"), extra):
        v = real_values(v, f"sample(u1, u2)'s {what} must be", f"({m},)")
        if v.shape not in ((m,), (m, 1)):
            raise UsageError(f"sample(u1, u2)'s {what} must have shape ({m},), got {v.shape}")
        values.append(v.reshape(-1))
    values += [None] * (2 - len(values))
    return _Draw(w, *values)


def _pdf_at(pdf, w: np.ndarray) -> np.ndarray:
    """``pdf(w)`` checked to be (M,) finite densities >= 0."""
    vals = real_values(pdf(w), "pdf(w) must return", f"({len(w)},)")
    if vals.size != len(w):
        raise UsageError(
            f"pdf(w) must return one density per direction, shape ({len(w)},); "
            f"got shape {vals.shape}"
        )
    vals = vals.reshape(-1)
    if not np.all(np.isfinite(vals)) or np.any(vals < 0):
        raise UsageError("pdf(w) must return finite densities >= 0 (sr⁻¹)")
    return vals


# --- causes of a misfit ----------------------------------------------------------------------
@dataclass(frozen=True)
class _Factor:
    """A factor a bug puts into a ratio: its name and its values at the points fitted."""

    name: str
    values: np.ndarray


def _factors(w: np.ndarray, wi) -> list:
    """The factors tried at sampled directions w (the half-vector ones only with ``wi``)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        out = [_Factor("cos θ", np.abs(w[:, 2]))]
        if wi is not None:
            h = vectors.half_vector(w, wi)
            out.append(_Factor("4|wo·h|", 4.0 * np.abs(vectors.dot(w, h))))
            out.append(_Factor("h·n", np.abs(h[:, 2])))
    return out


@dataclass(frozen=True)
class _Fit:
    """The best of the causes: ratio ≈ c × factor^sign (sign 0: a constant); ``power`` is the
    factor's exponent fitted freely (its size), ``resid`` and ``total`` the squared misfit of
    log ratio (weighted by its inverse variance) left by the fit and by ratio = 1, over
    ``points`` points."""

    factor: str | None
    sign: int
    power: float
    c: float
    resid: float
    total: float
    points: int

    @property
    def explained(self) -> float:
        """The share of the misfit beyond noise (≈ 1 per point) that the cause removes."""
        beyond = self.total - self.points
        return min(max((self.total - self.resid) / beyond, 0.0), 1.0) if beyond > 0 else 0.0

    @property
    def named(self) -> bool:
        """Whether the cause fits: the misfit is more than noise (5σ), the cause removes at
        least 3/4 of it and what it leaves is noise."""
        real = self.total - self.points > 5.0 * np.sqrt(2.0 * self.points)
        return real and self.explained >= 0.75 and self.resid <= 1.5 * self.points


def _best_cause(log_ratio, weight, shapes: dict, log_factors: dict) -> _Fit | None:
    """Fit log ratio ≈ log c + x, x = 0 (a constant) or ``shapes[(factor, s)]`` (the log of
    the ratio a factor^s predicts, s = ±1), by weighted least squares (``weight`` the inverse
    variance of log ratio): the best fit, its exponent fitted freely on ``log_factors``, or
    None if there is nothing to fit."""
    keep = np.isfinite(log_ratio) & (weight > 0)
    for x in shapes.values():
        keep &= np.isfinite(x)
    if keep.sum() < 3:
        return None
    y, v = log_ratio[keep], weight[keep]
    total = float(np.sum(v * y * y))
    if total <= 0:
        return None
    best = None
    for key, x in [((None, 0), 0.0), *shapes.items()]:
        r = y - (x[keep] if key[0] else x)
        mean = float(np.sum(v * r) / np.sum(v))
        resid = float(np.sum(v * (r - mean) ** 2))
        if best is None or resid < best[0]:
            best = (resid, key, mean)
    resid, (name, sign), log_c = best
    power = float(sign)
    if name is not None:
        x = log_factors[name][keep]
        xc = x - np.sum(v * x) / np.sum(v)
        power = float(np.sum(v * xc * y) / np.sum(v * xc * xc))
    return _Fit(name, sign, power, float(np.exp(log_c)), resid, total, int(keep.sum()))


_COUNT_CAUSES = {
    ("cos θ", +1): "the pdf lacks a factor cos θ of the sampled direction",
    ("cos θ", -1): "the pdf has a factor cos θ the sampler does not draw (cos θ once too often)",
    ("4|wo·h|", -1): (
        "the pdf lacks the Jacobian 1/(4|wo·h|) of the half-vector map (Walter et al. 2007, "
        "eq. 14; Mikkelsen 2009, eq. 15)"
    ),
    ("4|wo·h|", +1): (
        "the pdf has a Jacobian 1/(4|wo·h|) the sampler does not draw (applied twice, or to "
        "directions not drawn through h)"
    ),
    ("h·n", +1): "the pdf lacks the factor h·n of the half-vector density D(h)(h·n)",
    ("h·n", -1): "the pdf has a factor h·n the sampled half vectors do not have",
}
_WEIGHT_CAUSES = {
    ("cos θ", +1): "the cosine cos θ is included twice",
    ("cos θ", -1): "the cosine cos θ is left out",
    ("4|wo·h|", -1): "the weight divides by a pdf without the Jacobian 1/(4|wo·h|)",
    ("4|wo·h|", +1): "the weight divides by the Jacobian 1/(4|wo·h|) twice",
    ("h·n", +1): "the weight has a factor h·n too many",
    ("h·n", -1): "the weight lacks a factor h·n",
}


def _key(fit: _Fit) -> str:
    """The cause a fit tried, as a formula: "a constant", "(cos θ)^-1", …"""
    return "a constant" if fit.factor is None else f"({fit.factor})^{fit.sign:+d}"


def _describe(fit: _Fit | None, factors, causes: dict, constant: str, ratio: str) -> str:
    """One line naming the best cause of a misfit among a constant and ``factors`` (their
    phrases: ``causes``, ``constant``), or saying that none fits."""
    tried = ", ".join(["a constant", *factors])
    if fit is None or not fit.named:
        share = "" if fit is None else f" (the closest, {_key(fit)}, explains {fit.explained:.0%})"
        return f"no single factor ({tried}) explains the {ratio}{share}"
    if fit.factor is None:
        return constant.format(c=fit.c, inv=1.0 / fit.c)
    return (
        f"{causes[(fit.factor, fit.sign)]}: the {ratio} ∝ ({fit.factor})^{fit.power:.2f} "
        f"(explains {fit.explained:.0%} of the misfit beyond noise)"
    )


# --- the checks ------------------------------------------------------------------------------
def _check_pdf_values(d: _Draw, ref, keep, rtol: float) -> None:
    """AssertionError unless the sampler's pdf values equal pdf(w) within ``rtol``."""
    vals, w = d.pdf_values[keep], d.w[keep]
    fin = np.isfinite(vals)
    bad = fin & (np.abs(vals - ref) > rtol * np.abs(ref))
    if bad.any():
        k = np.flatnonzero(bad)[0]
        raise AssertionError(
            f"sampler pdf values disagree with pdf(w) at {int(bad.sum())} of {int(fin.sum())} "
            f"samples (rtol {rtol:g}); e.g. w = {np.round(w[k], 6).tolist()}: "
            f"sampler {vals[k]:.6g} vs pdf {ref[k]:.6g} sr⁻¹"
        )


def _check_weights(d: _Draw, ref, keep, brdf, rtol: float, wi) -> int:
    """Compare the weights of accepted samples where pdf(w) > 0 with brdf(w)·|cos θ|/pdf(w);
    AssertionError naming the likely cause if they disagree. Returns how many were compared."""
    w, weights = d.w[keep], d.weights[keep]
    f = real_values(brdf(w), "brdf(w) must return", f"({len(w)},)")
    if f.size != len(w):
        raise UsageError(
            f"brdf(w) must return one value per direction, shape ({len(w)},); got {f.shape}"
        )
    f = f.reshape(-1)
    if not np.all(np.isfinite(f)) or np.any(f < 0):
        raise UsageError("brdf(w) must return finite BRDF values >= 0 (sr⁻¹)")
    pos = ref > 0
    expected = np.zeros_like(ref)
    expected[pos] = f[pos] * np.abs(w[pos, 2]) / ref[pos]
    bad = pos & (np.abs(weights - expected) > rtol * expected)
    if bad.any():
        k = np.flatnonzero(bad)[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            log_ratio = np.log(weights[pos] / expected[pos])
        logs = {g.name: np.log(g.values) for g in _factors(w[pos], wi)}
        shapes = {(name, s): s * x for name, x in logs.items() for s in (+1, -1)}
        sigma = max(rtol, 1e-6)  # what rounding leaves of a right weight
        fit = _best_cause(log_ratio, np.full(len(log_ratio), sigma**-2.0), shapes, logs)
        cause = _describe(
            fit,
            logs,
            _WEIGHT_CAUSES,
            "weight/expected = {c:.4g} at every sample: f and pdf are normalised differently "
            "(a constant factor in the weight, the BRDF or the pdf)",
            "ratio weight/expected",
        )
        raise AssertionError(
            f"sample weights disagree with brdf(w)·|cos θ|/pdf(w) at {int(bad.sum())} of "
            f"{int(pos.sum())} samples (rtol {rtol:g}); e.g. w = {np.round(w[k], 6).tolist()}: "
            f"weight {weights[k]:.6g} vs {expected[k]:.6g} (ratio "
            f"{weights[k] / expected[k] if expected[k] else np.inf:.4g}); {cause}"
        )
    return int(pos.sum())


def _cell_masses(pdf, t_edges, p_edges, order: int) -> np.ndarray:
    """∫∫ pdf(θ, φ) sin θ dθ dφ over each (θ, φ) cell by tensor Gauss–Legendre of ``order``."""
    x, w = np.polynomial.legendre.leggauss(order)
    a, b = t_edges[:-1, None], t_edges[1:, None]
    th = 0.5 * (a + b) + 0.5 * (b - a) * x  # (Nt, order)
    wt = 0.5 * (b - a) * w
    c, d = p_edges[:-1, None], p_edges[1:, None]
    ph = 0.5 * (c + d) + 0.5 * (d - c) * x  # (Np, order)
    wp = 0.5 * (d - c) * w
    T = th[:, None, :, None]
    P = ph[None, :, None, :]
    st = np.sin(T)
    dirs = np.stack(np.broadcast_arrays(st * np.cos(P), st * np.sin(P), np.cos(T)), axis=-1)
    vals = _pdf_at(pdf, dirs.reshape(-1, 3)).reshape(dirs.shape[:-1])
    weight = (wt * np.sin(th))[:, None, :, None] * wp[None, :, None, :]
    return np.sum(vals * weight, axis=(2, 3))


def _theta_edges(pilot: _Draw, theta_cells: int) -> np.ndarray:
    """θ band edges: quantiles of the pilot's accepted directions, 0, 90° and 180°."""
    pt = np.arccos(np.clip(pilot.w[~pilot.rejected, 2], -1, 1))
    inner = np.quantile(pt, np.arange(1, theta_cells) / theta_cells) if pt.size else []
    return np.unique(np.concatenate([[0.0, 0.5 * np.pi, np.pi], inner]))


def _cell_index(w: np.ndarray, t_edges, p_edges) -> np.ndarray:
    """Flat (θ band, φ sector) cell of each unit direction (the last edge closed)."""
    nt, npp = len(t_edges) - 1, len(p_edges) - 1
    th = np.arccos(np.clip(w[:, 2], -1, 1))
    ph = np.arctan2(w[:, 1], w[:, 0])
    i = np.clip(np.searchsorted(t_edges, th, side="right") - 1, 0, nt - 1)
    j = np.clip(np.searchsorted(p_edges, ph, side="right") - 1, 0, npp - 1)
    return i * npp + j


def assert_sampler_matches(
    sample,
    pdf,
    *,
    n: int = 200_000,
    theta_cells: int = 24,
    phi_cells: int = 32,
    seed: int = 0,
    alpha: float = 0.01,
    n_tests: int = 1,
    min_expected: float = 5.0,
    order: int = 8,
    pdf_rtol: float = FLOAT32_RTOL,
    brdf=None,
    weight_rtol: float = FLOAT32_RTOL,
    wi=None,
) -> SamplerCheck:
    """Assert that ``sample`` draws directions with density ``pdf`` (Pearson χ², level α).

    ``sample(u1, u2)``: u1, u2 (n,) uniform in [0, 1) → directions (n, 3) (unit vectors on the
    sphere, z = macro normal), or ``(directions, pdf_values)``, or ``(directions, pdf_values,
    weights)`` (a renderer's sample: pbrt's ``f * AbsCosTheta(wi) / pdf``, the second output
    of Mitsuba 3's ``bsdf.sample``; one channel or their mean). A sample is *rejected* if its
    direction is NaN (or not unit), or its returned pdf value or weight is 0 (Mitsuba returns a
    direction below the horizon with weight 0). ``pdf(w)``: w (M, 3) → (M,) density in sr⁻¹
    over the whole sphere of directions (samples below the horizon are counted like any
    other); the probability it leaves out (1 − ∫ pdf) is the expected share of rejected
    samples. The returned pdf values must equal ``pdf(directions)`` within ``pdf_rtol``
    (relative) where finite. With ``brdf`` (brdf(w) → (M,) BRDF values in sr⁻¹ for the
    sampler's fixed direction, no cosine), the weights must equal brdf(w)·|cos θ|/pdf(w)
    within ``weight_rtol`` where pdf(w) > 0 (a failure names the ratio weight/expected: a
    constant, f and pdf normalised differently; ∝ cos θ^±1, the cosine twice or left out);
    without it, weights only mark rejections and
    must otherwise be finite and >= 0. Both tolerances default to ``FLOAT32_RTOL`` (10⁻³,
    derived there from single precision).

    Cells: ``theta_cells`` bands in θ ∈ [0°, 180°] with edges at quantiles of a pilot sample
    (5 % of n, its own random stream: about equal counts per band), × ``phi_cells`` equal
    azimuth sectors; the horizon θ = 90° is always an edge (where many pdfs jump to 0); one
    extra cell for the rejected samples. Expected
    counts: n × tensor Gauss–Legendre integral of pdf · sin θ over each cell with ``order``
    and 2 × ``order`` nodes; the 2×-order values are used, and if their difference could add
    more than 1 to χ² the pdf is too peaked for the cells and a UsageError says so.
    The test rejects when p < Šidák(alpha, n_tests) (``n_tests``: the size of the family the
    caller runs, e.g. several outgoing directions). On rejection AssertionError lists χ²,
    dof, p, samples that landed where pdf(w) is 0, the likely cause and the cells with the
    largest contributions (θ and φ ranges, observed vs expected). The cause: log(observed /
    expected) over the cells expecting ≥ 20 samples (weighted by its inverse variance, the
    expected count scaled to the observed total) is fitted as a constant (pdf normalisation),
    ∝ cos θ^±1, and — given ``wi``, the sampler's fixed direction (unit, away from the
    surface) and h = (wi + wo)/|wi + wo| — ∝ (4|wo·h|)^±1 (the half-vector Jacobian) or
    (h·n)^±1; the best is named if the misfit is real (5σ), it removes ≥ 75 % of it and
    leaves noise. A pdf integrating to more than 1 fails with the same diagnosis. Returns the
    numbers (``SamplerCheck``).
    """
    __tracebackhide__ = True
    if not callable(sample):
        raise UsageError(f"sample must be a callable sample(u1, u2) -> (n, 3), got {sample!r}")
    if not callable(pdf):
        raise UsageError(f"pdf must be a callable pdf(w) -> (n,) in sr⁻¹, got {pdf!r}")
    if brdf is not None and not callable(brdf):
        raise UsageError(f"brdf must be None or a callable brdf(w) -> (n,) in sr⁻¹, got {brdf!r}")
    for name, v, lo in (
        ("n", n, 1000),
        ("theta_cells", theta_cells, 2),
        ("phi_cells", phi_cells, 1),
        ("n_tests", n_tests, 1),
        ("order", order, 2),
    ):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise UsageError(f"{name} must be an integer >= {lo}, got {v!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise UsageError(f"seed must be an integer >= 0, got {seed!r}")
    if not (isinstance(alpha, (int, float)) and 0 < alpha < 1):
        raise UsageError(f"alpha must lie in (0, 1), got {alpha!r}")
    min_expected = _checks.positive("min_expected", min_expected)
    pdf_rtol = _checks.in_range("pdf_rtol", pdf_rtol, 0.0, 1.0)
    weight_rtol = _checks.in_range("weight_rtol", weight_rtol, 0.0, 1.0)
    if wi is not None:
        wi = _checks.directions("wi", wi)
        if wi.shape != (3,):
            raise UsageError(f"wi must be one unit direction of shape (3,), got {wi.shape}")
    p_thr = sidak(float(alpha), int(n_tests))

    pilot = _draw(sample, max(1000, int(n) // 20), np.random.default_rng([int(seed), 1]))
    d = _draw(sample, int(n), np.random.default_rng([int(seed), 0]))
    rejected = d.rejected
    w = d.w[~rejected]
    if brdf is not None and d.weights is None:
        raise UsageError(
            "brdf= checks the sample weights: sample(u1, u2) must return (directions, pdf, weight)"
        )
    ref = None
    if d.pdf_values is not None or d.weights is not None:
        ref = _pdf_at(pdf, w)
    if d.pdf_values is not None:
        _check_pdf_values(d, ref, ~rejected, pdf_rtol)
    weights_checked = 0
    if d.weights is not None:
        kept = d.weights[~rejected]
        if not np.all(np.isfinite(kept) & (kept >= 0)):
            raise AssertionError(
                f"sample weights must be finite and >= 0 (0 for a rejected sample), got "
                f"{int(np.count_nonzero(~(np.isfinite(kept) & (kept >= 0))))} that are not, "
                f"e.g. {kept[~(np.isfinite(kept) & (kept >= 0))][0]!r}"
            )
        if brdf is not None:
            weights_checked = _check_weights(d, ref, ~rejected, brdf, weight_rtol, wi)

    t_edges = _theta_edges(pilot, int(theta_cells))
    p_edges = np.linspace(-np.pi, np.pi, int(phi_cells) + 1)
    m_lo = _cell_masses(pdf, t_edges, p_edges, int(order))
    m_hi = _cell_masses(pdf, t_edges, p_edges, 2 * int(order))
    integral = float(m_hi.sum())
    exp = np.append(m_hi.ravel(), max(0.0, 1.0 - integral)) * n
    cell = _cell_index(w, t_edges, p_edges)
    obs = np.append(np.bincount(cell, minlength=m_hi.size), np.count_nonzero(rejected))

    def failure(headline: str) -> AssertionError:
        """``headline`` and what the counts say about the sampler's bug."""
        at = _pdf_at(pdf, w) if ref is None else ref
        misfit = _Misfit(obs, exp, w, cell, at, integral, d.weights is not None)
        return AssertionError(headline + misfit.report(wi, t_edges, p_edges))

    if integral > 1.0 + 1e-3:
        raise failure(
            f"pdf integrates to {integral:.6g} > 1 over the sphere: not a probability density\n"
        )
    quad = float(np.sum(n * (m_lo - m_hi).ravel() ** 2 / np.maximum(m_hi.ravel(), 1.0 / n)))
    if quad > 1.0:
        raise UsageError(
            f"pdf: the cell integrals did not converge (order {order} vs {2 * order} nodes could "
            f"add {quad:.3g} to χ²): the pdf is too peaked or singular for these cells; raise "
            f"order or theta_cells/phi_cells"
        )
    chi2, dof, p = pearson_chi2(obs, exp, min_expected)
    if dof < 1:
        raise UsageError(
            f"sample and pdf leave nothing to test: fewer than two cells expect "
            f"{min_expected:g} or more of the {n} samples (pdf integrates to "
            f"{integral:.3g} over the sphere); raise n or check the pdf"
        )
    out = SamplerCheck(
        chi2=chi2,
        dof=dof,
        p_value=p,
        p_threshold=p_thr,
        n=int(n),
        outside=int(np.count_nonzero(rejected)),
        cells=int(len(exp)),
        quad_chi2=quad,
        weights_checked=weights_checked,
    )
    if p < p_thr:
        raise failure(
            f"sampler does not match its pdf: χ² = {chi2:.1f} on {dof} dof, p = {p:.3g} < "
            f"{p_thr:.3g} (α = {alpha:g}, Šidák over {n_tests} test(s)); {n} samples, "
            f"{out['outside']} rejected, outside the direction cells (NaN direction, pdf value "
            f"or weight 0; expected {exp[-1]:.1f}).\n"
        )
    return out


@dataclass(frozen=True)
class _Misfit:
    """What a failed χ² test says about the sampler: counts per cell (the rejected last),
    the accepted directions, their cells and pdf(w) there."""

    obs: np.ndarray
    exp: np.ndarray
    w: np.ndarray
    cell: np.ndarray
    ref: np.ndarray
    integral: float
    has_weights: bool

    def report(self, wi, t_edges, p_edges) -> str:
        """The lines of a failure message after its headline."""
        return (
            self.landed_where_pdf_is_zero()
            + f"likely cause: {self.cause(wi)}\n"
            + "largest contributions:\n"
            + self.largest(t_edges, p_edges)
        )

    def landed_where_pdf_is_zero(self) -> str:
        """A line on the accepted samples where pdf(w) is 0 (empty if none) and what to return."""
        zero = self.ref == 0
        if not zero.any():
            return ""
        th = np.degrees(np.arccos(np.clip(self.w[zero, 2], -1, 1)))
        advice = (
            "a rejected sample needs weight 0 (or a NaN direction), theirs are not 0"
            if self.has_weights
            else "return NaN for a rejected sample, or (directions, pdf, weight) with weight 0"
        )
        return (
            f"{int(zero.sum())} samples landed where pdf(w) is 0 (θ {th.min():.1f}–"
            f"{th.max():.1f}°): {advice}\n"
        )

    def cause(self, wi) -> str:
        """The best-fitting cause of observed/expected over the well-filled cells."""
        n_cells = len(self.exp) - 1
        obs, exp = self.obs[:n_cells], self.exp[:n_cells]
        filled = exp >= _FILLED
        with np.errstate(divide="ignore", invalid="ignore"):
            log_ratio = np.where(filled, np.log((obs + 0.5) / exp), np.nan)
        counts = np.maximum(np.bincount(self.cell, minlength=n_cells), 1)

        def cell_mean(values):
            return np.bincount(self.cell, values, n_cells) / counts

        logs, shapes = {}, {}
        for g in _factors(self.w, wi):
            g_ = np.clip(g.values, 1e-300, 1e300)
            logs[g.name] = cell_mean(np.log(g_))
            # pdf(w) = sampling density × g^−s gives observed/expected = 1/⟨g^−s⟩ in a cell
            for s in (+1, -1):
                with np.errstate(divide="ignore"):
                    shapes[(g.name, s)] = -np.log(cell_mean(g_ ** float(-s)))
        # 1/var of log ratio ≈ the mean count: expected × the observed/expected overall (not
        # the observed count itself, which would favour cells that came out high)
        scale = obs[filled].sum() / max(exp[filled].sum(), 1.0)
        fit = _best_cause(log_ratio, np.where(filled, exp * scale, 0.0), shapes, logs)
        text = _describe(
            fit,
            logs,
            _COUNT_CAUSES,
            "samples are {c:.3g}× as frequent as pdf(w) says in every cell: pdf off by a "
            "constant factor {inv:.3g} (normalisation)",
            "ratio observed/expected",
        )
        named = fit is not None and fit.named
        if named and fit.factor is None:
            text += self._rejections(fit.c)
        if not named and wi is None:
            text += " (pass wi= to test the half-vector Jacobian too)"
        return text

    def _rejections(self, c: float) -> str:
        """What the pdf's integral and the rejected share say about a constant factor c."""
        share = self.obs[-1] / self.obs.sum()
        implies = f" (it implies {1.0 - self.integral:.1%})" if self.integral <= 1.0 else ""
        return (
            f"; pdf(w) integrates to {self.integral:.3g} over the sphere while {share:.1%} "
            f"of the samples are rejected{implies}: the pdf is too "
            f"{'small' if c > 1 else 'large'} by that factor"
        )

    def largest(self, t_edges, p_edges) -> str:
        """The five cells contributing most to χ², one line each."""
        contrib = (self.obs - self.exp) ** 2 / np.maximum(self.exp, 1e-300)
        npp = len(p_edges) - 1
        lines = []
        for k in np.argsort(-contrib)[:5]:
            if k == len(self.exp) - 1:
                where = "rejected samples"
            else:
                i, j = divmod(int(k), npp)
                where = (
                    f"θ {np.degrees(t_edges[i]):.1f}–{np.degrees(t_edges[i + 1]):.1f}°, "
                    f"φ {np.degrees(p_edges[j]):.0f}–{np.degrees(p_edges[j + 1]):.0f}°"
                )
            lines.append(f"  {where}: observed {int(self.obs[k])}, expected {self.exp[k]:.1f}")
        return "\n".join(lines)
