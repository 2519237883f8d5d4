"""Visual inspection of scenes with pyvista: surface, ray paths, BRDF lobe, halfway disk, normals.

    microsim view SCENE [--what surface|rays|lobe|disk|normals] [--theta-i DEG]
                    [--screenshot PNG] [--size WxH] [--rays N] [--seed S]

From Python (notebooks) every view returns a ``pyvista.Plotter``; call ``.show()`` or
``.screenshot(path)`` on it::

    from microsim.app import view
    view.view_lobe("gaussian-m0.3", theta_i=60).show()

Views (local frame, macro normal +z; angles in degrees; BRDFs in sr⁻¹):
  surface  the tile's mesh coloured by height or facet slope, the displayed region outlined. A
           V-groove tile of thousands of grooves is shown as a zoomed section of a few dozen
           grooves (the title says so): the surface is the extruded profile, so a section is exact.
  rays     a few hundred sampled paths at one incidence: incident segments, single-bounce
           escaping rays, masked rays (reflected up but blocked) and downward (multi-bounce) rays.
  lobe     the simulated single-bounce BRDF as a 3D polar surface (radius f·cos θo or log-scaled)
           beside the model's (Torrance–Sparrow with the scene's NDF; V-groove G on V-grooves,
           height-correlated Smith on heightfields), coloured by z = (sim − model)/σ.
  disk     Edwards' halfway-vector disk (Edwards et al. 2006, Fig. 13) for one viewing
           direction: simulated half vectors in the scaling and the orthogonal projection against
           contours of a fitted Edwards data-fitting BRDF (Edwards et al. 2006, eq. 34–36).
  normals  the facet-normal distribution (projected-area weighted) against the scene's NDF
           D(θh, φh) (anisotropic too), and the tilt densities; oriented grooves have no
           density of normals (the title says so): their tilts against the NDF they sample.

Headless: with no DISPLAY every view renders off screen (VTK's EGL window, Mesa's libEGL);
without ``--screenshot`` the image goes to ``microsim-view-<scene>-<what>.png``.

One module per view (``surface``, ``rays``, ``lobe``, ``disk``, ``normals``), the shared
set-up in ``common`` and the command line in ``command``.
"""

from __future__ import annotations

from .command import VIEWS, configure_view, main, run_view, view
from .common import headless
from .disk import view_disk
from .lobe import lobe_z, view_lobe
from .normals import view_normals
from .rays import RayPaths, trace_paths, view_rays
from .surface import view_surface

__all__ = [
    "VIEWS",
    "view",
    "view_surface",
    "view_rays",
    "view_lobe",
    "view_disk",
    "view_normals",
    "configure_view",
    "run_view",
    "main",
    "headless",
    "lobe_z",
    "trace_paths",
    "RayPaths",
]
