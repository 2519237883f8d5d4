"""Heightfields whose facet slopes follow the Student-t distribution (STD; Ribardière et al.
2017), GGX at γ = 2 (docs/design.md, "Student-t surfaces").

The STD slope density P22(s) = ((γ−1)/(γ−1 + |s|²/α²))^γ/(π α²) is a Gamma scale mixture of
Gaussians: given w ~ Gamma(γ − 1, 1), each slope axis is normal with variance α²(γ−1)/(2w).
Two constructions realise it:

* ``student_t_transform``: one tile, a unit-variance Gaussian field g mapped by a memoryless
  transform h = T(g) whose slope T′(g)∇g has exactly that law (g and ∇g are independent at a
  point); heights and |slope| are correlated by construction.
* ``student_t_mixture``: the mixture spread over realisations, each a Gaussian (Beckmann)
  patch of roughness m = α√((γ−1)/w) with w drawn from its stratum of Gamma(γ − 1).

``SlopeLaw`` measures how well a surface (or a set of patches) realises its law
(``Surface.stats()``, ``microsim surface``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import gammainc, gammainccinv, gammaincinv, ndtr

from microsim.analytic import GGX, AnisotropicGGX, AnisotropicStudentT, Beckmann, StudentT
from microsim.checks import finite, integer, positive

from .heightfields import (
    MAX_RMS_SLOPE,
    _finite_spectrum,
    _grid_args,
    _heightfield_surface,
    _mesh_alphas,
    check_resolved,
    gaussian,
    gaussian_anisotropic_psd,
    gaussian_psd,
    psd_grid,
    spectrum_moments,
    synthesize,
)
from .surface import Surface, facet_slopes

__all__ = [
    "student_t_transform",
    "student_t_mixture",
    "student_t_ensemble",
    "height_transform",
    "gamma_weight",
    "mixture_patch_m",
    "SlopeLaw",
    "slope_law_stats",
    "TRANSFORM_G_MAX",
    "TRANSFORM_G_STEP",
    "KS_LEVEL",
]

TRANSFORM_G_MAX = 9.0
"""The transform is tabulated on g ∈ [−9, 9]: a unit normal exceeds 9 with probability 1e-19,
never on a grid of at most 4096² points (beyond, ``np.interp``-like clamping would flatten)."""
TRANSFORM_G_STEP = 2.0**-10
"""Step of the g grid of the transform: cumulative Simpson integration of T′ and cubic Hermite
interpolation with the exact T′ at the nodes; the interpolant's derivative matches T′ within
1e-6 relative over |g| ≤ 6 (tests/test_student_t_surfaces.py)."""
KS_LEVEL = 0.01
"""Level of the Kolmogorov–Smirnov critical value ``SlopeLaw`` reports."""


def student_t_ensemble(alpha: float, gamma: float, alpha_y: float | None = None, rotation=0.0):
    """The distribution a Student-t surface samples, as its models name it: GGX (``GGX``,
    ``AnisotropicGGX``) at γ = 2, else ``StudentT`` / ``AnisotropicStudentT``."""
    if alpha_y is None:
        return GGX(alpha) if gamma == 2.0 else StudentT(alpha, gamma)
    if gamma == 2.0:
        return AnisotropicGGX(alpha, alpha_y, rotation)
    return AnisotropicStudentT(alpha, alpha_y, gamma, rotation)


def gamma_weight(g, gamma: float):
    """w(g) = GammaInv_{γ−1}(Φ(g)): the Gamma(γ − 1, 1) variable a unit normal g maps to,
    increasing in g (low g, the valleys, get small w: rough). Evaluated with the upper inverse
    gammainccinv(γ − 1, Φ(−g)) for g > 0, where Φ(g) is close to 1."""
    g = np.asarray(g, dtype=np.float64)
    a = gamma - 1.0
    return np.where(g < 0, gammaincinv(a, ndtr(g)), gammainccinv(a, ndtr(-g)))


def height_transform(gamma: float, scale: float):
    """T with T(0) = 0 and T′(g) = scale · √((γ−1)/(2 w(g))) (``gamma_weight``), tabulated on
    [−``TRANSFORM_G_MAX``, ``TRANSFORM_G_MAX``] with step ``TRANSFORM_G_STEP``. With scale² ·
    v_g = α², v_g the per-axis slope variance of g, the slope T′(g)∇g given w has per-axis
    variance α²(γ−1)/(2w): the STD. A ``scipy.interpolate.CubicHermiteSpline``."""
    from scipy.integrate import cumulative_simpson  # scipy.integrate and .interpolate take
    from scipy.interpolate import CubicHermiteSpline  # ~0.3 s to import: only when building

    g = np.arange(-TRANSFORM_G_MAX, TRANSFORM_G_MAX + 0.5 * TRANSFORM_G_STEP, TRANSFORM_G_STEP)
    dT = scale * np.sqrt((gamma - 1.0) / (2.0 * gamma_weight(g, gamma)))
    # integrated outwards from g = 0 on each side, so that the huge values of the rough end
    # never enter (by rounding) the small increments of the smooth end
    mid = len(g) // 2
    right = cumulative_simpson(dT[mid:], x=g[mid:], initial=0.0)
    left = -cumulative_simpson(dT[: mid + 1][::-1], x=-g[: mid + 1][::-1], initial=0.0)[::-1]
    return CubicHermiteSpline(g, np.concatenate([left[:-1], right]), dT)


@dataclass(frozen=True)
class SlopeLaw:
    """The law a heightfield's facet slopes should follow, and the measure of how well they do
    (``slope_law_stats``; called with a surface it is that surface's ``generator_stats``).

    Slopes are taken along axes rotated by ``rotation`` degrees and divided by ``stretch``
    (αx, αy); their magnitude r should then follow the equal-weight blend of the |slope| laws
    P(|s| ≤ r) = ``cdf_theta_rad(arctan r)`` of the isotropic ``ndfs`` (one NDF, or one per
    patch for a set of mixture patches). ``cell_area``: the area of one independent cell,
    corr_len² (ℓx·ℓy anisotropic). ``gamma``: with a stretch, the Student-t γ whose per-axis
    marginal (s/α ~ t_{2(γ−1)}/√2) turns median |slope| into a realised α per axis."""

    ndfs: tuple
    cell_area: float
    stretch: tuple[float, float] = (1.0, 1.0)
    rotation: float = 0.0
    gamma: float | None = None

    def cdf(self, r):
        """P(|s| ≤ r) of the (stretched) slopes."""
        theta = np.arctan(np.asarray(r, dtype=np.float64))
        return np.mean([np.asarray(n.cdf_theta_rad(theta)) for n in self.ndfs], axis=0)

    def __call__(self, surface: Surface) -> dict:
        return slope_law_stats([surface], self)


def _weighted_ks(x, w, cdf) -> float:
    """sup |F_n − F| of the weighted sample (x, w) against the CDF ``cdf``."""
    order = np.argsort(x)
    x, w = x[order], w[order] / w.sum()
    upper = np.cumsum(w)
    F = cdf(x)
    return float(max(np.max(upper - F), np.max(F - (upper - w))))


def slope_law_stats(surfaces, law: SlopeLaw) -> dict:
    """How the facets of ``surfaces`` (one tile, or the union of mixture patches) realise
    ``law``, weighted by projected area:

    ``slope_ks``: Kolmogorov–Smirnov distance of |slope| (stretched, ``SlopeLaw``) to
    ``law.cdf``; ``independent_cells`` N = tile area / ``cell_area`` summed over the surfaces
    (neighbouring facets are correlated over about one correlation length, so the facets count
    as N independent draws); ``slope_ks_critical``: the KS critical value at level
    ``KS_LEVEL`` for N draws (``scipy.stats.kstwo``, ≈ 1.628/√N); ``azimuth_ks``: KS distance
    of the (stretched) slope azimuth to the uniform law; ``tail_mass_truncated``: the law's
    mass beyond the largest realised |slope|; ``height_slope_rank_corr``: Spearman rank
    correlation of facet height (mean of its vertices) and |slope|, averaged over the surfaces
    (0 where Smith's uncorrelated-heights assumption holds); with ``law.gamma``:
    ``alpha_x_realised``/``alpha_y_realised`` from the median |slope| per rotated axis."""
    from scipy import stats as _stats  # ~0.4 s to import: only when the statistics are asked

    c, s = np.cos(np.radians(law.rotation)), np.sin(np.radians(law.rotation))
    sx, sy, weights, corr = [], [], [], []
    cells = 0.0
    for surf in surfaces:
        gx, gy = facet_slopes(surf.facet_normals())
        sx.append((c * gx + s * gy) / law.stretch[0])
        sy.append((-s * gx + c * gy) / law.stretch[1])
        weights.append(surf.projected_areas())
        cells += surf.tile_size[0] * surf.tile_size[1] / law.cell_area
        heights = surf.vertices[surf.faces][:, :, 2].mean(axis=1)
        corr.append(_stats.spearmanr(heights, np.hypot(gx, gy)).statistic)
    sx, sy, weights = np.concatenate(sx), np.concatenate(sy), np.concatenate(weights)
    r = np.hypot(sx, sy)
    azimuth = np.mod(np.arctan2(sy, sx), 2.0 * np.pi) / (2.0 * np.pi)
    n_cells = max(1, int(cells))
    out = {
        "slope_ks": _weighted_ks(r, weights, law.cdf),
        "slope_ks_critical": float(_stats.kstwo.isf(KS_LEVEL, n_cells)),
        "azimuth_ks": _weighted_ks(azimuth, weights, lambda u: u),
        "independent_cells": n_cells,
        "tail_mass_truncated": float(1.0 - law.cdf(r.max())),
        "height_slope_rank_corr": float(np.mean(corr)),
    }
    if law.gamma is not None:
        median = _stats.t.ppf(0.75, 2.0 * (law.gamma - 1.0)) / np.sqrt(2.0)
        out["alpha_x_realised"] = float(law.stretch[0] * np.median(np.abs(sx)) / median)
        out["alpha_y_realised"] = float(law.stretch[1] * np.median(np.abs(sy)) / median)
    return out


def _unit_sigma_field(n, dx, corr_len, corr_len_y, rotation):
    """(S, FX, FY, moments) of the σ = 1 Gaussian-correlated spectrum on the grid: ℓ =
    ``corr_len``, with ``corr_len_y`` the anisotropic one along axes rotated by ``rotation``
    degrees (its realised height variance ``moments.height_var`` is slightly below 1)."""
    with np.errstate(over="ignore", invalid="ignore"):
        if corr_len_y is None:
            S, FX, FY = psd_grid(lambda f: gaussian_psd(f, 1.0, corr_len), (n, n), dx)
        else:
            lx, ly = corr_len, corr_len_y
            S, FX, FY = psd_grid(
                lambda fx, fy: gaussian_anisotropic_psd(fx, fy, 1.0, lx, ly, rotation),
                (n, n),
                dx,
                of_xy=True,
            )
    _finite_spectrum(S, f"corr_len = {corr_len:g}")
    return S, FX, FY, spectrum_moments(S, FX, FY, dx)


def student_t_transform(
    n: int,
    dx: float,
    alpha: float,
    gamma: float,
    corr_len: float,
    seed: int = 0,
    exact_amplitude: bool = True,
    alpha_y: float | None = None,
    rotation: float = 0.0,
) -> Surface:
    """Periodic n×n heightfield whose facet slopes follow the STD (α, γ) in one tile.

    A unit-variance Gaussian field g (autocorrelation exp(−r²/ℓ²), ℓ = ``corr_len``, synthesised
    as ``heightfields.gaussian``) is mapped by h = T(g) (``height_transform``), T′(g)² v_g =
    α²(γ−1)/(2 w(g)), w(g) = GammaInv_{γ−1}(Φ(g)) (``gamma_weight``) and v_g the per-axis
    *mesh* slope variance of g (exact from the discrete spectrum, ``spectrum_moments``). At a
    point g and ∇g are independent and w(g) ~ Gamma(γ − 1), so the slope T′(g)∇g is exactly
    STD in the continuum; the mesh differences T over one grid step, which blurs the far tail
    where T′ changes within a step (``SlopeLaw`` measures the realised law). Φ(g) puts the
    rough parts (small w) in the valleys: heights and |slope| are (anti-)correlated by
    construction, so Smith's uncorrelated-heights assumption does not hold (``stats()``'
    ``height_slope_rank_corr``). The mirror choice, rough peaks, is the same slope law on the
    upside-down surface, but its heavy tail becomes spires far above the rest of the tile (z
    max ≈ 100 × the rms height on a 512² GGX tile) that shadow the tile at grazing incidence
    and slow the periodic ray walk ~25× (every masking ray must climb above them); rough
    valleys keep the top of the tile that of a Gaussian field.

    Anisotropic (``alpha_y`` given): g has correlation lengths ℓ and ℓ·α/αy along axes rotated
    by ``rotation`` degrees, so its slope variances there stand as αx² : αy²; T′ uses their
    geometric mean, and the ensemble NDF is ``AnisotropicStudentT(alpha, alpha_y, gamma,
    rotation)``. The mesh's own slope ratio differs by well under 1 % for ℓ ≥ 7·dx;
    ``stats()`` measures α per axis from median |slope| (``SlopeLaw``).
    """
    n, dx, seed = _grid_args(n, dx, seed)
    alpha, corr_len = positive("alpha", alpha), positive("corr_len", corr_len)
    rotation = finite("rotation", rotation)
    if alpha_y is None:
        ensemble, corr_len_y = student_t_ensemble(alpha, gamma), None
        check_resolved(dx, corr_len=corr_len)
    else:
        alpha_y = positive("alpha_y", alpha_y)
        ensemble = student_t_ensemble(alpha, alpha_y=alpha_y, gamma=gamma, rotation=rotation)
        corr_len_y = corr_len * alpha / alpha_y
        check_resolved(dx, corr_len=corr_len, **{"corr_len·alpha/alpha_y": corr_len_y})
    gamma = float(gamma)
    S, FX, FY, mom = _unit_sigma_field(n, dx, corr_len, corr_len_y, rotation)
    # g = field/√var is N(0, 1) at every point (exactly the realised variance with
    # exact_amplitude); v_g, its per-axis mesh slope variance, is the field's over var
    if alpha_y is None:
        v_g = 0.5 * (mom.slope_var_x + mom.slope_var_y) / mom.height_var
        scale = alpha / np.sqrt(v_g)
        law = SlopeLaw((StudentT(alpha, gamma),), corr_len**2)
    else:
        gx, gy = _mesh_alphas(S, FX, FY, dx, mom, rotation)  # √(2 × slope variance) per axis
        scale = np.sqrt(alpha * alpha_y * mom.height_var / (0.5 * gx * gy))
        stretch = (alpha, alpha_y)
        law = SlopeLaw((StudentT(1.0, gamma),), corr_len * corr_len_y, stretch, rotation, gamma)
    del FX, FY  # 16 bytes per point fewer during the synthesis
    g = synthesize(S, dx, np.random.default_rng(seed), exact_amplitude)
    g /= np.sqrt(mom.height_var)  # in place: the same quotients
    heights = height_transform(gamma, scale)(g)
    nominal = {
        "construction": "transform",
        "alpha": alpha,
        **({} if alpha_y is None else {"alpha_y": alpha_y, "rotation": rotation}),
        "gamma": gamma,
        "corr_len": corr_len,
        "n": n,
        "dx": dx,
        "seed": seed,
        "exact_amplitude": bool(exact_amplitude),
    }
    surf = _heightfield_surface(
        "student-t-transform", heights - heights.mean(), dx, nominal, [], ensemble, None
    )
    return surf.replaced(generator_stats=law)


def mixture_patch_m(alpha: float, gamma: float, patches: int, seed: int) -> float:
    """The Beckmann m = α√((γ−1)/w) of realisation ``seed``: patch k = seed mod ``patches``,
    w the Gamma(γ − 1) quantile of the stratum's midpoint (k + ½)/``patches``."""
    w = gammaincinv(gamma - 1.0, (seed % patches + 0.5) / patches)
    return float(alpha * np.sqrt((gamma - 1.0) / w))


def student_t_mixture(
    n: int,
    dx: float,
    alpha: float,
    gamma: float,
    corr_len: float,
    seed: int = 0,
    patches: int = 64,
    exact_amplitude: bool = True,
) -> Surface:
    """One patch of the STD (α, γ) as a Gamma scale mixture of Beckmann heightfields.

    Realisation ``seed`` is patch k = seed mod ``patches``: a ``heightfields.gaussian`` field
    (correlation length ℓ = ``corr_len``) of mesh roughness m = α√((γ−1)/w) with w the
    midpoint of the k-th of ``patches`` equal-probability strata of Gamma(γ − 1)
    (``mixture_patch_m``), its σ set so the *mesh* slope variance is m²/2 (σ = m ℓ/2 up to the
    mesh's finite-difference response). ``patches`` consecutive seeds cover every stratum
    once: the average of their BRDFs is the mixture's — a blend of Beckmann BRDFs with their
    own Smith masking, not the Smith-STD BRDF — so a run's realisations must be a multiple of
    ``patches`` (the scene check). The midpoint rule puts the blend of the patches' slope laws
    within KS 0.12/``patches`` of the STD at γ = 2 (0.0018 at the default 64; a uniform draw
    inside each stratum would be exact on average over seeds but ~3× farther for one set of
    patches, which is what a run traces). m is capped where the Gaussian generator's scene check
    would refuse (nominal rms slope 2σ/ℓ ≤ ``MAX_RMS_SLOPE``); the target mass thereby moved
    to the cap, P(m > m_cap) = P(w < (γ−1)α²/m_cap²), is ``nominal["capped_tail_mass"]``.

    ``ensemble_ndf`` is the mixture's ``StudentT(alpha, gamma)``; the patch's own law is
    Beckmann(``nominal["m_patch"]``), against which ``stats()`` measures it (``SlopeLaw``; for
    the union of patches pass a ``SlopeLaw`` of all their Beckmann NDFs to
    ``slope_law_stats``).
    """
    n, dx, seed = _grid_args(n, dx, seed)
    alpha, corr_len = positive("alpha", alpha), positive("corr_len", corr_len)
    patches = integer("patches", patches, 1, None, " (Gamma strata of the mixture)")
    ensemble = student_t_ensemble(alpha, gamma)
    gamma = float(gamma)
    check_resolved(dx, corr_len=corr_len)
    *_, mom = _unit_sigma_field(n, dx, corr_len, None, 0.0)
    m_per_sigma = np.sqrt(mom.slope_var_x + mom.slope_var_y)  # the mesh m of gaussian(σ = 1)
    m_cap = MAX_RMS_SLOPE * corr_len / 2.0 * m_per_sigma
    m = min(mixture_patch_m(alpha, gamma, patches, seed), m_cap)
    surf = gaussian(n, dx, m / m_per_sigma, corr_len, seed, exact_amplitude)
    nominal = {
        "construction": "mixture",
        "alpha": alpha,
        "gamma": gamma,
        "corr_len": corr_len,
        "patches": patches,
        "patch": seed % patches,
        "m_patch": m,
        "capped_tail_mass": float(gammainc(gamma - 1.0, (gamma - 1.0) * (alpha / m_cap) ** 2)),
        "sigma": surf.nominal["sigma"],
        "n": n,
        "dx": dx,
        "seed": seed,
        "exact_amplitude": bool(exact_amplitude),
    }
    law = SlopeLaw((Beckmann(m),), corr_len**2)
    return surf.replaced(
        kind="student-t-mixture",
        nominal=nominal,
        ensemble_ndf=ensemble,
        generator_stats=law,
    )
