"""The surface view: the tile's mesh coloured by height or facet slope, the displayed region
outlined. A V-groove tile of thousands of grooves is shown as a zoomed section of a few dozen
grooves (the title says so): the surface is the extruded profile, so a section is exact."""

from __future__ import annotations

import numpy as np

from ...errors import UsageError
from .common import (
    COLOURS,
    WINDOW,
    outline,
    plotter,
    resolve,
    scalar_bar,
    section,
    section_mesh,
    side_camera,
    tilt_deg,
    title,
)

__all__ = ["view_surface"]


def view_surface(
    scene_or_surface,
    color: str = "slope",
    grooves: int = 16,
    material=None,
    seed=None,
    off_screen=None,
    window_size=WINDOW,
):
    """The tile's mesh coloured by ``color`` = "height" (z, length units) or "slope" (facet tilt
    θ in degrees), with the displayed region outlined; V-grooves as a section of ``grooves``."""
    if color not in ("height", "slope"):
        raise UsageError(f"color must be 'height' or 'slope', got {color!r}")
    sc = resolve(scene_or_surface, material, seed)
    sec = section(sc.surface, int(grooves))
    mesh = section_mesh(sec)
    p = plotter(window_size=window_size, off_screen=off_screen)
    if color == "height":
        mesh.point_data["height"] = sec.vertices[:, 2]
        p.add_mesh(mesh, scalars="height", cmap="viridis", scalar_bar_args=scalar_bar("height z"))
    else:
        v, f = sec.vertices, sec.faces
        c = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        mesh.cell_data["slope (deg)"] = tilt_deg(c / np.linalg.norm(c, axis=1, keepdims=True))
        p.add_mesh(
            mesh,
            scalars="slope (deg)",
            cmap="magma",
            scalar_bar_args=scalar_bar("facet tilt θ (deg)"),
        )
    p.add_mesh(
        outline(sec.window, float(sec.vertices[:, 2].max())), color=COLOURS.outline, line_width=3
    )
    title(p, f"{sc.name}: surface coloured by {color}\n{sec.note}")
    side_camera(p, 20.0 if sc.surface.kind == "vgrooves" else 50.0)
    return p
