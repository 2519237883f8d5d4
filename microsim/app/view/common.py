"""What every view shares: pyvista set-up (off screen when headless), the scene a view shows,
the displayed section of a surface, text in VTK's fonts, cameras and polar surfaces.

Local frame with the macro normal +z; angles in degrees.
"""

from __future__ import annotations

import os
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import EnvironmentFailure, UsageError
from ...surfaces import Surface
from ..scene import Scene, load_scene

__all__ = [
    "DEFAULT_THETA",
    "DEFAULT_RAYS",
    "ViewDefaults",
    "VIEW_DEFAULTS",
    "RAYS_VIEW",
    "LOBE_VIEW",
    "DISK_VIEW",
    "WINDOW",
    "COLOURS",
    "headless",
    "pyvista",
    "plotter",
    "ViewScene",
    "resolve",
    "ascii_text",
    "title",
    "colour_key",
    "text_size",
    "scalar_bar",
    "Section",
    "whole_tile",
    "section",
    "section_mesh",
    "outline",
    "tilt_deg",
    "side_camera",
    "polar_surface",
]


@dataclass(frozen=True)
class ViewDefaults:
    """A view's defaults: ``theta`` in degrees (the incidence θi of rays and lobe, the viewing
    angle θo of disk; unused by surface and normals) and ``rays`` traced (None: it traces
    none)."""

    theta: float
    rays: int | None = None


RAYS_VIEW = ViewDefaults(60.0, 300)
LOBE_VIEW = ViewDefaults(30.0, 200_000)
DISK_VIEW = ViewDefaults(30.0, 100_000)
VIEW_DEFAULTS = {
    "surface": ViewDefaults(0.0),
    "rays": RAYS_VIEW,
    "lobe": LOBE_VIEW,
    "disk": DISK_VIEW,
    "normals": ViewDefaults(0.0),
}
"""Each view's ``ViewDefaults`` by its name (``command.VIEWS``)."""
DEFAULT_THETA = {name: d.theta for name, d in VIEW_DEFAULTS.items()}
DEFAULT_RAYS = {name: d.rays for name, d in VIEW_DEFAULTS.items() if d.rays is not None}
WINDOW = (1200, 800)
BACKGROUND = "white"


@dataclass(frozen=True)
class Colours:
    """The views' colours: incident rays, the fates of the traced rays (single bounce, masked,
    downward), a model's lobe or normals, the mirror direction and outlines."""

    incident: str = "#e6a100"
    single: str = "#2ca02c"
    masked: str = "#d62728"
    downward: str = "#1f57c4"
    model: str = "#2ca02c"
    mirror: str = "#444444"
    outline: str = "black"


COLOURS = Colours()


# --- set-up --------------------------------------------------------------------------------------
def headless() -> bool:
    """True on Linux without an X or Wayland display (render off screen)."""
    return sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    )


def pyvista():
    """Import pyvista; headless, select VTK's EGL window first (else VTK tries X and warns)."""
    if headless() and "vtkmodules" not in sys.modules:
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    try:
        import pyvista as pv
    except ImportError:
        raise EnvironmentFailure(
            "the views need pyvista, an optional extra: pip install 'microsim[view]'"
        ) from None
    return pv


def plotter(shape=(1, 1), window_size=WINDOW, off_screen=None):
    """A white ``pyvista.Plotter`` of ``shape`` subplots; off screen if headless (or asked)."""
    pv = pyvista()
    off = headless() if off_screen is None else bool(off_screen)
    p = pv.Plotter(
        shape=shape, window_size=tuple(int(s) for s in window_size), off_screen=off, border=False
    )
    p.set_background(BACKGROUND)
    return p


@dataclass(frozen=True)
class ViewScene:
    """What a view needs: the surface, material, analytic NDF (or None) and a display name."""

    surface: object
    ior: object
    ndf: object
    name: str


def resolve(scene_or_surface, material=None, seed=None) -> ViewScene:
    """Accept a scene path, a ``Scene`` or a ``Surface`` (then ``material``: default mirror)."""
    obj = scene_or_surface
    if isinstance(obj, (str, Path)):
        obj = load_scene(obj)
    if isinstance(obj, Scene):
        with warnings.catch_warnings():  # generator caveats: printed by `surface`
            warnings.simplefilter("ignore")
            surf = obj.build_surface(seed=seed)
        ior = obj.ior if material is None else material
        return ViewScene(surf, ior, obj.ndf(), obj.name)
    if isinstance(obj, Surface):
        return ViewScene(obj, material, obj.ensemble_ndf, obj.kind)
    raise UsageError(
        "scene_or_surface must be a scene file path, a microsim.app.scene.Scene or a "
        f"microsim.surfaces.Surface, got {type(obj).__name__}"
    )


# --- text ----------------------------------------------------------------------------------------
_ASCII = str.maketrans(
    {
        "θ": "theta_",
        "φ": "phi_",
        "σ": "sigma",
        "π": "pi",
        "×": "x",
        "≤": "<=",
        "−": "-",
        "–": "-",
        "·": "*",
    }
)


def ascii_text(text: str) -> str:
    """VTK's built-in fonts lack Greek letters and maths symbols: spell them out."""
    return text.translate(_ASCII).replace("_ ", " ").replace("_=", " =")


def text_size(p, size: int) -> int:
    """``size`` (points, chosen for the default 1200 × 800 window) scaled to ``p``'s window, so
    that titles and keys keep their share of a smaller or larger image (``--size``)."""
    w, h = p.window_size
    return max(5, int(round(size * min(2.0, max(0.4, min(w / 1200.0, h / 800.0))))))


def title(p, text: str, size: int = 8) -> None:
    p.add_text(ascii_text(text), position="upper_edge", font_size=text_size(p, size), color="black")


def colour_key(p, items, size: int = 10, bottom: int = 8) -> None:
    """Colour key: one line of text per (label, colour), stacked up from the lower left corner
    of the current viewport (pixel offsets; pyvista legends misplace themselves in subplots)."""
    size = text_size(p, size)
    for k, (label, colour) in enumerate(reversed(list(items))):
        p.add_text(
            ascii_text(label),
            position=(10, bottom + int(2.0 * size) * k),
            font_size=size,
            color=colour,
        )


def scalar_bar(text: str, **extra) -> dict:
    """``scalar_bar_args`` of ``add_mesh`` with the title ``text``."""
    return {
        "title": ascii_text(text),
        "color": "black",
        "title_font_size": 14,
        "label_font_size": 12,
        **extra,
    }


# --- geometry shown ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Section:
    """The displayed part of a surface: vertices/faces in tile coordinates, the xy window
    [x0, x1] × [y0, y1] it covers and a note for the title."""

    vertices: np.ndarray
    faces: np.ndarray
    window: tuple[float, float, float, float]
    note: str


def whole_tile(surface) -> Section:
    lx, ly = surface.tile_size
    return Section(
        surface.vertices,
        surface.faces,
        (-lx / 2, lx / 2, -ly / 2, ly / 2),
        "whole periodic tile outlined",
    )


def section(surface, grooves: int = 16, length: float = 0.5) -> Section:
    """Whole tile, or for V-grooves with more than ``grooves`` grooves a central section of
    ``grooves`` grooves, its groove length cut to ``length`` × the section's width (exact: the
    surface is an extruded profile; faces 4k … 4k+3 belong to groove k)."""
    n = len(surface.faces) // 4
    if surface.kind != "vgrooves" or n <= grooves:
        return whole_tile(surface)
    k0 = (n - grooves) // 2
    f = surface.faces[4 * k0 : 4 * (k0 + grooves)]
    used, inv = np.unique(f, return_inverse=True)
    v = surface.vertices[used].copy()
    half = 0.5 * length * (v[:, 0].max() - v[:, 0].min())
    v[:, 1] = np.sign(v[:, 1]) * half  # cut the grooves' length to the width
    return Section(
        v,
        inv.reshape(-1, 3).astype(np.int64),
        (v[:, 0].min(), v[:, 0].max(), -half, half),
        f"zoomed section: {grooves} of {n} grooves, groove length cut (the profile is extruded)",
    )


def section_mesh(sec: Section):
    """``pyvista.PolyData`` of the section's triangles."""
    f = np.asarray(sec.faces, dtype=np.int64)
    return pyvista().PolyData(sec.vertices, np.hstack([np.full((len(f), 1), 3), f]).ravel())


def outline(window, z: float):
    """Closed polyline around the xy ``window`` (x0, x1, y0, y1) at height ``z``."""
    x0, x1, y0, y1 = window
    pts = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z], [x0, y0, z]])
    return pyvista().lines_from_points(pts)


def tilt_deg(normals: np.ndarray) -> np.ndarray:
    """Tilt θ (degrees) of unit normals (N, 3) from +z."""
    return np.degrees(np.arccos(np.clip(normals[:, 2], -1.0, 1.0)))


# --- camera and polar surfaces -------------------------------------------------------------------
def side_camera(p, elevation: float = 25.0, azimuth: float = -30.0, zoom: float = 1.0) -> None:
    """Look at the xz plane (the plane of incidence, φ = 0) from −y, raised by ``elevation``
    and turned by ``azimuth`` degrees."""
    p.view_xz()
    p.camera.elevation = elevation
    p.camera.azimuth = azimuth
    p.reset_camera()
    p.camera.zoom(zoom)


def polar_surface(
    radius: np.ndarray,
    theta_deg: np.ndarray,
    phi_deg: np.ndarray,
    scalars: np.ndarray | None = None,
    name: str = "value",
):
    """StructuredGrid of the polar surface r(θ, φ) (closed in φ, capped at the pole)."""
    pv = pyvista()
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
