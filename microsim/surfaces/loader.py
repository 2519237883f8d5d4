"""Measured or externally generated heightfields from files."""
from __future__ import annotations

from microsim.errors import UsageError
from pathlib import Path

import numpy as np

from microsim.analytic._checks import positive
from .heightfields import MIN_GRID
from .surface import Surface, heightfield_mesh

__all__ = ["from_file", "read_heights", "mirror_periodic"]


def read_heights(path) -> np.ndarray:
    """A 2D float64 height array from .npy, .npz (its single array, or the key 'heights') or
    whitespace-separated text (any other suffix). Raises ValueError naming the file."""
    path = Path(path)
    if not path.is_file():
        raise UsageError(f"path: no such heightfield file {str(path)!r}")
    try:
        if path.suffix == ".npy":
            a = np.load(path, allow_pickle=False)
        elif path.suffix == ".npz":
            with np.load(path, allow_pickle=False) as z:
                keys = list(z.keys())
                if "heights" in keys:
                    a = z["heights"]
                elif len(keys) == 1:
                    a = z[keys[0]]
                else:
                    raise UsageError(f"{path}: .npz must hold a single array or the key 'heights', "
                                     f"found keys {keys}")
        else:
            a = np.loadtxt(path, ndmin=2)
    except ValueError as e:
        raise UsageError(f"{path}: cannot read heights ({e})") from None
    a = np.asarray(a)
    if a.ndim != 2:
        raise UsageError(f"{path}: heights must be a 2D array (rows = y, columns = x), "
                         f"got shape {a.shape}")
    if not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
        raise UsageError(f"{path}: heights must be real numbers, got dtype {a.dtype}")
    a = a.astype(np.float64)
    if not np.all(np.isfinite(a)):
        raise UsageError(f"{path}: heights contain NaN or inf ({int(np.sum(~np.isfinite(a)))} "
                         f"values); fill or crop them first")
    if min(a.shape) < MIN_GRID:
        raise UsageError(f"{path}: heights grid must be at least {MIN_GRID}x{MIN_GRID}, "
                         f"got {a.shape[0]}x{a.shape[1]}")
    return a


def mirror_periodic(h: np.ndarray) -> np.ndarray:
    """Even (whole-sample) reflection of h along both axes: (2ny−2) × (2nx−2), periodic.

    Rows h_0 … h_{n−1} are followed by h_{n−2} … h_1, so no sample is repeated and no new
    slope is created at the seams: every finite difference of the mirrored tile is one of the
    input's, as is or sign-flipped (the first/last row and column are represented half as
    often as interior ones). Windowing instead would taper the edges and distort every slope
    there, which the ray tracer would see as real facets.
    """
    h = np.concatenate([h, h[-2:0:-1]], axis=0)
    return np.concatenate([h, h[:, -2:0:-1]], axis=1)


def from_file(path, dx: float, periodic: bool = False) -> Surface:
    """Heightfield surface from a file (``read_heights``) with grid spacing ``dx``.

    ``periodic=True``: the caller asserts the grid already tiles seamlessly (the sample after
    the last column is the first column) and it is used as is. Otherwise it is made periodic
    by mirroring (``mirror_periodic``), which doubles the tile, keeps every slope magnitude
    and symmetrises the slope distribution (each slope also appears with the opposite sign).
    The mean height is subtracted.
    """
    dx = positive("dx", dx)
    raw = read_heights(path)
    h = raw if periodic else mirror_periodic(raw)
    h = h - h.mean()
    vertices, faces = heightfield_mesh(h, dx)
    ny, nx = h.shape
    nominal = {"path": str(path), "dx": dx, "periodic_input": bool(periodic),
               "input_shape": tuple(int(s) for s in raw.shape)}
    warns = () if periodic else (f"file: {Path(path).name} was made periodic by mirroring "
                                 f"(tile {nx}x{ny} from {raw.shape[1]}x{raw.shape[0]})",)
    return Surface(kind="file", vertices=vertices, faces=faces, tile_size=(nx * dx, ny * dx),
                   periodic=True, nominal=nominal, heights=h, dx=dx, warnings=warns)
