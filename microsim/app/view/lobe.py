"""The lobe view: the simulated single-bounce BRDF as a 3D polar surface (radius f·cos θo,
linear or log-scaled) beside the model's (Torrance–Sparrow with the scene's NDF; V-groove G on
V-grooves, height-correlated Smith on heightfields), coloured by z = (sim − model)/σ."""

from __future__ import annotations

import warnings

import numpy as np

from microsim.vectors import spherical_deg

from ...analytic.models import TorranceSparrow
from ...errors import UsageError
from ...sim import Bins, simulate
from ...sim.predict import predict
from ...stats import MIN_EVENTS
from .common import (
    COLOURS,
    LOBE_VIEW,
    WINDOW,
    ascii_text,
    plotter,
    polar_surface,
    pyvista,
    resolve,
    scalar_bar,
    side_camera,
    text_size,
    title,
)

__all__ = ["lobe_z", "view_lobe"]


def _default_shadowing(surface) -> str:
    return surface.exact_shadowing or "smith-correlated"


def _full_circle(values: np.ndarray, bins) -> tuple[np.ndarray, np.ndarray]:
    """Folded (Θ, Φ) values → full azimuth (Θ, 2Φ − 2) and their Δφ (deg), mirrored (isotropy)."""
    phi = bins.phi_centers
    full_phi = np.concatenate([phi, 360.0 - phi[-2:0:-1]])
    full = np.concatenate([values, values[:, -2:0:-1]], axis=1)
    return full, full_phi


def _lobe_radius(fcos: np.ndarray, peak: float, scale: str) -> np.ndarray:
    """Radius of the polar plot: f cos θo / peak (linear) or log10(1 + 1000 f cos θo / peak)/3
    (log: 3 decades), so that the peak has radius 1 in either case."""
    x = np.maximum(fcos, 0.0) / peak
    return x if scale == "linear" else np.log10(1.0 + 1000.0 * x) / np.log10(1001.0)


def lobe_z(
    sim: np.ndarray,
    stderr: np.ndarray,
    model: np.ndarray,
    omega: np.ndarray,
    rays: int,
    mean_weight: float,
    counts: np.ndarray | None = None,
) -> np.ndarray:
    """z = (sim − model)/σ per bin. σ is the simulation's standard error where the bin holds
    at least ``MIN_EVENTS`` events (``counts``; all bins when None); elsewhere — no ray, or so
    few that the paired-strata estimate is meaningless (two equal Fresnel weights in one
    stratum pair give σ ≈ 0 and |z| in the thousands) — the Poisson error the model predicts,
    √(model · w̄ / (N Ω)) with w̄ the mean Fresnel weight. 0 where both vanish. The verdicts
    leave such bins out altogether (``analysis.verdicts``)."""
    se_model = np.sqrt(np.maximum(model, 0.0) * mean_weight / (rays * omega))
    resolved = stderr > 0 if counts is None else (stderr > 0) & (counts >= MIN_EVENTS)
    se = np.where(resolved, stderr, se_model)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(se > 0, (sim - model) / se, 0.0)


def _directions(p, wi: np.ndarray, length: float = 1.25) -> None:
    """Incident (gold) and mirror (dark grey) directions as arrows from the origin, plus the
    horizon circle for scale."""
    pv = pyvista()
    mirror = np.array([-wi[0], -wi[1], wi[2]])
    for w, col in ((wi, COLOURS.incident), (mirror, COLOURS.mirror)):
        p.add_mesh(
            pv.Arrow(
                start=(0, 0, 0),
                direction=w,
                scale=length,
                tip_length=0.12,
                tip_radius=0.04,
                shaft_radius=0.012,
            ),
            color=col,
        )
    p.add_mesh(
        pv.Circle(radius=1.0, resolution=120).extract_feature_edges(), color="#999999", line_width=1
    )


def _simulation_panel(p, name, res, bins, model, r_sim, phi, theta_i) -> None:
    """The simulated lobe (radius ``r_sim``) in ``p``'s current view: coloured by z against
    ``model``'s bin averages, or by f where there is no model."""
    sim, se, rays = res.brdf[0], res.stderr[0], int(res.rays[0])
    if model is None:
        g = polar_surface(r_sim, bins.theta_centers, phi, _full_circle(sim, bins)[0], "f")
        p.add_mesh(g, scalars="f", cmap="viridis", scalar_bar_args=scalar_bar("f (1/sr)"))
        title(
            p,
            f"{name}: simulated BRDF\nθi = {theta_i:g}°, {rays} rays (no analytic NDF: no model)",
        )
        return
    single = res.ledger_counts["single"][0]
    w_mean = res.ledger["single_fresnel"][0] * res.rays[0] / max(single, 1)
    omega = bins.projected_solid_angle()
    z = lobe_z(sim, se, model, omega, rays, w_mean, res.counts[0])
    z_full, _ = _full_circle(z, bins)
    g = polar_surface(r_sim, bins.theta_centers, phi, np.clip(z_full, -5, 5), "z")
    p.add_mesh(
        g,
        scalars="z",
        cmap="coolwarm",
        clim=(-5, 5),
        smooth_shading=True,
        scalar_bar_args=scalar_bar(
            "z = (sim − model)/σ",
            vertical=False,
            position_x=0.3,
            position_y=0.1,
            width=0.6,
            height=0.08,
        ),
    )
    title(
        p,
        f"{name}: simulation\nθi = {theta_i:g}°, {rays} rays, "
        f"coloured by z\n(clipped to ±5; largest abs(z) = {np.max(np.abs(z)):.1f})\n"
        f"(σ of bins under {MIN_EVENTS} events: Poisson)",
    )


def _model_panel(p, lobe, caption: str, wi) -> None:
    """The model's lobe (the mesh ``lobe``) in the second view, linked to the first."""
    p.subplot(0, 1)
    p.add_mesh(lobe, color=COLOURS.model, smooth_shading=True)
    _directions(p, wi)
    title(p, f"model: Torrance–Sparrow\n{caption}\n(same bins, same radius scale)")
    p.link_views()


def view_lobe(
    scene_or_surface,
    theta_i: float = LOBE_VIEW.theta,
    rays: int = LOBE_VIEW.rays,
    scale: str = "linear",
    shadowing: str | None = None,
    n_theta: int = 30,
    n_phi: int = 25,
    material=None,
    seed=0,
    off_screen=None,
    window_size=WINDOW,
):
    """Simulated BRDF at θi (degrees) as a polar surface (radius f·cos θo, linear or log —
    ``scale``) beside the Torrance–Sparrow model with the scene's NDF (``shadowing`` default:
    "vgroove" on V-grooves, "smith-correlated" on heightfields) on the same folded bins; the
    simulation is coloured by z = (sim − model)/σ, the model drawn in green. Without an NDF
    (flat, file) only the simulation is drawn, coloured by f."""
    if scale not in ("linear", "log"):
        raise UsageError(f"scale must be 'linear' or 'log', got {scale!r}")
    sc = resolve(scene_or_surface, material, seed)
    bins = Bins(int(n_theta), int(n_phi), folded=True)
    res = simulate(sc.surface, sc.ior, theta_i, rays=int(rays), bins=bins, seed=int(seed))
    sim = res.brdf[0]
    cos_o = np.cos(np.radians(bins.theta_centers))[:, None]
    model = None
    if sc.ndf is not None:
        shadow = shadowing or _default_shadowing(sc.surface)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            model = predict(
                {"ts": TorranceSparrow(sc.ndf, shadow, sc.ior)},
                [theta_i],
                bins,
                rtol=1e-2,
            )["ts"][0]
    # the smooth model sets the scale (a noisy bin near the pole, tiny Ω, would set it otherwise)
    peak = float(np.max((sim if model is None else model) * cos_o))
    peak = peak if peak > 0 else 1.0
    r_sim, phi = _full_circle(_lobe_radius(sim * cos_o, peak, scale), bins)
    wi = spherical_deg(theta_i, 0.0)
    shape = (1, 2) if model is not None else (1, 1)
    p = plotter(shape, window_size, off_screen)
    radius_txt = (
        "radius = f·cosθo / peak"
        if scale == "linear"
        else "radius = log10(1 + 1000 f·cosθo/peak), 3 decades"
    )
    _simulation_panel(p, sc.name, res, bins, model, r_sim, phi, theta_i)
    _directions(p, wi)
    scale_from = "model" if model is not None else "simulation"
    p.add_text(
        ascii_text(
            f"{radius_txt}; peak of the {scale_from}"
            f" f·cosθo = {peak:.3g} 1/sr\ngold: incident, grey: mirror"
        ),
        position="lower_left",
        font_size=text_size(p, 10),
        color="black",
    )
    side_camera(p, 20.0, -20.0, 1.3)
    if model is not None:
        r_mod, _ = _full_circle(_lobe_radius(model * cos_o, peak, scale), bins)
        caption = f"{type(sc.ndf).__name__} NDF, {shadow} G"
        _model_panel(p, polar_surface(r_mod, bins.theta_centers, phi), caption, wi)
    return p
