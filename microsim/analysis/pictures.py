"""What a BRDF looks like: a flat plane of the material under a directional light, seen at a
grazing angle, rendered straight from the tables — the simulated BRDF and the best and the
worst closed form, at one exposure, with their differences.

Scene (the same for every image): a directional light of unit irradiance normal to its beam
from the traced incidence wi = (sin θi, 0, cos θi) (φi as traced); a pinhole camera looking
at the plane from the mirror side, its axis at θi clipped to ``VIEW_THETA`` from the normal
(so the mirror highlight sits in the frame, towards the horizon at grazing light, and the
plane fills most of it), field of view ``FOV``. The
plane is homogeneous and infinite and the light directional, so a pixel's radiance depends on
its viewing direction only: the pixel whose ray d meets the plane sees wo = −d and

    L(pixel) = f̄_B(wo) cos θi,

f̄_B the bin average of the bin B that holds wo (sr⁻¹, ``Result.brdf`` or a model's values on
the same bins): exactly what the tables say, at their resolution — no renderer, no
interpolation, blocky where the bins are coarse. Pixels above the horizon show the sky (grey).

Exposure: one scale for the three renders, the simulated image's 99.5th percentile mapped to
0.9, then the sRGB curve; values beyond clip to white. Differences: (model − simulation)/
simulation per pixel on a diverging scale of ±``DIFF_RANGE``, grey where the simulated bin
holds fewer than ``MIN_EVENTS`` events (as the verdicts leave such bins out).

In colour (``appearance_colour``): the same scene for BRDFs given at several wavelengths
(``measured.SpectralBRDF``: a ``Result`` per wavelength, rendered from its bins as above, or a
callable, evaluated at each pixel's wo), the light's spectrum that of an illuminant (D65 by
default): each pixel's spectrum f(wo, λ) cos θi is taken to linear sRGB
(``analytic.colour_matching``: CIE 1931 2°, a white of 1 where f cos θi = 1 at every
wavelength), one exposure for all panels — the 99.5th percentile of the pixels' largest
component mapped to 0.9 — clipped to [0, 1] per component, then the sRGB curve.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from microsim.analytic import colour_matching
from microsim.analytic.colour_matching import srgb_encode
from microsim.errors import UsageError
from microsim.measured.spectral import SpectralBRDF
from microsim.sim.result import Result
from microsim.stats import MIN_EVENTS
from microsim.vectors import spherical_deg

from . import incidence
from .charts import _figure, _output, _select_verdicts, _title

__all__ = [
    "FOV",
    "VIEW_THETA",
    "DIFF_RANGE",
    "view_directions",
    "render",
    "appearance",
    "render_colour",
    "appearance_colour",
]

FOV = 70.0
"""Horizontal field of view of the camera, degrees."""
VIEW_THETA = (25.0, 65.0)
"""Range of the camera axis' polar angle from the plane's normal, degrees (θi clipped to it)."""
DIFF_RANGE = 0.5
"""± relative difference at the ends of the difference images' colour scale."""
SKY = 0.35
"""Grey of the pixels that see no plane (above the horizon)."""


def view_directions(view_theta: float, phi_i: float, width: int = 240, height: int = 160):
    """(wo (H, W, 3), mask (H, W)): the outgoing direction each pixel of the camera sees on
    the plane (module docstring) and whether it sees the plane at all; the camera sits on the
    mirror side (azimuth φi + 180°) at ``view_theta`` degrees from the normal."""
    if not 0.0 < view_theta < 90.0:
        raise UsageError(f"view_theta must lie in (0, 90) degrees, got {view_theta!r}")
    t, p = math.radians(view_theta), math.radians(phi_i + 180.0)
    back = np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])
    forward = -back  # the camera looks along −back, at the plane's centre
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    half = math.tan(math.radians(FOV) / 2.0)
    x = np.linspace(-half, half, width)
    y = np.linspace(half * height / width, -half * height / width, height)
    d = forward + x[None, :, None] * right + y[:, None, None] * up
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    mask = d[..., 2] < -1e-6
    return np.where(mask[..., None], -d, np.array([0.0, 0.0, 1.0])), mask


def render(values: np.ndarray, bins, wo: np.ndarray, mask: np.ndarray, theta_i, phi_i):
    """Radiance (H, W) of the plane: the bin average of ``values`` (Θ, Φ) sr⁻¹ at each pixel's
    wo times cos θi; NaN off the plane."""
    idx = bins.locate(wo.reshape(-1, 3), phi_i).reshape(mask.shape)
    vals = np.asarray(values, dtype=np.float64).ravel()
    out = np.where(mask & (idx >= 0), vals[np.maximum(idx, 0)], np.nan)
    return out * math.cos(math.radians(theta_i))


def _tone(radiance: np.ndarray, scale: float) -> np.ndarray:
    """sRGB grey levels in [0, 1] of ``radiance`` × ``scale``; the sky grey where NaN."""
    x = np.clip(np.nan_to_num(radiance, nan=0.0) * scale, 0.0, 1.0)
    return np.where(np.isnan(radiance), SKY, srgb_encode(x))


def appearance(
    result,
    models: Mapping[str, np.ndarray],
    verdicts: Sequence[Mapping],
    t_index: int,
    path=None,
    scene_name: str = "",
):
    """The appearance chart (module docstring) of incidence ``t_index`` of ``result``: the
    simulation and the best and the worst of ``models`` there (by rel_rms among ``verdicts``
    of that incidence), their relative differences, one exposure. Returns the Figure; writes a
    PNG to ``path`` unless None."""
    t = int(t_index)
    if not 0 <= t < len(result.theta_i):
        raise UsageError(f"t_index must be in [0, {len(result.theta_i) - 1}], got {t_index}")
    th, ph = float(result.theta_i[t]), float(result.phi_i[t])
    sel = _select_verdicts(verdicts, th, ph, set(models))
    shown = [sel[0]["model"]] + ([sel[-1]["model"]] if sel[-1] is not sel[0] else [])
    view = float(np.clip(th, *VIEW_THETA))
    wo, mask = view_directions(view, ph)
    sim = render(result.brdf[t], result.bins, wo, mask, th, ph)
    imgs = {name: render(models[name][t], result.bins, wo, mask, th, ph) for name in shown}
    finite = sim[np.isfinite(sim) & (sim > 0)]
    scale = 0.9 / float(np.percentile(finite, 99.5)) if finite.size else 1.0
    fig = _figure((3.2 * 3, 2.35 * 2 + 0.4))
    axes = fig.subplots(2, 3)
    panels = [("simulation", sim)] + [
        (f"{'best' if k == 0 else 'worst'}: {n}", imgs[n]) for k, n in enumerate(shown)
    ]
    for ax, (title, img) in zip(axes[0], panels):
        ax.imshow(_tone(img, scale), cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        ax.set_title(title, fontsize=9)
    diff_im = None
    events = render(result.counts[t], result.bins, wo, mask, 0.0, ph)  # cos 0 = 1
    for ax, name in zip(axes[1, 1:], shown):
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.where((sim > 0) & (events >= MIN_EVENTS), (imgs[name] - sim) / sim, np.nan)
        diff_im = ax.imshow(
            rel, cmap="RdBu_r", vmin=-DIFF_RANGE, vmax=DIFF_RANGE, interpolation="nearest"
        )
        ax.set_facecolor(str(SKY))
        ax.set_title(f"({name} − sim)/sim", fontsize=9)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in list(axes[0, len(panels) :]) + list(axes[1, 1 + len(shown) :]):
        ax.axis("off")
    note = axes[1, 0]
    note.axis("off")
    at = incidence.label(th, ph, incidence.several_azimuths(result.phi_i))
    note.text(
        0.0,
        1.0,
        f"plane under a directional\nlight at {at};\n"
        f"camera {view:g}° from the normal,\nmirror side, {FOV:g}° field of view;\n"
        "each pixel: its bin's average\n× cos θi (the tables, no renderer);\n"
        f"one exposure for the renders;\ngrey: sky, or < {MIN_EVENTS} events",
        fontsize=8,
        va="top",
        transform=note.transAxes,
    )
    if diff_im is not None:
        fig.colorbar(diff_im, ax=list(axes[1, 1:]), shrink=0.8, label="relative difference")
    fig.suptitle(_title(scene_name, f"appearance at {at}"))
    return _output(fig, path)


def _incidence_index(result, theta_i: float, phi_i: float, nm: float) -> int:
    """The index of incidence (``theta_i``, ``phi_i``) in ``result``, or a UsageError listing
    the traced ones."""
    at = np.isclose(result.theta_i, theta_i, atol=1e-6) & np.isclose(result.phi_i, phi_i, atol=1e-6)
    if not np.any(at):
        traced = ", ".join(f"({t:g}°, {p:g}°)" for t, p in zip(result.theta_i, result.phi_i))
        raise UsageError(
            f"theta_i, phi_i must be an incidence the Result at {nm:g} nm traced, one of "
            f"{traced}; got ({theta_i:g}°, {phi_i:g}°)"
        )
    return int(np.flatnonzero(at)[0])


def render_colour(brdf: SpectralBRDF, theta_i: float, phi_i: float = 0.0, illuminant="D65"):
    """Linear sRGB radiance (H, W, 3) of the plane (module docstring) for the spectral
    ``brdf`` under a light of ``illuminant`` from (``theta_i``, ``phi_i``) degrees; NaN off the
    plane. A ``Result`` among ``brdf.brdfs`` must have traced that incidence."""
    if not isinstance(brdf, SpectralBRDF):
        raise UsageError(
            f"brdf must be a microsim.measured.SpectralBRDF (wavelengths_nm, brdfs), got "
            f"{type(brdf).__name__}"
        )
    th = float(theta_i)
    if not 0.0 <= th < 90.0:
        raise UsageError(f"theta_i must lie in [0, 90) degrees, got {theta_i!r}")
    ph = float(phi_i)
    wo, mask = view_directions(float(np.clip(th, *VIEW_THETA)), ph)
    wi = np.broadcast_to(spherical_deg(th, ph), (int(mask.sum()), 3))
    spectra = np.empty(mask.shape + (len(brdf.wavelengths_nm),))
    for k, (nm, b) in enumerate(zip(brdf.wavelengths_nm, brdf.brdfs)):
        if isinstance(b, Result):
            t = _incidence_index(b, th, ph, nm)
            spectra[..., k] = render(b.brdf_total()[t], b.bins, wo, mask, th, ph)
        else:
            spectra[..., k] = np.nan
            spectra[mask, k] = brdf.functions[k](wi, wo[mask]) * math.cos(math.radians(th))
    rgb = np.full(mask.shape + (3,), np.nan)
    seen = np.all(np.isfinite(spectra), axis=-1)
    rgb[seen] = colour_matching.linear_srgb(brdf.wavelengths_nm, spectra[seen], illuminant)
    return rgb


def appearance_colour(
    brdfs: Mapping[str, SpectralBRDF],
    theta_i: float,
    path=None,
    *,
    phi_i: float = 0.0,
    scene_name: str = "",
    illuminant: str = "D65",
):
    """The colour appearance chart: one panel per spectral BRDF of ``brdfs`` (name →
    ``SpectralBRDF``; ``render_colour``) under a light of ``illuminant`` at (``theta_i``,
    ``phi_i``) degrees, one exposure (module docstring). Returns the Figure; writes a PNG to
    ``path`` unless None."""
    if not isinstance(brdfs, Mapping) or not brdfs:
        raise UsageError(
            f"brdfs must be a non-empty mapping of names to SpectralBRDFs, got "
            f"{type(brdfs).__name__}"
        )
    images = {name: render_colour(b, theta_i, phi_i, illuminant) for name, b in brdfs.items()}
    brightest = np.concatenate([np.nanmax(img, axis=-1).ravel() for img in images.values()])
    brightest = brightest[np.isfinite(brightest) & (brightest > 0)]
    scale = 0.9 / float(np.percentile(brightest, 99.5)) if brightest.size else 1.0
    fig = _figure((max(3.2 * len(images), 4.8), 2.35 + 1.2))  # room for the title
    axes = np.atleast_1d(fig.subplots(1, len(images)))
    for ax, (name, img) in zip(axes, images.items()):
        sky = np.isnan(img).any(axis=-1)
        x = srgb_encode(np.clip(np.nan_to_num(img, nan=0.0) * scale, 0.0, 1.0))
        ax.imshow(np.where(sky[..., None], SKY, x), interpolation="nearest")
        ax.set_title(name, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    at = incidence.label(float(theta_i), float(phi_i), float(phi_i) != 0.0)
    view = float(np.clip(float(theta_i), *VIEW_THETA))
    fig.supxlabel(
        f"plane under a directional {illuminant} light at {at};\ncamera {view:g}° from the "
        f"normal, mirror side;\nCIE 1931 2°, linear sRGB, one exposure, sRGB curve",
        fontsize=8,
    )
    fig.suptitle(_title(scene_name, f"appearance in colour at {at}"))
    return _output(fig, path)
