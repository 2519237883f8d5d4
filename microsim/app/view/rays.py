"""The rays view: a few hundred sampled paths at one incidence — incident segments,
single-bounce escaping rays, masked rays (reflected up but blocked) and downward
(multi-bounce) rays — over a section of the surface."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from microsim.vectors import spherical_deg

from ...sim import Tracer
from ...sim.tracer import ESCAPED, HIT
from .common import (
    COLOURS,
    RAYS_VIEW,
    WINDOW,
    Section,
    colour_key,
    outline,
    plotter,
    pyvista,
    resolve,
    section,
    section_mesh,
    side_camera,
    title,
    whole_tile,
)

__all__ = ["RayPaths", "trace_paths", "view_rays"]

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


def trace_paths(
    surface, theta_i: float, phi_i: float = 0.0, rays: int = 300, seed: int = 0, window=None
) -> RayPaths:
    """Trace ``rays`` primary rays from direction (θi, φi) (degrees) aimed uniformly at the
    central 60% of ``window`` (x0, x1, y0, y1; default the tile) and classify them as the
    estimator does (single / masked / downward), with the public ``Tracer`` API (the estimator's
    ray origins and groove azimuths are private, so the hit points are traced here; for
    V-grooves the groove azimuth is not randomised: φi is relative to the grooves' normal
    plane, 0° = across the grooves)."""
    tracer = Tracer(surface)
    lx, ly = surface.tile_size
    x0, x1, y0, y1 = window if window is not None else (-lx / 2, lx / 2, -ly / 2, ly / 2)
    rng = np.random.default_rng(seed)
    n = int(rays)
    cx, cy, wx, wy = (x0 + x1) / 2, (y0 + y1) / 2, 0.6 * (x1 - x0), 0.6 * (y1 - y0)
    target = np.stack(
        [
            cx + (rng.random(n) - 0.5) * wx,
            cy + (rng.random(n) - 0.5) * wy,
            np.full(n, 0.5 * (tracer.zmin + tracer.zmax)),
        ],
        axis=1,
    )
    wi = spherical_deg(theta_i, phi_i)
    top = tracer.zmax + tracer.top_margin
    origins = target + wi * ((top - target[:, 2]) / wi[2])[:, None]
    hits = tracer.first_hit(origins, -wi)
    ok = hits.status == HIT
    origins, p_tile, nrm = origins[ok], hits.point[ok], hits.normal[ok]
    hit = origins - wi * ((origins[:, 2] - p_tile[:, 2]) / wi[2])[:, None]  # unwrapped
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


def segments(a: np.ndarray, b: np.ndarray):
    """PolyData of line segments a[k] → b[k] (both (N, 3))."""
    pv = pyvista()
    n = len(a)
    pts = np.empty((2 * n, 3))
    pts[0::2], pts[1::2] = a, b
    lines = np.column_stack([np.full(n, 2), 2 * np.arange(n), 2 * np.arange(n) + 1]).ravel()
    return pv.PolyData(pts, lines=lines)


def view_rays(
    scene_or_surface,
    theta_i: float = RAYS_VIEW.theta,
    phi_i: float = 0.0,
    rays: int = RAYS_VIEW.rays,
    grooves: int = 12,
    material=None,
    seed=0,
    off_screen=None,
    window_size=WINDOW,
):
    """A few hundred ray paths at incidence (θi, φi) (degrees) over the displayed section:
    incident segments, single-bounce escaping rays, masked and downward (multi-bounce) rays."""
    sc = resolve(scene_or_surface, material, seed)
    sec = section(sc.surface, int(grooves))
    x0, x1, y0, y1 = sec.window
    if sc.surface.kind != "vgrooves":  # heightfields: a window of ~128 cells
        span = min(x1 - x0, 128 * (sc.surface.dx or (x1 - x0)))
        sec = crop(sc.surface, span)
        x0, x1, y0, y1 = sec.window
    paths = trace_paths(sc.surface, theta_i, phi_i, rays, seed, sec.window)
    length = 0.2 * (x1 - x0)
    p = plotter(window_size=window_size, off_screen=off_screen)
    p.add_mesh(section_mesh(sec), color="#c8c8c8")
    p.add_mesh(outline(sec.window, float(sec.vertices[:, 2].max())), color="black", line_width=2)
    p.add_mesh(
        segments(paths.hit + length * paths.wi, paths.hit),
        color=COLOURS.incident,
        line_width=1,
        opacity=0.6,
    )
    key = [("incident", COLOURS.incident)]
    fates = (
        (SINGLE, "escaping (single bounce)", COLOURS.single),
        (MASKED, "masked (blocked on the way out)", COLOURS.masked),
        (DOWNWARD, "downward (multi-bounce)", COLOURS.downward),
    )
    for kind, label, colour in fates:
        sel = paths.status == kind
        if not sel.any():
            continue
        end = paths.end[sel] if kind != SINGLE else paths.hit[sel] + length * paths.wo[sel]
        miss = ~np.all(np.isfinite(end), axis=1)  # second hit not resolved: fixed length
        end[miss] = paths.hit[sel][miss] + 0.2 * length * paths.wo[sel][miss]
        p.add_mesh(
            segments(paths.hit[sel], end),
            color=colour,
            line_width=1.5 if kind == SINGLE else 4,
            opacity=0.7 if kind == SINGLE else 1,
        )
        key.append((f"{label}: {int(sel.sum())}", colour))
    colour_key(p, key)
    title(
        p,
        f"{sc.name}: {len(paths.hit)} rays at θi = {theta_i:g}°, φi = {phi_i:g}°"
        f"{' (across the grooves)' if sc.surface.kind == 'vgrooves' and phi_i == 0 else ''}"
        f"\n{sec.note}",
    )
    side_camera(p, 8.0, -10.0, 1.3)
    return p


def crop(surface, span: float) -> Section:
    """Central square window of side ``span`` of a heightfield tile (faces by centroid)."""
    lx, ly = surface.tile_size
    if span >= min(lx, ly):
        return whole_tile(surface)
    cen = surface.vertices[surface.faces].mean(axis=1)
    keep = np.all(np.abs(cen[:, :2]) < span / 2, axis=1)
    used, inv = np.unique(surface.faces[keep], return_inverse=True)
    v = surface.vertices[used]
    return Section(
        v,
        inv.reshape(-1, 3).astype(np.int64),
        (v[:, 0].min(), v[:, 0].max(), v[:, 1].min(), v[:, 1].max()),
        f"zoomed section: {span:g} × {span:g} of the {lx:g} × {ly:g} tile",
    )
