"""Pearson χ² goodness of fit of an importance sampler against its own pdf.

The harness microsim uses for its own samplers (docs/design.md, "Tests"), public: draw N
directions, count them in cells of the sphere, integrate the pdf over the same cells, and
test the counts with Pearson's χ² (cells whose expected count is below ``min_expected``
pooled into one; Šidák's correction for a family of tests). Mitsuba 3 and pbrt-v4 ship the
same kind of test for their BSDF samplers.
"""

from __future__ import annotations

import numpy as np

from microsim import checks as _checks
from microsim.errors import UsageError
from microsim.stats import chi2_sf, sidak

from .returns import real_values

__all__ = ["pearson_chi2", "assert_sampler_matches", "SamplerCheck"]


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
    p_threshold, n, outside (samples not in any cell: invalid or NaN), cells, quad_chi2."""


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
    flat = dirs.reshape(-1, 3)
    vals = real_values(pdf(flat), "pdf(w) must return", f"({len(flat)},)")
    if vals.size != len(flat):
        raise UsageError(
            f"pdf(w) must return one density per direction, shape ({len(flat)},); "
            f"got shape {vals.shape}"
        )
    vals = vals.reshape(dirs.shape[:-1])
    if not np.all(np.isfinite(vals)) or np.any(vals < 0):
        raise UsageError("pdf(w) must return finite densities >= 0 (sr⁻¹)")
    weight = (wt * np.sin(th))[:, None, :, None] * wp[None, :, None, :]
    return np.sum(vals * weight, axis=(2, 3))


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
    pdf_rtol: float = 1e-6,
) -> SamplerCheck:
    """Assert that ``sample`` draws directions with density ``pdf`` (Pearson χ², level α).

    ``sample(u1, u2)``: u1, u2 (n,) uniform in [0, 1) → directions (n, 3) (unit vectors on the
    sphere, z = macro normal; a sample the sampler rejects may be NaN), or a tuple
    ``(directions, pdf_values)``, in which case the returned pdf values must equal
    ``pdf(directions)`` within ``pdf_rtol`` (relative) where finite. ``pdf(w)``: w (M, 3) →
    (M,) density in sr⁻¹ over the whole sphere of directions (samples below the horizon are
    counted like any other); the probability it leaves out (1 − ∫ pdf) is the expected share
    of rejected samples.

    Cells: ``theta_cells`` bands in θ ∈ [0°, 180°] with edges at quantiles of a pilot sample
    (5 % of n, its own random stream: about equal counts per band), × ``phi_cells`` equal
    azimuth sectors; the horizon θ = 90° is always an edge (where many pdfs jump to 0); one
    extra cell for the samples outside (NaN or non-unit). Expected
    counts: n × tensor Gauss–Legendre integral of pdf · sin θ over each cell with ``order``
    and 2 × ``order`` nodes; the 2×-order values are used, and if their difference could add
    more than 1 to χ² the pdf is too peaked for the cells and a UsageError says so.
    The test rejects when p < Šidák(alpha, n_tests) (``n_tests``: the size of the family the
    caller runs, e.g. several outgoing directions). On rejection AssertionError lists χ²,
    dof, p and the cells with the largest contributions (θ and φ ranges, observed vs
    expected). Returns the numbers (``SamplerCheck``).
    """
    __tracebackhide__ = True
    if not callable(sample):
        raise UsageError(f"sample must be a callable sample(u1, u2) -> (n, 3), got {sample!r}")
    if not callable(pdf):
        raise UsageError(f"pdf must be a callable pdf(w) -> (n,) in sr⁻¹, got {pdf!r}")
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
    p_thr = sidak(float(alpha), int(n_tests))

    def draw(m, rng):
        out = sample(rng.random(m), rng.random(m))
        vals = None
        if isinstance(out, tuple):
            if len(out) != 2:
                raise UsageError("sample must return directions (n, 3) or (directions, pdf)")
            out, vals = out
        w = real_values(out, "sample(u1, u2) must return directions as", f"({m}, 3)")
        if w.shape != (m, 3):
            raise UsageError(
                f"sample(u1, u2) must return directions of shape ({m}, 3), got {w.shape}"
            )
        return w, vals

    pilot, _ = draw(max(1000, int(n) // 20), np.random.default_rng([int(seed), 1]))
    w, vals = draw(int(n), np.random.default_rng([int(seed), 0]))
    with np.errstate(invalid="ignore"):
        norm = np.linalg.norm(w, axis=1)
        ok = np.isfinite(norm) & (np.abs(norm - 1.0) < 1e-6)
    if vals is not None:
        vals = real_values(vals, "sample(u1, u2)'s pdf values must be", f"({n},)").reshape(-1)
        if vals.shape != (int(n),):
            raise UsageError(f"sample's pdf values must have shape ({n},), got {vals.shape}")
        m_ok = int(np.count_nonzero(ok))
        ref = real_values(pdf(w[ok]), "pdf(w) must return", f"({m_ok},)")
        if ref.size != m_ok:
            raise UsageError(
                f"pdf(w) must return one density per direction, shape ({m_ok},); "
                f"got shape {ref.shape}"
            )
        ref = ref.reshape(-1)
        fin = np.isfinite(vals[ok]) & np.isfinite(ref)
        bad = np.abs(vals[ok][fin] - ref[fin]) > pdf_rtol * np.abs(ref[fin])
        if bad.any():
            k = np.flatnonzero(bad)[0]
            raise AssertionError(
                f"sampler pdf values disagree with pdf(w) at {int(bad.sum())} of {int(fin.sum())} "
                f"samples (rtol {pdf_rtol:g}); e.g. w = {np.round(w[ok][fin][k], 6).tolist()}: "
                f"sampler {vals[ok][fin][k]:.6g} vs pdf {ref[fin][k]:.6g} sr⁻¹"
            )
    pn = np.linalg.norm(pilot, axis=1)
    pt = np.arccos(np.clip(pilot[np.isfinite(pn) & (np.abs(pn - 1) < 1e-6), 2], -1, 1))
    inner = np.quantile(pt, np.arange(1, theta_cells) / theta_cells) if pt.size else []
    t_edges = np.unique(np.concatenate([[0.0, 0.5 * np.pi, np.pi], inner]))
    p_edges = np.linspace(-np.pi, np.pi, int(phi_cells) + 1)
    m_lo = _cell_masses(pdf, t_edges, p_edges, int(order))
    m_hi = _cell_masses(pdf, t_edges, p_edges, 2 * int(order))
    outside_mass = max(0.0, 1.0 - float(m_hi.sum()))
    if m_hi.sum() > 1.0 + 1e-3:
        raise AssertionError(
            f"pdf integrates to {m_hi.sum():.6g} > 1 over the sphere: not a probability density"
        )
    exp = np.append(m_hi.ravel(), outside_mass) * n
    quad = float(np.sum(n * (m_lo - m_hi).ravel() ** 2 / np.maximum(m_hi.ravel(), 1.0 / n)))
    if quad > 1.0:
        raise UsageError(
            f"pdf: the cell integrals did not converge (order {order} vs {2 * order} nodes could "
            f"add {quad:.3g} to χ²): the pdf is too peaked or singular for these cells; raise "
            f"order or theta_cells/phi_cells"
        )
    wt = w[ok]
    th = np.arccos(np.clip(wt[:, 2], -1, 1))
    ph = np.arctan2(wt[:, 1], wt[:, 0])
    counts, _, _ = np.histogram2d(th, ph, [t_edges, p_edges])
    obs = np.append(counts.ravel(), np.count_nonzero(~ok))
    chi2, dof, p = pearson_chi2(obs, exp, min_expected)
    if dof < 1:
        raise UsageError(
            f"sample and pdf leave nothing to test: fewer than two cells expect "
            f"{min_expected:g} or more of the {n} samples (pdf integrates to "
            f"{m_hi.sum():.3g} over the sphere); raise n or check the pdf"
        )
    out = SamplerCheck(
        chi2=chi2,
        dof=dof,
        p_value=p,
        p_threshold=p_thr,
        n=int(n),
        outside=int(np.count_nonzero(~ok)),
        cells=int(len(exp)),
        quad_chi2=quad,
    )
    if p < p_thr:
        contrib = (obs - exp) ** 2 / np.maximum(exp, 1e-300)
        worst = np.argsort(-contrib)[:5]
        nt, npp = len(t_edges) - 1, len(p_edges) - 1
        lines = []
        for k in worst:
            if k == nt * npp:
                where = "outside (rejected/NaN samples)"
            else:
                i, j = divmod(int(k), npp)
                where = (
                    f"θ {np.degrees(t_edges[i]):.1f}–{np.degrees(t_edges[i + 1]):.1f}°, "
                    f"φ {np.degrees(p_edges[j]):.0f}–{np.degrees(p_edges[j + 1]):.0f}°"
                )
            lines.append(f"  {where}: observed {int(obs[k])}, expected {exp[k]:.1f}")
        raise AssertionError(
            f"sampler does not match its pdf: χ² = {chi2:.1f} on {dof} dof, p = {p:.3g} < "
            f"{p_thr:.3g} (α = {alpha:g}, Šidák over {n_tests} test(s)); {n} samples, "
            f"{out['outside']} outside the sphere's cells (expected {exp[-1]:.1f}).\n"
            "largest contributions:\n" + "\n".join(lines)
        )
    return out
