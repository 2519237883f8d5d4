"""Random periodic heightfields by FFT synthesis: Gaussian-correlated and fractal (ABC PSD).

Both are stationary Gaussian random fields given by a 2D isotropic power spectral density
PSD(f) (length⁴, f in cycles per length), normalised so that ∫ PSD d²f = height variance, or
by its elliptical variant along axes rotated in the plane (``corr_len_y``, ``B_y``).
Synthesis (docs/design.md, "Facts to build on — Surfaces"): the Fourier transform of real
white noise is multiplied by √PSD(f)/dx and transformed back; PSD(0) = 0 so the mean height is zero.

*Exact-amplitude* mode (the default) keeps only the phases of the noise and gives every
Fourier mode exactly the amplitude √PSD, so the realised periodogram, height variance and
mesh slope variance equal their discrete-spectrum predictions (random phases, Hermitian
symmetry inherited from the real noise, so the field is real). With ``exact_amplitude=False``
each mode's power scatters as an exponential variable (plain filtered noise).

Mesh slopes are finite differences over one grid step, whose response is
(2 sin(π f dx)/dx)² instead of the continuum (2π f)²; ``spectrum_moments`` predicts the mesh
slope variance from the discrete spectrum with that response. Each generated ``Surface``
carries those predictions (``Surface.predicted``) and the NDF the field samples
(``Surface.ensemble_ndf``): the slopes of a Gaussian random field are Gaussian, so it is
Beckmann with m² = 2 × per-axis slope variance (Beckmann & Spizzichino 1963).
"""

from __future__ import annotations

import warnings as _warnings
from dataclasses import dataclass, replace

import numpy as np

from microsim.analytic import (
    AnisotropicBeckmann,
    Beckmann,
    abc_psd_anisotropic,
    abc_psd_church,
    church_to_condensed,
)
from microsim.checks import check_memory, finite, integer, positive
from microsim.errors import UsageError

from .surface import Predicted, Surface, check_relief, rotated_alphas

__all__ = [
    "gaussian",
    "abc",
    "gaussian_psd",
    "abc_amplitude",
    "abc_anisotropic_psd",
    "psd_grid",
    "synthesize",
    "spectrum_moments",
    "SpectrumMoments",
    "gaussian_mesh_slope_var",
    "abc_continuum_slope_var",
    "abc_spectrum",
    "gaussian_ensemble_ndf",
    "check_resolved",
    "abc_ensemble_ndf",
]

MIN_GRID = 8
GAUSS_MIN_CORR_CELLS = 7.0  # ℓ ≥ 7·dx keeps the triangulation slope bias under 1 %
MAX_RMS_SLOPE = 10.0
"""Largest nominal rms slope 2σ/ℓ of a Gaussian heightfield a scene may ask for."""
GAUSS_RESOLVED_CELLS = 1.0
"""Shortest Gaussian ℓ, in grid steps, that the grid resolves: the synthesis keeps the spectrum
up to the Nyquist frequency 1/(2dx), i.e. erf(πℓ/(2dx))² of σ² — 95 % at ℓ = dx, 18 % at dx/4,
nothing as ℓ → 0 (the mesh turns flat whatever the nominal m = 2σ/ℓ). Shorter ℓ is refused."""
BYTES_PER_GRID_POINT = 64
"""Peak memory per grid point of a heightfield built and traced ray by ray (two triangles).
The build peaks highest: its in-place synthesis holds the spectrum (8 bytes), the noise's
complex transform and its inverse (16 each) and the heights. The run holds the heights (8)
— the surface stores no mesh (``Surface.stores_mesh``), and the tracer keeps no per-facet
normals or plane offsets (``sim.engine.facets``) — the grid walk's copy of them with its
cell maxima and minima (24) and, during the tracer's set-up, the facet slopes (16).
Measured: 57 bytes per point at 4096², 56 at 8192² (peak RSS growth; ``microsim bench
--scale``)."""
TABLED_FACETS_MAX = 1 << 25
"""Largest mesh, in facets, whose tracer builds per-incidence facet tables (the run's rays
at least as many as its facets, ``sim.facet_tables.table_pays``): a 4096² heightfield. A
larger one is traced ray by ray whatever the ray count, so that its memory stays
``BYTES_PER_GRID_POINT`` per point."""
TABLE_BYTES_PER_GRID_POINT = 100
"""What the facet-table path adds per grid point where it is taken: the newest incidence's
table (26 bytes per facet and 1 per cell: 53 per point) and the beam grid it reads (per-facet
gradients and block maxima, 40 per point), besides the older tables the tracer keeps
(``TABLES_KEPT_BYTES`` in all)."""
TABLES_KEPT_BYTES = 256 * 2**20
"""Bytes of the older facet tables a tracer keeps beside the newest (``sim.facet_tables``)."""


def traced_bytes(points: int) -> float:
    """Peak bytes of a heightfield of ``points`` grid points built and traced:
    ``BYTES_PER_GRID_POINT`` per point, and where its mesh is small enough for facet tables
    (``TABLED_FACETS_MAX``) ``TABLE_BYTES_PER_GRID_POINT`` per point and the kept tables'
    ``TABLES_KEPT_BYTES``; checked against ``microsim.checks.memory_limit`` before
    synthesis."""
    need = float(points) * BYTES_PER_GRID_POINT
    if 2 * points <= TABLED_FACETS_MAX:
        need += float(points) * TABLE_BYTES_PER_GRID_POINT + TABLES_KEPT_BYTES
    return need


# --- spectra -----------------------------------------------------------------------------------
def gaussian_psd(f, sigma: float, corr_len: float):
    """PSD of the autocorrelation σ² exp(−r²/ℓ²): S(f) = π σ² ℓ² exp(−π² ℓ² f²) (length⁴)."""
    f = np.asarray(f, dtype=np.float64)
    sigma, corr_len = np.float64(sigma), np.float64(corr_len)  # inf on overflow, no raise
    return np.pi * sigma**2 * corr_len**2 * np.exp(-((np.pi * corr_len * f) ** 2))


def _erf2(x: float) -> float:
    from scipy.special import erf

    return float(erf(x) ** 2)


def abc_amplitude(sigma: float, B: float, C: float, B_y: float | None = None) -> float:
    """A of the 2D ABC PSD with ∫ PSD d²f = σ²: A = σ² B² (C − 1)/(2π) (needs C > 1); with
    ``B_y`` that of the elliptical PSD (``abc_anisotropic_psd``), A = σ² B B_y (C − 1)/(2π)."""
    if B_y is None:
        return sigma**2 * B**2 * (C - 1.0) / (2.0 * np.pi)
    return sigma**2 * B * B_y * (C - 1.0) / (2.0 * np.pi)


def abc_anisotropic_psd(FX, FY, A: float, B: float, B_y: float, C: float, rotation: float):
    """Church's ABC PSD made elliptical: S(f) = A/(1 + B² f'x² + B_y² f'y²)^((C+1)/2) (length⁴),
    (f'x, f'y) the frequency (FX, FY) in the frame rotated by ``rotation`` degrees (as
    ``gaussian_anisotropic_psd``); Church's a, b, c per axis, evaluated as Löw's condensed
    ``abc_psd_anisotropic`` with (A, B², B_y², (C + 1)/2) (``church_to_condensed``).

    Normalisation: with u = B f'x, v = B_y f'y (d²f = du dv/(B B_y), the rotation keeps areas),
    ∫ S d²f = (A/(B B_y)) ∫ (1 + ρ²)^−(C+1)/2 d²(u, v) = (A/(B B_y)) · 2π/(C − 1), so
    ∫ S d²f = σ² for A = σ² B B_y (C − 1)/(2π) (``abc_amplitude``); B_y = B is the isotropic
    ``abc_psd_church``."""
    a, b2, c = church_to_condensed(A, B, C)
    return abc_psd_anisotropic(FX, FY, a, b2, c, church_to_condensed(A, B_y, C)[1], rotation)


def psd_grid(psd, shape: tuple[int, int], dx: float, f_max: float = np.inf, *, of_xy=False):
    """``psd(|f|)`` on the FFT frequency grid of a (ny, nx) grid, 0 at f = 0 and beyond f_max
    (radially); with ``of_xy`` an anisotropic ``psd(FX, FY)``.

    Returns (S, FX, FY) with FX, FY the frequencies (cycles per length) of each FFT cell.
    """
    ny, nx = shape
    FX, FY = np.meshgrid(np.fft.fftfreq(nx, dx), np.fft.fftfreq(ny, dx))
    f = np.hypot(FX, FY)
    S = np.where((f > 0) & (f <= f_max), psd(FX, FY) if of_xy else psd(f), 0.0)
    return S, FX, FY


def synthesize(S: np.ndarray, dx: float, rng: np.random.Generator, exact_amplitude: bool = True):
    """Real periodic heightfield with discrete spectrum S (length⁴) on the FFT grid.

    h = IFFT(W · √S / dx) with W the FFT of real unit white noise, so E[h²] = Σ S df²
    (df² = 1/(N dx²), N grid cells). ``exact_amplitude`` replaces W by √N · W/|W|: random
    phases, exact amplitude, realised variance = Σ S df² exactly.
    """
    ny, nx = S.shape
    W = np.fft.fft2(rng.standard_normal((ny, nx)))
    if exact_amplitude:  # in place, element by element as W·√N/|W| (1 where |W| = 0)
        mag = np.abs(W)
        np.divide(W, mag, out=W, where=mag > 0)
        W[mag == 0] = 1.0
        del mag
        np.multiply(np.sqrt(nx * ny), W, out=W)
    W *= np.sqrt(S)
    W /= dx
    h = np.fft.ifft2(W).real
    del W
    return h - h.mean()


@dataclass(frozen=True)
class SpectrumMoments:
    """Discrete-spectrum predictions for a synthesised grid (per axis for slopes).

    ``*_rel_sd``: relative standard deviation of the realised value between plain-noise
    realisations (every mode's power ~ Exp(1): var = 2 Σ a_k² for a sum Σ a_k over modes).
    """

    height_var: float
    slope_var_x: float
    slope_var_y: float
    height_var_rel_sd: float
    slope_var_x_rel_sd: float
    slope_var_y_rel_sd: float


def spectrum_moments(S: np.ndarray, FX: np.ndarray, FY: np.ndarray, dx: float) -> SpectrumMoments:
    """Height variance and mesh per-axis slope variance of a grid with discrete spectrum S.

    Mesh slopes are one-step finite differences: response (2 sin(π f dx)/dx)² per axis
    (docs/design.md, "Facts to build on — Surfaces") — the continuum (2πf)² overestimates the
    mesh slope variance.
    """
    df2 = 1.0 / (S.size * dx * dx)

    def moment(a):
        total = float(a.sum() * df2)
        rel = float(np.sqrt(2.0 * np.sum(a * a)) / a.sum()) if total > 0 else 0.0
        return total, rel

    hv, hr = moment(S)
    vx, rx = moment(S * (2.0 * np.sin(np.pi * FX * dx) / dx) ** 2)
    vy, ry = moment(S * (2.0 * np.sin(np.pi * FY * dx) / dx) ** 2)
    return SpectrumMoments(hv, vx, vy, hr, rx, ry)


def gaussian_mesh_slope_var(sigma: float, corr_len: float, dx: float) -> float:
    """Per-axis slope variance of the triangulated Gaussian heightfield: 2σ²(1 − e^{−u})/dx²,
    u = (dx/ℓ)² (→ continuum 2σ²/ℓ² as dx → 0)."""
    u = (dx / corr_len) ** 2
    return 2.0 * sigma**2 * (-np.expm1(-u)) / dx**2


def abc_continuum_slope_var(
    sigma: float, B: float, C: float, f_max: float, B_y: float | None = None
) -> float:
    """Per-axis continuum slope variance ½ ∫_{|f| ≤ f_max} (2πf)² PSD d²f of the ABC surface;
    with ``B_y`` the mean of the two axes' of the elliptical PSD (``abc_anisotropic_psd``; the
    band is radial, so the rotation drops out): along the direction θ of the rotated frame the
    PSD is ``abc_psd_church`` with b(θ)² = B² cos²θ + B_y² sin²θ, integrated over θ (4 × the
    quadrant, by symmetry)."""
    from scipy import integrate  # ~0.3 s to import: only for ABC surfaces

    if B_y is None:
        A = abc_amplitude(sigma, B, C)
        val, _ = integrate.quad(lambda f: f**3 * abc_psd_church(f, A, B, C), 0.0, f_max, limit=200)
        return 0.5 * (2.0 * np.pi) ** 2 * 2.0 * np.pi * val
    A = abc_amplitude(sigma, B, C, B_y)

    def radial(theta):
        b = float(np.hypot(B * np.cos(theta), B_y * np.sin(theta)))
        return integrate.quad(lambda f: f**3 * abc_psd_church(f, A, b, C), 0.0, f_max, limit=200)[0]

    val, _ = integrate.quad(radial, 0.0, 0.5 * np.pi, limit=200)
    return 0.5 * (2.0 * np.pi) ** 2 * 4.0 * val


# --- generators --------------------------------------------------------------------------------
def _grid_args(n, dx, seed):
    """(n, dx, seed) validated; an n×n grid that would not fit in memory is refused here,
    before anything is allocated (``traced_bytes``)."""
    n = integer("n", n, MIN_GRID, None, " (grid points per side)")
    dx, seed = positive("dx", dx), integer("seed", seed, 0)
    check_memory(
        "n",
        traced_bytes(n * n),
        f"a {n}x{n} heightfield (synthesised, meshed and traced: "
        f"{traced_bytes(n * n) / (n * n):.0f} bytes per grid point)",
    )
    return n, dx, seed


def _finite_spectrum(S: np.ndarray, names: str) -> None:
    if not np.all(np.isfinite(S)):
        raise UsageError(
            f"{names}: the spectrum overflows float64 (height variance beyond "
            f"1e308); use lengths of a sensible scale"
        )


def _heightfield_surface(kind, heights, dx, nominal, warns, ensemble_ndf, predicted):
    ny, nx = heights.shape
    check_relief("sigma", heights.min(), heights.max(), (nx * dx, ny * dx))
    for w in warns:
        _warnings.warn(w, stacklevel=3)
    return Surface(
        kind=kind,
        vertices=None,  # derived from the heights where needed
        faces=None,
        tile_size=(nx * dx, ny * dx),
        periodic=True,
        nominal=nominal,
        heights=heights,
        dx=dx,
        warnings=tuple(warns),
        ensemble_ndf=ensemble_ndf,
        predicted=predicted,
    )


def _predicted(mom: SpectrumMoments, continuum: float) -> Predicted:
    """Predicted statistics from the discrete spectrum with the finite-difference response:
    exact for the mesh (Gaussian: equal to 2σ²(1 − e^{−u})/dx² within 1e-4 for ℓ ≥ 2·dx, and
    still exact below, where that point-sampled formula is not); ``continuum`` the dx → 0
    per-axis slope variance (ABC: within the band)."""
    spec = 0.5 * (mom.slope_var_x + mom.slope_var_y)
    return Predicted(
        rms_height=float(np.sqrt(mom.height_var)),
        slope_var=float(spec),
        spectrum_slope_var=float(spec),
        continuum_slope_var=float(continuum),
        m=float(np.sqrt(2.0 * spec)),
    )


def gaussian_ensemble_ndf(sigma: float, corr_len: float, corr_len_y=None, rotation: float = 0.0):
    """The NDF a Gaussian heightfield samples: Beckmann with the nominal m = 2σ/ℓ (per-axis
    slope variance 2σ²/ℓ² = m²/2; the mesh realises slightly less, see ``gaussian``); with
    ``corr_len_y`` the anisotropic Beckmann (2σ/ℓx, 2σ/ℓy, ``rotation``)."""
    if corr_len_y is None:
        return Beckmann(2.0 * sigma / corr_len)
    return AnisotropicBeckmann(2.0 * sigma / corr_len, 2.0 * sigma / corr_len_y, rotation)


def abc_spectrum(
    n: int,
    dx: float,
    sigma: float,
    B: float,
    C: float,
    band_limit: float,
    B_y: float | None = None,
    rotation: float = 0.0,
):
    """(A, f_max, S, FX, FY): amplitude, radial cut-off 1/(2·band_limit·dx) and the discrete
    ABC spectrum (``abc_psd_church``; with ``B_y`` the elliptical ``abc_anisotropic_psd``) of
    an n×n grid (``psd_grid``). Arguments as ``abc`` (validated there; ``B_y`` and
    ``rotation`` also here); an amplitude beyond float64 raises a UsageError."""
    f_max = 1.0 / (2.0 * band_limit * dx)
    if B_y is not None:
        B_y, rotation = positive("B_y", B_y), finite("rotation", rotation)
    with np.errstate(over="ignore", invalid="ignore"):
        if B_y is None:
            A = abc_amplitude(np.float64(sigma), np.float64(B), C)
            _finite_spectrum(A, f"sigma = {sigma:g}, B = {B:g}")  # S ≤ A
            S, FX, FY = psd_grid(lambda f: abc_psd_church(f, A, B, C), (n, n), dx, f_max)
            return A, f_max, S, FX, FY
        A = abc_amplitude(np.float64(sigma), np.float64(B), C, np.float64(B_y))
        _finite_spectrum(A, f"sigma = {sigma:g}, B = {B:g}, B_y = {B_y:g}")
        _finite_spectrum(np.float64(B) ** 2 + np.float64(B_y) ** 2, f"B = {B:g}, B_y = {B_y:g}")
        S, FX, FY = psd_grid(
            lambda fx, fy: abc_anisotropic_psd(fx, fy, A, B, B_y, C, rotation),
            (n, n),
            dx,
            f_max,
            of_xy=True,
        )
    return A, f_max, S, FX, FY


def _mesh_alphas(S, FX, FY, dx, mom: SpectrumMoments, rotation: float) -> tuple[float, float]:
    """(αx, αy) of the mesh's facet slopes along axes rotated by ``rotation`` degrees, exact from
    the discrete spectrum: ``rotated_alphas`` of the variances of ``spectrum_moments`` (``mom``)
    and the cross term of ``_mesh_slope_cov``."""
    return rotated_alphas(
        mom.slope_var_x, _mesh_slope_cov(S, FX, FY, dx), mom.slope_var_y, rotation
    )


def _abc_ndf(S, FX, FY, dx, mom: SpectrumMoments, B_y, rotation):
    """The ensemble NDF of an ABC grid with this discrete spectrum: Beckmann with m² = 2 ×
    per-axis slope variance; with ``B_y`` AnisotropicBeckmann at the mesh's (αx, αy) along the
    PSD's rotated axes (``_mesh_alphas``)."""
    if B_y is None:
        return Beckmann(float(np.sqrt(mom.slope_var_x + mom.slope_var_y)))
    return AnisotropicBeckmann(*_mesh_alphas(S, FX, FY, dx, mom, rotation), rotation)


def abc_ensemble_ndf(
    n: int,
    dx: float,
    sigma: float,
    B: float,
    C: float,
    band_limit: float = 4,
    B_y: float | None = None,
    rotation: float = 0.0,
):
    """The NDF an ``abc`` heightfield of these parameters samples: Beckmann with the predicted
    mesh m, m² = 2 × per-axis slope variance of the discrete spectrum (the facet slopes of any
    Gaussian random field are Gaussian; Löw et al. 2012's ABC *NDF* is a different object);
    with ``B_y`` the anisotropic Beckmann at the predicted mesh (αx, αy) along the PSD's axes
    rotated by ``rotation`` degrees, where the continuum slope covariance of the elliptical PSD
    is diagonal (``abc``)."""
    *_, S, FX, FY = abc_spectrum(n, dx, sigma, B, C, band_limit, B_y, rotation)
    mom = spectrum_moments(S, FX, FY, dx)
    return _abc_ndf(S, FX, FY, dx, mom, B_y, rotation)


def gaussian_anisotropic_psd(FX, FY, sigma: float, lx: float, ly: float, rotation: float):
    """PSD of the autocorrelation σ² exp(−(x'²/ℓx² + y'²/ℓy²)), (x', y') the frame rotated by
    ``rotation`` degrees: S(f) = π σ² ℓx ℓy exp(−π² (ℓx² f'x² + ℓy² f'y²)) (length⁴; ∫ S d²f
    = σ², per-axis slope variances 2σ²/ℓx², 2σ²/ℓy² along x', y')."""
    c, s = np.cos(np.radians(rotation)), np.sin(np.radians(rotation))
    fx, fy = c * FX + s * FY, -s * FX + c * FY
    return np.pi * sigma**2 * lx * ly * np.exp(-(np.pi**2) * ((lx * fx) ** 2 + (ly * fy) ** 2))


def gaussian(
    n: int,
    dx: float,
    sigma: float,
    corr_len: float,
    seed: int = 0,
    exact_amplitude: bool = True,
    corr_len_y: float | None = None,
    rotation: float = 0.0,
) -> Surface:
    """Periodic n×n Gaussian heightfield with autocorrelation σ² exp(−r²/ℓ²).

    ``dx`` grid spacing, ``sigma`` rms height, ``corr_len`` ℓ (all in the same length unit).
    Spectrum S(f) = π σ² ℓ² exp(−π² ℓ² f²), S(0) = 0 (module docstring for the synthesis).
    Facet normals follow Beckmann with nominal m = 2σ/ℓ (per-axis slope variance 2σ²/ℓ²);
    the mesh realises the discrete-spectrum slope variance (``spectrum_moments``; equal to
    2σ²(1 − e^{−u})/dx², u = (dx/ℓ)², within 1e-4 for ℓ ≥ 2·dx), which warns — stating that
    realised m — when ℓ < 7·dx. ℓ < dx (``GAUSS_RESOLVED_CELLS``) is not resolved by the grid
    and raises a UsageError. Grids beyond the memory limit are refused before synthesis.

    Anisotropic (``corr_len_y`` given): autocorrelation σ² exp(−(x'²/ℓx² + y'²/ℓy²)) with
    ℓx = ``corr_len``, ℓy = ``corr_len_y`` along axes rotated by ``rotation`` degrees
    (``gaussian_anisotropic_psd``); the facet slopes are Gaussian with variances 2σ²/ℓx²,
    2σ²/ℓy² along those axes, so the ensemble NDF is ``AnisotropicBeckmann(2σ/ℓx, 2σ/ℓy,
    rotation)``; ``predicted`` carries the mesh's per-axis slope variances along the grid axes
    (exact, as for the isotropic field) and ``predicted.alpha_x``/``alpha_y`` along the
    rotated axes (``surface.stats()``' ``alpha_x_realised``/``alpha_y_realised`` measure them).
    """
    if corr_len_y is not None:
        return _gaussian_anisotropic(
            n, dx, sigma, corr_len, corr_len_y, rotation, seed, exact_amplitude
        )
    n, dx, seed = _grid_args(n, dx, seed)
    sigma, corr_len = positive("sigma", sigma), positive("corr_len", corr_len)
    if corr_len < GAUSS_RESOLVED_CELLS * dx:
        raise UsageError(
            f"corr_len must be >= dx = {dx:g} (a shorter correlation length is not "
            f"resolved by the grid: it keeps erf(πℓ/(2dx))² of σ², "
            f"{100 * _erf2(np.pi * corr_len / (2 * dx)):.3g} % here), got "
            f"{corr_len:g}"
        )
    with np.errstate(over="ignore", invalid="ignore"):
        S, FX, FY = psd_grid(lambda f: gaussian_psd(f, sigma, corr_len), (n, n), dx)
    _finite_spectrum(S, f"sigma = {sigma:g}, corr_len = {corr_len:g}")
    warns = []
    mom = spectrum_moments(S, FX, FY, dx)
    del FX, FY  # 16 bytes per point fewer during the synthesis
    if corr_len < GAUSS_MIN_CORR_CELLS * dx:
        mesh = 0.5 * (mom.slope_var_x + mom.slope_var_y)
        bias = mesh / (2 * np.float64(sigma) ** 2 / np.float64(corr_len) ** 2)
        warns.append(
            f"gaussian: corr_len = {corr_len:g} < 7·dx = {7 * dx:g}: the mesh slope "
            f"variance is {bias:.4f} × the continuum 2σ²/ℓ² (realised m "
            f"{np.sqrt(2 * mesh):.4g} vs nominal {2 * sigma / corr_len:.4g})"
        )
    h = synthesize(S, dx, np.random.default_rng(seed), exact_amplitude)
    nominal = {
        "sigma": sigma,
        "corr_len": corr_len,
        "m": 2.0 * sigma / corr_len,
        "n": n,
        "dx": dx,
        "seed": seed,
        "exact_amplitude": bool(exact_amplitude),
    }
    predicted = _predicted(mom, 2.0 * sigma**2 / corr_len**2)
    return _heightfield_surface(
        "gaussian", h, dx, nominal, warns, gaussian_ensemble_ndf(sigma, corr_len), predicted
    )


def abc(
    n: int,
    dx: float,
    sigma: float,
    B: float,
    C: float,
    seed: int = 0,
    band_limit: float = 4,
    exact_amplitude: bool = True,
    B_y: float | None = None,
    rotation: float = 0.0,
) -> Surface:
    """Periodic n×n fractal heightfield with the isotropic 2D ABC PSD (Löw et al. 2012, eq. 7–8;
    Church et al. 1989).

        PSD(f) = A / (1 + B² f²)^((C+1)/2),   ∫ PSD d²f = 2π A / (B² (C − 1)) = σ²,

    so A = σ² B² (C − 1)/(2π): ``sigma`` is the rms height of the continuum (unbounded-band)
    surface; ``B`` (length; B = 2π × correlation length) sets the knee, ``C`` > 1 the fall-off
    f^−(C+1). These are Löw's lowercase (a, b, c) of eq. 7; his condensed eq. 11 writes the same
    function as A'/(1 + B' f²)^C' with A' = A, B' = B², C' = (C + 1)/2. (Löw's eq. 8 normalises
    a *1D profile* spectrum, a = σ² b Γ((c+1)/2)/(√π Γ(c/2)); here the spectrum is 2D.)

    The PSD is band-limited radially to f ≤ 1/(2k·dx), k = ``band_limit`` ≥ 1 (k = 4 keeps the
    normals isotropic; docs/design.md). C ≤ 1: infinite height variance (ValueError). 1 < C ≤ 3: the
    slope variance grows without bound as the cut-off rises, so the ray-traced BRDF depends on
    dx (warning). Also warns when the tile and band keep < 90 % of σ².

    Anisotropic (``B_y`` given, length): the elliptical PSD (``abc_anisotropic_psd``)

        PSD(f) = A / (1 + B² f'x² + B_y² f'y²)^((C+1)/2),   A = σ² B B_y (C − 1)/(2π),

    (f'x, f'y) the frequency along axes rotated by ``rotation`` degrees (counter-clockwise, as
    ``gaussian``'s); u = B f'x, v = B_y f'y map it onto the isotropic unit spectrum, whence
    ∫ PSD d²f = 2π A/(B B_y (C − 1)) = σ². Same radial band limit, warnings and checks. The
    facet slopes are Gaussian, their continuum covariance diagonal along the rotated axes (the
    PSD is even in f'x and in f'y), so the ensemble NDF is ``AnisotropicBeckmann(αx, αy,
    rotation)`` with the mesh's (αx, αy) along those axes predicted exactly from the discrete
    spectrum (``abc_ensemble_ndf``; ``predicted.alpha_x``/``alpha_y``, measured by ``stats()``'
    ``alpha_x_realised``/``alpha_y_realised``); the triangulation's own slope correlation, also
    present on isotropic fields (``stats()["slope_corr"]``), is not in that NDF.
    ``continuum_slope_var`` is the mean of the two axes' (``abc_continuum_slope_var``).
    ``B_y = None`` (the default) is the isotropic field above, unchanged.
    """
    n, dx, seed = _grid_args(n, dx, seed)
    sigma, B = positive("sigma", sigma), positive("B", B)
    if B_y is not None:
        B_y = positive("B_y", B_y)
    rotation = finite("rotation", rotation)
    C = float(C)
    if not C > 1.0 or not np.isfinite(C):
        raise UsageError(
            f"C must be a finite number > 1 (the ABC height variance "
            f"2πA/(B²(C−1)) is infinite for C <= 1), got {C!r}"
        )
    k = float(band_limit)
    if not (k >= 1.0) or not np.isfinite(k):
        raise UsageError(
            f"band_limit must be a finite number >= 1 (cut-off f <= 1/(2·k·dx)), got {band_limit!r}"
        )
    A, f_max, S, FX, FY = abc_spectrum(n, dx, sigma, B, C, k, B_y, rotation)
    warns = []
    if C <= 3.0:
        warns.append(
            f"abc: C = {C:g} <= 3: the slope variance depends on the grid cut-off "
            f"f_max = 1/(2·{k:g}·dx) (it diverges as dx → 0), so the ray-traced BRDF "
            f"depends on dx = {dx:g}"
        )
    mom = spectrum_moments(S, FX, FY, dx)
    kept = mom.height_var / sigma**2
    if kept < 0.9:
        warns.append(
            f"abc: the tile (L = {n * dx:g}) and band (f <= {f_max:g}) keep only "
            f"{100 * kept:.1f} % of the nominal height variance σ² = {sigma**2:g}"
        )
    ensemble = _abc_ndf(S, FX, FY, dx, mom, B_y, rotation)
    del FX, FY  # 16 bytes per point fewer during the synthesis
    h = synthesize(S, dx, np.random.default_rng(seed), exact_amplitude)
    aniso = {} if B_y is None else {"B_y": B_y, "rotation": rotation}
    nominal = {
        "sigma": sigma,
        "B": B,
        **aniso,
        "C": C,
        "A": A,
        "band_limit": k,
        "f_max": f_max,
        "n": n,
        "dx": dx,
        "seed": seed,
        "exact_amplitude": bool(exact_amplitude),
    }
    predicted = _predicted(mom, abc_continuum_slope_var(sigma, B, C, f_max, B_y))
    if B_y is not None:
        predicted = replace(predicted, alpha_x=ensemble.alpha_x, alpha_y=ensemble.alpha_y)
    return _heightfield_surface("abc", h, dx, nominal, warns, ensemble, predicted)


def check_resolved(dx: float, **lengths) -> None:
    """UsageError naming the first correlation length (keyword: its name) shorter than the grid
    step ``dx`` resolves (``GAUSS_RESOLVED_CELLS``)."""
    for name, ell in lengths.items():
        if ell < GAUSS_RESOLVED_CELLS * dx:
            raise UsageError(f"{name} must be >= dx = {dx:g} (resolved by the grid), got {ell:g}")


def _gaussian_anisotropic(n, dx, sigma, lx, ly, rotation, seed, exact_amplitude) -> Surface:
    """``gaussian`` with ``corr_len_y`` (its docstring)."""
    n, dx, seed = _grid_args(n, dx, seed)
    sigma = positive("sigma", sigma)
    lx, ly = positive("corr_len", lx), positive("corr_len_y", ly)
    rotation = finite("rotation", rotation)
    check_resolved(dx, corr_len=lx, corr_len_y=ly)
    with np.errstate(over="ignore", invalid="ignore"):
        S, FX, FY = psd_grid(
            lambda fx, fy: gaussian_anisotropic_psd(fx, fy, sigma, lx, ly, rotation),
            (n, n),
            dx,
            of_xy=True,
        )
    _finite_spectrum(S, f"sigma = {sigma:g}, corr_len = {lx:g}, corr_len_y = {ly:g}")
    warns = []
    if min(lx, ly) < GAUSS_MIN_CORR_CELLS * dx:
        warns.append(
            f"gaussian: min(corr_len, corr_len_y) = {min(lx, ly):g} < 7·dx = {7 * dx:g}: the "
            "mesh slope variances fall short of the continuum 2σ²/ℓ² (predicted.alpha_x/_y "
            "state the mesh values)"
        )
    mom = spectrum_moments(S, FX, FY, dx)
    ax_, ay_ = _mesh_alphas(S, FX, FY, dx, mom, rotation)
    del FX, FY  # 16 bytes per point fewer during the synthesis
    h = synthesize(S, dx, np.random.default_rng(seed), exact_amplitude)
    nominal = {
        "sigma": sigma,
        "corr_len": lx,
        "corr_len_y": ly,
        "rotation": rotation,
        "alpha_x": 2.0 * sigma / lx,
        "alpha_y": 2.0 * sigma / ly,
        "n": n,
        "dx": dx,
        "seed": seed,
        "exact_amplitude": bool(exact_amplitude),
    }
    predicted = replace(
        _predicted(mom, sigma**2 * (1.0 / lx**2 + 1.0 / ly**2)), alpha_x=ax_, alpha_y=ay_
    )
    ndf = gaussian_ensemble_ndf(sigma, lx, ly, rotation)
    return _heightfield_surface("gaussian", h, dx, nominal, warns, ndf, predicted)


def _mesh_slope_cov(S, FX, FY, dx) -> float:
    """The covariance of the mesh's facet slopes along x and y, exact from the discrete
    spectrum. ``heightfield_mesh`` splits cell (i, j) into (v00, v01, v11), whose gradient is
    (Δx h at row i, Δy h at column j + 1), and (v00, v11, v10), with (Δx h at row i + 1,
    Δy h at column j) — equal areas. With a = 2π fx dx, b = 2π fy dx the one-step
    differences respond as e^{ia} − 1 and e^{ib} − 1 (over dx), so the covariance averages
    the two triangles' Re[(1 − e^{−ia})(e^{−ib} − 1)] and Re[(e^{ia} − 1)(1 − e^{ib})]
    (the variances are ``spectrum_moments``')."""
    df2 = 1.0 / (S.size * dx * dx)
    ea, eb = np.exp(2j * np.pi * FX * dx), np.exp(2j * np.pi * FY * dx)
    cross = 0.5 * ((1.0 - np.conj(ea)) * (np.conj(eb) - 1.0) + (ea - 1.0) * (1.0 - eb)).real
    return float(np.sum(S * cross) * df2) / dx**2
