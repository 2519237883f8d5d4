"""The wave-optics part of ``microsim run`` for a scene with a ``[wave]`` table.

After the ray trace (whose geometric verdicts are unchanged and judged against the ray
tracer), the scalar Kirchhoff (tangent-plane) solver ``wave.kirchhoff_brdf`` is run on the
same realisations of the surface (realisation r built with seed ``seed + r``, in quick mode
on the quick-scaled tile, as the ray tracer saw it; at most ``MAX_WAVE_REALISATIONS`` of
them), on the run's bins and incidences, and the wave closed forms — Rayleigh–Rice, Löw's
smooth-surface model, the first-order Kirchhoff expression (``analysis.wave_verdicts``) —
are judged against its diffuse part. Those verdicts are theory against theory: both sides
are approximations, so a verdict gives the energy-weighted difference and the angular region
of agreement, never "deviates".

Units: ``wavelength`` in the unit of ``dx`` (micrometres by convention). The Kirchhoff result
is saved in ``<run>/kirchhoff/`` (``brdf.npz`` + ``meta.json``, the ``Result`` schema with
``meta["method"] = "kirchhoff"``); the verdicts go to ``verdicts.json`` under ``"wave"``
(``wave_document``).

Planning (``check_wave_plan``) checks, before anything is written, what the scene loader
cannot: the tile actually solved (quick scale) still holds ``MIN_TILE_WAVELENGTHS``
wavelengths, and, for ``surface_model = "smooth"``, every planned realisation's grid samples
the integrand's phase — the solver's own condition (``wave.kirchhoff.phase_sampling``):
per incidence, k(1 + sin θi)·s + k(1 + cos θi)·|Δh|max ≤ π, with s = dx/upsample and |Δh|max
the largest step between neighbours of the Fourier-upsampled heights. For
``realisations = "auto"`` only the pilot's realisations are checked; a later one that fails
stops the analysis with the solver's message.

Kirchhoff's domain: no shadowing or multiple scattering. Incidences where the ray tracer
masked ≥ ``MASKED_LIMIT`` (1 %) of the rays are flagged outside it in the document.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import numpy as np

from ...analysis.study_records import RegimeMaps, WaveSection
from ...analysis.wave_verdicts import wave_verdicts_for_result
from ...analytic.fresnel import fresnel
from ...errors import UsageError
from ...wave import kirchhoff_brdf
from ...wave.kirchhoff import (
    fourier_upsample,
    incident_direction,
    largest_height_step,
    phase_sampling,
)
from ..scene import MIN_TILE_WAVELENGTHS, scaled_grid

__all__ = [
    "WAVE_DIR",
    "MAX_WAVE_REALISATIONS",
    "MASKED_LIMIT",
    "check_wave_plan",
    "wave_surfaces",
    "run_wave",
]

WAVE_DIR = "kirchhoff"
"""Subdirectory of a run holding the Kirchhoff ``Result``."""
MAX_WAVE_REALISATIONS = 16
"""At most this many of the run's realisations go through the wave solver (memory: every
tile is held at once; the standard error is then that of the mean over these)."""
MASKED_LIMIT = 0.01
"""Incidences where the ray tracer's masked fraction reaches this are outside Kirchhoff's
domain (it has no shadowing)."""


def _where(scene) -> str:
    return str(scene.path) if scene.path is not None else scene.name


def check_wave_plan(scene, scale: float, seed: int, realisations: int, theta_i) -> None:
    """UsageError (one line, naming the scene file, the key and what is needed) unless the
    wave solver can run on the planned tiles (module docstring); nothing for a scene without
    ``[wave]``. ``scale``: the effort's surface scale of the scene's kind."""
    w = getattr(scene, "wave", None)
    if w is None:
        return
    where, lam = _where(scene), w.wavelength
    p = scene.surface.params
    n = scaled_grid(p["n"], scale)
    tile = n * p["dx"]
    if tile < MIN_TILE_WAVELENGTHS * lam:
        raise UsageError(
            f"{where}: wave.wavelength: the tile solved at surface scale {scale:g} is "
            f"n·dx = {tile:g}, only {tile / lam:.3g} wavelengths; the wave solver needs >= "
            f"{MIN_TILE_WAVELENGTHS:g} (a larger n·dx or a shorter wavelength)"
        )
    if w.surface_model != "smooth":
        return  # the mesh rule adapts to the phase: no sampling condition
    k = 2.0 * math.pi / lam
    u = w.upsample
    step = p["dx"] / u
    for r in range(min(int(realisations), MAX_WAVE_REALISATIONS)):  # the tiles solved
        with warnings.catch_warnings():  # the generator's notes go to meta.json with the run
            warnings.simplefilter("ignore", UserWarning)
            surface = scene.build_surface(seed=seed + r, scale=scale)
        dh = largest_height_step(fourier_upsample(surface.heights, u))
        for t in theta_i:
            ok, height_step, need = phase_sampling(dh, step, k, incident_direction(t, 0.0))
            if not ok:
                raise UsageError(
                    f"{where}: surface.dx: grid too coarse for wavelength {lam:g}: realisation "
                    f"{r} (seed {seed + r}) steps the height phase by "
                    f"{height_step:.3g} rad between grid points at θi = {t:g}° "
                    f"(largest slope {dh / step:.3g}); need dx/upsample <= {need:.3g} "
                    f"(dx = {p['dx']:g}, wave.upsample = {u}: try upsample >= "
                    f"{math.ceil(p['dx'] / need)}, at most 16)"
                )


def wave_surfaces(plan) -> list:
    """The tiles the wave solver uses: realisations 0 … min(R, ``MAX_WAVE_REALISATIONS``) − 1
    of the run (seed ``plan.seed + r``, the effort's scale), as the ray tracer built them."""
    sc = plan.scene
    scale = plan.effort.scale_for(sc.surface.kind)
    n = min(int(plan.realisations), MAX_WAVE_REALISATIONS)
    return [sc.build_surface(seed=plan.seed + r, scale=scale) for r in range(n)]


def run_wave(plan, result) -> tuple:
    """(Kirchhoff ``Result``, ``"wave"`` section of verdicts.json (``WaveSection``), seconds)
    of a planned run whose ray-traced ``result`` is complete (module docstring). It holds the
    settings, per incidence g = (4πσ cos θi/λ)² with σ the tiles' realised rms height (root
    mean square over the tiles), the specular order's
    power against the Debye–Waller value F(θi)·e^{−g}, the ray tracer's masked fraction and
    whether the incidence is inside Kirchhoff's domain, and the wave verdicts
    (``wave_verdicts.WAVE_VERDICT_SCHEMA``)."""
    sc, w = plan.scene, plan.scene.wave
    t0 = time.perf_counter()
    surfaces = wave_surfaces(plan)
    try:
        kres = kirchhoff_brdf(
            surfaces,
            sc.ior,
            list(plan.theta_i),
            phi_i=plan.phi_i[0],
            wavelength=w.wavelength,
            bins=result.bins,
            fresnel_angle=w.fresnel_angle,
            upsample=w.upsample,
            workers=plan.threads,
            surface_model=w.surface_model,
        )
    except UsageError as e:
        raise UsageError(f"{_where(sc)}: wave: {' '.join(str(e).split())}") from None
    verdicts = wave_verdicts_for_result(kres, surfaces[0], sc.ior)
    seconds = time.perf_counter() - t0
    lam = w.wavelength
    sigma = float(sc.surface.params["sigma"])
    # the tiles' own rms height (the generator's band limit keeps only part of σ²)
    sigma_r = math.sqrt(float(np.mean([np.var(s.heights) for s in surfaces])))
    th = np.asarray(plan.theta_i, dtype=float)
    cos_i = np.cos(np.radians(th))
    g = (4.0 * math.pi * sigma_r * cos_i / lam) ** 2
    f_i = np.asarray(fresnel(cos_i, sc.ior), dtype=float)
    masked = np.asarray(result.ledger["masked"], dtype=float)
    tile = [float(v) for v in kres.info.tile]
    section = WaveSection(
        reference="kirchhoff",
        kind="theory-vs-theory",
        wavelength=lam,
        length_unit="unit of dx (micrometres by convention)",
        surface_model=w.surface_model,
        upsample=int(w.upsample),
        fresnel_angle=w.fresnel_angle,
        tile=tile,
        tile_over_lambda=[v / lam for v in tile],
        sigma_over_lambda=sigma / lam,
        realised_sigma_over_lambda=sigma_r / lam,
        realisations=int(kres.info.realisations),
        run_realisations=int(plan.realisations),
        stderr_method=kres.info.stderr_method,
        theta_i=th.tolist(),
        g=g.tolist(),
        specular_power=[float(v) for v in kres.info.specular_power],
        debye_waller=(f_i * np.exp(-g)).tolist(),
        masked_fraction=masked.tolist(),
        masked_limit=MASKED_LIMIT,
        in_domain=[bool(m < MASKED_LIMIT) for m in masked],
        orders=[int(v) for v in kres.info.orders],
        file=f"{WAVE_DIR}/",
        verdicts=verdicts,
    )
    return kres, section, seconds


@dataclass(frozen=True)
class RegimeGrid:
    """How a regime map is sampled: ``sigmas`` values of σ/λ, one tile of ``tile_over_lambda``
    wavelengths per σ."""

    sigmas: int
    tile_over_lambda: float


REGIME_QUICK = RegimeGrid(sigmas=8, tile_over_lambda=32.0)
"""``microsim report --quick``'s regime map: 8 σ/λ values geometric from 0.01 to 3 and tiles
of 32 λ; the full report uses ``regime_map``'s defaults (14 values, 64 λ: several times
the cost)."""


def regime_maps(quick: bool) -> RegimeMaps:
    """The regime maps of the ABC and Gaussian families for the index's "Where each method
    holds" (``analysis.regimes.regime_map``; ℓ = 10 λ, θi = 0, 30, 60°, aluminium, seed 0,
    18 × 7 folded bins), reduced in quick mode (``REGIME_QUICK``), with one line saying which
    settings were used."""
    from ...analysis.regimes import regime_map

    kw = {}
    if quick:
        kw = {
            "sigmas": np.geomspace(0.01, 3.0, REGIME_QUICK.sigmas),
            "tile_over_lambda": REGIME_QUICK.tile_over_lambda,
        }
    maps = [regime_map(family, **kw) for family in ("abc", "gaussian")]
    m, s = maps[0], maps[0].meta
    settings = (
        f"{'quick (`--quick`): ' if quick else ''}{len(m.sigma)} values of σ/λ geometric "
        f"from {m.sigma[0]:g} to {m.sigma[-1]:g}, ℓ = {s.corr_over_lambda:g} λ "
        f"(ABC: B = 2πℓ, C = {s.abc_C:g}), one tile of "
        f"{s.tile_over_lambda:g} λ per σ (seed {s.seed}, grid refined until "
        f"the solver's phase sampling holds), aluminium, θi = "
        f"{', '.join(f'{t:g}' for t in m.theta_i)}°, {s.bins['n_theta']} × "
        f"{s.bins['n_phi']} folded bins, criterion {100 * s.criterion:g} % "
        "on the energy deviation"
    )
    return RegimeMaps(maps=maps, settings=settings)
