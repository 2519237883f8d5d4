"""Measured surface scans: reading, missing points, square cells and form removal.

Formats: ISO 25178-72 X3P (``.x3p``) read and written through ``x3pio``; the instrument
formats of SurfaceTopography (the extra ``topography``: Digital Surf ``.sur``, Gwyddion
``.gwy``, Nanoscope ``.spm``, ..., ``TOPOGRAPHY_SUFFIXES``) read through
``SurfaceTopography.read_topography``. ``read_scan`` gives the heights and the lateral
spacings in metres, NaN where a point was not measured.

Units: the simulator is unit-free; a scan enters it in micrometres (``SCAN_UNIT``), the unit
the scenes' wavelengths use, so heights, ``dx`` and every length the surface reports are µm.

Preparing a scan for the mesh (``loader.from_file`` runs these in this order):

* ``remove_form``: the F-operator of ISO 25178-2:2012 with the least-squares form of
  ISO 25178-3:2012 — the polynomial in x and y of the given degree (a plane by default)
  fitted to the measured points is subtracted;
* ``fill_missing``: missing points are filled by harmonic inpainting (the discrete Laplace
  equation over the holes, the measured points fixed); at most ``MAX_MISSING`` of the points;
* ``square_grid``: the mesh has square cells, so a scan with dx != dy is resampled to the finer
  spacing by linear interpolation along the coarser axis (the other axis keeps its samples).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from microsim.atomic import atomic_open
from microsim.checks import file_path, positive
from microsim.errors import UsageError

__all__ = [
    "Scan",
    "FormRemoved",
    "read_scan",
    "write_x3p",
    "is_scan",
    "default_form",
    "form_degree",
    "remove_form",
    "fill_missing",
    "square_shape",
    "square_grid",
    "FORMS",
    "SCAN_UNIT",
    "MAX_MISSING",
    "TOPOGRAPHY_SUFFIXES",
]

SCAN_UNIT = 1e-6
"""Metres per length unit of a scan in microsim: scans are used in micrometres."""
MAX_MISSING = 0.2
"""Largest fraction of missing (NaN) points that ``fill_missing`` fills; more is refused."""
SQUARE_TOLERANCE = 1e-6
"""Relative difference of dx and dy below which the grid counts as square (dx is used)."""
FORMS = ("none", "plane", "poly2", "poly3", "poly4")
"""Form removal: none, the least-squares plane, or a polynomial of degree 2 to 4 (a form's
index here is its degree)."""
TOPOGRAPHY_SUFFIXES = (
    *("sdf", "spm", "001", "002", "003", "004", "005", "mdt", "opd", "opdx", "ibw", "mi"),
    *("datx", "sur", "tmd", "vk3", "vk4", "vk6", "vk7", "zmg", "zon", "os3d", "al3d", "ezd"),
    *("nid", "bcr", "bcrf", "gwy", "plu", "apx", "frt", "lext", "oir", "poir", "plux", "jpk"),
    *("mnt", "qep", "nms", "nc"),
)
"""Suffixes read through SurfaceTopography: its instrument formats. Its generic ones (text,
.npy, .npz, .mat, .h5, .tif, ...) are not: text and NumPy files are read by ``loader``."""
_INSTALL = "pip install microsim[topography]"


@dataclass(frozen=True)
class Scan:
    """A measured surface: ``heights`` (ny, nx) in metres (row = y, column = x; NaN where not
    measured) on a grid ``dx`` (along x) by ``dy`` (along y) metres."""

    heights: np.ndarray
    dx: float
    dy: float


@dataclass(frozen=True)
class FormRemoved:
    """The form ``remove_form`` subtracted: ``method`` (one of ``FORMS``), the polynomial's
    ``terms`` ("1", "x", "y", "x^2", "x*y", ...; x, y from the scan's centre) with their
    ``coefficients`` (in the scan's length unit), and ``rms_removed``: the rms of the
    subtracted form over the measured points about its mean (the height offset, which the
    mesh removes anyway, is not counted)."""

    method: str
    terms: tuple[str, ...] = ()
    coefficients: tuple[float, ...] = ()
    rms_removed: float = 0.0

    def nominal(self) -> dict:
        """The entries a surface's ``nominal`` records: ``form`` (the method) and
        ``form_rms_removed``; the coefficients are in ``describe``'s line."""
        return {"form": self.method, "form_rms_removed": self.rms_removed}

    def describe(self, unit: str = "") -> str:
        """One line for reports: the method, the coefficients and the rms removed."""
        unit = f" {unit}" if unit else ""
        terms = ", ".join(f"{t}: {c:.4g}" for t, c in zip(self.terms, self.coefficients))
        return f"form removed: {self.method} ({terms}), rms {self.rms_removed:.4g}{unit}"


def is_scan(path) -> bool:
    """Whether ``path`` names a scan format (X3P or ``TOPOGRAPHY_SUFFIXES``) by its suffix."""
    suffix = Path(path).suffix.lower().lstrip(".")
    return suffix == "x3p" or suffix in TOPOGRAPHY_SUFFIXES


def default_form(path) -> str:
    """The form removed when none is asked: the plane for a scan (metrology's default, an
    instrument's tilt), none for a heightfield array (already a surface's heights)."""
    return "plane" if is_scan(path) else "none"


def form_degree(form: str) -> int:
    """Polynomial degree of a ``FORMS`` value (0 for "none"); other values are refused."""
    if form not in FORMS:
        raise UsageError(f"form must be one of {', '.join(FORMS)}, got {form!r}")
    return FORMS.index(form)


def _fail(path, what) -> UsageError:
    return UsageError(f"{path}: {' '.join(str(what).split())}")


def read_scan(path) -> Scan:
    """The surface in a scan file (X3P, or a SurfaceTopography format): heights and spacings
    in metres. A file that is not a readable surface on a regular grid with its lateral size
    and unit is a one-line UsageError naming it; OS errors propagate."""
    path = file_path("path", path)
    if not path.is_file():
        raise _fail(path, "no such scan file")
    if path.suffix.lower() == ".x3p":
        return _read_x3p(path)
    if not is_scan(path):
        raise _fail(
            path,
            f"not a scan format; scans are .x3p or, through SurfaceTopography, "
            f".{', .'.join(TOPOGRAPHY_SUFFIXES)}",
        )
    return _read_topography(path)


def _read_x3p(path: Path) -> Scan:
    import x3pio

    try:
        x3p = x3pio.read(path)
    except x3pio.X3pError as e:
        raise _fail(path, f"not a readable X3P file ({e})") from None
    if not isinstance(x3p, x3pio.Surface):
        raise _fail(path, f"holds a {type(x3p).__name__}, not a surface (an X3P of type SUR)")
    if not x3p.is_regular_grid:
        raise _fail(path, "holds a surface on an irregular grid; a regular grid is needed")
    layer = x3p.layers[0]
    dx, dy = layer.spacing
    return Scan(np.array(layer.z, dtype=np.float64), float(dx), float(dy))


def _read_topography(path: Path) -> Scan:
    try:
        import SurfaceTopography
    except ImportError:
        raise _fail(path, f"reading this format needs SurfaceTopography: {_INSTALL}") from None
    try:
        topography = SurfaceTopography.read_topography(str(path))
    except OSError:
        raise
    except Exception as e:  # its readers raise many types; the first line says what failed
        first = next((line for line in str(e).splitlines() if line.strip()), type(e).__name__)
        raise _fail(path, f"SurfaceTopography cannot read it ({first.strip()})") from None
    if topography.dim != 2 or not topography.is_uniform:
        raise _fail(path, "holds a line profile or an irregular grid; a 2-D uniform grid is needed")
    if topography.unit is None or topography.physical_sizes is None:
        raise _fail(path, "gives no length unit or lateral size; save it as .x3p or .npy")
    metres = topography.to_unit("m")
    heights = np.ma.filled(np.ma.asarray(metres.heights(), dtype=np.float64), np.nan)
    sx, sy = metres.pixel_size  # SurfaceTopography's arrays are indexed [x, y]
    return Scan(np.ascontiguousarray(heights.T), float(sx), float(sy))


def write_x3p(path, heights, dx: float, dy: float | None = None) -> None:
    """Write ``heights`` (ny, nx; metres, NaN: not measured) on a grid ``dx`` by ``dy``
    (default ``dx``) metres to the X3P file ``path`` (float64 heights), atomically."""
    import x3pio

    dx = positive("dx", dx)
    dy = dx if dy is None else positive("dy", dy)
    heights = np.asarray(heights, dtype=np.float64)
    if heights.ndim != 2:
        raise UsageError(f"heights must be a 2-D array (rows = y), got shape {heights.shape}")
    try:
        surface = x3pio.Surface.from_array(heights, x_scale=dx, y_scale=dy)
    except x3pio.X3pError as e:
        raise UsageError(f"heights: cannot be written as X3P ({e})") from None
    with atomic_open(path, "wb") as fh:
        surface.save(fh)


def _terms(degree: int) -> list[tuple[int, int]]:
    """Exponents (a, b) of x^a y^b for a + b <= degree, by degree, x first."""
    return [(d - b, b) for d in range(degree + 1) for b in range(d + 1)]


def _term_name(a: int, b: int) -> str:
    parts = [f"{v}^{p}" if p > 1 else v for v, p in (("x", a), ("y", b)) if p]
    return "*".join(parts) or "1"


def remove_form(heights, dx: float, dy: float, form: str) -> tuple[np.ndarray, FormRemoved]:
    """``heights`` minus its least-squares polynomial ``form`` (``FORMS``) fitted to the
    finite points, x = column·dx and y = row·dy from the grid's centre (NaN points stay NaN);
    and the ``FormRemoved``. Solved by the normal equations in coordinates scaled to
    [-1, 1] (the moments of the measured points), the coefficients then rescaled."""
    degree = form_degree(form)
    heights = np.asarray(heights, dtype=np.float64)
    if degree == 0:
        return heights, FormRemoved("none")
    ny, nx = heights.shape
    u = np.linspace(-1.0, 1.0, nx)
    v = np.linspace(-1.0, 1.0, ny)
    rows, cols = np.nonzero(np.isfinite(heights))
    z = heights[rows, cols]
    terms = _terms(degree)
    if len(z) < len(terms):
        raise UsageError(f"form {form!r}: {len(z)} measured points, fewer than its terms")
    pu = [u[cols] ** p for p in range(2 * degree + 1)]
    pv = [v[rows] ** p for p in range(2 * degree + 1)]
    gram = np.array([[np.dot(pu[a + c], pv[b + d]) for c, d in terms] for a, b in terms])
    rhs = np.array([np.dot(pu[a] * pv[b], z) for a, b in terms])
    scaled = np.linalg.solve(gram, rhs)
    fitted = sum(c * np.outer(v**b, u**a) for c, (a, b) in zip(scaled, terms))
    measured = fitted[rows, cols]
    half_x, half_y = (nx - 1) * dx / 2, (ny - 1) * dy / 2
    record = FormRemoved(
        form,
        tuple(_term_name(a, b) for a, b in terms),
        tuple(float(c / (half_x**a * half_y**b)) for c, (a, b) in zip(scaled, terms)),
        float(np.sqrt(np.mean((measured - measured.mean()) ** 2))),
    )
    return heights - fitted, record


def fill_missing(heights, dx: float, dy: float, max_fraction: float = MAX_MISSING):
    """``heights`` with its NaN (and inf) points filled, and the fraction filled, by harmonic
    inpainting: the filled heights solve the discrete Laplace equation (weights 1/dx² along x,
    1/dy² along y) with the measured points held fixed and no flux across the grid's border
    (the Laplace fill of Gwyddion and SurfaceTopography's harmonic one), one sparse linear
    system over the missing points (``scipy.sparse.linalg.spsolve``). It is exact on a plane
    inside a hole and never overshoots the measured heights around it. More than
    ``max_fraction`` missing is a UsageError."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.linalg import spsolve

    heights = np.asarray(heights, dtype=np.float64)
    missing = ~np.isfinite(heights)
    fraction = float(missing.mean())
    if not missing.any():
        return heights, 0.0
    if fraction > max_fraction:
        raise UsageError(
            f"heights: {fraction:.1%} of the points are missing (NaN); at most "
            f"{max_fraction:.0%} are filled — crop the scan to its measured part"
        )
    ny, nx = heights.shape
    rows, cols = np.nonzero(missing)
    n = len(rows)
    unknown = np.full(heights.shape, -1, dtype=np.intp)
    unknown[rows, cols] = np.arange(n)
    diagonal, rhs = np.zeros(n), np.zeros(n)
    links = ([np.arange(n)], [np.arange(n)], [diagonal])  # (row, column, weight) entries
    for di, dj, weight in ((1, 0, dy**-2), (-1, 0, dy**-2), (0, 1, dx**-2), (0, -1, dx**-2)):
        r, c = rows + di, cols + dj
        inside = (r >= 0) & (r < ny) & (c >= 0) & (c < nx)
        k, r, c = np.nonzero(inside)[0], r[inside], c[inside]
        diagonal[k] += weight
        other = unknown[r, c]
        free = other >= 0
        links[0].append(k[free])
        links[1].append(other[free])
        links[2].append(np.full(int(free.sum()), -weight))
        np.add.at(rhs, k[~free], weight * heights[r[~free], c[~free]])
    i, j, w = (np.concatenate(part) for part in links)
    out = heights.copy()
    out[rows, cols] = spsolve(csr_matrix((w, (i, j)), shape=(n, n)), rhs)
    return out, fraction


def square_shape(shape: tuple[int, int], dx: float, dy: float) -> tuple[tuple[int, int], float]:
    """Shape (ny, nx) and spacing of ``square_grid``'s result for a grid ``shape``, ``dx``
    by ``dy``: the finer spacing, as many samples along the coarser axis as fit in its
    length (dx and dy within ``SQUARE_TOLERANCE``: unchanged, spacing dx)."""
    ny, nx = shape
    if abs(dx - dy) <= SQUARE_TOLERANCE * min(dx, dy):
        return (ny, nx), dx
    step = min(dx, dy)
    if dy > dx:
        return (int(np.floor((ny - 1) * dy / step + 1e-9)) + 1, nx), step
    return (ny, int(np.floor((nx - 1) * dx / step + 1e-9)) + 1), step


def square_grid(heights, dx: float, dy: float) -> tuple[np.ndarray, float]:
    """``heights`` (finite) on square cells of the finer spacing (``square_shape``),
    linearly interpolated along the coarser axis; and that spacing."""
    heights = np.asarray(heights, dtype=np.float64)
    shape, step = square_shape(heights.shape, dx, dy)
    if shape == heights.shape:
        return heights, step
    axis = 0 if shape[0] != heights.shape[0] else 1
    coarse = dy if axis == 0 else dx
    n = heights.shape[axis]
    t = np.arange(shape[axis]) * (step / coarse)
    i = np.minimum(np.floor(t).astype(np.intp), n - 2)
    w = t - i
    lo, hi = np.take(heights, i, axis=axis), np.take(heights, i + 1, axis=axis)
    w = w[:, None] if axis == 0 else w[None, :]
    return lo * (1.0 - w) + hi * w, step
