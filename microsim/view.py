"""Visual inspection of scenes with pyvista: surface, ray paths, BRDF lobe, halfway disk, normals.

    microsim view SCENE.toml [--what surface|rays|lobe|disk|normals] [--theta-i DEG]
                             [--screenshot PNG] [--size WxH] [--rays N] [--seed S]

From Python (notebooks) every view returns a ``pyvista.Plotter``; call ``.show()`` or
``.screenshot(path)`` on it::

    from microsim import view
    view.view_lobe("surfaces/gaussian-m0.3.toml", theta_i=60).show()

Views (local frame, macro normal +z; angles in degrees; BRDFs in sr⁻¹):
  surface  the tile's mesh coloured by height or facet slope, the displayed region outlined. A
           V-groove tile of thousands of grooves is shown as a zoomed section of a few dozen
           grooves (the title says so): the surface is the extruded profile, so a section is exact.
  rays     a few hundred sampled paths at one incidence: incident segments, single-bounce
           escaping rays, masked rays (reflected up but blocked) and downward (multi-bounce) rays.
  lobe     the simulated single-bounce BRDF as a 3D polar surface (radius f·cos θo or log-scaled)
           beside the model's (Torrance–Sparrow with the scene's NDF; V-groove G on V-grooves,
           height-correlated Smith on heightfields), coloured by z = (sim − model)/σ.
  disk     Edwards' halfway-vector disk (Edwards Fig. 13) for one viewing direction: simulated
           half vectors in the scaling and the orthogonal projection against contours of a fitted
           Edwards data-fitting BRDF (Edwards eq. 34–36).
  normals  the facet-normal distribution (projected-area weighted) against the scene's NDF.

Headless: with no DISPLAY every view renders off screen (VTK's EGL window, Mesa's libEGL);
without ``--screenshot`` the image goes to ``microsim-view-<scene>-<what>.png``.
"""
from __future__ import annotations

from microsim.errors import UsageError
import argparse
import os
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["VIEWS", "view", "view_surface", "view_rays", "view_lobe", "view_disk",
           "view_normals", "add_view_command", "main", "headless", "fit_edwards_disk"]

VIEWS = ("surface", "rays", "lobe", "disk", "normals")
DEFAULT_THETA = {"surface": 0.0, "rays": 60.0, "lobe": 30.0, "disk": 30.0, "normals": 0.0}
DEFAULT_RAYS = {"rays": 300, "lobe": 200_000, "disk": 100_000}
WINDOW = (1200, 800)
BACKGROUND = "white"
CONTOUR_LEVELS = (0.02, 0.1, 0.3, 0.6, 0.9)
CONTOUR_COLOURS = ("#1f57c4", "#17becf", "#2ca02c", "#ff7f0e", "#d62728")
COLOURS = {"incident": "#e6a100", "single": "#2ca02c", "masked": "#d62728",
           "downward": "#1f57c4", "model": "#2ca02c", "mirror": "#444444", "outline": "black"}


# --- set-up --------------------------------------------------------------------------------------
def headless() -> bool:
    """True on Linux without an X or Wayland display (render off screen)."""
    return sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                     or os.environ.get("WAYLAND_DISPLAY"))


def _pyvista():
    """Import pyvista; headless, select VTK's EGL window first (else VTK tries X and warns)."""
    if headless() and "vtkmodules" not in sys.modules:
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv
    return pv


def _plotter(shape=(1, 1), window_size=WINDOW, off_screen=None):
    pv = _pyvista()
    off = headless() if off_screen is None else bool(off_screen)
    p = pv.Plotter(shape=shape, window_size=tuple(int(s) for s in window_size), off_screen=off,
                   border=False)
    p.set_background(BACKGROUND)
    return p


@dataclass(frozen=True)
class _Scene:
    """What a view needs: the surface, material, analytic NDF (or None) and a display name."""

    surface: object
    ior: object
    ndf: object
    name: str


def _resolve(scene_or_surface, material=None, seed=None) -> _Scene:
    """Accept a scene path, a ``Scene`` or a ``Surface`` (then ``material``: default mirror)."""
    from .scene import Scene, load_scene
    from .surfaces import Surface
    obj = scene_or_surface
    if isinstance(obj, (str, Path)):
        obj = load_scene(obj)
    if isinstance(obj, Scene):
        with warnings.catch_warnings():            # generator caveats: printed by `surface`
            warnings.simplefilter("ignore")
            surf = obj.build_surface(seed=seed)
        ior = obj.ior if material is None else material
        return _Scene(surf, ior, obj.ndf(), obj.name)
    if isinstance(obj, Surface):
        return _Scene(obj, material, obj.source_ndf, obj.kind)
    raise UsageError("scene_or_surface must be a scene file path, a microsim.scene.Scene or a "
                     f"microsim.surfaces.Surface, got {type(obj).__name__}")


def _faces_pv(faces: np.ndarray) -> np.ndarray:
    f = np.asarray(faces, dtype=np.int64)
    return np.hstack([np.full((len(f), 1), 3), f]).ravel()


_ASCII = str.maketrans({"θ": "theta_", "φ": "phi_", "σ": "sigma", "π": "pi", "×": "x",
                        "≤": "<=", "−": "-", "–": "-", "·": "*"})


def _ascii(text: str) -> str:
    """VTK's built-in fonts lack Greek letters and maths symbols: spell them out."""
    return text.translate(_ASCII).replace("_ ", " ").replace("_=", " =")


def _title(p, text: str, size: int = 8) -> None:
    p.add_text(_ascii(text), position="upper_edge", font_size=size, color="black")


def _key(p, items, size: int = 10, bottom: int = 8) -> None:
    """Colour key: one line of text per (label, colour), stacked up from the lower left corner
    of the current viewport (pixel offsets; pyvista legends misplace themselves in subplots)."""
    for k, (label, colour) in enumerate(reversed(list(items))):
        p.add_text(_ascii(label), position=(10, bottom + int(2.0 * size) * k), font_size=size,
                   color=colour)


def _bar(title: str, **extra) -> dict:
    return {"title": _ascii(title), "color": "black", "title_font_size": 14,
            "label_font_size": 12, **extra}


# --- geometry shown ------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Section:
    """The displayed part of a surface: vertices/faces in tile coordinates, the xy window
    [x0, x1] × [y0, y1] it covers and a note for the title."""

    vertices: np.ndarray
    faces: np.ndarray
    window: tuple[float, float, float, float]
    note: str


def _section(surface, grooves: int = 16, length: float = 0.5) -> _Section:
    """Whole tile, or for V-grooves with more than ``grooves`` grooves a central section of
    ``grooves`` grooves, its groove length cut to ``length`` × the section's width (exact: the
    surface is an extruded profile; faces 4k … 4k+3 belong to groove k)."""
    lx, ly = surface.tile_size
    n = len(surface.faces) // 4
    if surface.kind != "vgrooves" or n <= grooves:
        return _Section(surface.vertices, surface.faces, (-lx / 2, lx / 2, -ly / 2, ly / 2),
                        "whole periodic tile outlined")
    k0 = (n - grooves) // 2
    f = surface.faces[4 * k0: 4 * (k0 + grooves)]
    used, inv = np.unique(f, return_inverse=True)
    v = surface.vertices[used].copy()
    half = 0.5 * length * (v[:, 0].max() - v[:, 0].min())
    v[:, 1] = np.sign(v[:, 1]) * half                  # cut the grooves' length to the width
    return _Section(v, inv.reshape(-1, 3).astype(np.int64),
                    (v[:, 0].min(), v[:, 0].max(), -half, half),
                    f"zoomed section: {grooves} of {n} grooves, groove length cut (the profile is extruded)")


def _section_mesh(sec: _Section):
    pv = _pyvista()
    return pv.PolyData(sec.vertices, _faces_pv(sec.faces))


def _outline(window, z: float):
    pv = _pyvista()
    x0, x1, y0, y1 = window
    pts = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z], [x0, y0, z]])
    return pv.lines_from_points(pts)


def _tilt_deg(normals: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(normals[:, 2], -1.0, 1.0)))


# --- surface -------------------------------------------------------------------------------------
def view_surface(scene_or_surface, color: str = "slope", grooves: int = 16, material=None,
                 seed=None, off_screen=None, window_size=WINDOW):
    """The tile's mesh coloured by ``color`` = "height" (z, length units) or "slope" (facet tilt
    θ in degrees), with the displayed region outlined; V-grooves as a section of ``grooves``."""
    if color not in ("height", "slope"):
        raise UsageError(f"color must be 'height' or 'slope', got {color!r}")
    sc = _resolve(scene_or_surface, material, seed)
    sec = _section(sc.surface, int(grooves))
    mesh = _section_mesh(sec)
    p = _plotter(window_size=window_size, off_screen=off_screen)
    if color == "height":
        mesh.point_data["height"] = sec.vertices[:, 2]
        p.add_mesh(mesh, scalars="height", cmap="viridis",
                   scalar_bar_args=_bar("height z"))
    else:
        v, f = sec.vertices, sec.faces
        c = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        mesh.cell_data["slope (deg)"] = _tilt_deg(c / np.linalg.norm(c, axis=1, keepdims=True))
        p.add_mesh(mesh, scalars="slope (deg)", cmap="magma",
                   scalar_bar_args=_bar("facet tilt θ (deg)"))
    p.add_mesh(_outline(sec.window, float(sec.vertices[:, 2].max())), color=COLOURS["outline"],
               line_width=3)
    _title(p, f"{sc.name}: surface coloured by {color}\n{sec.note}")
    _side_camera(p, 20.0 if sc.surface.kind == "vgrooves" else 50.0)
    return p


# --- rays ----------------------------------------------------------------------------------------
SINGLE, MASKED, DOWNWARD = "single", "masked", "downward"


@dataclass(frozen=True)
class RayPaths:
    """Sampled paths (unwrapped coordinates): ``hit`` (N, 3) first hit, ``wi`` (3,), ``wo``
    (N, 3) reflected direction, ``status`` (N,) of "single" | "masked" | "downward" |
    "unresolved", ``end`` (N, 3) second hit of masked/downward rays (NaN otherwise)."""

    hit: np.ndarray
    wi: np.ndarray
    wo: np.ndarray
    status: np.ndarray
    end: np.ndarray


def trace_paths(surface, theta_i: float, phi_i: float = 0.0, rays: int = 300, seed: int = 0,
                window=None) -> RayPaths:
    """Trace ``rays`` primary rays from direction (θi, φi) (degrees) aimed uniformly at the
    central 60% of ``window`` (x0, x1, y0, y1; default the tile) and classify them as the
    estimator does (single / masked / downward), with the public ``Tracer`` API (the estimator's
    ray origins and groove azimuths are private, so the hit points are traced here; for
    V-grooves the groove azimuth is not randomised: φi is relative to the grooves' normal
    plane, 0° = across the grooves)."""
    from .analytic._checks import spherical_deg
    from .sim import Tracer
    from .sim.tracer import ESCAPED, HIT
    tracer = Tracer(surface)
    lx, ly = surface.tile_size
    x0, x1, y0, y1 = window if window is not None else (-lx / 2, lx / 2, -ly / 2, ly / 2)
    rng = np.random.default_rng(seed)
    n = int(rays)
    cx, cy, wx, wy = (x0 + x1) / 2, (y0 + y1) / 2, 0.6 * (x1 - x0), 0.6 * (y1 - y0)
    target = np.stack([cx + (rng.random(n) - 0.5) * wx, cy + (rng.random(n) - 0.5) * wy,
                       np.full(n, 0.5 * (tracer.zmin + tracer.zmax))], axis=1)
    wi = spherical_deg(theta_i, phi_i)
    top = tracer.zmax + tracer.top_margin
    origins = target + wi * ((top - target[:, 2]) / wi[2])[:, None]
    hits = tracer.first_hit(origins, -wi)
    ok = hits.status == HIT
    origins, p_tile, nrm = origins[ok], hits.point[ok], hits.normal[ok]
    hit = origins - wi * ((origins[:, 2] - p_tile[:, 2]) / wi[2])[:, None]   # unwrapped
    c = nrm @ wi
    wo = 2.0 * c[:, None] * nrm - wi
    status = np.full(len(hit), "unresolved", dtype=object)
    up = wo[:, 2] > 0
    status[~up] = DOWNWARD
    esc = tracer.escapes(p_tile[up], nrm[up], wo[up])
    status[np.flatnonzero(up)[esc == ESCAPED]] = SINGLE
    status[np.flatnonzero(up)[esc == HIT]] = MASKED
    end = np.full_like(hit, np.nan)
    sec = np.flatnonzero((status == MASKED) | (status == DOWNWARD))
    if sec.size:
        h2 = tracer.first_hit(p_tile[sec] + tracer.eps * nrm[sec], wo[sec])
        good = (h2.status == HIT) & (np.abs(wo[sec, 2]) > 1e-9)
        t = (h2.point[good, 2] - p_tile[sec[good], 2]) / wo[sec[good], 2]
        end[sec[good]] = hit[sec[good]] + t[:, None] * wo[sec[good]]
    return RayPaths(hit=hit, wi=wi, wo=wo, status=status.astype(str), end=end)


def _segments(a: np.ndarray, b: np.ndarray):
    """PolyData of line segments a[k] → b[k] (both (N, 3))."""
    pv = _pyvista()
    n = len(a)
    pts = np.empty((2 * n, 3))
    pts[0::2], pts[1::2] = a, b
    lines = np.column_stack([np.full(n, 2), 2 * np.arange(n), 2 * np.arange(n) + 1]).ravel()
    return pv.PolyData(pts, lines=lines)


def view_rays(scene_or_surface, theta_i: float = DEFAULT_THETA["rays"], phi_i: float = 0.0,
              rays: int = DEFAULT_RAYS["rays"], grooves: int = 12, material=None, seed=0,
              off_screen=None, window_size=WINDOW):
    """A few hundred ray paths at incidence (θi, φi) (degrees) over the displayed section:
    incident segments, single-bounce escaping rays, masked and downward (multi-bounce) rays."""
    sc = _resolve(scene_or_surface, material, seed)
    sec = _section(sc.surface, int(grooves))
    x0, x1, y0, y1 = sec.window
    if sc.surface.kind != "vgrooves":                 # heightfields: a window of ~128 cells
        span = min(x1 - x0, 128 * (sc.surface.dx or (x1 - x0)))
        sec = _crop(sc.surface, span)
        x0, x1, y0, y1 = sec.window
    paths = trace_paths(sc.surface, theta_i, phi_i, rays, seed, sec.window)
    length = 0.2 * (x1 - x0)
    p = _plotter(window_size=window_size, off_screen=off_screen)
    p.add_mesh(_section_mesh(sec), color="#c8c8c8")
    p.add_mesh(_outline(sec.window, float(sec.vertices[:, 2].max())), color="black", line_width=2)
    p.add_mesh(_segments(paths.hit + length * paths.wi, paths.hit), color=COLOURS["incident"],
               line_width=1, opacity=0.6)
    counts = {}
    key = [("incident", COLOURS["incident"])]
    for kind in (SINGLE, MASKED, DOWNWARD):
        sel = paths.status == kind
        counts[kind] = int(sel.sum())
        if not sel.any():
            continue
        end = paths.end[sel] if kind != SINGLE else paths.hit[sel] + length * paths.wo[sel]
        miss = ~np.all(np.isfinite(end), axis=1)        # second hit not resolved: fixed length
        end[miss] = paths.hit[sel][miss] + 0.2 * length * paths.wo[sel][miss]
        label = {SINGLE: "escaping (single bounce)", MASKED: "masked (blocked on the way out)",
                 DOWNWARD: "downward (multi-bounce)"}[kind]
        p.add_mesh(_segments(paths.hit[sel], end), color=COLOURS[kind],
                   line_width=1.5 if kind == SINGLE else 4, opacity=0.7 if kind == SINGLE else 1)
        key.append((f"{label}: {counts[kind]}", COLOURS[kind]))
    _key(p, key)
    _title(p, f"{sc.name}: {len(paths.hit)} rays at θi = {theta_i:g}°, φi = {phi_i:g}°"
              f"{' (across the grooves)' if sc.surface.kind == 'vgrooves' and phi_i == 0 else ''}"
              f"\n{sec.note}")
    _side_camera(p, 8.0, -10.0, 1.3)
    return p


def _side_camera(p, elevation: float = 25.0, azimuth: float = -30.0, zoom: float = 1.0) -> None:
    """Look at the xz plane (the plane of incidence, φ = 0) from −y, raised by ``elevation``
    and turned by ``azimuth`` degrees."""
    p.view_xz()
    p.camera.elevation = elevation
    p.camera.azimuth = azimuth
    p.reset_camera()
    p.camera.zoom(zoom)


def _crop(surface, span: float) -> _Section:
    """Central square window of side ``span`` of a heightfield tile (faces by centroid)."""
    lx, ly = surface.tile_size
    if span >= min(lx, ly):
        return _Section(surface.vertices, surface.faces, (-lx / 2, lx / 2, -ly / 2, ly / 2),
                        "whole periodic tile outlined")
    cen = surface.vertices[surface.faces].mean(axis=1)
    keep = np.all(np.abs(cen[:, :2]) < span / 2, axis=1)
    used, inv = np.unique(surface.faces[keep], return_inverse=True)
    v = surface.vertices[used]
    return _Section(v, inv.reshape(-1, 3).astype(np.int64),
                    (v[:, 0].min(), v[:, 0].max(), v[:, 1].min(), v[:, 1].max()),
                    f"zoomed section: {span:g} × {span:g} of the {lx:g} × {ly:g} tile")


# --- lobe ----------------------------------------------------------------------------------------
def _default_shadowing(surface) -> str:
    return "vgroove" if surface.kind == "vgrooves" else "smith-correlated"


def _full_circle(values: np.ndarray, bins) -> tuple[np.ndarray, np.ndarray]:
    """Folded (Θ, Φ) values → full azimuth (Θ, 2Φ − 2) and their Δφ (deg), mirrored (isotropy)."""
    phi = bins.phi_centers
    full_phi = np.concatenate([phi, 360.0 - phi[-2:0:-1]])
    full = np.concatenate([values, values[:, -2:0:-1]], axis=1)
    return full, full_phi


def _polar_surface(radius: np.ndarray, theta_deg: np.ndarray, phi_deg: np.ndarray,
                   scalars: np.ndarray | None = None, name: str = "value"):
    """StructuredGrid of the polar surface r(θ, φ) (closed in φ, capped at the pole)."""
    pv = _pyvista()
    th = np.radians(np.concatenate([[0.0], theta_deg]))
    ph = np.radians(np.concatenate([phi_deg, [phi_deg[0] + 360.0]]))
    r = np.concatenate([np.full((1, radius.shape[1]), radius[0].mean()), radius])
    r = np.concatenate([r, r[:, :1]], axis=1)
    T, P = np.meshgrid(th, ph, indexing="ij")
    g = pv.StructuredGrid(r * np.sin(T) * np.cos(P), r * np.sin(T) * np.sin(P), r * np.cos(T))
    if scalars is not None:
        s = np.concatenate([np.full((1, scalars.shape[1]), np.nanmean(scalars[0])), scalars])
        s = np.concatenate([s, s[:, :1]], axis=1)
        g.point_data[name] = s.ravel(order="F")
    return g


def _lobe_radius(fcos: np.ndarray, peak: float, scale: str) -> np.ndarray:
    """Radius of the polar plot: f cos θo / peak (linear) or log10(1 + 1000 f cos θo / peak)/3
    (log: 3 decades), so that the peak has radius 1 in either case."""
    x = np.maximum(fcos, 0.0) / peak
    return x if scale == "linear" else np.log10(1.0 + 1000.0 * x) / np.log10(1001.0)


def lobe_z(sim: np.ndarray, stderr: np.ndarray, model: np.ndarray, omega: np.ndarray,
           rays: int, mean_weight: float) -> np.ndarray:
    """z = (sim − model)/σ per bin; bins without any ray (σ = 0) use the Poisson error the model
    predicts, √(model · w̄ / (N Ω)) with w̄ the mean Fresnel weight; 0 where both vanish."""
    se_model = np.sqrt(np.maximum(model, 0.0) * mean_weight / (rays * omega))
    se = np.where(stderr > 0, stderr, se_model)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(se > 0, (sim - model) / se, 0.0)


def _directions(p, wi: np.ndarray, length: float = 1.25) -> None:
    """Incident (gold) and mirror (dark grey) directions as arrows from the origin, plus the
    horizon circle for scale."""
    pv = _pyvista()
    mirror = np.array([-wi[0], -wi[1], wi[2]])
    for w, col in ((wi, COLOURS["incident"]), (mirror, COLOURS["mirror"])):
        p.add_mesh(pv.Arrow(start=(0, 0, 0), direction=w, scale=length, tip_length=0.12, tip_radius=0.04,
                            shaft_radius=0.012), color=col)
    p.add_mesh(pv.Circle(radius=1.0, resolution=120).extract_feature_edges(), color="#999999",
               line_width=1)


def view_lobe(scene_or_surface, theta_i: float = DEFAULT_THETA["lobe"],
              rays: int = DEFAULT_RAYS["lobe"], scale: str = "linear", shadowing: str | None = None,
              n_theta: int = 30, n_phi: int = 25, material=None, seed=0, off_screen=None,
              window_size=WINDOW):
    """Simulated BRDF at θi (degrees) as a polar surface (radius f·cos θo, linear or log —
    ``scale``) beside the Torrance–Sparrow model with the scene's NDF (``shadowing`` default:
    "vgroove" on V-grooves, "smith-correlated" on heightfields) on the same folded bins; the
    simulation is coloured by z = (sim − model)/σ, the model drawn in green. Without an NDF
    (flat, file) only the simulation is drawn, coloured by f."""
    from .sim import Bins, simulate
    from .sim.predict import ModelSpec, predict
    from .analytic._checks import spherical_deg
    if scale not in ("linear", "log"):
        raise UsageError(f"scale must be 'linear' or 'log', got {scale!r}")
    sc = _resolve(scene_or_surface, material, seed)
    bins = Bins(int(n_theta), int(n_phi), folded=True)
    res = simulate(sc.surface, sc.ior, theta_i, rays=int(rays), bins=bins, seed=int(seed))
    sim, se = res.brdf[0], res.stderr[0]
    cos_o = np.cos(np.radians(bins.theta_centers))[:, None]
    model = None
    if sc.ndf is not None:
        shadow = shadowing or _default_shadowing(sc.surface)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            model = predict([ModelSpec.torrance_sparrow("ts", sc.ndf, shadow, sc.ior)],
                            [theta_i], bins, rtol=1e-2)["ts"][0]
    # the smooth model sets the scale (a noisy bin near the pole, tiny Ω, would set it otherwise)
    peak = float(np.max((sim if model is None else model) * cos_o))
    peak = peak if peak > 0 else 1.0
    r_sim, phi = _full_circle(_lobe_radius(sim * cos_o, peak, scale), bins)
    wi = spherical_deg(theta_i, 0.0)
    shape = (1, 2) if model is not None else (1, 1)
    p = _plotter(shape, window_size, off_screen)
    radius_txt = ("radius = f·cosθo / peak" if scale == "linear"
                  else "radius = log10(1 + 1000 f·cosθo/peak), 3 decades")
    if model is not None:
        single = res.ledger_counts["single"][0]
        w_mean = res.ledger["single_fresnel"][0] * res.rays[0] / max(single, 1)
        z = lobe_z(sim, se, model, bins.projected_solid_angle(), int(res.rays[0]), w_mean)
        z_full, _ = _full_circle(z, bins)
        g = _polar_surface(r_sim, bins.theta_centers, phi, np.clip(z_full, -5, 5), "z")
        p.add_mesh(g, scalars="z", cmap="coolwarm", clim=(-5, 5), smooth_shading=True,
                   scalar_bar_args=_bar("z = (sim − model)/σ", vertical=False, position_x=0.3,
                                        position_y=0.1, width=0.6, height=0.08))
        _title(p, f"{sc.name}: simulation\nθi = {theta_i:g}°, {int(res.rays[0])} rays, "
                  f"coloured by z\n(clipped to ±5; largest abs(z) = {np.max(np.abs(z)):.1f})")
    else:
        g = _polar_surface(r_sim, bins.theta_centers, phi, _full_circle(sim, bins)[0], "f")
        p.add_mesh(g, scalars="f", cmap="viridis",
                   scalar_bar_args=_bar("f (1/sr)"))
        _title(p, f"{sc.name}: simulated BRDF\nθi = {theta_i:g}°, {int(res.rays[0])} rays "
                  "(no analytic NDF: no model)")
    _directions(p, wi)
    p.add_text(_ascii(f"{radius_txt}; peak of the {'model' if model is not None else 'simulation'}"
                      f" f·cosθo = {peak:.3g} 1/sr\ngold: incident, grey: mirror"),
               position="lower_left", font_size=10, color="black")
    _side_camera(p, 20.0, -20.0, 1.3)
    if model is not None:
        p.subplot(0, 1)
        r_mod, _ = _full_circle(_lobe_radius(model * cos_o, peak, scale), bins)
        p.add_mesh(_polar_surface(r_mod, bins.theta_centers, phi), color=COLOURS["model"],
                   smooth_shading=True)
        _directions(p, wi)
        _title(p, f"model: Torrance–Sparrow\n{type(sc.ndf).__name__} NDF, {shadow} G\n"
                  "(same bins, same radius scale)")
        p.link_views()
    return p


# --- halfway disk --------------------------------------------------------------------------------
@dataclass(frozen=True)
class DiskFit:
    """Edwards data-fitting BRDF fitted at one viewing direction (orthogonal projection).

    ``params`` (``EdwardsParams``: cd = 0, f0 = f90 = F(θo) since at a single θo only the product
    F·p is identifiable), ``grid_uv`` (M, 2) cell centres, ``density`` (M,) simulated disk density
    per unit area (= f, Edwards eq. 24), ``cost`` (½Σ residual², residuals in standard errors)."""

    params: object
    grid_uv: np.ndarray
    density: np.ndarray
    cost: float


def fit_edwards_disk(wo, uv: np.ndarray, weight: np.ndarray, rays: int, cells: int = 40) -> DiskFit:
    """Least-squares fit of the Edwards data-fitting BRDF (eq. 34–36, orthogonal projection) to
    the weighted disk histogram of simulated half vectors.

    ``uv`` (K, 2) orthogonal-projection points of single-bounce escaping rays, ``weight`` (K,)
    their Fresnel weights, ``rays`` primary rays traced. Σw/N over a disk region equals
    ∫ f cos θi dω_i = ∫ f du dv (orthogonal: du dv = cos θi dω_i), so the histogram density per
    unit area is f itself. Cells: a square grid over [−R, R]² (R from the 99.5% radius of the
    points) keeping cells inside the disk; residuals are divided by the cells' standard errors.
    """
    from scipy.optimize import least_squares
    from . import analytic as an
    wo = np.asarray(wo, dtype=np.float64)
    centre = an.disk_centre(wo)
    rad = np.linalg.norm(uv, axis=1)
    R = float(min(1.0 + np.linalg.norm(centre), max(1.5 * np.quantile(rad, 0.995), 1e-3)))
    edges = np.linspace(-R, R, cells + 1)
    s, _, _ = np.histogram2d(uv[:, 0], uv[:, 1], [edges, edges], weights=weight)
    s2, _, _ = np.histogram2d(uv[:, 0], uv[:, 1], [edges, edges], weights=weight ** 2)
    area = (edges[1] - edges[0]) ** 2
    mid = 0.5 * (edges[1:] + edges[:-1])
    U, V = np.meshgrid(mid, mid, indexing="ij")
    grid = np.stack([U.ravel(), V.ravel()], axis=1)
    half_diag = (edges[1] - edges[0]) / np.sqrt(2)
    inside = np.linalg.norm(grid - centre, axis=1) + half_diag <= 1.0
    dens = (s.ravel() / (rays * area))[inside]
    var = np.maximum(s2.ravel() / rays - (s.ravel() / rays) ** 2, 0.0) / (rays - 1) / area ** 2
    floor = np.max(weight) / (rays * area)             # one ray's worth: empty cells count
    sigma = np.sqrt(var[inside] + floor ** 2)
    grid = grid[inside]
    r2 = float(np.sum(weight * np.sum(uv * uv, axis=1)) / max(np.sum(weight), 1e-300))
    r1 = 1.2 * float(np.quantile(rad, 0.99)) + 1e-3
    n1 = max(r1 * r1 / max(r2, 1e-12) - 2.0, 0.0)     # E[r²] = R²/(n+2) for the lump (eq. 26)
    F0 = float(np.sum(weight) / rays)
    lo, hi = an.EdwardsParams.bounds()
    names = an.EdwardsParams.names()
    idx = [names.index(k) for k in ("k", "r1", "n1", "r2", "n2")]
    x0 = np.array([min(max(F0, 1e-3), 1.0), 0.1, min(r1, 4.0), min(n1, 1e4), min(2 * r1, 4.0), 1.0])
    lower = np.concatenate([[0.0], lo[idx]])
    upper = np.concatenate([[1.0], hi[idx]])

    def params(x):
        return an.EdwardsParams(cd=0.0, f0=x[0], f90=x[0], k=x[1], r1=x[2], n1=x[3], r2=x[4],
                                n2=x[5])

    def resid(x):
        return (x[0] * params(x).lumps().pdf(wo, grid) - dens) / sigma

    fit = least_squares(resid, np.clip(x0, lower, upper), bounds=(lower, upper), x_scale="jac",
                        max_nfev=400)
    return DiskFit(params=params(fit.x), grid_uv=grid, density=dens, cost=float(fit.cost))


def _disk_model_density(fit: DiskFit, wo: np.ndarray, projection: str, n: int = 201):
    """(U, V, density) of the fitted BRDF on the disk of ``wo`` in ``projection`` (per unit area):
    the orthogonal BRDF is the density itself; in the scaling projection p = f cos θi / J."""
    from . import analytic as an
    c = an.disk_centre(wo)
    u = np.linspace(-1.0, 1.0, n)
    U, V = np.meshgrid(c[0] + u, c[1] + u, indexing="ij")
    uv = np.stack([U, V], axis=-1)
    inside = (U - c[0]) ** 2 + (V - c[1]) ** 2 < 1.0
    wi = an.disk_to_incident(wo, uv, projection)
    wi = wi / np.linalg.norm(wi, axis=-1, keepdims=True)
    f = an.edwards_fit_brdf(wi, wo, fit.params, "orthogonal")
    d = an.brdf_to_disk_density(f, wi, wo, projection)
    return U, V, np.where(inside & (wi[..., 2] > 0), d, 0.0)


def view_disk(scene_or_surface, theta_o: float = DEFAULT_THETA["disk"],
              rays: int = DEFAULT_RAYS["disk"], points: int = 3000, material=None, seed=0,
              off_screen=None, window_size=WINDOW):
    """Edwards' halfway-vector disk (Edwards Fig. 13) for the viewing direction θo (degrees,
    φo = 0): half vectors of simulated single-bounce escaping rays in the scaling (eq. 15) and the
    orthogonal (eq. 22) projection, on the unit disk centred at ``disk_centre(wo)``, against
    contours of the fitted Edwards data-fitting BRDF (eq. 36).

    Roles are swapped: the single-bounce BRDF is reciprocal, so the simulation is run with its
    *incident* direction at wo; each escaping ray's direction plays wi, and its half vector
    normalize(wi + wo) is the facet normal it reflected from."""
    from . import analytic as an
    from .analytic._checks import normalize, spherical_deg
    from .sim import LEDGER, ray_events
    sc = _resolve(scene_or_surface, material, seed)
    ev = ray_events(sc.surface, sc.ior, theta_o, rays=int(rays), seed=int(seed))
    wo = spherical_deg(theta_o, 0.0)
    single = ev.status == LEDGER.index("single")
    wi = ev.wo[single]
    h = normalize(wi + wo)
    uv_o = an.orthogonal_projection(wo, h)
    fit = fit_edwards_disk(wo, uv_o, ev.weight[single], int(rays))
    rng = np.random.default_rng(seed)
    show = rng.permutation(len(h))[:int(points)]
    pv = _pyvista()
    p = _plotter((1, 2), window_size, off_screen)
    c = an.disk_centre(wo)
    for col, projection in enumerate(("scaling", "orthogonal")):
        p.subplot(0, col)
        uv = an.disk_projection(wo, h[show], projection)
        p.add_mesh(pv.PolyData(np.column_stack([uv, np.zeros(len(uv))])), color="black",
                   point_size=3, render_points_as_spheres=False)
        U, V, d = _disk_model_density(fit, wo, projection)
        img = pv.StructuredGrid(U, V, np.zeros_like(U))
        img.point_data["density"] = d.ravel(order="F")
        top = float(d.max())
        for frac, colour in zip(CONTOUR_LEVELS, CONTOUR_COLOURS):
            cont = img.contour(isosurfaces=[frac * top], scalars="density") if top > 0 else None
            if cont is not None and cont.n_points:
                p.add_mesh(cont, color=colour, line_width=3)
        p.add_mesh(pv.Circle(radius=1.0, resolution=200).translate((c[0], c[1], 0))
                   .extract_feature_edges(), color="#555555", line_width=2)
        for point, colour in (((c[0], c[1], 0.0), "#1f57c4"), ((0.0, 0.0, 0.0), "#d62728")):
            p.add_mesh(pv.PolyData(np.array([point])), color=colour, point_size=14,
                       render_points_as_spheres=True)
        where = "retro-reflection" if projection == "scaling" else "wi = n"
        _title(p, f"{projection} projection (Edwards eq. {15 if projection == 'scaling' else 22})"
                  f"\nblue: disk centre ({where})\nred: (u,v) = 0 (mirror)")
        if col == 1:
            _key(p, [(f"fitted BRDF density: {100 * f:g}% of its peak", c_)
                     for f, c_ in zip(CONTOUR_LEVELS, CONTOUR_COLOURS)])
        p.view_xy()
        p.enable_parallel_projection()
        p.reset_camera()
        p.camera.zoom(1.25)
    q = fit.params
    p.subplot(0, 0)
    p.add_text(_ascii(f"{sc.name}, viewer θo = {theta_o:g}°\n{len(h)} single-bounce rays of "
                      f"{int(rays)} ({len(show)} shown)\nEdwards fit (eq. 36, orthogonal disk):\n"
                      f"F(θo) = {q.f0:.3f}, k = {q.k:.2f}, C_d = 0\n"
                      f"lump 1: r = {q.r1:.3g}, n = {q.n1:.3g}\nlump 2: r = {q.r2:.3g}, "
                      f"n = {q.n2:.3g}"), position="lower_left", font_size=10, color="black")
    return p


# --- normals -------------------------------------------------------------------------------------
def _normal_histogram(surface, theta_max: float, n_theta: int, n_phi: int):
    """Projected-area weighted facet-normal density D(h) (sr⁻¹) on a (θ, φ) grid to theta_max
    (degrees): Σ w / (W Ω_cell cos θ) since the weighted normals sample D(h)(h·n). Azimuth-
    averaged surfaces (V-grooves) are histogrammed in θ only and spread over φ."""
    nrm = surface.facet_normals()
    w = surface.projected_areas()
    th = _tilt_deg(nrm)
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


def view_normals(scene_or_surface, n_theta: int = 30, n_phi: int = 36, material=None, seed=None,
                 off_screen=None, window_size=WINDOW):
    """Facet-normal distribution (projected-area weighted; azimuth-averaged for V-grooves) as a
    polar surface of D(h)·cos θh (per solid angle; radius and colour), with the scene's NDF as a
    green wireframe on the same grid, beside the tilt densities 2π D cos θ sin θ (per degree)."""
    sc = _resolve(scene_or_surface, material, seed)
    th_all = _tilt_deg(sc.surface.facet_normals())
    theta_max = float(min(90.0, max(1.3 * np.quantile(th_all, 0.999), 1.0)))
    D, t_edges, p_edges, th, w = _normal_histogram(sc.surface, theta_max, n_theta, n_phi)
    tc = 0.5 * (t_edges[1:] + t_edges[:-1])
    pc = 0.5 * (p_edges[1:] + p_edges[:-1])
    cos_c = np.cos(np.radians(tc))[:, None]
    ndf_D = None
    if sc.ndf is not None:
        ndf_D = np.broadcast_to(np.asarray(sc.ndf.D_cos(cos_c)), D.shape)
    peak = float(np.max(D * cos_c) if ndf_D is None else max(np.max(D * cos_c),
                                                             np.max(ndf_D * cos_c)))
    peak = peak if peak > 0 else 1.0
    p = _plotter((1, 2), window_size, off_screen)
    scale_t = 90.0 / theta_max                        # stretch θ so the lobe fills the plot
    g = _polar_surface(D * cos_c / peak, np.minimum(tc * scale_t, 90.0), pc, D * cos_c, "pdf")
    p.add_mesh(g, scalars="pdf", cmap="viridis",
               scalar_bar_args=_bar("facets: D(h) cos θh (1/sr)"))
    if ndf_D is not None:
        m = _polar_surface(ndf_D * cos_c / peak, np.minimum(tc * scale_t, 90.0), pc)
        p.add_mesh(m, style="wireframe", color=COLOURS["model"], line_width=1.5)
    avg = " (azimuth-averaged grooves)" if sc.surface.azimuth_average else ""
    _title(p, f"{sc.name}: facet normals{avg} (surface)\nvs "
              f"{'NDF ' + type(sc.ndf).__name__ + ' (green wireframe)' if ndf_D is not None else 'no analytic NDF'}"
              f"\nradius: D cos θh / peak\npolar angle stretched ×{scale_t:.3g} (θh ≤ {theta_max:.3g}°)")
    _side_camera(p, 20.0, -30.0, 1.2)
    p.subplot(0, 1)
    pv = _pyvista()
    chart = pv.Chart2D(x_label="tilt theta_h (deg)", y_label="density per degree")
    edges = np.linspace(0.0, theta_max, 2 * n_theta + 1)
    hist, _ = np.histogram(th, edges, weights=w)
    mid = 0.5 * (edges[1:] + edges[:-1])
    width = np.diff(edges)
    chart.line(mid, hist / (w.sum() * width), color="black", width=2.5, label="facets")
    if sc.ndf is not None:
        try:
            cdf = np.asarray(sc.ndf.cdf_theta(np.radians(edges)))
            expected = np.diff(cdf) / width
        except NotImplementedError:
            expected = sc.ndf.tilt_pdf(np.radians(mid)) * np.pi / 180.0
        chart.line(mid, expected, color=COLOURS["model"], width=2.5, style="--",
                   label=f"NDF {type(sc.ndf).__name__} (bin average)")
    chart.title = "projected-area weighted tilt density 2 pi D cos(theta) sin(theta)"
    p.add_chart(chart)
    return p


# --- dispatch and command line -------------------------------------------------------------------
def view(scene_or_surface, what: str = "surface", theta_i: float | None = None, rays=None,
         seed: int = 0, window_size=WINDOW, off_screen=None, **options):
    """Build the ``what`` view (one of ``VIEWS``) and return its ``pyvista.Plotter``.

    ``theta_i`` (degrees): incidence for rays/lobe, viewing direction θo for disk; ignored by
    surface/normals. ``rays``: rays traced (default per view: 300 / 200 000 / 100 000)."""
    if what not in VIEWS:
        raise UsageError(f"what must be one of {', '.join(VIEWS)}, got {what!r}")
    theta = DEFAULT_THETA[what] if theta_i is None else float(theta_i)
    if what in ("rays", "lobe", "disk"):
        from .analytic._checks import in_range
        in_range("theta_i", theta, 0.0, 90.0, hi_open=True)
    common = {"off_screen": off_screen, "window_size": window_size}
    n = DEFAULT_RAYS.get(what) if rays is None else int(rays)
    if what == "surface":
        return view_surface(scene_or_surface, **options, **common)
    if what == "normals":
        return view_normals(scene_or_surface, **options, **common)
    if what == "rays":
        return view_rays(scene_or_surface, theta, rays=n, seed=seed, **options, **common)
    if what == "lobe":
        return view_lobe(scene_or_surface, theta, rays=n, seed=seed, **options, **common)
    return view_disk(scene_or_surface, theta, rays=n, seed=seed, **options, **common)


def _window_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(s) for s in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must be WIDTHxHEIGHT, e.g. 1200x800, got {text!r}")
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"size must be between 16 and 8192 pixels per side, got {text!r}")
    return w, h


def _configure(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="scene file (TOML), e.g. surfaces/vgroove-beckmann-0.3.toml")
    p.add_argument("--what", choices=VIEWS, default="surface", help="which view (default surface)")
    p.add_argument("--theta-i", type=float, default=None, metavar="DEG",
                   help="incidence for rays/lobe, viewing angle θo for disk (default: "
                        + ", ".join(f"{k} {v:g}" for k, v in DEFAULT_THETA.items()
                                    if k in ("rays", "lobe", "disk")) + ")")
    p.add_argument("--screenshot", metavar="PNG", default=None,
                   help="render off screen to this PNG (default with no display: "
                        "microsim-view-<scene>-<what>.png)")
    p.add_argument("--size", type=_window_size, default=WINDOW, metavar="WxH",
                   help="image size in pixels (default 1200x800)")
    p.add_argument("--rays", type=int, default=None, help="rays traced (rays/lobe/disk)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--color", choices=("height", "slope"), default="slope",
                   help="surface view colouring (default slope)")
    p.add_argument("--scale", choices=("linear", "log"), default="linear",
                   help="lobe radius: f·cosθo or log-scaled (default linear)")
    p.set_defaults(func=run_view)


def add_view_command(subparsers) -> argparse.ArgumentParser:
    """Register ``view`` on an argparse subparsers object (``func`` = ``run_view``)."""
    p = subparsers.add_parser("view", help="inspect a scene with pyvista: surface, rays, lobe, "
                                           "halfway disk or normals (off screen when headless)")
    _configure(p)
    return p


def run_view(args) -> int:
    """Run the ``view`` subcommand: show the view, or write a PNG (``--screenshot`` / headless)."""
    from .scene import load_scene
    scene = load_scene(args.scene)
    options = {"surface": {"color": args.color}, "lobe": {"scale": args.scale}}.get(args.what, {})
    shot = args.screenshot
    if shot is None and headless():
        shot = f"microsim-view-{scene.name}-{args.what}.png"
        print(f"microsim: no display: rendering off screen to {shot}", file=sys.stderr)
    p = view(scene, args.what, args.theta_i, args.rays, args.seed, args.size,
             off_screen=shot is not None, **options)
    if shot is None:
        p.show()
        return 0
    Path(shot).parent.mkdir(parents=True, exist_ok=True)
    p.screenshot(shot, window_size=args.size)
    p.close()
    print(shot)
    return 0


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        print(f"microsim view: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def main(argv=None) -> int:
    """``python -m microsim.view SCENE [options]`` (same options as ``microsim view``)."""
    p = _Parser(prog="python -m microsim.view", description="Inspect a scene with pyvista.")
    _configure(p)
    args = p.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, FileNotFoundError) as exc:
        print(f"microsim view: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
