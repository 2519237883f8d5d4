"""The explicit microsurface: a periodic triangle mesh plus what generated it.

Conventions (DESIGN.md): macro normal +z; the tile is [-Lx/2, Lx/2] x [-Ly/2, Ly/2]; every face
is ordered so that its geometric normal cross(v1 - v0, v2 - v0) points up. A facet with unit
normal n has slopes (∂z/∂x, ∂z/∂y) = (-n_x/n_z, -n_y/n_z); statistics over facets are weighted
by projected area (area · n_z), so that a histogram of facet normals samples D(h)(h·n)
(Mikkelsen eq. 14).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from microsim.errors import UsageError

__all__ = ["Surface", "flat", "heightfield_mesh", "facet_slopes", "check_relief", "MAX_RELIEF",
           "MAX_COORDINATE"]

MAX_RELIEF = 1000.0
"""Largest height range of a surface in units of its (smaller) tile side. The tracer walks a
ray through copies of the tile; one 89.5° from the normal crosses the tile ~230 times per tile
height it descends, so a relief of 1000 tiles already allows ~2·10⁵ crossings per ray."""
MAX_COORDINATE = 1e30
"""Largest vertex coordinate: Embree traces in float32 (max 3.4e38), with room for products."""


def check_relief(name: str, zmin: float, zmax: float, tile) -> None:
    """Raise a UsageError naming ``name`` unless the height range zmax − zmin is finite,
    within ``MAX_COORDINATE`` and at most ``MAX_RELIEF`` × the smaller tile side."""
    relief, side = float(zmax) - float(zmin), float(min(tile))
    big = max(abs(float(zmin)), abs(float(zmax)))
    if not (np.isfinite(relief) and big <= MAX_COORDINATE):
        raise UsageError(f"{name}: surface heights must be finite and within ±{MAX_COORDINATE:g} "
                         f"(Embree traces in float32), got the range [{zmin:g}, {zmax:g}]")
    if relief > MAX_RELIEF * side:
        raise UsageError(f"{name}: the surface's height range {relief:.4g} is more than "
                         f"{MAX_RELIEF:g} × its tile side {side:.4g}: a grazing ray would cross "
                         f"the tile ~{230 * relief / side:.2g} times (reduce the heights or "
                         f"enlarge the tile)")


@dataclass(frozen=True, eq=False)
class Surface:
    """A periodic microsurface tile (the contract between surfaces and the tracer).

    ``vertices`` (V, 3) float64 and ``faces`` (F, 3) int32 (normals up); ``tile_size`` (Lx, Ly)
    are the periods; ``nominal`` holds the generator parameters; ``heights`` (ny, nx) with
    spacing ``dx`` for heightfields (row = y index, col = x index); ``azimuth_average`` is True
    for V-grooves (the estimator averages the groove azimuth to get the isotropic V-cavity
    surface); ``warnings`` are caveats to show in reports.
    """

    kind: str
    vertices: np.ndarray
    faces: np.ndarray
    tile_size: tuple[float, float]
    periodic: bool
    nominal: dict
    heights: np.ndarray | None = None
    dx: float | None = None
    azimuth_average: bool = False
    warnings: tuple[str, ...] = ()
    source_ndf: object = None           # the analytic NDF a V-groove surface was drawn from

    def mesh(self):
        """``trimesh.Trimesh`` (process=False) of the tile, centred on the origin.

        Vertices are rounded to float32 (what Embree sees); trimesh stores them as float64
        arrays of those float32 values. Faces are int32 values.
        """
        import trimesh
        return trimesh.Trimesh(vertices=self.vertices.astype(np.float32),
                               faces=self.faces.astype(np.int32), process=False)

    def _cross(self) -> np.ndarray:
        v = self.vertices
        f = self.faces
        return np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])

    def facet_normals(self) -> np.ndarray:
        """(F, 3) float64 unit facet normals (z > 0)."""
        c = self._cross()
        return c / np.linalg.norm(c, axis=1, keepdims=True)

    def facet_areas(self) -> np.ndarray:
        """(F,) float64 true facet areas (length² in the units of ``vertices``)."""
        return 0.5 * np.linalg.norm(self._cross(), axis=1)

    def projected_areas(self) -> np.ndarray:
        """(F,) float64 facet areas projected onto the macro plane (area · n_z)."""
        return 0.5 * self._cross()[:, 2]

    @property
    def z_range(self) -> tuple[float, float]:
        """(zmin, zmax) of the vertices."""
        z = self.vertices[:, 2]
        return float(z.min()), float(z.max())

    def ndf(self):
        """Empirical NDF of the facets, weighted by projected area (``microsim.analytic.Empirical``)."""
        from microsim.analytic import Empirical
        return Empirical(self.facet_normals(), weights=self.projected_areas())

    def stats(self) -> dict:
        """Measured statistics next to nominal and predicted (mesh-exact) values.

        Keys (lengths in vertex units, slopes dimensionless): ``triangles``, ``tile_size``,
        ``z_range``, ``slope_var_x``, ``slope_var_y`` (projected-area weighted, about zero),
        ``slope_corr`` (correlation of the two slopes over facets), ``mean_tan2`` (E[tan²θ]),
        ``m_realised`` = √(var_x + var_y) (Beckmann: per-axis variance m²/2), ``nominal``;
        heightfields add ``rms_height`` and the generator's predictions (``predicted_*``);
        V-grooves add their tilt distribution (see ``vgrooves.groove_stats``).
        """
        from .heightfields import predictions
        from .vgrooves import groove_stats
        sx, sy = facet_slopes(self.facet_normals())
        w = self.projected_areas()
        w = w / w.sum()
        vx = float(np.sum(w * sx * sx))
        vy = float(np.sum(w * sy * sy))
        cxy = float(np.sum(w * sx * sy))
        out = {
            "kind": self.kind,
            "triangles": int(len(self.faces)),
            "tile_size": tuple(float(t) for t in self.tile_size),
            "z_range": self.z_range,
            "slope_var_x": vx,
            "slope_var_y": vy,
            "slope_corr": cxy / np.sqrt(vx * vy) if vx > 0 and vy > 0 else 0.0,
            "mean_tan2": vx + vy,
            "m_realised": float(np.sqrt(vx + vy)),
            "nominal": dict(self.nominal),
        }
        if self.heights is not None:
            out["grid"] = tuple(int(s) for s in self.heights.shape)
            out["dx"] = float(self.dx)
            out["rms_height"] = float(np.sqrt(np.mean(self.heights ** 2)))
        out.update(predictions(self))
        out.update(groove_stats(self))
        return out


def facet_slopes(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Slopes (∂z/∂x, ∂z/∂y) = (-n_x/n_z, -n_y/n_z) of facets with unit normals (..., 3)."""
    n = np.asarray(normals, dtype=np.float64)
    return -n[..., 0] / n[..., 2], -n[..., 1] / n[..., 2]


def heightfield_mesh(heights: np.ndarray, dx: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a periodic heightfield tile (two triangles per cell).

    ``heights`` (ny, nx), row = y index. The mesh has (ny+1)(nx+1) vertices on x_j = -Lx/2 + j·dx,
    y_i = -Ly/2 + i·dx; the last row/column repeat the first heights, so the tile joins its
    copies seamlessly. Cell (i, j) is split along its (i,j)–(i+1,j+1) diagonal into
    (v00, v01, v11) and (v00, v11, v10): 2·nx·ny triangles, all with normal z > 0 and the same
    projected area dx²/2.
    """
    ny, nx = heights.shape
    hp = np.pad(heights, ((0, 1), (0, 1)), mode="wrap")
    x = (np.arange(nx + 1) - nx / 2.0) * dx
    y = (np.arange(ny + 1) - ny / 2.0) * dx
    X, Y = np.meshgrid(x, y)
    vertices = np.stack([X.ravel(), Y.ravel(), hp.ravel()], axis=1).astype(np.float64)
    idx = np.arange((ny + 1) * (nx + 1), dtype=np.int64).reshape(ny + 1, nx + 1)
    v00, v01 = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    v10, v11 = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([v00, v01, v11], axis=1),
                            np.stack([v00, v11, v10], axis=1)]).astype(np.int32)
    return vertices, faces


def flat(size: float = 1.0) -> Surface:
    """A flat square mirror at z = 0 of side ``size`` (2 triangles), periodic."""
    from microsim.analytic._checks import positive
    s = positive("size", size) / 2.0
    vertices = np.array([[-s, -s, 0.0], [s, -s, 0.0], [s, s, 0.0], [-s, s, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
    return Surface(kind="flat", vertices=vertices, faces=faces, tile_size=(2 * s, 2 * s),
                   periodic=True, nominal={"size": 2 * s})
