"""The facets' unit normals and plane offsets as the kernels read them (``Facets``): stored
per facet for any mesh, or, on a heightfield grid, derived where they are read from the
grid's vertex heights, so that a heightfield tile keeps nothing per facet.

A facet (v0, v1, v2) has the unit normal n = cross(v1 − v0, v2 − v0)/|…| and the plane
offset n·v0 (``triangle_plane``); a secondary ray from it starts on the plane n·x = n·v0 +
eps. On the grid of ``surfaces.heightfield_mesh`` (heights hp (ny + 1, nx + 1), spacing c,
vertex (i, j) at x_i = (i − nx/2)·c, y_j = (j − ny/2)·c) face k < nx·ny is triangle A =
(v00, v01, v11) of cell (i, j) = (k mod nx, k div nx), and face nx·ny + k its triangle B =
(v00, v11, v10) (``grid_facet_plane``): the same vertices in the same float64 arithmetic as
the stored columns, so the same bits.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from microsim.jit import compiled, vector_inlined

__all__ = [
    "Facets",
    "mesh_facets",
    "grid_facets",
    "facet_plane",
    "grid_facet_plane",
    "grid_facet_corners",
    "facet_corners",
    "triangle_plane",
    "fill_normals",
]

NO_HEIGHTS = np.zeros((2, 2))
"""``Facets.hp`` of a mesh that is not a heightfield grid (never read)."""
NO_COLUMN = np.empty(0)
"""``Facets``' stored columns on a heightfield grid (empty: derived where read)."""


class Facets(NamedTuple):
    """The ``count`` facets of a tile: their unit normals (``nx``, ``ny``, ``nz``) and plane
    offsets ``plane`` = n·v0, stored (F,) each, or — on a heightfield grid, whose columns
    are then empty — derived from its vertex heights ``hp`` (ny + 1, nx + 1) and cell size
    ``cell`` (``grid_facet_plane``); ``eps``: a secondary ray starts on the plane
    n·x = plane + eps (tile length units)."""

    nx: np.ndarray
    ny: np.ndarray
    nz: np.ndarray
    plane: np.ndarray
    hp: np.ndarray
    cell: float
    count: int
    eps: float

    @property
    def stored(self) -> bool:
        """Whether the normals and planes are stored columns (else derived from ``hp``)."""
        return len(self.plane) > 0

    def columns(self, lo: int = 0, hi: int | None = None) -> tuple:
        """The unit normals of facets ``lo`` … ``hi`` − 1 as three (hi − lo,) columns: views
        of the stored ones, else computed."""
        hi = self.count if hi is None else hi
        if self.stored:
            return self.nx[lo:hi], self.ny[lo:hi], self.nz[lo:hi]
        return tuple(self._derived(np.arange(lo, hi))[0])

    def normals(self, prim=None) -> np.ndarray:
        """(K, 3) unit normals of facets ``prim`` (an index array; None: every facet)."""
        prim = np.arange(self.count) if prim is None else np.asarray(prim, dtype=np.int64)
        if self.stored:
            return np.stack([self.nx[prim], self.ny[prim], self.nz[prim]], axis=-1)
        return self._derived(prim)[0].T.reshape(*prim.shape, 3)

    def planes(self, prim) -> np.ndarray:
        """The plane offsets n·v0 of facets ``prim`` (an index array)."""
        prim = np.asarray(prim, dtype=np.int64)
        if self.stored:
            return self.plane[prim]
        return self._derived(prim)[1].reshape(prim.shape)

    def _derived(self, prim: np.ndarray) -> tuple:
        """(normals (3, K), plane offsets (K,)) of facets ``prim``, computed
        (``fill_normals``)."""
        prim = np.ascontiguousarray(prim, dtype=np.int64).ravel()
        cols, plane = np.empty((3, len(prim))), np.empty(len(prim))
        fill_normals(self, prim, cols, plane)
        return cols, plane


def mesh_facets(rows: np.ndarray, plane: np.ndarray, eps: float) -> Facets:
    """The ``Facets`` of a mesh from its normals' rows (3, F) and plane offsets (F,)."""
    return Facets(*rows, plane, NO_HEIGHTS, 0.0, len(plane), float(eps))


def grid_facets(hp: np.ndarray, cell: float, eps: float) -> Facets:
    """The ``Facets`` of a heightfield grid of vertex heights ``hp`` (ny + 1, nx + 1), cell
    size ``cell``: nothing stored per facet."""
    count = 2 * (hp.shape[0] - 1) * (hp.shape[1] - 1)
    return Facets(NO_COLUMN, NO_COLUMN, NO_COLUMN, NO_COLUMN, hp, float(cell), count, float(eps))


@vector_inlined
def triangle_plane(x0, y0, z0, x1, y1, z1, x2, y2, z2):
    """(nx, ny, nz, n·v0, |cross|) of the triangle (v0, v1, v2): n = cross(v1 − v0,
    v2 − v0)/|…| in NumPy's order of operations. A zero-area triangle has |cross| = 0, which
    the caller checks (its components are then NaN in a ``vectorised`` kernel)."""
    e1x, e1y, e1z = x1 - x0, y1 - y0, z1 - z0
    e2x, e2y, e2z = x2 - x0, y2 - y0, z2 - z0
    cx = e1y * e2z - e1z * e2y
    cy = e1z * e2x - e1x * e2z
    cz = e1x * e2y - e1y * e2x
    norm = math.sqrt(cx * cx + cy * cy + cz * cz)
    nx, ny, nz = cx / norm, cy / norm, cz / norm
    return nx, ny, nz, nx * x0 + ny * y0 + nz * z0, norm


@vector_inlined
def grid_facet_corners(hp, cell, f):
    """The corners (x0, y0, z0, x1, y1, z1, x2, y2, z2) of face ``f`` of the heightfield grid of
    vertex heights ``hp`` (module docstring: triangle A = (v00, v01, v11) of cell k = f for
    f < nx·ny, else triangle B = (v00, v11, v10) of cell f − nx·ny)."""
    rows, cols = hp.shape[0] - 1, hp.shape[1] - 1
    upper = f < rows * cols
    k = f if upper else f - rows * cols
    j = k // cols
    i = k - j * cols
    xa, xb = (i - cols / 2.0) * cell, (i + 1 - cols / 2.0) * cell
    ya, yb = (j - rows / 2.0) * cell, (j + 1 - rows / 2.0) * cell
    h00, h01, h10, h11 = hp[j, i], hp[j, i + 1], hp[j + 1, i], hp[j + 1, i + 1]
    # both triangles' corners read, then selected: no branch on the triangle
    y1, z1 = (ya, h01) if upper else (yb, h11)
    x2, z2 = (xb, h11) if upper else (xa, h10)
    return xa, ya, h00, xb, y1, z1, x2, yb, z2


@vector_inlined
def grid_facet_plane(hp, cell, f):
    """(nx, ny, nz, n·v0) of face ``f`` of the heightfield grid of vertex heights ``hp``
    (``grid_facet_corners``)."""
    x0, y0, z0, x1, y1, z1, x2, y2, z2 = grid_facet_corners(hp, cell, f)
    nx, ny, nz, plane, _ = triangle_plane(x0, y0, z0, x1, y1, z1, x2, y2, z2)
    return nx, ny, nz, plane


@vector_inlined
def facet_corners(facets, vertices, faces, f):
    """The corners (x0, y0, z0, x1, …, z2) of facet ``f``: of the mesh (``vertices`` (V, 3),
    ``faces`` (F, 3)), or, where ``faces`` is empty, of the heightfield grid of ``facets``."""
    if len(faces) == 0:
        return grid_facet_corners(facets.hp, facets.cell, f)
    a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
    return (
        vertices[a, 0], vertices[a, 1], vertices[a, 2],
        vertices[b, 0], vertices[b, 1], vertices[b, 2],
        vertices[c, 0], vertices[c, 1], vertices[c, 2],
    )  # fmt: skip


@vector_inlined
def facet_plane(facets, f):
    """(nx, ny, nz, n·v0) of facet ``f`` of ``facets`` (``Facets``): stored, or derived from
    the grid's heights."""
    if len(facets.plane) > 0:
        return facets.nx[f], facets.ny[f], facets.nz[f], facets.plane[f]
    return grid_facet_plane(facets.hp, facets.cell, f)


@compiled
def fill_normals(facets, prim, cols, plane):
    """The unit normals of facets ``prim`` into ``cols`` (3, K) and their plane offsets into
    ``plane`` (K,)."""
    for k in range(len(prim)):
        cols[0, k], cols[1, k], cols[2, k], plane[k] = facet_plane(facets, prim[k])
