"""Explicit periodic microsurfaces: V-grooves, Gaussian and fractal (ABC-PSD) heightfields,
heightfields from files, and a flat mirror. Each generator returns a ``Surface`` (mesh +
nominal parameters + ``stats()``); ``load_scene`` reads a scene file (``microsim.scene``).
"""
from .surface import Surface, flat
from .vgrooves import vgrooves
from .heightfields import gaussian, abc
from .loader import from_file

__all__ = ["Surface", "vgrooves", "gaussian", "abc", "flat", "from_file", "load_scene"]


def load_scene(path):
    """Read a scene file (TOML); see ``microsim.scene.load_scene``."""
    from microsim.scene import load_scene as _load
    return _load(path)
