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
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from microsim.errors import UsageError
from microsim.stats import MIN_EVENTS

from . import incidence
from .charts import _figure, _output, _select_verdicts, _title

__all__ = ["FOV", "VIEW_THETA", "DIFF_RANGE", "view_directions", "render", "appearance"]

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
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.where(np.isnan(radiance), SKY, srgb)


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
