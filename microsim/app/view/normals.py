"""The normals view: the facet-normal distribution (projected-area weighted) against the
scene's NDF, as a polar surface and as tilt densities."""

from __future__ import annotations

import numpy as np

from microsim.vectors import spherical_deg

from .common import (
    COLOURS,
    WINDOW,
    plotter,
    polar_surface,
    pyvista,
    resolve,
    scalar_bar,
    side_camera,
    tilt_deg,
    title,
)

__all__ = ["view_normals"]


def _normal_histogram(surface, theta_max: float, n_theta: int, n_phi: int):
    """Projected-area weighted facet-normal density D(h) (sr⁻¹) on a (θ, φ) grid to theta_max
    (degrees): Σ w / (W Ω_cell cos θ) since the weighted normals sample D(h)(h·n). Azimuth-
    averaged surfaces (V-grooves) are histogrammed in θ only and spread over φ."""
    nrm = surface.facet_normals()
    w = surface.projected_areas()
    th = tilt_deg(nrm)
    t_edges = np.linspace(0.0, theta_max, n_theta + 1)
    p_edges = np.linspace(0.0, 360.0, n_phi + 1)
    phi = np.degrees(np.arctan2(nrm[:, 1], nrm[:, 0])) % 360.0
    if surface.azimuth_average:
        ht, _ = np.histogram(th, t_edges, weights=w)
        hist = np.repeat(ht[:, None] / n_phi, n_phi, axis=1)
    else:
        hist, _, _ = np.histogram2d(th, phi, [t_edges, p_edges], weights=w)
    t = np.radians(t_edges)
    omega = (np.cos(t[:-1]) - np.cos(t[1:]))[:, None] * np.radians(np.diff(p_edges))[None, :]
    tc = np.radians(0.5 * (t_edges[1:] + t_edges[:-1]))
    D = hist / (w.sum() * omega * np.cos(tc)[:, None])
    return D, t_edges, p_edges, th, w


def _model_note(sc) -> str:
    """What the facet normals are drawn against (the title's second line)."""
    if sc.ndf is not None:
        return f"vs NDF {type(sc.ndf).__name__} (green wireframe)"
    if sc.surface.tilt_ndf is not None:
        return (
            "no NDF density: oriented grooves' normals\nlie in one plane "
            f"(tilts vs {type(sc.surface.tilt_ndf).__name__}'s)"
        )
    return "no analytic NDF: facets only"


def view_normals(
    scene_or_surface,
    n_theta: int = 30,
    n_phi: int = 36,
    material=None,
    seed=None,
    off_screen=None,
    window_size=WINDOW,
):
    """Facet-normal distribution (projected-area weighted; azimuth-averaged for V-grooves) as a
    polar surface of D(h)·cos θh (per solid angle; radius and colour), with the scene's NDF
    D(θh, φh) (anisotropic too) as a green wireframe on the same grid, beside the tilt densities
    2π D cos θ sin θ (per degree; for an anisotropic NDF its azimuth integral). Oriented grooves
    have no density of normals (they lie in one plane): their tilts are compared with the tilt
    density the grooves sample (``Surface.tilt_ndf``), and the title says so."""
    sc = resolve(scene_or_surface, material, seed)
    th_all = tilt_deg(sc.surface.facet_normals())
    theta_max = float(min(90.0, max(1.3 * np.quantile(th_all, 0.999), 1.0)))
    D, t_edges, p_edges, th, w = _normal_histogram(sc.surface, theta_max, n_theta, n_phi)
    tc = 0.5 * (t_edges[1:] + t_edges[:-1])
    pc = 0.5 * (p_edges[1:] + p_edges[:-1])
    cos_c = np.cos(np.radians(tc))[:, None]
    ndf_D = None if sc.ndf is None else sc.ndf.D(spherical_deg(tc[:, None], pc[None, :]))
    peak = float(
        np.max(D * cos_c) if ndf_D is None else max(np.max(D * cos_c), np.max(ndf_D * cos_c))
    )
    peak = peak if peak > 0 else 1.0
    p = plotter((1, 2), window_size, off_screen)
    scale_t = 90.0 / theta_max  # stretch θ so the lobe fills the plot
    g = polar_surface(D * cos_c / peak, np.minimum(tc * scale_t, 90.0), pc, D * cos_c, "pdf")
    p.add_mesh(
        g, scalars="pdf", cmap="viridis", scalar_bar_args=scalar_bar("facets: D(h) cos θh (1/sr)")
    )
    if ndf_D is not None:
        m = polar_surface(ndf_D * cos_c / peak, np.minimum(tc * scale_t, 90.0), pc)
        p.add_mesh(m, style="wireframe", color=COLOURS.model, line_width=1.5)
    avg = " (azimuth-averaged grooves)" if sc.surface.azimuth_average else ""
    title(
        p,
        f"{sc.name}: facet normals{avg} (surface)\n{_model_note(sc)}"
        f"\nradius: D cos θh / peak\npolar angle stretched ×{scale_t:.3g} "
        f"(θh ≤ {theta_max:.3g}°)",
    )
    side_camera(p, 20.0, -30.0, 1.2)
    p.subplot(0, 1)
    pv = pyvista()
    chart = pv.Chart2D(x_label="tilt theta_h (deg)", y_label="density per degree")
    edges = np.linspace(0.0, theta_max, 2 * n_theta + 1)
    hist, _ = np.histogram(th, edges, weights=w)
    mid = 0.5 * (edges[1:] + edges[:-1])
    width = np.diff(edges)
    chart.line(mid, hist / (w.sum() * width), color="black", width=2.5, label="facets")
    tilts = sc.ndf if sc.ndf is not None else sc.surface.tilt_ndf
    if tilts is not None:
        expected = np.diff(np.asarray(tilts.cdf_theta_rad(np.radians(edges)))) / width
        chart.line(
            mid,
            expected,
            color=COLOURS.model,
            width=2.5,
            style="--",
            label=f"{type(tilts).__name__} tilts (bin average)",
        )
    chart.title = "projected-area weighted tilt density 2 pi D cos(theta) sin(theta)"
    p.add_chart(chart)
    return p
