"""Measured or externally generated heightfields from files.

Formats: ``.npy`` (read through its header first), ``.npz`` (its single array or the key
'heights'; the member's header is read before it is inflated), a measured scan (``.x3p`` and
the formats of ``scan.TOPOGRAPHY_SUFFIXES``: read, form removed, missing points filled and
resampled to square cells by ``scan``, in micrometres) or whitespace-separated text (any other
suffix; at most ``MAX_TEXT_BYTES``). ``check_heightfield_file(path, dx)`` validates a file
without building anything — callers run it before creating outputs; every problem is a
one-line ``UsageError`` naming the file.
"""

from __future__ import annotations

import errno
import os
import stat
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from microsim.checks import check_memory, file_path, positive
from microsim.errors import UsageError

from . import scan
from .heightfields import MIN_GRID, traced_bytes
from .surface import Surface, check_relief

__all__ = [
    "from_file",
    "read_heights",
    "check_heightfield_file",
    "mirror_periodic",
    "MAX_TEXT_BYTES",
]

MAX_TEXT_BYTES = 64 << 20
"""Largest text heightfield read (64 MiB): ``np.loadtxt`` holds every value as a Python object
while parsing (~10× the file); save larger grids as ``.npy``."""


def _fail(path: Path, what: str) -> UsageError:
    return UsageError(f"{path}: {' '.join(str(what).split())}")


def _header(path: Path, f) -> tuple[tuple, np.dtype]:
    """(shape, dtype) from the .npy header at the current position of the binary file ``f``."""
    try:
        version = np.lib.format.read_magic(f)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(f)
        else:
            shape, _, dtype = np.lib.format.read_array_header_2_0(f)
    except (ValueError, EOFError, OSError, SyntaxError) as e:
        raise _fail(path, f"not a readable .npy array ({e or type(e).__name__})") from None
    return tuple(int(s) for s in shape), np.dtype(dtype)


def _check_shape(
    path: Path, shape: tuple, dtype: np.dtype | None, periodic: bool, max_side: int | None = None
) -> None:
    """Refuse a wrong dtype, ndim or size (``max_side``: largest side, None: any), and a grid
    whose surface would not fit in memory."""
    if dtype is not None and dtype.kind not in "iuf":
        raise _fail(path, f"heights must be real numbers, got dtype {dtype}")
    if len(shape) != 2:
        raise _fail(path, f"heights must be a 2D array (rows = y, columns = x), got shape {shape}")
    if min(shape) < MIN_GRID:
        raise _fail(
            path, f"heights grid must be at least {MIN_GRID}x{MIN_GRID}, got {shape[0]}x{shape[1]}"
        )
    if max_side is not None and max(shape) > max_side:
        raise _fail(
            path, f"heights grid must be at most {max_side}x{max_side}, got {shape[0]}x{shape[1]}"
        )
    ny, nx = shape
    points = ny * nx if periodic else (2 * ny - 2) * (2 * nx - 2)
    try:
        check_memory(
            str(path),
            traced_bytes(points),
            f"a {ny}x{nx} heightfield ({'as is' if periodic else 'mirrored'}: "
            f"{points:,} grid points × {traced_bytes(points) / points:.0f} bytes to mesh "
            f"and trace)",
        )
    except UsageError as e:
        raise UsageError(" ".join(str(e).split())) from None


def _check_npz_header(path: Path, periodic: bool, max_side: int | None = None) -> str:
    """Check the shape and dtype of the heights in an .npz from its header alone (nothing is
    inflated); returns the array's key."""
    key = _npz_member(path)
    with zipfile.ZipFile(path) as z:
        member = key + ".npy" if key + ".npy" in z.namelist() else key
        with z.open(member) as f:
            shape, dtype = _header(path, f)
    _check_shape(path, shape, dtype, periodic, max_side)
    return key


def _npz_member(path: Path) -> str:
    """Name of the array a .npz holds: 'heights', or its only member."""
    try:
        with zipfile.ZipFile(path) as z:
            names = [n[:-4] if n.endswith(".npy") else n for n in z.namelist()]
    except (zipfile.BadZipFile, OSError, EOFError) as e:
        raise _fail(path, f"not a readable .npz archive ({e or type(e).__name__})") from None
    if "heights" in names:
        return "heights"
    if len(names) != 1:
        raise _fail(path, f".npz must hold a single array or the key 'heights', found keys {names}")
    return names[0]


def _regular_file(path: Path) -> None:
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise _fail(path, "no such heightfield file") from None
    except OSError as e:  # a symlink loop, a name too long, a file used as a directory
        if e.errno not in (errno.ELOOP, errno.ENAMETOOLONG, errno.ENOTDIR):
            raise
        raise _fail(path, f"{os.strerror(e.errno)}; not a usable heightfield file") from None
    if not stat.S_ISREG(mode):
        raise _fail(path, "not a regular file (a heightfield file must be .npy, .npz or text)")


FLAT_RELIEF = 1e-6
"""Smallest height range of a heightfield file, in units of dx: a flatter one (slopes below
1e-6) is a mirror, to be given as ``kind = "flat"``."""


def _check_values(path: Path, heights, dx, periodic: bool) -> None:
    """Refuse NaN or inf heights and, when ``dx`` is given, a surface the tracer cannot take
    (``check_relief`` on the tile ``from_file`` builds) or a flat one (``FLAT_RELIEF``).
    ``heights`` may be a memory map: it is read in slabs of 1024 rows."""
    bad, lo, hi = 0, np.inf, -np.inf
    for i in range(0, heights.shape[0], 1024):
        slab = np.asarray(heights[i : i + 1024], dtype=np.float64)
        finite = np.isfinite(slab)
        bad += int(slab.size - np.count_nonzero(finite))
        if finite.any():
            lo, hi = min(lo, slab[finite].min()), max(hi, slab[finite].max())
    if bad:
        raise _fail(path, f"heights contain NaN or inf ({bad} values); fill or crop them first")
    if dx is None:
        return
    ny, nx = heights.shape
    tile = (nx * dx, ny * dx) if periodic else ((2 * nx - 2) * dx, (2 * ny - 2) * dx)
    check_relief(str(path), lo, hi, tile)
    if hi - lo < FLAT_RELIEF * dx:
        raise _fail(
            path,
            f"heights vary by {hi - lo:g}, less than {FLAT_RELIEF:g} × dx: a flat "
            f'surface; use kind = "flat"',
        )


@dataclass(frozen=True)
class _ScanGrid:
    """A scan prepared for the mesh (``_scan_grid``): ``heights`` (µm, square cells ``dx``
    µm apart), the scan's own grid shape, what was done to it as ``nominal`` entries and as
    report lines (``notes``)."""

    heights: np.ndarray
    dx: float
    input_shape: tuple[int, int]
    nominal: dict
    notes: tuple[str, ...]


def _form(path, form) -> str:
    """``form`` checked (``scan.FORMS``), or the file's default (``scan.default_form``)."""
    if form is None:
        return scan.default_form(path)
    scan.form_degree(form)
    return form


def _scan_grid(path: Path, dx, periodic: bool, form: str, max_side=None) -> _ScanGrid:
    """A scan file's heights in micrometres (``scan.SCAN_UNIT``): read, checked in size (as
    read and as resampled), the form removed, missing points filled, resampled to square
    cells (``scan``). ``dx`` must be None: the scan gives its spacing."""
    if dx is not None:
        raise UsageError(f"dx: the scan {path} gives its own spacing; leave dx out (got {dx!r})")
    measured = scan.read_scan(path)
    h = measured.heights / scan.SCAN_UNIT
    dx, dy = measured.dx / scan.SCAN_UNIT, measured.dy / scan.SCAN_UNIT
    _check_shape(path, h.shape, None, periodic, max_side)
    square, step = scan.square_shape(h.shape, dx, dy)
    _check_shape(path, square, None, periodic, max_side)
    try:
        h, removed = scan.remove_form(h, dx, dy, form)
        h, filled = scan.fill_missing(h, dx, dy)
    except UsageError as e:
        raise _fail(path, e) from None
    h, step = scan.square_grid(h, dx, dy)
    notes = [f"file: {path.name}: {removed.describe('µm')}"] if form != "none" else []
    if filled:
        notes.append(
            f"file: {path.name}: {filled:.2%} of the points were not measured; filled by "
            f"harmonic inpainting from the measured points around them"
        )
    if square != measured.heights.shape:
        notes.append(
            f"file: {path.name}: cells {dx:.4g} × {dy:.4g} µm resampled to {step:.4g} µm "
            f"square by linear interpolation along {'y' if dy > dx else 'x'}"
        )
    nominal = {
        "unit": "µm",
        "scan_spacing": (dx, dy),
        "filled_fraction": filled,
        **removed.nominal(),
    }
    return _ScanGrid(h, step, tuple(measured.heights.shape), nominal, tuple(notes))


def _array_form(path: Path, heights, dx: float, form: str):
    """A heightfield array with ``form`` removed (none: as is), the nominal entries and the
    report lines saying so."""
    if form == "none":
        return heights, {}, ()
    heights, removed = scan.remove_form(heights, dx, dx, form)
    return heights, removed.nominal(), (f"file: {path.name}: {removed.describe()}",)


def check_heightfield_file(
    path, dx=None, periodic: bool = False, max_side: int | None = None, form: str | None = None
) -> tuple[int, int]:
    """Validate a heightfield file for ``from_file(path, dx, periodic, form)`` without
    building the surface; returns the grid shape (ny, nx) it meshes. Headers are read first
    (shape, dtype, size, at most ``max_side`` per side if given: a file that would not fit in
    memory is refused before it is read); the values are then checked to be finite (.npy
    through a memory map, in slabs) and, given ``dx``, neither flat nor too tall or large for
    the tracer (``_check_values``; after the form's removal). ``dx`` (None: those two not
    checked) must be a finite length > 0. A scan (``scan.is_scan``) is read and prepared as
    ``from_file`` does, and checked with its own spacing (``dx`` must then be None). Every
    problem raises a one-line UsageError naming the file (or ``dx``, ``form``); OS errors
    such as a permission denied propagate as ``OSError``."""
    path = file_path("path", path)
    form = _form(path, form)
    if dx is not None:
        positive("dx", dx)
    _regular_file(path)
    if scan.is_scan(path):
        grid = _scan_grid(path, dx, periodic, form, max_side)
        _check_values(path, grid.heights, grid.dx, periodic)
        return grid.heights.shape
    if path.suffix == ".npy":
        with open(path, "rb") as f:
            shape, dtype = _header(path, f)
            offset = f.tell()
        _check_shape(path, shape, dtype, periodic, max_side)
        need = offset + dtype.itemsize * shape[0] * shape[1]
        size = path.stat().st_size
        if size < need:
            raise _fail(path, f"truncated .npy file: {size} bytes, its header promises {need}")
        try:
            a = np.load(path, mmap_mode="r", allow_pickle=False)
        except (ValueError, EOFError, OSError) as e:
            raise _fail(path, f"not a readable .npy array ({e})") from None
        _check_values(path, a, dx, periodic)
        if form != "none" and dx is not None:
            _check_values(path, _array_form(path, np.asarray(a), dx, form)[0], dx, periodic)
        return shape
    if path.suffix == ".npz":
        _check_npz_header(path, periodic, max_side)
    elif path.stat().st_size > MAX_TEXT_BYTES:
        raise _fail(
            path,
            f"text heightfield larger than {MAX_TEXT_BYTES >> 20} MiB "
            f"({path.stat().st_size:,} bytes); save it as .npy",
        )
    heights = read_heights(path, periodic=periodic)
    _check_shape(path, heights.shape, None, periodic, max_side)
    _check_values(path, heights, dx, periodic)
    if form != "none" and dx is not None:
        _check_values(path, _array_form(path, heights, dx, form)[0], dx, periodic)
    return heights.shape


def read_heights(path, periodic: bool = False) -> np.ndarray:
    """A 2D float64 height array from .npy, .npz (its single array, or the key 'heights') or
    whitespace-separated text (any other suffix). Raises a one-line UsageError naming the file
    for a missing or unreadable file, a wrong dtype, ndim or size, non-finite values, or a
    grid whose surface (mirrored unless ``periodic``) would not fit in memory."""
    path = file_path("path", path)
    _regular_file(path)
    try:
        if path.suffix == ".npy":
            with open(path, "rb") as f:
                shape, dtype = _header(path, f)
            _check_shape(path, shape, dtype, periodic)
            a = np.load(path, allow_pickle=False)
        elif path.suffix == ".npz":
            key = _check_npz_header(path, periodic)
            with np.load(path, allow_pickle=False) as z:
                a = z[key]
        else:
            if path.stat().st_size > MAX_TEXT_BYTES:
                raise _fail(
                    path,
                    f"text heightfield larger than {MAX_TEXT_BYTES >> 20} MiB; save it as .npy",
                )
            with warnings.catch_warnings():  # an empty file: refused below, in one line
                warnings.simplefilter("ignore", UserWarning)
                a = np.loadtxt(path, ndmin=2)
            if a.size == 0:
                raise _fail(path, "the text file holds no heights")
    except UsageError:
        raise
    except (ValueError, EOFError, zipfile.BadZipFile) as e:
        raise _fail(path, f"cannot read heights ({e or type(e).__name__})") from None
    a = np.asarray(a)
    if not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
        raise _fail(path, f"heights must be real numbers, got dtype {a.dtype}")
    _check_shape(path, a.shape, None, periodic)
    a = a.astype(np.float64)
    if not np.all(np.isfinite(a)):
        raise _fail(
            path,
            f"heights contain NaN or inf ({int(np.sum(~np.isfinite(a)))} values); "
            f"fill or crop them first",
        )
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


def from_file(path, dx: float | None = None, periodic: bool = False, form: str | None = None):
    """Heightfield surface from a file: an array (``read_heights``) with grid spacing ``dx``
    (required), or a scan (``scan.is_scan``: X3P or a SurfaceTopography format), which gives
    its own spacing (``dx`` must be None) and is used in micrometres (``_scan_grid``).

    ``form`` (``scan.FORMS``; None: "plane" for a scan, "none" for an array) is the
    least-squares polynomial subtracted first (``scan.remove_form``); what was removed is
    recorded in ``nominal`` (``form``, ``form_rms_removed``) and the surface's warnings (with
    its coefficients), as are a scan's filled points
    and resampling. ``periodic=True``: the caller asserts the grid already tiles seamlessly
    (the sample after the last column is the first column) and it is used as is. Otherwise it
    is made periodic by mirroring (``mirror_periodic``), which doubles the tile, keeps every
    slope magnitude and symmetrises the slope distribution (each slope also appears with the
    opposite sign). The mean height is subtracted.
    """
    form = _form(path, form)
    if scan.is_scan(path):
        grid = _scan_grid(file_path("path", path), dx, periodic, form)
        raw, dx, input_shape, extra, notes = (
            grid.heights,
            grid.dx,
            grid.input_shape,
            grid.nominal,
            grid.notes,
        )
    else:
        dx = positive("dx", dx)
        raw = read_heights(path, periodic=periodic)
        input_shape = raw.shape
        raw, extra, notes = _array_form(Path(path), raw, dx, form)
    _check_values(Path(path), raw, dx, periodic)
    h = raw if periodic else mirror_periodic(raw)
    h = h - h.mean()
    ny, nx = h.shape
    nominal = {
        "path": str(path),
        "dx": dx,
        "periodic_input": bool(periodic),
        "input_shape": tuple(int(s) for s in input_shape),
        **extra,
    }
    warns = notes + (
        ()
        if periodic
        else (
            f"file: {Path(path).name} was made periodic by mirroring "
            f"(tile {nx}x{ny} from {raw.shape[1]}x{raw.shape[0]})",
        )
    )
    return Surface(
        kind="file",
        vertices=None,  # derived from the heights where needed
        faces=None,
        tile_size=(nx * dx, ny * dx),
        periodic=True,
        nominal=nominal,
        heights=h,
        dx=dx,
        warnings=warns,
    )
