"""Explicit periodic microsurfaces: V-grooves, Gaussian, fractal (ABC-PSD) and Student-t (GGX)
heightfields, heightfields from files, and a flat mirror. Each generator returns a ``Surface``:
the mesh, its nominal parameters, ``stats()`` and what the generator knows about it
(``ensemble_ndf``, ``exact_shadowing``, ``predicted``). Scene files are read by
``microsim.app.scene.load_scene``.
"""

from .gratings import sinusoidal_grating, triangular_grating
from .heightfields import abc, gaussian
from .loader import from_file
from .student_t import student_t_mixture, student_t_transform
from .surface import Predicted, Surface, flat
from .vgrooves import vgrooves

__all__ = [
    "Surface",
    "Predicted",
    "vgrooves",
    "gaussian",
    "abc",
    "student_t_transform",
    "student_t_mixture",
    "flat",
    "from_file",
    "sinusoidal_grating",
    "triangular_grating",
]
