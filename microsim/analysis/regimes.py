"""Where each method holds: closed forms and geometric optics against the Kirchhoff solver as
the roughness σ/λ grows (the regime map).

For a surface family (``"abc"``: Church's ABC PSD with B = 2π ℓ and C = 3.5, band-limited by
the generator; ``"gaussian"``: autocorrelation σ² exp(−r²/ℓ²)) at a fixed correlation length
ℓ/λ (default 10, so that Kirchhoff's tangent-plane condition ℓ ≫ λ holds) and σ/λ from 0.01
to 3, one tile per σ is synthesised (same seed; tile 64 λ; the grid refined until the solver's
phase-sampling check passes), its Kirchhoff BRDF computed at θi = 0, 30, 60° (aluminium), and
each model judged against it with ``wave_verdicts.wave_verdict`` (diffuse part, bins up to
θo = 80°, energy set of 90 %):

    "rayleigh-rice"     RR with the nominal PSD (Löw et al. 2012, eq. 3), no fit;
    "low-smooth"        Löw's smooth-surface model with the PSD's A, B, C (ABC family only);
    "ts-smith"          Torrance–Sparrow with Beckmann(m realised by the tile) and Smith
                        masking (geometric optics of the ensemble);
    "geometric-facets"  Torrance–Sparrow with the tile's own facets and no masking
                        (``sim.predict.bin_average_facets``): the geometric-optics limit of that
                        very mesh, i.e. the ray tracer with masking off.

The error plotted and used for the crossovers is the energy-weighted mean relative error over
the energy set, ``energy_dev`` = Σ_E Ω(f̄ − m)/Σ_E Ω f̄ (reference minus model); the 5 %
criterion is applied to its magnitude. Its standard error (``energy_dev_se``, from the result's
speckle se, which counts the trend of f across a bin as scatter and so overstates the noise of
a smooth, exact-amplitude tile) is reported beside it: measured 2–30 % (median 5–6 %) where a
model is within 10 %. The energy-weighted RMS (``rel_error``) is kept too, but one tile's
speckle puts a floor of 9–64 % under it (``noise_floor``), so it cannot resolve 5 %. Exact
check of tests/test_wave_rough.py removes that floor for "geometric-facets" deep
in the rough regime: with several independent tiles, each against its own facets, the mean over
pairs of tiles of Σ_E w e_t e_t' estimates the systematic part of the RMS without the speckle;
measured 0.7–1.5 % at σ = 2λ, ℓ = 20λ, θi = 0–30° (mesh and smooth surface) and ≤ 1.7 % at σ =
2λ, ℓ = 40λ up to θi = 60°, where the Smith masked fraction is below 1 % (it is 2.1 % at 60°
for m = 0.2).

Expected crossovers (first-order theory, to check the map against): with g = (4πσ cos θi/λ)²
the Kirchhoff diffuse power is F(1 − e^{−g}) (Davies 1954) while RR's is ≈ F g, so RR
overestimates by ≈ g/2 and leaves 5 % at g ≈ 0.1, σ/λ ≈ 0.025/cos θi; geometric optics puts
all of F into the lobe, so it overestimates the diffuse power by e^{−g}/(1 − e^{−g}), below 5 %
only for g ≥ 3.04, σ/λ ≥ 0.139/cos θi. Smith masking (absent from Kirchhoff) lowers "ts-smith"
by a few % at m = 2σ/ℓ ≳ 0.4 (σ/λ ≳ 2 here): only incidences where masking is below 1 % judge
geometric optics cleanly.

Measured (``regime_map(family)`` defaults: ℓ = 10 λ, tile 64 λ, 18 × 7 folded bins, aluminium,
seed 0; grids 256²–1024²; 1–2 min per family on 2 busy cores), σ/λ at θi = 0, 30, 60°:

    family    RR stops holding      geometric (own facets) holds from    TS-Smith holds from
    gaussian  0.027 0.028 0.048     0.177 0.202 0.358                    0.148 0.191 0.317
    abc       0.031 0.034 0.059     0.243 0.208 0.396                    0.243 0.214 0.444

RR: σ cos θi/λ = 0.024–0.031 against 0.025 predicted; geometric optics: σ cos θi/λ =
0.175–0.243 (g = 4.8–9.3), between the g = 1 and g = 10 bounds (0.080, 0.252). Löw smooth
never holds on aluminium (its Q' = F(Re η) with Re η = 0.769 < 1 and G' = 1: −98 % at
θi ≤ 30°, +340 % at 60°). TS-Smith fails again at σ = 3 λ on the Gaussian family (−11 to
−12 %: m = 0.6, Smith masking, which Kirchhoff lacks), not on the ABC one (−3 to −4 %).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from microsim.analytic import Beckmann
from microsim.analytic.brdf import torrance_sparrow
from microsim.errors import UsageError
from microsim.sim import Bins
from microsim.sim.predict import bin_average_facets
from microsim.surfaces.heightfields import abc, gaussian
from microsim.vectors import spherical_deg
from microsim.wave import kirchhoff_brdf

from .json_record import JsonRecord
from .wave_verdicts import closed_form, lattice_average, surface_spectrum, wave_verdict

__all__ = [
    "FAMILIES",
    "MODELS",
    "RegimeMap",
    "RegimeSettings",
    "regime_surface",
    "regime_map",
    "crossover",
    "regime_chart",
    "CRITERION",
]

FAMILIES = ("abc", "gaussian")
MODELS = ("rayleigh-rice", "low-smooth", "ts-smith", "geometric-facets")
CRITERION = 0.05
"""A method holds where |energy_dev| ≤ this (5 %)."""
ABC_C = 3.5
GRIDS = (128, 256, 512, 1024, 2048)


@dataclass(frozen=True, eq=False)
class RegimeSettings(JsonRecord):
    """How a regime map was made (``RegimeMap.meta``): correlation length and tile in λ, the
    material, the bins (``Bins.to_dict``), the seed, Church's C of the ABC family (None for
    the Gaussian), the grid used and the seconds per σ, the criterion and what the error is."""

    corr_over_lambda: float
    tile_over_lambda: float
    material: str
    bins: dict
    seed: int
    abc_C: float | None
    grids: list
    seconds: list
    criterion: float
    error: str


@dataclass
class RegimeMap:
    """Errors of each model against Kirchhoff, arrays (models, σ, θi): ``energy_dev`` (signed
    energy-weighted mean relative error) and its ``energy_dev_se``, ``rel_error`` (energy-
    weighted RMS) and ``noise_floor``; ``sigma`` in units of λ; ``meta`` the settings, grids
    and seconds per σ (``RegimeSettings``). NaN where a model does not apply (Löw smooth on a
    Gaussian PSD)."""

    family: str
    sigma: np.ndarray
    theta_i: np.ndarray
    models: tuple
    energy_dev: np.ndarray
    energy_dev_se: np.ndarray
    rel_error: np.ndarray
    noise_floor: np.ndarray
    meta: Mapping = field(default_factory=dict)

    def crossovers(self, criterion: float = CRITERION) -> dict:
        """{model: {θi: σ/λ}}: for RR and Löw smooth the σ above which they stop holding
        (``crossover(..., "below")``), for the geometric models the σ above which they hold
        (``"above"``); None when the grid does not bracket it."""
        out = {}
        for i, name in enumerate(self.models):
            side = "below" if name in ("rayleigh-rice", "low-smooth") else "above"
            out[name] = {
                float(th): crossover(self.sigma, self.energy_dev[i, :, t], criterion, side)
                for t, th in enumerate(self.theta_i)
            }
        return out

    def to_dict(self) -> dict:
        """JSON-able form."""
        return {
            "family": self.family,
            "sigma_over_lambda": self.sigma.tolist(),
            "theta_i": self.theta_i.tolist(),
            "models": list(self.models),
            "energy_dev": np.where(np.isfinite(self.energy_dev), self.energy_dev, None).tolist(),
            "energy_dev_se": np.where(
                np.isfinite(self.energy_dev_se), self.energy_dev_se, None
            ).tolist(),
            "rel_error": np.where(np.isfinite(self.rel_error), self.rel_error, None).tolist(),
            "noise_floor": np.where(np.isfinite(self.noise_floor), self.noise_floor, None).tolist(),
            "crossovers": {
                k: {str(t): v for t, v in d.items()} for k, d in self.crossovers().items()
            },
            "meta": self.meta,
        }


def crossover(sigma, error, criterion: float = CRITERION, side: str = "below"):
    """σ where |error| crosses ``criterion``, by linear interpolation of |error| in log σ
    between the two grid points that bracket it (σ ascending). ``side="below"``: the method
    holds at small σ; the crossing at the upper end of the run of holding points that starts
    at the smallest σ (None if the smallest σ fails or every point holds). ``side="above"``:
    the method holds at large σ; the crossing at the lower end of the last run of holding
    points, the one reaching the largest holding σ (None if no point holds or the run starts
    at the smallest σ); failing points above that run (e.g. masking at the steepest surfaces)
    are reported by the caller, not here."""
    s = np.asarray(sigma, dtype=np.float64)
    e = np.abs(np.asarray(error, dtype=np.float64))
    ok = e <= criterion
    if side not in ("below", "above"):
        raise UsageError(f"side must be 'below' or 'above', got {side!r}")
    if side == "below":
        if not ok[0] or ok.all():
            return None
        b = int(np.argmin(ok))  # first failing point
        a = b - 1
    else:
        if not ok.any():
            return None
        top = int(np.flatnonzero(ok)[-1])
        a = top
        while a > 0 and ok[a - 1]:
            a -= 1
        if a == 0:
            return None
        b, a = a, a - 1  # a fails, b holds
    ea, eb = e[a], e[b]
    if not (np.isfinite(ea) and np.isfinite(eb)) or eb == ea:
        return float(s[b])
    x = (criterion - ea) / (eb - ea)
    return float(math.exp(math.log(s[a]) + x * (math.log(s[b]) - math.log(s[a]))))


def regime_surface(family: str, sigma: float, grid: int, *, corr: float, tile: float, seed: int):
    """One tile of ``family`` with rms height ``sigma``, correlation length ``corr`` (ABC:
    B = 2π·corr, C = ``ABC_C``), side ``tile`` on a ``grid``² grid (lengths in λ)."""
    dx = tile / grid
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if family == "gaussian":
            return gaussian(grid, dx, sigma, corr, seed=seed)
        if family == "abc":
            return abc(grid, dx, sigma, 2.0 * math.pi * corr, ABC_C, seed=seed)
    raise UsageError(f"family must be one of {FAMILIES}, got {family!r}")


def _kirchhoff(family, sigma, theta_i, *, corr, tile, seed, material, bins, grids):
    last = None
    for grid in grids:
        s = regime_surface(family, sigma, grid, corr=corr, tile=tile, seed=seed)
        try:
            return s, kirchhoff_brdf(s, material, theta_i, wavelength=1.0, bins=bins)
        except UsageError as err:
            if "too coarse" not in str(err):
                raise
            last = err
    raise UsageError(f"sigma = {sigma:g} λ: no grid up to {grids[-1]}² samples the phase ({last})")


@dataclass(frozen=True)
class _TileModels:
    """What the models need of one tile, computed once for all its incidences: its spectrum
    (``surface_spectrum``), Beckmann at its realised m, its facet normals and projected
    areas."""

    spectrum: object
    ndf: Beckmann
    normals: np.ndarray
    areas: np.ndarray

    @classmethod
    def of(cls, surface) -> "_TileModels":
        return cls(
            surface_spectrum(surface),
            Beckmann(surface.stats()["m_realised"]),
            surface.facet_normals(),
            surface.projected_areas(),
        )


def _model_bins(name, tile: _TileModels, result, t, material):
    th, ph = float(result.theta_i[t]), float(result.phi_i[t])
    if name in ("rayleigh-rice", "low-smooth"):
        if name == "low-smooth" and tile.spectrum.kind != "abc":
            return None
        return lattice_average(result, t, closed_form(name, tile.spectrum, 1.0, material))
    if name == "ts-smith":
        return lattice_average(
            result, t, lambda wi, wo: torrance_sparrow(wi, wo, tile.ndf, "smith", material)
        )
    if name == "geometric-facets":
        wi = spherical_deg(th, ph)
        est = bin_average_facets(wi, result.bins, tile.normals, tile.areas, "none", material, ph)
        return est.values
    raise UsageError(f"model must be one of {MODELS}, got {name!r}")


def regime_map(
    family: str,
    sigmas=None,
    theta_i=(0.0, 30.0, 60.0),
    *,
    corr_over_lambda: float = 10.0,
    tile_over_lambda: float = 64.0,
    material="aluminium",
    bins: Bins | None = None,
    seed: int = 0,
    models=MODELS,
    grids=GRIDS,
) -> RegimeMap:
    """The regime map of one ``family`` (module docstring). ``sigmas`` σ/λ (default 14 values
    geometric from 0.01 to 3). Lengths in units of λ = 1. Default bins 18 × 7 folded
    (5° × 30°): a 64 λ tile puts ~100 orders in a bin."""
    if family not in FAMILIES:
        raise UsageError(f"family must be one of {FAMILIES}, got {family!r}")
    if not corr_over_lambda >= 10.0:
        raise UsageError(
            f"corr_over_lambda must be >= 10 (Kirchhoff needs ℓ ≫ λ), got {corr_over_lambda!r}"
        )
    sig = np.geomspace(0.01, 3.0, 14) if sigmas is None else np.asarray(sigmas, dtype=float)
    th = np.asarray(theta_i, dtype=float)
    bins = Bins(18, 7, True) if bins is None else bins
    names = tuple(models)
    shape = (len(names), len(sig), len(th))
    dev, dev_se, rel, noise = (np.full(shape, np.nan) for _ in range(4))
    grid_used, seconds = [], []
    for j, s in enumerate(sig):
        t0 = time.perf_counter()
        surf, res = _kirchhoff(
            family,
            float(s),
            th,
            corr=corr_over_lambda,
            tile=tile_over_lambda,
            seed=seed,
            material=material,
            bins=bins,
            grids=grids,
        )
        grid_used.append(int(surf.heights.shape[0]))
        tile = _TileModels.of(surf)
        for t in range(len(th)):
            for i, name in enumerate(names):
                mb = _model_bins(name, tile, res, t, material)
                if mb is None:
                    continue
                v = wave_verdict(res, t, mb, model=name, tol=CRITERION)
                if v.energy_dev is None:
                    continue
                dev[i, j, t] = v.energy_dev
                dev_se[i, j, t] = v.energy_dev_se
                rel[i, j, t] = v.rel_error
                noise[i, j, t] = v.noise_floor
        seconds.append(time.perf_counter() - t0)
    meta = RegimeSettings(
        corr_over_lambda=float(corr_over_lambda),
        tile_over_lambda=float(tile_over_lambda),
        material=repr(material),
        bins=bins.to_dict(),
        seed=int(seed),
        abc_C=ABC_C if family == "abc" else None,
        grids=grid_used,
        seconds=seconds,
        criterion=CRITERION,
        error="energy_dev (energy-weighted mean relative error over the 90 % energy set)",
    )
    return RegimeMap(family, sig, th, names, dev, dev_se, rel, noise, meta)


_MARKERS = {"rayleigh-rice": "o", "low-smooth": "s", "ts-smith": "^", "geometric-facets": "v"}
_COLOUR_OF = {"geometric-facets": "ts-facets"}  # the ray trace of the facets: ts-facets' colour


def regime_chart(maps, ax=None, *, theta_i=None, criterion: float = CRITERION):
    """Chart "Where each method holds": |energy-weighted error| of each method against the
    Kirchhoff reference over σ/λ (log–log), as small multiples: one row per family (``maps``,
    a ``RegimeMap`` or a list), one column per incidence (``theta_i``: a subset, default all),
    one line per method in its report colour and marker (``charts.model_style``), the
    ``criterion`` band (|error| ≤ 5 %) shaded, the legend outside the panels. With ``ax`` every
    map, method and incidence goes on that one Axes (line style per incidence). Returns the
    matplotlib Figure (no pyplot)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from .charts import model_style

    maps = [maps] if isinstance(maps, RegimeMap) else list(maps)
    if not maps:
        raise UsageError("maps: give at least one RegimeMap")
    wanted = None if theta_i is None else [float(x) for x in theta_i]
    thetas = [float(t) for t in maps[0].theta_i if wanted is None or float(t) in wanted]
    if ax is None:
        fig = Figure(figsize=(3.4 * len(thetas) + 2.2, 3.0 * len(maps) + 0.5), dpi=100,
                     layout="constrained")  # fmt: skip
        FigureCanvasAgg(fig)
        grid = fig.subplots(len(maps), len(thetas), squeeze=False, sharex=True, sharey=True)
        panels = [(grid[r, c], rm, th, "-") for r, rm in enumerate(maps)
                  for c, th in enumerate(thetas)]  # fmt: skip
    else:
        fig, styles = ax.figure, ["-", "--", ":", "-."]
        panels = [(ax, rm, th, styles[k % 4]) for rm in maps for k, th in enumerate(thetas)]
    for a, rm, th, style in panels:
        t = [float(x) for x in rm.theta_i].index(th)
        for i, name in enumerate(rm.models):
            y = np.abs(rm.energy_dev[i, :, t])
            if not np.any(np.isfinite(y)):
                continue
            a.plot(
                rm.sigma,
                np.maximum(y, 1e-4),
                linestyle=style,
                color=model_style(_COLOUR_OF.get(name, name))[0],
                marker=_MARKERS.get(name, "d"),
                markersize=3.5,
                label=name if ax is None else f"{name} θi={th:g}°",
            )
        a.axhspan(1e-4, criterion, color="0.9", zorder=0)
        a.axhline(criterion, color="0.5", linewidth=1)
        a.set_xscale("log")
        a.set_yscale("log")
        a.grid(True, which="major", alpha=0.3)
        if ax is None:
            a.set_title(f"{rm.family}, ℓ/λ = {rm.meta.get('corr_over_lambda', float('nan')):g}, "
                        f"θi = {th:g}°", fontsize=9)  # fmt: skip
    if ax is not None:
        ax.set_xlabel("σ/λ")
        ax.set_ylabel("|energy-weighted error| vs Kirchhoff")
        ax.legend(fontsize=6, ncol=2)
        return fig
    fig.supxlabel("σ/λ (rms height over wavelength)")
    fig.supylabel("|energy-weighted error| against Kirchhoff")
    handles, labels = {}, []
    for a, *_ in panels:
        for h, lab in zip(*a.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    labels = list(handles)
    labels.append(f"within {100 * criterion:g} %")
    from matplotlib.patches import Patch

    fig.legend(
        list(handles.values()) + [Patch(color="0.9")], labels, loc="outside right upper", fontsize=8
    )
    return fig
