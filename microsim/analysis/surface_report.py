"""What a measured surface is: the report of a heightfield (``surface_report(heights, dx)``,
``microsim surface FILE --dx DX``).

The heights (rows = y, columns = x, the unit of ``dx``; NaN marks a missing point) are first
levelled: the least-squares plane through the finite points is removed (its tilt is reported;
a periodic tile, ``EDGE_MISMATCH``, only loses its mean) and the statistics below are those of
the levelled surface.

* Heights: ISO 25178-2's Sq (rms), Sa (mean |z|), Ssk (skewness), Sku (kurtosis), Sz (range),
  the correlation length ℓ (where the azimuthally averaged autocorrelation falls to 1/e; a
  Gaussian autocorrelation σ² exp(−r²/ℓ²) gives its ℓ) and ISO's Sal (the shortest lag at which
  it falls to 0.2).
* Slopes: those of the facets the ray tracer builds from the grid (``surface.heightfield_mesh``:
  two triangles per cell, split along the (i, j)–(i+1, j+1) diagonal), every facet of the same
  projected area, so the area-weighted statistics are plain means: rms per axis, total
  m = √(E[sx²] + E[sy²]), largest |slope|. A periodic tile includes the facets across its
  seams; otherwise only the cells inside the grid count.
* PSD: the periodogram S(f) = |FFT(h)|² dx²/N (length⁴, Σ S df² = Sq²), Hann-windowed
  (divided by the window's mean square) unless the tile is periodic; its azimuthal average over
  rings one frequency step wide; Church's ABC PSD (Church et al. 1989; Löw et al. 2012, eq. 7,
  ``analytic.abc_psd_church``) fitted to the rings by least squares on log S, each ring
  averaged over its own cells (no binning bias) and weighted by the scatter of the log of a
  mean of k/2 exponential modes for k cells (a Gaussian field's periodogram; its log bias
  ψ(k/2) − ln(k/2) removed; ``HANN_SPREAD`` times fewer modes when
  windowed). A, B, C carry the standard errors of the fit's covariance (the inverse of JᵀJ at
  that weighting). On a scan that is not periodic, levelling and the window take power from
  the lowest rings: A and B come out low by about one standard error (ABC tiles cropped to
  150 × 170 points, 12 seeds).
* NDF: Beckmann (m), GGX (α) and Student-t (α, γ; ``analytic``'s distributions) fitted by
  maximum likelihood to the facets' tilts θ = arctan|slope| (binned in 2048 bins), each with
  its Kolmogorov–Smirnov distance to the |slope| distribution and the critical value at level
  ``KS_LEVEL`` for N independent draws; the best fit has the smallest distance. Beckmann's m is
  the rms slope: per-axis slope variance m²/2 (Beckmann & Spizzichino 1963).
* Uncertainties of slope statistics count N = tile area/ℓ² independent cells (neighbouring
  facets are correlated over about one correlation length, as ``surfaces.student_t.SlopeLaw``
  counts them): the likelihood's curvature is scaled from the facets to those N.
* Anisotropy: the principal axes of the slope covariance, αx ≥ αy = √(2 × variance) along
  them (``surface.rotated_alphas``) and the angle of the αx axis from the grid's x axis.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, is_dataclass

import numpy as np

from microsim.analytic import GGX, Beckmann, StudentT, abc_psd_church
from microsim.analytic.student_t import GAMMA_MAX
from microsim.checks import positive
from microsim.errors import UsageError
from microsim.surfaces.heightfields import MIN_GRID
from microsim.surfaces.surface import rotated_alphas

__all__ = [
    "surface_report",
    "SurfaceReport",
    "HeightStats",
    "SlopeStats",
    "Estimate",
    "RadialPsd",
    "AbcFit",
    "NdfFit",
    "Anisotropy",
    "Regime",
    "surface_chart",
    "MIN_CORR_CELLS",
    "EDGE_MISMATCH",
    "KS_LEVEL",
]

MIN_CORR_CELLS = 4.0
"""Shortest correlation length, in grid steps, whose slopes the facets resolve: below it the
finite differences over one step alias the slopes (a Gaussian ℓ = 4 dx keeps 94 % of the
continuum slope variance 2σ²/ℓ², ``heightfields.gaussian_mesh_slope_var``; ℓ = 2 dx 78 %)."""
EDGE_MISMATCH = 2.0
"""A tile is periodic when the rms height step across each pair of opposite edges is at most
this many times the rms step between neighbours inside it."""
KS_LEVEL = 0.01
"""Level of the Kolmogorov–Smirnov critical value of the NDF fits."""
TILT_WARNING = 0.2
"""The levelled plane's slope, as a fraction of the rms slope, above which the report warns
that the file should be levelled before it is traced."""
RAYLEIGH_RICE_BELOW = 0.025
GEOMETRIC_FROM = 0.24
"""σ cos θi/λ below which Rayleigh–Rice holds and from which geometric optics (the ray tracer)
holds within 5 %, as ``analysis.regimes`` measured them (Gaussian and ABC surfaces,
aluminium: 0.024–0.031 and 0.175–0.243)."""
HANN_SPREAD = (1.0 + 2.0 * ((2.0 / 3.0) ** 2 + (1.0 / 6.0) ** 2)) ** 2
"""How many times the variance of a ring's mean grows when the heights are Hann-windowed: the
windowed periodogram's neighbours along an axis correlate by (2/3)² at one cell and (1/6)² at
two (the Fourier coefficients of the squared window), so a sum over cells has 1 + 2((2/3)² +
(1/6)²) ≈ 1.94 times the variance of independent ones along each axis, ≈ 3.8 in 2D."""
ABC_POOR_FIT = 4.0
"""Reduced χ² of the ABC fit above which the report says the model does not describe the PSD
(a Gaussian random field with an ABC spectrum gives about 1)."""
_TILT_BINS = 2048


@dataclass(frozen=True)
class Estimate:
    """A fitted value and its standard error (None: the fit stopped at the parameter's bound,
    e.g. Student-t's γ at ``GAMMA_MAX`` where it is Beckmann)."""

    value: float
    error: float | None

    def __str__(self) -> str:
        if self.error is None:
            return f"{self.value:.4g} (at its bound)"
        return f"{self.value:.4g} ± {self.error:.2g}"


@dataclass(frozen=True)
class HeightStats:
    """ISO 25178-2 height parameters of the levelled surface (length unit of the heights)."""

    Sq: float
    Sa: float
    Ssk: float
    Sku: float
    Sz: float
    corr_len: float
    Sal: float
    tilt_deg: float


@dataclass(frozen=True)
class SlopeStats:
    """Facet slopes, as the tracer's mesh has them: rms per grid axis, total m = √(vx + vy),
    the slope correlation, the largest |slope| and its angle, the facet count and the N
    independent cells the uncertainties count."""

    rms_x: float
    rms_y: float
    rms: float
    correlation: float
    max: float
    max_deg: float
    facets: int
    independent_cells: int


@dataclass(frozen=True)
class RadialPsd:
    """The azimuthally averaged PSD: ring frequencies (cycles per length, mean |f| of the
    ring's cells), power (length⁴) and the number of FFT cells in each ring."""

    frequency: tuple[float, ...]
    power: tuple[float, ...]
    cells: tuple[int, ...]


@dataclass(frozen=True)
class AbcFit:
    """Church's ABC PSD A/(1 + B² f²)^((C+1)/2) fitted to the radial PSD: A (length⁴), B
    (length), C, with the standard errors of the fit's covariance; ``sigma`` the rms height
    √(2πA/(B²(C − 1))) of the fitted continuum (None for C ≤ 1); the fitted frequency range
    and the reduced χ² at the periodogram's scatter."""

    A: Estimate
    B: Estimate
    C: Estimate
    sigma: float | None
    f_range: tuple[float, float]
    reduced_chi2: float
    uncertainty: str = "covariance of the weighted least-squares fit on log S"

    def psd(self, f):
        """The fitted PSD at frequencies ``f``."""
        return abc_psd_church(f, self.A.value, self.B.value, self.C.value)


@dataclass(frozen=True)
class NdfFit:
    """One distribution fitted to the facet tilts: its name, parameters (with standard
    errors), the KS distance of |slope| to it and the critical value at ``KS_LEVEL``."""

    name: str
    params: dict
    ks: float
    ks_critical: float

    def ndf(self):
        """The fitted distribution (``analytic``)."""
        return _FAMILIES[self.name](**{k: v.value for k, v in self.params.items()})

    @property
    def consistent(self) -> bool:
        return self.ks <= self.ks_critical


@dataclass(frozen=True)
class Anisotropy:
    """Principal axes of the slope covariance: αx ≥ αy along them, the angle of the αx axis
    from the grid's x axis (degrees, counter-clockwise, in (−90, 90]), the ratio αx/αy with
    its standard error, and whether it differs from 1 by more than three of them."""

    alpha_x: float
    alpha_y: float
    angle_deg: float
    ratio: Estimate
    anisotropic: bool


@dataclass(frozen=True)
class Regime:
    """Heights against a wavelength λ (the heights' unit): σ/λ, the Davies 1954 roughness
    g = (4πσ/λ)² at normal incidence, the Rayleigh criterion σ < λ/8 (Beckmann & Spizzichino
    1963) and which optics hold (``RAYLEIGH_RICE_BELOW``, ``GEOMETRIC_FROM``)."""

    wavelength: float
    sigma_over_lambda: float
    g: float
    rayleigh_smooth: bool
    optics: str


@dataclass(frozen=True)
class SurfaceReport:
    """``surface_report``'s result. ``psd_image`` (fft-shifted 2D PSD, rows = fy) with its
    axes ``psd_fx``/``psd_fy`` and the levelled ``heights`` are kept for charts, not in
    ``to_dict``."""

    shape: tuple[int, int]
    dx: float
    periodic: bool
    missing: int
    heights_stats: HeightStats
    slopes: SlopeStats
    psd: RadialPsd
    abc: AbcFit | None
    ndf_fits: tuple[NdfFit, ...]
    best_ndf: str
    anisotropy: Anisotropy
    regime: Regime | None
    warnings: tuple[str, ...]
    heights: np.ndarray = field(repr=False, compare=False)
    psd_image: np.ndarray = field(repr=False, compare=False)
    psd_fx: np.ndarray = field(repr=False, compare=False)
    psd_fy: np.ndarray = field(repr=False, compare=False)
    theta: np.ndarray = field(repr=False, compare=False)

    def fit(self, name: str) -> NdfFit:
        """The NDF fit called ``name``."""
        for f in self.ndf_fits:
            if f.name == name:
                return f
        names = ", ".join(f.name for f in self.ndf_fits)
        raise UsageError(f"name must be one of {names}, got {name!r}")

    def to_dict(self) -> dict:
        """Everything but the arrays (the fields not compared), as JSON-ready values."""
        out = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.compare:
                out[f.name] = asdict(value) if is_dataclass(value) else value
        out["ndf_fits"] = [{**asdict(f), "consistent": f.consistent} for f in self.ndf_fits]
        return out

    def to_markdown(self) -> str:
        """The report as markdown text."""
        return _markdown(self)


# --- the report --------------------------------------------------------------------------
def surface_report(heights, dx, *, wavelength=None) -> SurfaceReport:
    """The report of the heightfield ``heights`` (2D, rows = y; NaN: missing points) with grid
    step ``dx`` (module docstring); ``wavelength`` (the heights' unit) adds the optical regime.
    Bad input raises a one-line UsageError naming ``heights``, ``dx`` or ``wavelength``."""
    dx = positive("dx", dx)
    if wavelength is not None:
        wavelength = positive("wavelength", wavelength)
    h = _checked_heights(heights)
    missing = int(np.count_nonzero(~np.isfinite(h)))
    periodic, edges = _periodicity(h)
    h, tilt = _levelled(h, dx, periodic)
    heights_stats = _height_stats(h, dx, tilt, periodic)
    sx, sy = _facet_slopes(h, dx, periodic)
    cells = _independent_cells(h.shape, dx, heights_stats.corr_len, sx.size)
    slopes = _slope_stats(sx, sy, cells)
    image, fx, fy = _psd_image(h, dx, periodic)
    radial, ring_of = _radial(image, fx, fy, dx)
    abc = _abc_fit(radial, ring_of, fx, fy, periodic)
    theta = np.arctan(np.hypot(sx, sy))
    fits = _ndf_fits(theta, cells)
    best = min(fits, key=lambda f: f.ks).name
    anisotropy = _anisotropy(sx, sy, cells)
    regime = None if wavelength is None else _regime(heights_stats.Sq, wavelength)
    report = dict(
        shape=tuple(int(s) for s in h.shape),
        dx=dx,
        periodic=periodic,
        missing=missing,
        heights_stats=heights_stats,
        slopes=slopes,
        psd=radial,
        abc=abc,
        ndf_fits=fits,
        best_ndf=best,
        anisotropy=anisotropy,
        regime=regime,
    )
    arrays = dict(
        heights=h,
        psd_image=np.fft.fftshift(image),
        psd_fx=np.fft.fftshift(fx),
        psd_fy=np.fft.fftshift(fy),
        theta=theta,
    )
    for a in arrays.values():
        a.flags.writeable = False
    return SurfaceReport(**report, warnings=_warnings(report, edges), **arrays)


def _checked_heights(heights) -> np.ndarray:
    try:
        h = np.array(heights, dtype=np.float64)
    except (TypeError, ValueError):
        raise UsageError(
            f"heights must be a 2D array of real numbers, got {type(heights).__name__}"
        ) from None
    if h.ndim != 2 or min(h.shape) < MIN_GRID:
        raise UsageError(
            f"heights must be a 2D array of at least {MIN_GRID}x{MIN_GRID} points, got shape "
            f"{h.shape}"
        )
    h[np.isinf(h)] = np.nan
    finite_h = h[np.isfinite(h)]
    if finite_h.size < 0.5 * h.size:
        raise UsageError(
            f"heights: only {finite_h.size} of {h.size} points are finite; at least half must be"
        )
    if np.ptp(finite_h) == 0.0:
        raise UsageError("heights are all equal: a flat surface has no statistics to report")
    return h


def _levelled(h: np.ndarray, dx: float, periodic: bool) -> tuple[np.ndarray, float]:
    """(heights minus their least-squares plane, the plane's tilt in degrees); a periodic tile
    has no tilt (a plane would break its periodicity): only its mean is removed."""
    if periodic:
        return h - np.nanmean(h), 0.0
    ny, nx = h.shape
    Y, X = np.mgrid[0:ny, 0:nx] * dx
    ok = np.isfinite(h)
    design = np.stack([X[ok], Y[ok], np.ones(np.count_nonzero(ok))], axis=1)
    (gx, gy, c), *_ = np.linalg.lstsq(design, h[ok], rcond=None)
    return h - (gx * X + gy * Y + c), math.degrees(math.atan(math.hypot(gx, gy)))


def _periodicity(h: np.ndarray) -> tuple[bool, tuple[float, float]]:
    """(whether the tile is periodic, the edge mismatch per axis: rms step across the edges
    over the rms step inside, ``EDGE_MISMATCH``)."""

    def ratio(a):  # along axis 1
        inside = np.nanmean(np.diff(a, axis=1) ** 2)
        across = np.nanmean((a[:, 0] - a[:, -1]) ** 2)
        return math.sqrt(across / inside) if inside > 0 else math.inf

    edges = (ratio(h), ratio(h.T))
    return max(edges) <= EDGE_MISMATCH, edges


def _filled(h: np.ndarray) -> np.ndarray:
    """Levelled heights with the missing points at the plane (zero)."""
    return np.where(np.isfinite(h), h, 0.0)


def _height_stats(h, dx, tilt, periodic) -> HeightStats:
    z = h[np.isfinite(h)]
    z = z - z.mean()
    sq = float(np.sqrt(np.mean(z**2)))
    acf_len, sal = _correlation_lengths(h, dx, periodic)
    return HeightStats(
        Sq=sq,
        Sa=float(np.mean(np.abs(z))),
        Ssk=float(np.mean(z**3) / sq**3),
        Sku=float(np.mean(z**4) / sq**4),
        Sz=float(np.ptp(z)),
        corr_len=acf_len,
        Sal=sal,
        tilt_deg=tilt,
    )


def _correlation_lengths(h, dx, periodic) -> tuple[float, float]:
    """(ℓ, Sal) from the autocorrelation (module docstring): circular for a periodic tile,
    else zero-padded and divided by the overlap of the finite points at each lag."""
    ok = np.isfinite(h).astype(np.float64)
    z = _filled(h)
    ny, nx = h.shape
    shape = (ny, nx) if periodic else (2 * ny, 2 * nx)
    power = np.abs(np.fft.rfft2(z, shape)) ** 2
    overlap = np.fft.irfft2(np.abs(np.fft.rfft2(ok, shape)) ** 2, shape)
    acf = np.fft.irfft2(power, shape) / np.maximum(overlap, 0.5)
    acf /= acf[0, 0]
    lag_y = np.fft.fftfreq(shape[0], 1.0 / shape[0])[:, None] * dx
    lag_x = np.fft.fftfreq(shape[1], 1.0 / shape[1])[None, :] * dx
    r = np.hypot(lag_x, lag_y)
    inside = (np.abs(lag_x) <= nx * dx / 2) & (np.abs(lag_y) <= ny * dx / 2)
    ring = np.rint(r / dx).astype(np.int64)
    sums = np.bincount(ring[inside], acf[inside])
    counts = np.bincount(ring[inside])
    radial = sums / np.maximum(counts, 1)
    below = np.nonzero(radial < math.exp(-1.0))[0]
    if below.size:
        k = int(below[0])  # interpolate between ring k − 1 and k
        a, b = radial[k - 1], radial[k]
        acf_len = (k - 1 + (a - math.exp(-1.0)) / (a - b)) * dx
    else:
        acf_len = min(nx, ny) * dx / 2
    low = inside & (acf <= 0.2)
    sal = float(r[low].min()) if low.any() else min(nx, ny) * dx / 2
    return float(acf_len), sal


def _facet_slopes(h, dx, periodic) -> tuple[np.ndarray, np.ndarray]:
    """(∂z/∂x, ∂z/∂y) of the mesh's facets (``heightfield_mesh``'s triangles (v00, v01, v11)
    and (v00, v11, v10) of each cell) with no missing vertex; across the seams only when
    ``periodic``."""
    if periodic:
        h01, h10 = np.roll(h, -1, axis=1), np.roll(h, -1, axis=0)
        h11 = np.roll(h10, -1, axis=1)
        h00 = h
    else:
        h00, h01, h10, h11 = h[:-1, :-1], h[:-1, 1:], h[1:, :-1], h[1:, 1:]
    sx = np.concatenate([(h01 - h00).ravel(), (h11 - h10).ravel()]) / dx
    sy = np.concatenate([(h11 - h01).ravel(), (h10 - h00).ravel()]) / dx
    ok = np.isfinite(sx) & np.isfinite(sy)
    return sx[ok], sy[ok]


def _independent_cells(shape, dx, corr_len, facets) -> int:
    """N = tile area/ℓ², between 1 and the number of facets."""
    area = shape[0] * shape[1] * dx * dx
    return int(min(max(1.0, area / corr_len**2), facets))


def _slope_stats(sx, sy, cells) -> SlopeStats:
    vx, vy = float(np.mean(sx * sx)), float(np.mean(sy * sy))
    r = np.hypot(sx, sy)
    top = float(r.max())
    return SlopeStats(
        rms_x=math.sqrt(vx),
        rms_y=math.sqrt(vy),
        rms=math.sqrt(vx + vy),
        correlation=float(np.mean(sx * sy) / math.sqrt(vx * vy)) if vx * vy > 0 else 0.0,
        max=top,
        max_deg=math.degrees(math.atan(top)),
        facets=int(sx.size),
        independent_cells=cells,
    )


# --- the PSD -----------------------------------------------------------------------------
EMPTY = 1e-12
"""Periodogram cells below this fraction of the largest hold no power (a synthetic tile's
band cut-off; a measured scan's noise floor lies far above it)."""


def _psd_image(h, dx, periodic):
    """(S, FX, FY): the periodogram (module docstring) on the FFT grid."""
    z = _filled(h)
    ny, nx = z.shape
    if periodic:
        window = np.ones_like(z)
    else:
        window = np.outer(np.hanning(ny), np.hanning(nx))
    z = (z - np.average(z, weights=window)) * window
    S = np.abs(np.fft.fft2(z)) ** 2 * dx * dx / (z.size * np.mean(window**2))
    FX, FY = np.meshgrid(np.fft.fftfreq(nx, dx), np.fft.fftfreq(ny, dx))
    return S, FX, FY


def _radial(S, FX, FY, dx) -> tuple[RadialPsd, np.ndarray]:
    """The rings (``RadialPsd``) from the first frequency step to Nyquist (the last whole
    ring below it), and each FFT cell's ring index (−1: outside every ring). Cells without
    power (``EMPTY`` of the largest: beyond a band-limited tile's cut-off, which may run
    through a ring) belong to no ring, so that a ring's mean is that of the cells the band
    holds and the fit's model is averaged over the same cells."""
    ny, nx = S.shape
    df = max(1.0 / (nx * dx), 1.0 / (ny * dx))
    f = np.hypot(FX, FY)
    ring = np.rint(f / df).astype(np.int64)
    rings = int(0.5 / dx / df - 0.5)  # whole rings below Nyquist
    ring = np.where((ring >= 1) & (ring <= rings) & (S > EMPTY * S.max()), ring - 1, -1)
    inside = ring >= 0
    cells = np.bincount(ring[inside], minlength=rings)
    power = np.bincount(ring[inside], S[inside], minlength=rings) / np.maximum(cells, 1)
    freq = np.bincount(ring[inside], f[inside], minlength=rings) / np.maximum(cells, 1)
    keep = cells > 0
    radial = RadialPsd(
        frequency=tuple(float(v) for v in freq[keep]),
        power=tuple(float(v) for v in power[keep]),
        cells=tuple(int(v) for v in cells[keep]),
    )
    index = np.full(rings, -1)
    index[keep] = np.arange(np.count_nonzero(keep))
    return radial, np.where(inside, index[np.maximum(ring, 0)], -1)


def _abc_fit(radial: RadialPsd, ring_of, FX, FY, periodic: bool) -> AbcFit | None:
    """The ABC fit (module docstring) over the rings holding power (a band-limited tile's
    empty rings left out); None when fewer than four rings do or the fit fails. A ring of k
    cells averages k/2 independent modes, ``HANN_SPREAD`` times fewer when windowed."""
    from scipy.optimize import least_squares
    from scipy.special import digamma, polygamma

    power = np.array(radial.power)
    used = np.nonzero(power > EMPTY * power.max())[0]
    if used.size < 4:
        return None
    freq, cells = np.array(radial.frequency), np.array(radial.cells)
    inside = np.isin(ring_of, used)
    f_cells, ring_cells = np.hypot(FX, FY)[inside], ring_of[inside]
    n_rings = len(power)
    modes = cells[used] / (2.0 if periodic else 2.0 * HANN_SPREAD)
    modes = np.maximum(modes, 1.0)
    weight = 1.0 / np.sqrt(polygamma(1, modes))
    log_p = np.log(power[used]) - (digamma(modes) - np.log(modes))

    def residual(p):
        model = abc_psd_church(f_cells, math.exp(p[0]), math.exp(p[1]), p[2])
        ring_mean = np.bincount(ring_cells, model, minlength=n_rings)[used] / cells[used]
        return (log_p - np.log(np.maximum(ring_mean, 1e-300))) * weight

    a0 = float(power[used[:3]].mean())
    hi = used[used.size // 2 :]
    slope = np.polyfit(np.log(freq[hi]), np.log(power[hi]), 1)[0]
    c0 = float(np.clip(-slope - 1.0, 0.2, 10.0))
    b0 = (a0 / power[hi[-1]]) ** (1.0 / (c0 + 1.0)) / freq[hi[-1]]
    start = [math.log(a0), math.log(max(b0, 1e-3 / freq[used[-1]])), c0]
    try:
        fit = least_squares(residual, start, bounds=([-np.inf, -np.inf, 0.01], [np.inf] * 2 + [50]))
        cov = np.linalg.inv(fit.jac.T @ fit.jac)
    except (np.linalg.LinAlgError, ValueError):
        return None
    err = [None if at else float(e) for at, e in zip(fit.active_mask, np.sqrt(np.diag(cov)))]
    A, B, C = math.exp(fit.x[0]), math.exp(fit.x[1]), float(fit.x[2])
    dof = max(used.size - 3, 1)
    return AbcFit(
        A=Estimate(A, None if err[0] is None else A * err[0]),
        B=Estimate(B, None if err[1] is None else B * err[1]),
        C=Estimate(C, err[2]),
        sigma=math.sqrt(2 * math.pi * A / (B * B * (C - 1.0))) if C > 1.0 else None,
        f_range=(float(freq[used[0]]), float(freq[used[-1]])),
        reduced_chi2=float(np.sum(fit.fun**2) / dof),
    )


# --- the NDF fits ------------------------------------------------------------------------
_FAMILIES = {"beckmann": Beckmann, "ggx": GGX, "student-t": StudentT}
"""The distributions fitted, by name. Free parameters: log m or log α, and log(γ − 1)."""
_LOG_ALPHA = (-20.0, 5.0)
_LOG_GAMMA_M1 = (0.0, math.log(GAMMA_MAX - 1.0))


def _distribution(name: str, p):
    """The distribution ``name`` at free parameters ``p``."""
    if name == "student-t":
        return StudentT(math.exp(p[0]), 1.0 + math.exp(p[1]))
    return _FAMILIES[name](math.exp(p[0]))


class _TiltLikelihood:
    """The binned log-likelihood of the facet tilts (per facet), and their sorted values for
    the KS distance."""

    def __init__(self, theta: np.ndarray):
        top = float(theta.max())
        self.edges = np.append(np.linspace(0.0, top * (1 + 1e-9), _TILT_BINS + 1), 0.5 * np.pi)
        counts = np.histogram(theta, self.edges)[0].astype(np.float64)
        self.share = counts / counts.sum()
        self.ordered = np.sort(theta)

    def nll(self, name: str, p) -> float:
        prob = np.diff(_distribution(name, p).cdf_theta_rad(self.edges))
        return -float(np.sum(self.share * np.log(np.maximum(prob, 1e-300))))

    def ks(self, ndf) -> float:
        cdf = ndf.cdf_theta_rad(self.ordered)
        n = cdf.size
        return float(max(np.max(np.arange(1, n + 1) / n - cdf), np.max(cdf - np.arange(n) / n)))


def _ndf_fits(theta: np.ndarray, cells: int) -> tuple[NdfFit, ...]:
    """Beckmann, GGX and Student-t by binned maximum likelihood on the tilts (module
    docstring); Student-t starts from the better of the two it spans (γ = 2: GGX; large γ:
    Beckmann)."""
    from scipy import stats as _stats

    like = _TiltLikelihood(theta)
    critical = float(_stats.kstwo.isf(KS_LEVEL, cells))
    log_m = 0.5 * math.log(float(np.mean(np.tan(theta) ** 2)))
    beckmann = _fit(like, "beckmann", [log_m], [_LOG_ALPHA], cells, critical)
    ggx = _fit(like, "ggx", [log_m - 0.3], [_LOG_ALPHA], cells, critical)
    starts = (
        [math.log(ggx.params["alpha"].value), 0.0],
        [math.log(beckmann.params["m"].value), math.log(100.0)],
    )
    start = min(starts, key=lambda p: like.nll("student-t", p))
    student = _fit(like, "student-t", start, [_LOG_ALPHA, _LOG_GAMMA_M1], cells, critical)
    return beckmann, ggx, student


def _fit(like: _TiltLikelihood, name, start, bounds, cells, critical) -> NdfFit:
    """One distribution's maximum-likelihood fit, its standard errors and KS distance."""
    from scipy.optimize import minimize

    res = minimize(lambda p: like.nll(name, p), start, method="L-BFGS-B", bounds=bounds)
    errors = _errors(lambda p: like.nll(name, p), res.x, bounds, cells)
    ndf = _distribution(name, res.x)
    params = {}
    for (key, value), err in zip(ndf.params().items(), errors):
        scale = value - 1.0 if key == "gamma" else value  # d(parameter)/d(its logarithm)
        params[key] = Estimate(value, None if err is None else scale * err)
    return NdfFit(name=name, params=params, ks=like.ks(ndf), ks_critical=critical)


def _errors(nll, x, bounds, cells) -> list:
    """Standard errors of the free parameters: the inverse Hessian (central differences) of
    the log-likelihood per facet, times N independent cells; None for a parameter at its
    bound."""
    x = np.asarray(x, dtype=np.float64)
    step = 1e-3
    free = [i for i, (lo, hi) in enumerate(bounds) if min(x[i] - lo, hi - x[i]) > 10 * step]
    unit = np.eye(x.size) * step

    def second(i, j):
        return (
            nll(x + unit[i] + unit[j])
            - nll(x + unit[i] - unit[j])
            - nll(x - unit[i] + unit[j])
            + nll(x - unit[i] - unit[j])
        ) / (4 * step**2)

    hess = np.array([[second(i, j) for j in free] for i in free])
    out = [None] * x.size
    try:
        cov = np.linalg.inv(hess * cells)
    except np.linalg.LinAlgError:
        return out
    for a, i in enumerate(free):
        if cov[a, a] > 0:
            out[i] = math.sqrt(cov[a, a])
    return out


def _anisotropy(sx, sy, cells) -> Anisotropy:
    vxx, vyy, vxy = float(np.mean(sx * sx)), float(np.mean(sy * sy)), float(np.mean(sx * sy))
    values, vectors = np.linalg.eigh(np.array([[vxx, vxy], [vxy, vyy]]))
    major = vectors[:, 1]
    angle = math.degrees(math.atan2(major[1], major[0]))
    angle = angle - 180.0 if angle > 90.0 else angle + 180.0 if angle <= -90.0 else angle
    ax, ay = rotated_alphas(vxx, vxy, vyy, angle)
    ratio = ax / ay if ay > 0 else math.inf
    error = ratio / math.sqrt(cells)  # each α from N cells: relative error 1/√(2N)
    return Anisotropy(
        alpha_x=ax,
        alpha_y=ay,
        angle_deg=angle,
        ratio=Estimate(ratio, error),
        anisotropic=ratio - 1.0 > 3.0 * error,
    )


def _regime(sigma: float, wavelength: float) -> Regime:
    s = sigma / wavelength
    if s < RAYLEIGH_RICE_BELOW:
        optics = "smooth: Rayleigh–Rice holds, geometric optics (the ray tracer) does not"
    elif s < GEOMETRIC_FROM:
        optics = (
            "intermediate: neither Rayleigh–Rice nor geometric optics holds; Kirchhoff does "
            "(microsim.wave)"
        )
    else:
        optics = "rough: geometric optics (the ray tracer) holds"
    return Regime(
        wavelength=wavelength,
        sigma_over_lambda=s,
        g=(4 * math.pi * s) ** 2,
        rayleigh_smooth=s < 0.125,
        optics=optics,
    )


def _warnings(r: dict, edges) -> tuple[str, ...]:
    """The report's warnings (module docstring) from its parts ``r`` and the edge mismatch."""
    out = []
    dx, slopes, hs = r["dx"], r["slopes"], r["heights_stats"]
    acf_len = hs.corr_len
    if acf_len < MIN_CORR_CELLS * dx:
        out.append(
            f"sampling too coarse: correlation length {acf_len:.3g} < {MIN_CORR_CELLS:g} dx = "
            f"{MIN_CORR_CELLS * dx:.3g}; the facets alias the slopes (the mesh's slopes are "
            f"not the surface's, they depend on dx, and the triangulation correlates them "
            f"along its diagonal)"
        )
    if r["abc"] is not None and r["abc"].C.value <= 3.0:
        out.append(
            f"ABC C = {r['abc'].C.value:.3g} <= 3: the slope variance grows with the "
            f"resolution (it diverges as dx → 0), so the facets' slopes depend on dx = {dx:g}"
        )
    if r["abc"] is not None and r["abc"].reduced_chi2 > ABC_POOR_FIT:
        out.append(
            f"the ABC model does not describe this PSD (reduced χ² {r['abc'].reduced_chi2:.3g} "
            f"> {ABC_POOR_FIT:g}): its A, B, C are not the surface's"
        )
    if r["regime"] is not None and r["regime"].sigma_over_lambda < GEOMETRIC_FROM:
        out.append(
            f"σ/λ = {r['regime'].sigma_over_lambda:.3g} < {GEOMETRIC_FROM}: {r['regime'].optics}"
        )
    if not r["periodic"]:
        out.append(
            f"not a periodic tile: the height step across the edges is {edges[0]:.3g}× (x) and "
            f"{edges[1]:.3g}× (y) the rms step inside; the PSD is Hann-windowed and a traced "
            f"tile is mirrored (loader.mirror_periodic), which keeps each axis's slopes but "
            f"not their correlation"
        )
        if r["anisotropy"].anisotropic and abs(slopes.correlation) > 0.1:
            out.append(
                f"the slope axes are rotated by {r['anisotropy'].angle_deg:.3g}° from the grid; "
                f"a mirrored tile aligns them with the grid: rotate the scan before tracing it"
            )
    if math.tan(math.radians(hs.tilt_deg)) > TILT_WARNING * slopes.rms:
        out.append(
            f"the heights' mean plane is tilted by {hs.tilt_deg:.3g}° (removed here); level "
            f"the file before tracing it (microsim traces it as given)"
        )
    if r["missing"]:
        total = r["shape"][0] * r["shape"][1]
        out.append(
            f"{r['missing']} of {total} points missing ({100 * r['missing'] / total:.2g} %): "
            f"left out of the height and slope statistics, set to the mean plane in the PSD"
        )
    return tuple(out)


# --- rendering ---------------------------------------------------------------------------
def _markdown(r: SurfaceReport) -> str:
    hs, sl, an = r.heights_stats, r.slopes, r.anisotropy
    ny, nx = r.shape
    lines = [
        f"# Surface: {nx} x {ny} points, dx {r.dx:g} "
        f"({'periodic tile' if r.periodic else 'not periodic'}"
        + (f", {r.missing} missing points" if r.missing else "")
        + ")",
        "",
        "## Heights (ISO 25178-2, levelled)",
        "",
        "| Sq | Sa | Ssk | Sku | Sz | ℓ (1/e) | Sal (0.2) | tilt removed |",
        "|---|---|---|---|---|---|---|---|",
        f"| {hs.Sq:.4g} | {hs.Sa:.4g} | {hs.Ssk:.3g} | {hs.Sku:.3g} | {hs.Sz:.4g} | "
        f"{hs.corr_len:.4g} | {hs.Sal:.4g} | {hs.tilt_deg:.3g}° |",
        "",
        "## Slopes (the tracer's facets)",
        "",
        "| rms x | rms y | rms m | correlation | max | facets | independent cells |",
        "|---|---|---|---|---|---|---|",
        f"| {sl.rms_x:.4g} | {sl.rms_y:.4g} | {sl.rms:.4g} | {sl.correlation:.3g} | "
        f"{sl.max:.4g} ({sl.max_deg:.3g}°) | {sl.facets} | {sl.independent_cells} |",
        "",
        "## NDF fits (maximum likelihood on the facet tilts)",
        "",
        f"| distribution | parameters | KS distance | KS critical ({KS_LEVEL:g}) | |",
        "|---|---|---|---|---|",
    ]
    for f in r.ndf_fits:
        params = ", ".join(f"{k} = {v}" for k, v in f.params.items())
        mark = "best" if f.name == r.best_ndf else ""
        verdict = "consistent" if f.consistent else "rejected"
        lines.append(
            f"| {f.name} | {params} | {f.ks:.3g} | {f.ks_critical:.3g} | {verdict} {mark} |"
        )
    lines += [
        "",
        "Beckmann m is the rms slope (per-axis variance m²/2); errors count the independent cells.",
        "",
        "## Anisotropy (slope covariance)",
        "",
        f"αx = {an.alpha_x:.4g}, αy = {an.alpha_y:.4g} along axes at {an.angle_deg:.3g}° "
        f"from x; αx/αy = {an.ratio}: "
        + ("anisotropic" if an.anisotropic else "isotropic within 3 standard errors"),
        "",
        "## PSD",
        "",
    ]
    if r.abc is None:
        lines.append("No ABC fit: fewer than four rings of the radial PSD hold power.")
    else:
        a = r.abc
        sigma = f"{a.sigma:.4g}" if a.sigma is not None else "infinite (C <= 1)"
        lines += [
            f"ABC (Church et al. 1989): A = {a.A}, B = {a.B}, C = {a.C} "
            f"(σ of the continuum {sigma}); fitted over f = {a.f_range[0]:.3g} to "
            f"{a.f_range[1]:.3g}, reduced χ² {a.reduced_chi2:.3g}; errors: {a.uncertainty}.",
        ]
    if r.regime is not None:
        g = r.regime
        lines += [
            "",
            "## Optical regime",
            "",
            f"λ = {g.wavelength:g}: σ/λ = {g.sigma_over_lambda:.3g}, g = (4πσ/λ)² = {g.g:.3g}, "
            f"Rayleigh criterion σ < λ/8: {'smooth' if g.rayleigh_smooth else 'rough'}; "
            f"{g.optics}.",
        ]
    if r.warnings:
        lines += ["", "## Warnings", ""] + [f"- {w}" for w in r.warnings]
    return "\n".join(lines) + "\n"


def surface_chart(report: SurfaceReport, path=None):
    """Four panels: the levelled heights, the 2D PSD, the radial PSD with the ABC fit and the
    facet tilt density with the fitted NDFs; written as PNG to ``path`` if given. Returns the
    Figure."""
    from matplotlib.colors import LogNorm

    from .chart_style import _figure, _output, model_colour

    fig = _figure((11.0, 8.5))
    (ax_h, ax_s), (ax_r, ax_n) = fig.subplots(2, 2)
    ny, nx = report.shape
    extent = (0, nx * report.dx, 0, ny * report.dx)
    im = ax_h.imshow(report.heights, origin="lower", extent=extent, cmap="viridis")
    fig.colorbar(im, ax=ax_h, label="height")
    ax_h.set(title="levelled heights", xlabel="x", ylabel="y")
    image = np.where(report.psd_image > 0, report.psd_image, np.nan)
    fx, fy = report.psd_fx, report.psd_fy
    im = ax_s.imshow(
        image,
        origin="lower",
        extent=(fx.min(), fx.max(), fy.min(), fy.max()),
        norm=LogNorm(vmin=np.nanpercentile(image, 1), vmax=np.nanmax(image)),
        cmap="magma",
    )
    fig.colorbar(im, ax=ax_s, label="PSD (length⁴)")
    ax_s.set(title="2D PSD", xlabel="fx (cycles/length)", ylabel="fy")
    f, p = np.array(report.psd.frequency), np.array(report.psd.power)
    ax_r.loglog(f, np.where(p > 0, p, np.nan), ".", ms=3, color="0.3", label="radial PSD")
    if report.abc is not None:
        ff = np.geomspace(f[0], f[-1], 200)
        a = report.abc
        ax_r.loglog(ff, a.psd(ff), "-", color="#1565c0", label=f"ABC fit, C = {a.C.value:.3g}")
    ax_r.set(title="radial PSD", xlabel="f (cycles/length)", ylabel="PSD (length⁴)")
    ax_r.legend()
    edges = np.linspace(0.0, float(report.theta.max()), 61)
    density, _ = np.histogram(report.theta, edges, density=True)
    mid = 0.5 * (edges[1:] + edges[:-1])
    ax_n.semilogy(
        np.degrees(mid),
        np.where(density > 0, density, np.nan),
        "o",
        ms=3,
        color="0.3",
        label="facets",
    )
    for fit in report.ndf_fits:
        try:
            colour = model_colour(f"ts-{fit.name}")
        except UsageError:
            colour = None
        label = f"{fit.name}: " + ", ".join(f"{k} {v.value:.3g}" for k, v in fit.params.items())
        ax_n.semilogy(np.degrees(mid), fit.ndf().tilt_pdf_rad(mid), color=colour, label=label)
    ax_n.set(title="facet tilts", xlabel="θ (degrees)", ylabel="density (1/rad)")
    ax_n.legend(fontsize="small")
    return _output(fig, path)
