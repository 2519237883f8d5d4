"""The disk view: Edwards' halfway-vector disk (Edwards et al. 2006, Fig. 13) for one viewing
direction — simulated half vectors in the scaling and the orthogonal projection against
contours of the Edwards data-fitting BRDF fitted to them (``analysis.fits.fit_edwards_disk``,
Edwards et al. 2006, eq. 34–36)."""

from __future__ import annotations

import numpy as np

from microsim.vectors import normalize, spherical_deg

from ... import analytic as an
from ...analysis.fits import DiskFit, fit_edwards_disk
from ...sim import LEDGER, ray_events
from .common import (
    DISK_VIEW,
    WINDOW,
    ascii_text,
    colour_key,
    plotter,
    pyvista,
    resolve,
    text_size,
    title,
)

__all__ = ["view_disk"]

CONTOUR_LEVELS = (0.02, 0.1, 0.3, 0.6, 0.9)
CONTOUR_COLOURS = ("#1f57c4", "#17becf", "#2ca02c", "#ff7f0e", "#d62728")


def _disk_model_density(fit: DiskFit, wo: np.ndarray, projection: str, n: int = 201):
    """(U, V, density) of the fitted BRDF on the disk of ``wo`` in ``projection`` (per unit area):
    the orthogonal BRDF is the density itself; in the scaling projection p = f cos θi / J."""
    c = an.disk_centre(wo)
    u = np.linspace(-1.0, 1.0, n)
    U, V = np.meshgrid(c[0] + u, c[1] + u, indexing="ij")
    uv = np.stack([U, V], axis=-1)
    inside = (U - c[0]) ** 2 + (V - c[1]) ** 2 < 1.0
    wi = an.disk_to_incident(wo, uv, projection)
    wi = wi / np.linalg.norm(wi, axis=-1, keepdims=True)
    f = an.edwards_fit_brdf(wi, wo, fit.params, "orthogonal")
    d = an.brdf_to_disk_density(wi, wo, f, projection)
    return U, V, np.where(inside & (wi[..., 2] > 0), d, 0.0)


def _disk_panel(p, fit, wo, uv, projection: str) -> None:
    """One projection's view: the half vectors ``uv`` as points, contours of ``fit``'s density,
    the unit disk, its centre and the mirror point, and the title."""
    pv = pyvista()
    c = an.disk_centre(wo)
    p.add_mesh(
        pv.PolyData(np.column_stack([uv, np.zeros(len(uv))])),
        color="black",
        point_size=3,
        render_points_as_spheres=False,
    )
    U, V, d = _disk_model_density(fit, wo, projection)
    img = pv.StructuredGrid(U, V, np.zeros_like(U))
    img.point_data["density"] = d.ravel(order="F")
    top = float(d.max())
    for frac, colour in zip(CONTOUR_LEVELS, CONTOUR_COLOURS):
        cont = img.contour(isosurfaces=[frac * top], scalars="density") if top > 0 else None
        if cont is not None and cont.n_points:
            p.add_mesh(cont, color=colour, line_width=3)
    p.add_mesh(
        pv.Circle(radius=1.0, resolution=200).translate((c[0], c[1], 0)).extract_feature_edges(),
        color="#555555",
        line_width=2,
    )
    for point, colour in (((c[0], c[1], 0.0), "#1f57c4"), ((0.0, 0.0, 0.0), "#d62728")):
        p.add_mesh(
            pv.PolyData(np.array([point])),
            color=colour,
            point_size=14,
            render_points_as_spheres=True,
        )
    where = "retro-reflection" if projection == "scaling" else "wi = n"
    title(
        p,
        f"{projection} projection (Edwards eq. {15 if projection == 'scaling' else 22})"
        f"\nblue: disk centre ({where})\nred: (u,v) = 0 (mirror)",
    )


def _disk_camera(p) -> None:
    """Looking down on the disk, in parallel projection, with room below the unit disk for the
    colour key and the fit's text (lower corners)."""
    p.view_xy()
    p.enable_parallel_projection()
    p.reset_camera()
    cam = p.camera
    fx, fy, fz = cam.focal_point
    px, py, pz = cam.position
    cam.focal_point, cam.position = (fx, fy - 0.28, fz), (px, py - 0.28, pz)
    cam.zoom(0.95)


def view_disk(
    scene_or_surface,
    theta_o: float = DISK_VIEW.theta,
    rays: int = DISK_VIEW.rays,
    points: int = 3000,
    material=None,
    seed=0,
    off_screen=None,
    window_size=WINDOW,
):
    """Edwards' halfway-vector disk (Edwards Fig. 13) for the viewing direction θo (degrees,
    φo = 0): half vectors of simulated single-bounce escaping rays in the scaling (eq. 15) and the
    orthogonal (eq. 22) projection, on the unit disk centred at ``disk_centre(wo)``, against
    contours of the fitted Edwards data-fitting BRDF (eq. 36).

    Roles are swapped: the single-bounce BRDF is reciprocal, so the simulation is run with its
    *incident* direction at wo; each escaping ray's direction plays wi, and its half vector
    normalize(wi + wo) is the facet normal it reflected from."""
    sc = resolve(scene_or_surface, material, seed)
    ev = ray_events(sc.surface, sc.ior, theta_o, rays=int(rays), seed=int(seed))
    wo = spherical_deg(theta_o, 0.0)
    single = ev.status == LEDGER.index("single")
    wi = ev.wo[single]
    h = normalize(wi + wo)
    uv_o = an.orthogonal_projection(wo, h)
    fit = fit_edwards_disk(wo, uv_o, ev.weight[single], int(rays))
    rng = np.random.default_rng(seed)
    show = rng.permutation(len(h))[: int(points)]
    p = plotter((1, 2), window_size, off_screen)
    for col, projection in enumerate(("scaling", "orthogonal")):
        p.subplot(0, col)
        _disk_panel(p, fit, wo, an.disk_projection(wo, h[show], projection), projection)
        if col == 1:
            colour_key(
                p,
                [
                    (f"fitted BRDF density: {100 * f:g}% of its peak", c_)
                    for f, c_ in zip(CONTOUR_LEVELS, CONTOUR_COLOURS)
                ],
            )
        _disk_camera(p)
    q = fit.params
    p.subplot(0, 0)
    p.add_text(
        ascii_text(
            f"{sc.name}, viewer θo = {theta_o:g}°\n{len(h)} single-bounce rays "
            f"of {int(rays)} ({len(show)} shown)\n"
            f"Edwards fit (eq. 36, orthogonal disk):\n"
            f"F(θo) = {q.f0:.3f}, k = {q.k:.2f}, C_d = 0\n"
            f"lump 1: r = {q.r1:.3g}, n = {q.n1:.3g}\nlump 2: r = {q.r2:.3g}, "
            f"n = {q.n2:.3g}"
        ),
        position="lower_left",
        font_size=text_size(p, 10),
        color="black",
    )
    return p
