"""The explicit microsurface: a periodic triangle mesh plus what generated it.

Conventions (docs/design.md, "Conventions"): macro normal +z; the tile is [-Lx/2, Lx/2] x
[-Ly/2, Ly/2]; every face is ordered so that its geometric normal cross(v1 - v0, v2 - v0)
points up. A facet with unit
normal n has slopes (∂z/∂x, ∂z/∂y) = (-n_x/n_z, -n_y/n_z); statistics over facets are weighted
by projected area (area · n_z), so that a histogram of facet normals samples D(h)(h·n)
(Mikkelsen 2009, eq. 14).

Each generator attaches what only it knows (``Surface.ensemble_ndf``, ``exact_shadowing``,
``predicted``, ``generator_stats``), so code above this package asks the surface instead of
switching on ``kind``.
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass
from typing import Callable

import numpy as np

from microsim.analytic import Empirical
from microsim.analytic.anisotropic import AnisotropicNDF
from microsim.checks import positive
from microsim.errors import EnvironmentFailure, UsageError

__all__ = [
    "Surface",
    "Predicted",
    "flat",
    "heightfield_mesh",
    "facet_slopes",
    "check_relief",
    "anisotropy_of",
    "MAX_RELIEF",
    "MAX_COORDINATE",
]

MAX_RELIEF = 1000.0
"""Largest height range of a surface in units of its (smaller) tile side. The tracer walks a
ray through copies of the tile; one 89.5° from the normal crosses the tile ~230 times per tile
height it descends, so a relief of 1000 tiles already allows ~2·10⁵ crossings per ray."""
MAX_COORDINATE = 1e30
"""Largest vertex coordinate: Embree traces in float32 (max 3.4e38), with room for products."""


_ANISOTROPIC = {
    "vgrooves": ("oriented", "oriented V-grooves"),
    "gaussian": ("corr_len_y", "a Gaussian field with two correlation lengths"),
    "abc": ("B_y", "an ABC field with two B"),
    "student-t-transform": ("alpha_y", "a Student-t field with two alphas"),
    "grating": (None, "a grating, its grooves along y"),
}
"""Surface kind → (the generator parameter that makes it anisotropic, None: always; what it
then is)."""


def anisotropy_of(kind: str, params) -> str | None:
    """What makes a surface of ``kind`` with generator parameters ``params`` (a scene's
    ``[surface]`` table or ``Surface.nominal``) anisotropic — its BRDF then depends on the
    incidence azimuth: oriented V-grooves, a Gaussian field with two correlation lengths, an
    ABC field with two B, a grating — or None for a statistically isotropic one (a file's
    heightfield counts as isotropic: nothing says otherwise)."""
    key, what = _ANISOTROPIC.get(kind, ("", None))
    if key is None or params.get(key) not in (None, False):
        return what
    return None


def check_relief(name: str, zmin: float, zmax: float, tile) -> None:
    """Raise a UsageError naming ``name`` unless the height range zmax − zmin is finite,
    within ``MAX_COORDINATE`` and at most ``MAX_RELIEF`` × the smaller tile side."""
    relief, side = float(zmax) - float(zmin), float(min(tile))
    big = max(abs(float(zmin)), abs(float(zmax)))
    if not (np.isfinite(relief) and big <= MAX_COORDINATE):
        raise UsageError(
            f"{name}: surface heights must be finite and within ±{MAX_COORDINATE:g} "
            f"(Embree traces in float32), got the range [{zmin:g}, {zmax:g}]"
        )
    if relief > MAX_RELIEF * side:
        raise UsageError(
            f"{name}: the surface's height range {relief:.4g} is more than "
            f"{MAX_RELIEF:g} × its tile side {side:.4g}: a grazing ray would cross "
            f"the tile ~{230 * relief / side:.2g} times (reduce the heights or "
            f"enlarge the tile)"
        )


@dataclass(frozen=True)
class Predicted:
    """Statistics a generator predicts for the surface it built (lengths in vertex units).

    ``rms_height``; ``slope_var``: per-axis slope variance of the mesh (mesh-exact);
    ``spectrum_slope_var``: the discrete-spectrum value; ``continuum_slope_var``: the dx → 0
    value; ``m`` = √(2 · slope_var), the Beckmann m of those slopes (per-axis variance m²/2).
    """

    rms_height: float
    slope_var: float
    spectrum_slope_var: float
    continuum_slope_var: float
    m: float
    alpha_x: float | None = None
    alpha_y: float | None = None

    def as_stats(self) -> dict:
        """The ``Surface.stats()`` keys: ``predicted_rms_height``, ``predicted_slope_var``,
        ``spectrum_slope_var``, ``continuum_slope_var``, ``predicted_m``; for anisotropic
        fields also ``predicted_alpha_x``/``_y`` (√(2 × slope variance) along the ensemble
        NDF's rotated axes)."""
        out = {
            "predicted_rms_height": self.rms_height,
            "predicted_slope_var": self.slope_var,
            "spectrum_slope_var": self.spectrum_slope_var,
            "continuum_slope_var": self.continuum_slope_var,
            "predicted_m": self.m,
        }
        if self.alpha_x is not None:
            out.update(predicted_alpha_x=self.alpha_x, predicted_alpha_y=self.alpha_y)
        return out


FINGERPRINT_ROWS = 1 << 16
"""Vertex or face rows ``Surface.fingerprint`` hashes at a time."""


def _frozen(array) -> bool:
    """Whether ``array`` is a read-only ndarray owning its memory (no writable view of it can
    exist)."""
    return isinstance(array, np.ndarray) and array.base is None and not array.flags.writeable


@dataclass(frozen=True, eq=False, repr=False)
class Surface:
    """A periodic microsurface tile (the contract between surfaces and the tracer).

    ``vertices`` (V, 3) float64 and ``faces`` (F, 3) int32 (normals up), read-only (a changed
    mesh is a new ``Surface``: its identity, ``fingerprint``, is computed once). A periodic
    heightfield given as ``heights`` and ``dx`` with ``vertices`` and ``faces`` None (what the
    generators and the file loader build) stores no mesh: its ``heightfield_mesh`` is derived
    on each access of ``vertices`` or ``faces`` (48 bytes per grid point, not kept; the tracer
    needs only the heights), ``replaced`` keeps it so; ``tile_size``
    (Lx, Ly) are the periods; ``nominal`` holds the generator parameters; ``heights`` (ny, nx) with
    spacing ``dx`` for heightfields (row = y index, col = x index); ``azimuth_average`` is True
    for V-grooves (the estimator averages the groove azimuth to get the isotropic V-cavity
    surface); ``warnings`` are caveats to show in reports.

    What the generator knows about its surface:

    ``ensemble_ndf``     the analytic NDF the generator samples, or None (V-grooves: the NDF
                         the tilts were drawn from; Gaussian: Beckmann(2σ/ℓ); ABC: Beckmann
                         with the predicted mesh m; file and flat: None)
    ``exact_shadowing``  the shadowing kind (``microsim.analytic.SHADOWING_KINDS``) that is
                         exact for single scattering on this surface, or None (V-grooves:
                         "vgroove", Mikkelsen 2009, eq. 25; flat: "none"; heightfields: None)
    ``predicted``        ``Predicted`` statistics (heightfields synthesised from a spectrum),
                         or None
    ``generator_stats``  a function of the surface returning the generator's own measured
                         statistics for ``stats()`` (V-grooves: the tilt distribution), or None
    ``tilt_ndf``         V-grooves: the NDF whose tilt density the groove tilts sample — for
                         oriented grooves too, where it is no NDF of the facets (their normals
                         all lie in the xz plane) but defines the continuum of tilts the tile
                         quantises; None for other surfaces
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
    ensemble_ndf: object = None
    exact_shadowing: str | None = None
    predicted: Predicted | None = None
    generator_stats: Callable[["Surface"], dict] | None = None
    tilt_ndf: object = None

    def __post_init__(self):
        if self.stores_mesh is None:
            raise UsageError(
                "Surface: give vertices and faces, or neither with heights (ny, nx) and dx "
                "for a periodic heightfield"
            )
        stored = (self.__dict__["_vertices"], self.__dict__["_faces"])
        for array in stored if self.stores_mesh else (self.heights,):
            if isinstance(array, np.ndarray):
                array.flags.writeable = False

    @property
    def stores_mesh(self) -> bool | None:
        """True when the surface holds its vertices and faces, False for a heightfield whose
        mesh is derived from its heights on access, None when it has neither."""
        stored = (self.__dict__.get("_vertices"), self.__dict__.get("_faces"))
        if all(a is not None for a in stored):
            return True
        if all(a is None for a in stored) and self.heights is not None and self.dx is not None:
            return False
        return None

    @property
    def facet_count(self) -> int:
        """The number of facets (triangles), without deriving a mesh."""
        if self.stores_mesh:
            return len(self.faces)
        ny, nx = np.shape(self.heights)
        return 2 * nx * ny

    def replaced(self, **changes) -> "Surface":
        """``dataclasses.replace`` that keeps a derived mesh derived (``dataclasses.replace``
        itself would read, and then store, the derived arrays)."""
        mesh = {"vertices": self.__dict__["_vertices"], "faces": self.__dict__["_faces"]}
        return dataclasses.replace(self, **{**mesh, **changes})

    def __repr__(self) -> str:
        """One line: kind, grid or groove count, tile, triangles and the nominal parameters."""
        shown = {"n", "dx", "tile", "size", "n_grooves", "A", "f_max"}
        parts = [self.kind]
        if self.heights is not None:
            ny, nx = self.heights.shape
            parts.append(f"grid {nx}x{ny}, dx {self.dx:g}")
        if "n_grooves" in self.nominal:
            parts.append(f"{self.nominal['n_grooves']} grooves")
        lx, ly = self.tile_size
        parts.append(f"tile {lx:g}x{ly:g}, {self.facet_count} triangles")
        parts += [
            f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
            for k, v in self.nominal.items()
            if k not in shown
        ]
        return f"Surface({', '.join(parts)})"

    @property
    def anisotropy(self) -> str | None:
        """What makes this surface anisotropic (``anisotropy_of``), or None."""
        return anisotropy_of(self.kind, self.nominal)

    def mesh(self):
        """``trimesh.Trimesh`` (process=False) of the tile, centred on the origin.

        Vertices are rounded to float32 (what Embree sees); trimesh stores them as float64
        arrays of those float32 values. Faces are int32 values.
        """
        try:
            import trimesh
        except ImportError:
            raise EnvironmentFailure(
                "Surface.mesh needs trimesh, an optional extra: pip install 'microsim[view]'"
            ) from None
        return trimesh.Trimesh(
            vertices=self.vertices.astype(np.float32),
            faces=self.faces.astype(np.int32),
            process=False,
        )

    def _cross(self) -> np.ndarray:
        v = self.vertices
        f = self.faces
        return np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])

    def fingerprint(self) -> str:
        """The mesh's identity, as ``simulate`` records it in meta ("fingerprint"): SHA-1 of
        the vertices (float64) and faces (int64), first 16 hex digits. Computed once where
        both arrays are read-only and own their memory (the surface's own arrays: nothing can
        change them), else on every call."""
        cached = self.__dict__.get("_fingerprint")
        if cached is not None:
            return cached
        digest = hashlib.sha1()
        for block in self._mesh_blocks():
            digest.update(memoryview(np.ascontiguousarray(block)).cast("B"))
        digest = digest.hexdigest()[:16]
        owners = (self.vertices, self.faces) if self.stores_mesh else (self.heights,)
        if all(_frozen(a) for a in owners):
            object.__setattr__(self, "_fingerprint", digest)
        return digest

    def _mesh_blocks(self):
        """The vertices (float64) and then the faces (int64), a block of rows at a time: of
        the stored arrays, or of the derived mesh (``heightfield_mesh_rows``) without building
        it whole."""
        if not self.stores_mesh:
            yield from heightfield_mesh_rows(self.heights, self.dx, FINGERPRINT_ROWS)
            return
        for array, dtype in ((self.vertices, np.float64), (self.faces, np.int64)):
            rows = np.asarray(array)
            for a in range(0, len(rows), FINGERPRINT_ROWS):
                yield np.asarray(rows[a : a + FINGERPRINT_ROWS], dtype=dtype)

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
        z = self.vertices[:, 2] if self.stores_mesh else self.heights
        return float(z.min()), float(z.max())

    def ndf(self):
        """Empirical NDF of the facets, weighted by projected area (``analytic.Empirical``)."""
        return Empirical(self.facet_normals(), weights=self.projected_areas())

    def stats(self) -> dict:
        """Measured statistics next to nominal and predicted (mesh-exact) values.

        Keys (lengths in vertex units, slopes dimensionless): ``triangles``, ``tile_size``,
        ``z_range``, ``slope_var_x``, ``slope_var_y`` (projected-area weighted, about zero),
        ``slope_corr`` (correlation of the two slopes over facets), ``mean_tan2`` (E[tan²θ]),
        ``m_realised`` = √(var_x + var_y) (Beckmann: per-axis variance m²/2), ``nominal``;
        heightfields add ``grid``, ``dx``, ``rms_height``; then come the generator's predictions
        (``Predicted.as_stats``) and its own measurements (``generator_stats``; V-grooves: the
        tilt distribution, see ``vgrooves.groove_stats``). With an anisotropic ensemble NDF
        (``alpha_x``, ``alpha_y``, ``rotation``): ``alpha_x_realised``/``alpha_y_realised`` =
        √(2 × slope variance) of the facets along its rotated axes.
        """
        sx, sy = facet_slopes(self.facet_normals())
        w = self.projected_areas()
        w = w / w.sum()
        vx = float(np.sum(w * sx * sx))
        vy = float(np.sum(w * sy * sy))
        cxy = float(np.sum(w * sx * sy))
        out = {
            "kind": self.kind,
            "triangles": self.facet_count,
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
            out["rms_height"] = float(np.sqrt(np.mean(self.heights**2)))
        if self.predicted is not None:
            out.update(self.predicted.as_stats())
        if isinstance(self.ensemble_ndf, AnisotropicNDF):
            ax, ay = rotated_alphas(vx, cxy, vy, self.ensemble_ndf.rotation)
            out.update(alpha_x_realised=ax, alpha_y_realised=ay)
        if self.generator_stats is not None:
            out.update(self.generator_stats(self))
        return out


def _mesh_array(name: str, index: int) -> property:
    """``Surface.vertices`` / ``faces``: the stored array, else (a heightfield that stores no
    mesh) the ``heightfield_mesh`` array derived from its heights, read-only, not kept."""
    key = "_" + name

    def get(self):
        stored = self.__dict__.get(key)
        if stored is not None or self.stores_mesh is not False:
            return stored
        array = (heightfield_vertices, heightfield_faces)[index](self.heights, self.dx)
        array.flags.writeable = False
        return array

    def put(self, value) -> None:  # the dataclass's __init__ only: a Surface is frozen
        self.__dict__[key] = value

    return property(get, put, doc=get.__doc__)


Surface.vertices = _mesh_array("vertices", 0)
Surface.faces = _mesh_array("faces", 1)


def rotated_alphas(vxx: float, vxy: float, vyy: float, rotation: float) -> tuple[float, float]:
    """(αx, αy) = √(2 × slope variance) along axes rotated by ``rotation`` degrees, from the
    slope covariance (vxx, vxy, vyy) along the grid axes (Beckmann: per-axis variance α²/2)."""
    c, s = np.cos(np.radians(rotation)), np.sin(np.radians(rotation))
    v1 = c * c * vxx + 2 * c * s * vxy + s * s * vyy
    v2 = s * s * vxx - 2 * c * s * vxy + c * c * vyy
    return float(np.sqrt(2.0 * v1)), float(np.sqrt(2.0 * v2))


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
    return heightfield_vertices(heights, dx), heightfield_faces(heights, dx)


def heightfield_vertices(heights: np.ndarray, dx: float) -> np.ndarray:
    """``heightfield_mesh``'s vertices ((ny + 1)(nx + 1), 3), filled in place."""
    ny, nx = np.shape(heights)
    x, y, _, _ = _grid_layout(ny, nx, dx, cells=False)
    vertices = np.empty(((ny + 1) * (nx + 1), 3))  # filled in place: no meshgrid, no copies
    _fill_vertex_rows(vertices.reshape(ny + 1, nx + 1, 3), heights, x, y, 0)
    return vertices


def heightfield_faces(heights: np.ndarray, dx: float) -> np.ndarray:
    """``heightfield_mesh``'s faces (2·nx·ny, 3) int32: triangles A of every cell, then B."""
    ny, nx = np.shape(heights)
    _, _, v00, corners = _grid_layout(ny, nx, dx)
    faces = np.empty((2 * nx * ny, 3), dtype=np.int32)
    for half, offsets in zip(_triangle_halves(faces, ny, nx), corners):
        for k, offset in enumerate(offsets):
            half[:, :, k] = v00 + offset
    return faces


def heightfield_mesh_rows(heights: np.ndarray, dx: float, rows: int):
    """``heightfield_mesh``'s vertices (float64) and then its faces (int64) in blocks of about
    ``rows`` rows (whole grid rows of vertices, whole rows of cells of faces), each built on
    its own: the mesh's bytes in order without the mesh."""
    ny, nx = np.shape(heights)
    x, y, _, corners = _grid_layout(ny, nx, dx, cells=False)
    step = max(1, rows // (nx + 1))
    for j in range(0, ny + 1, step):
        block = np.empty((min(step, ny + 1 - j), nx + 1, 3))
        _fill_vertex_rows(block, heights, x, y, j)
        yield block.reshape(-1, 3)
    for offsets in corners:
        for j in range(0, ny, step):
            v00 = _corner_index(nx, range(j, min(ny, j + step)))
            yield np.stack([v00 + offset for offset in offsets], axis=-1).reshape(-1, 3)


def _fill_vertex_rows(block: np.ndarray, heights: np.ndarray, x, y, j: int) -> None:
    """Vertex grid rows j … j + len(block) − 1 of ``heightfield_mesh`` into ``block``
    (rows, nx + 1, 3): x, y and the heights, the last row and column repeating the first."""
    ny, nx = np.shape(heights)
    block[:, :, 0] = x
    block[:, :, 1] = y[j : j + len(block), None]
    for r in range(len(block)):
        block[r, :-1, 2] = heights[(j + r) % ny]
    block[:, -1, 2] = block[:, 0, 2]


def _grid_layout(ny: int, nx: int, dx: float, cells: bool = True) -> tuple:
    """What ``heightfield_mesh`` lays out: the vertex columns' x and rows' y, each cell's
    (i, j) corner index v00 (ny, nx; None without ``cells``), and the corner offsets from it
    of its two triangles (v00, v01, v11) and (v00, v11, v10)."""
    x = (np.arange(nx + 1) - nx / 2.0) * dx
    y = (np.arange(ny + 1) - ny / 2.0) * dx
    v00 = _corner_index(nx, range(ny)) if cells else None
    return x, y, v00, ((0, 1, nx + 2), (0, nx + 2, nx + 1))


def _corner_index(nx: int, rows: range) -> np.ndarray:
    """The vertex index v00 = (nx + 1)·j + i of each cell (i, j) of the cell ``rows`` (len(rows),
    nx)."""
    return (nx + 1) * np.arange(rows.start, rows.stop)[:, None] + np.arange(nx)[None, :]


def _triangle_halves(faces: np.ndarray, ny: int, nx: int) -> tuple:
    """``faces``' two halves (triangles A, then B) as (ny, nx, 3) views, one row per cell."""
    return faces[: nx * ny].reshape(ny, nx, 3), faces[nx * ny :].reshape(ny, nx, 3)


def is_heightfield_mesh(
    heights: np.ndarray, dx: float, vertices: np.ndarray, faces: np.ndarray
) -> bool:
    """Whether (``vertices``, ``faces``) is exactly ``heightfield_mesh(heights, dx)``, checked
    axis by axis against its layout without building it (a few bytes per vertex at a time)."""
    ny, nx = heights.shape
    if vertices.shape != ((ny + 1) * (nx + 1), 3) or faces.shape != (2 * nx * ny, 3):
        return False
    x, y, v00, corners = _grid_layout(ny, nx, dx)
    v = vertices.reshape(ny + 1, nx + 1, 3)
    z = v[:, :, 2]
    if not (
        np.array_equal(v[:, :, 0], np.broadcast_to(x, (ny + 1, nx + 1)))
        and np.array_equal(v[:, :, 1], np.broadcast_to(y[:, None], (ny + 1, nx + 1)))
        and np.array_equal(z[:-1, :-1], heights)
        and np.array_equal(z[-1, :-1], heights[0])
        and np.array_equal(z[:, -1], z[:, 0])
    ):
        return False
    for half, offsets in zip(_triangle_halves(faces, ny, nx), corners):
        for k, offset in enumerate(offsets):
            if not np.array_equal(half[:, :, k] - offset, v00):
                return False
    return True


def flat(size: float = 1.0) -> Surface:
    """A flat square mirror at z = 0 of side ``size`` (2 triangles), periodic; nothing shadows,
    so ``exact_shadowing`` is "none"."""
    s = positive("size", size) / 2.0
    vertices = np.array([[-s, -s, 0.0], [s, -s, 0.0], [s, s, 0.0], [-s, s, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
    return Surface(
        kind="flat",
        vertices=vertices,
        faces=faces,
        tile_size=(2 * s, 2 * s),
        periodic=True,
        nominal={"size": 2 * s},
        exact_shadowing="none",
    )
