"""The MERL BRDF format (Matusik, Pfister, Brand & McMillan 2003): write, read, use as a reference.

Coordinates (Rusinkiewicz 1998, half/difference angles). For unit wi, wo (away from the surface,
n = +z) the half vector h = (wi + wo)/|wi + wo| has polar angles (θh, φh); the difference
vector d = R_y(−θh) R_z(−φh) wi is wi seen in a frame whose pole is h, with polar angles
(θd, φd). Conversely wi = R_z(φh) R_y(θh) d and wo = R_z(φh) R_y(θh) (−dx, −dy, dz) — wo is
wi mirrored about h, wo = 2(wi·h)h − wi — so θd is half the angle between wi and wo
(cos 2θd = wi·wo). R_z(α) turns about +z by α, R_y(α) about +y (right-handed). An isotropic
BRDF does not depend on φh (this module takes φh = 0 when it builds directions). Reciprocity,
f(wi, wo) = f(wo, wi), swaps wi and wo, which takes d to (−dx, −dy, dz): φd → φd + π, so
φd ∈ [0, π) is enough. (Isotropy's mirror symmetry y → −y also gives φd → −φd, hence
f(φd) = f(π − φd): the 180 stored φd values hold each value twice; the format keeps both.)

Grid (MERL's reference reader, BRDFRead.cpp, as cells; angles in degrees):
    θh: i = ⌊90 √(θh / 90°)⌋ ∈ [0, 89] (clamped): cell i covers [(i/90)², ((i+1)/90)²)·90°,
        (2i + 1)/90° wide — 0.011° at the specular peak θh = 0, 1.99° at the last cell, so
        narrow peaks are resolved where they live (the square-root mapping);
    θd: j = ⌊θd / 1°⌋ ∈ [0, 89]: 90 cells of 1° over [0°, 90°);
    φd: k = ⌊φd / 1°⌋ ∈ [0, 179] after φd < 0 → φd + 180° (reciprocity): 180 cells of 1°.
The format does not say where inside its cell a value lies; this module puts each sample at
its cell's centre in the index coordinates, θh = ((i + ½)/90)²·90°, θd = j + ½°,
φd = k + ½° (``sample_angles_rad``): there the reader's cell value has no first-order bias.

File layout (34,992,012 bytes): a 12-byte header of three little-endian int32, (90, 90, 180)
(the reference reader checks only that their product is 1,458,000); then 3 × 1,458,000
little-endian float64, all red values, then all green, then all blue; within a channel the
value of cell (i, j, k) is at ((i·90) + j)·180 + k (φd fastest, θh slowest). Values are raw:
the BRDF in sr⁻¹ (no cosine) is raw × scale, with scales red 1/1500, green 1.15/1500 and blue
1.66/1500 — multiplied on reading, as the reference reader does, divided on writing.
Negative values mark samples without data (the reference reader prints "Below horizon." for
them): the database's cells whose directions lie below the horizon or were not measured.
``write_merl`` writes −1 where the cell's centre has wi or wo below the horizon (z ≤ 1e-9);
``read_merl`` refuses a file in which no cell holds data in all three channels.

Lookup (``MERLBRDF.f``, in index coordinates u = (90 √(θh/90°), θd/1°, φd/1°), each
sample centre at u = index + ½):
    "reader"      the value of the cell holding (θh, θd, φd), as BRDFRead.cpp computes it
                  (θ from atan2 instead of acos: the same angles, accurate near the pole):
                  piecewise constant, resolution 1° in θd and φd and (2i + 1)/90° in θh. Its
                  error f(centre) − f ≈ Σ_u ∂f/∂u · s_u, s_u the offset to the centre, uniform
                  on [−½, ½): RMS² ≈ Σ_u (∂f/∂u)²/12 — first order.
    "linear"      trilinear between the eight surrounding centres (φd periodic with period
                  180°, u clamped at the first and last centres): error ≈ −½ Σ_u ∂²f/∂u²
                  t_u(1 − t_u), t_u the fraction across the cell — second order (mean −∂²f/∂u²/12,
                  an overestimate of the convex lobe tails).
    "log-linear"  the same on ln max(f, ``table.FLOOR``), exponentiated (as ``BRDFTable``):
                  relative error ≈ −½ Σ_u ∂²ln f/∂u² t_u(1 − t_u), small where a lobe is
                  close to exponential in u.
An invalid sample reads as 0 (reader) or is left out of the interpolation (the weights
renormalised over the valid corners; 0 if none is valid). Pairs with wi or wo below the
horizon give 0.

Reference for the fits: ``MERLBRDF.table(theta_i, bins)`` is the ``BRDFTable`` of its bin
averages (``sim.predict``, deterministic quadrature), with every bin touching an invalid
sample set to 0; ``result_of_table`` makes a ``Result`` of any table for
``analysis.fits.fit_all``. ``low2012_result`` does both the way Löw et al. 2012 (§5.1) fit
MERL materials: θi in 10° steps, 1° bins in θo and φo, near-grazing angles left out.
"""

from __future__ import annotations

import dataclasses
import os
import stat
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, ClassVar

import numpy as np

from microsim import checks as _checks
from microsim import vectors
from microsim.atomic import atomic_open
from microsim.bins import Bins
from microsim.errors import UsageError
from microsim.sim.predict import bin_average
from microsim.sim.result import Result

from .table import FLOOR, BRDFTable

__all__ = [
    "MERLBRDF",
    "read_merl",
    "write_merl",
    "result_of_table",
    "low2012_result",
    "rusinkiewicz_rad",
    "from_rusinkiewicz_rad",
    "sample_angles_rad",
    "MERL_SHAPE",
    "MERL_SAMPLES",
    "MERL_FILE_BYTES",
    "MERL_SCALE",
    "CHANNELS",
    "LOOKUPS",
    "LUMINANCE",
    "EXACT_COUNT",
    "LOW2012_THETA_I",
    "LOW2012_BINS",
    "LOW2012_THETA_MAX",
]

MERL_SHAPE = (90, 90, 180)
"""Cells (θh, θd, φd) of one channel."""
MERL_SAMPLES = 90 * 90 * 180
"""1,458,000 values per channel."""
_HEADER = 12
MERL_FILE_BYTES = _HEADER + 3 * 8 * MERL_SAMPLES
"""34,992,012: three int32, then 3 × 1,458,000 float64."""
MERL_SCALE = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)
"""Red, green, blue: BRDF (sr⁻¹) = raw file value × scale."""
INVALID = -1.0
"""Raw value ``write_merl`` writes for a sample without data (any negative value reads so)."""
HORIZON = 1e-9
"""A sample direction with z ≤ this is below the horizon (written as ``INVALID``)."""
CHANNELS = ("red", "green", "blue", "luminance")
LUMINANCE = (0.2126, 0.7152, 0.0722)
"""Y of linear Rec. 709 RGB: the luminance channel (MERL's RGB taken as linear Rec. 709 —
the database does not name its primaries)."""
LOOKUPS = ("reader", "linear", "log-linear")
EXACT_COUNT = np.iinfo(np.int32).max
"""``Result.counts`` of a used bin in ``result_of_table``: a marker, not events (the values
are taken as exact), above any ``min_events`` a fit asks for."""

LOW2012_THETA_I = tuple(float(t) for t in range(0, 80, 10))
"""Incidences 0°, 10°, …, 70°: Löw et al. 2012, §5.1, sample θi "with 10 degree steps" and
leave out near-grazing angles (which θi they keep is not stated; θi < 80° as for θo)."""
LOW2012_BINS = Bins(n_theta=90, n_phi=181, folded=True)
"""1° bins in θo and in Δφ over [0°, 180°] (Löw: θo and φo "in one degree steps, yielding
360 × 80 samples per sampled incident angle"; isotropy folds ±Δφ)."""
LOW2012_THETA_MAX = 80.0
"""θo bins above 80° are left out (Löw's 80 θo samples; MERL data near grazing is unreliable,
Ngan et al. 2005, as Löw cites)."""

_CHUNK = 2**18  # direction pairs per call of a user's brdf in write_merl


# --- coordinates -------------------------------------------------------------------------------
def rusinkiewicz_rad(wi, wo) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(θh, θd, φd) in radians of unit directions wi, wo (..., 3) (module docstring);
    φd ∈ (−π, π] as atan2 gives it (the reader folds it onto [0, π))."""
    wi = _checks.directions("wi", wi)
    wo = _checks.directions("wo", wo)
    wi, wo = np.broadcast_arrays(wi, wo)
    return _rusinkiewicz(wi, wo)


def _rusinkiewicz(wi, wo):
    h = wi + wo
    h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
    rho = np.hypot(h[..., 0], h[..., 1])
    theta_h = np.arctan2(rho, h[..., 2])
    phi_h = np.arctan2(h[..., 1], h[..., 0])
    c, s = np.cos(phi_h), np.sin(phi_h)
    tx = c * wi[..., 0] + s * wi[..., 1]  # R_z(−φh) wi
    ty = -s * wi[..., 0] + c * wi[..., 1]
    ct, st = np.cos(theta_h), np.sin(theta_h)
    dx = ct * tx - st * wi[..., 2]  # R_y(−θh)
    dz = st * tx + ct * wi[..., 2]
    theta_d = np.arctan2(np.hypot(dx, ty), dz)
    phi_d = np.arctan2(ty, dx)
    return theta_h, theta_d, phi_d


def from_rusinkiewicz_rad(theta_h, theta_d, phi_d) -> tuple[np.ndarray, np.ndarray]:
    """Unit (wi, wo), each broadcast(θh, θd, φd) + (3,), with φh = 0: the inverse of
    ``rusinkiewicz_rad`` (radians; module docstring)."""
    th, td, pd = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (theta_h, theta_d, phi_d))
    )
    dx, dy, dz = np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)
    ct, st = np.cos(th), np.sin(th)
    wi = np.stack([ct * dx + st * dz, dy, -st * dx + ct * dz], axis=-1)
    wo = np.stack([-ct * dx + st * dz, -dy, st * dx + ct * dz], axis=-1)
    return wi, wo


def sample_angles_rad() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sample positions (θh (90,), θd (90,), φd (180,)) in radians: the cells' centres in
    the index coordinates (module docstring)."""
    u = np.arange(90) + 0.5
    return (u / 90.0) ** 2 * (np.pi / 2), np.radians(u), np.radians(np.arange(180) + 0.5)


def _grid_directions():
    """wi, wo (90, 90, 180, 3) at the sample positions."""
    th, td, pd = sample_angles_rad()
    return from_rusinkiewicz_rad(th[:, None, None], td[None, :, None], pd[None, None, :])


# --- writing -----------------------------------------------------------------------------------
def _rgb(rgb) -> np.ndarray:
    a = np.asarray(rgb, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a) & (a >= 0)):
        raise UsageError(f"rgb must be three finite factors >= 0 (red, green, blue), got {rgb!r}")
    return a


def brdf_rgb(brdf: Callable, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """brdf at the pairs (M, 3) in chunks: (M, 3) RGB (a grey result repeated), checked to be
    finite and >= 0 (the writers' common input check)."""
    out = np.empty((len(wi), 3))
    for s in range(0, len(wi), _CHUNK):
        a, b = wi[s : s + _CHUNK], wo[s : s + _CHUNK]
        f = np.asarray(brdf(a, b), dtype=np.float64)
        if f.shape == (len(a),):
            f = np.repeat(f[:, None], 3, axis=1)
        if f.shape != (len(a), 3):
            raise UsageError(
                f"brdf(wi, wo) must return shape {(len(a),)} (grey) or {(len(a), 3)} (RGB) "
                f"for {len(a)} direction pairs, got shape {f.shape}"
            )
        if not np.all(np.isfinite(f) & (f >= 0)):
            raise UsageError("brdf(wi, wo) must return finite values >= 0 (sr⁻¹)")
        out[s : s + len(a)] = f
    return out


def write_merl(path, brdf: Callable, rgb=(1.0, 1.0, 1.0)) -> None:
    """Write the MERL file of ``brdf(wi, wo)`` (sr⁻¹; wi, wo (M, 3) unit; returns (M,) grey
    or (M, 3) RGB) to ``path``, atomically: nothing is written on an error.

    Each sample holds ½[f(wi, wo) + f(wo, wi)] at its cell's centre (``sample_angles_rad``;
    the format stores one value for both orders — reciprocity — so a table that is not exactly
    reciprocal is averaged; for a ``BRDFTable``, where one order is interpolated from bins
    that all hold events and the other is not (``BRDFTable.resolved``), the measured order
    alone), times ``rgb`` per channel, as raw = value / ``MERL_SCALE``;
    samples whose wi or wo lies below the horizon get ``INVALID``. A grey BRDF gives equal
    channels (times ``rgb``). ``brdf`` may be a ``BRDFTable``, a model's ``.f``, a
    ``MERLBRDF.rgb``, any vectorised callable.
    """
    if not callable(brdf):
        raise UsageError(f"brdf must be a callable f(wi, wo) -> sr⁻¹, got {brdf!r}")
    rgb = _rgb(rgb)
    wi, wo = _grid_directions()
    wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
    up = (wi[:, 2] > HORIZON) & (wo[:, 2] > HORIZON)
    a, b = wi[up], wo[up]
    fa, fb = brdf_rgb(brdf, a, b), brdf_rgb(brdf, b, a)
    f = 0.5 * (fa + fb)
    if hasattr(brdf, "resolved"):  # a table: where only one order is measured, that one
        ra, rb = brdf.resolved(a, b)[:, None], brdf.resolved(b, a)[:, None]
        f = np.where(ra & ~rb, fa, np.where(rb & ~ra, fb, f))
    raw = np.full((3, MERL_SAMPLES), INVALID)
    raw[:, up] = (f * (rgb / np.asarray(MERL_SCALE))).T
    header = np.asarray(MERL_SHAPE, dtype="<i4")
    with atomic_open(path, "wb") as fh:
        fh.write(header.tobytes())
        fh.write(raw.astype("<f8", copy=False).tobytes())


# --- reading -----------------------------------------------------------------------------------
def _fail(path, what: str) -> UsageError:
    return UsageError(f"{path}: {what}")


def _read_raw(path: Path) -> np.ndarray:
    """Raw values (3, 1,458,000) of the MERL file ``path``, its header and size checked."""
    try:
        st = path.stat()
    except FileNotFoundError:
        raise _fail(path, "no such MERL file") from None
    if not stat.S_ISREG(st.st_mode):
        raise _fail(path, "not a regular file (a MERL BRDF is a .binary file)")
    size = st.st_size
    with open(path, "rb") as fh:
        head = fh.read(_HEADER)
        if len(head) < _HEADER:
            raise _fail(
                path,
                f"truncated: {size} bytes, shorter than the 12-byte header of three int32 "
                f"dimensions (not a MERL BRDF file)",
            )
        dims = np.frombuffer(head, dtype="<i4")
        n = int(np.prod(dims.astype(np.int64)))
        if np.any(dims <= 0) or n != MERL_SAMPLES:
            swapped = np.frombuffer(head, dtype=">i4")
            hint = (
                " (they read as 90 × 90 × 180 big-endian; MERL files are little-endian)"
                if np.all(swapped > 0) and int(np.prod(swapped.astype(np.int64))) == MERL_SAMPLES
                else " (not a MERL isotropic BRDF file)"
            )
            raise _fail(
                path,
                f"header dimensions {tuple(int(d) for d in dims)} multiply to {n:,}; a MERL "
                f"BRDF has 90 × 90 × 180 = {MERL_SAMPLES:,} samples per channel{hint}",
            )
        if size != MERL_FILE_BYTES:
            what = "truncated" if size < MERL_FILE_BYTES else "has trailing data"
            raise _fail(
                path,
                f"{what}: {size:,} bytes, a MERL BRDF file has {MERL_FILE_BYTES:,} (12-byte "
                f"header + 3 × {MERL_SAMPLES:,} float64)",
            )
        raw = np.fromfile(fh, dtype="<f8", count=3 * MERL_SAMPLES)
    if raw.size != 3 * MERL_SAMPLES:  # the file shrank while being read
        raise _fail(path, f"truncated: read {raw.size:,} of {3 * MERL_SAMPLES:,} values")
    bad = np.count_nonzero(~np.isfinite(raw))
    if bad:
        raise _fail(path, f"holds {bad:,} NaN or infinite values (a MERL value is a number)")
    return raw.reshape(3, MERL_SAMPLES)


def read_merl(path, channel: str = "luminance", lookup: str = "reader") -> "MERLBRDF":
    """The ``MERLBRDF`` of the MERL file ``path`` (a ``UsageError`` naming the file and what is
    wrong for a missing, truncated or foreign file, or one without a single valid sample).
    ``channel``: one of ``CHANNELS``; ``lookup``: one of ``LOOKUPS`` (module docstring)."""
    path = Path(os.fspath(path))
    raw = _read_raw(path)
    values = raw * np.asarray(MERL_SCALE)[:, None]
    values[raw < 0] = INVALID  # invalid stays marked, whatever its scale
    values = values.reshape((3,) + MERL_SHAPE)
    if not np.any(np.all(values >= 0, axis=0)):
        raise _fail(
            path,
            "holds no measured samples: every cell has a negative value in some channel "
            "(MERL's marker of a sample without data)",
        )
    values.setflags(write=False)
    return MERLBRDF(values, channel, lookup, path.stem, str(path))


@dataclass(frozen=True, eq=False)
class MERLBRDF:
    """A MERL BRDF: ``values`` (3, 90, 90, 180) sr⁻¹ (red, green, blue; cells (θh, θd, φd);
    negative = no data), evaluated in ``channel`` (``CHANNELS``) with ``lookup``
    (``LOOKUPS``); ``name`` and the ``path`` it was read from. Arrays are read-only."""

    values: np.ndarray
    channel: str = "luminance"
    lookup: str = "reader"
    name: str = "merl"
    path: str | None = None

    def __post_init__(self):
        v = np.asarray(self.values, dtype=np.float64)
        if v.shape != (3,) + MERL_SHAPE:
            raise UsageError(f"values must have shape {(3,) + MERL_SHAPE}, got {v.shape}")
        if not np.all(np.isfinite(v)):
            raise UsageError("values must be finite (negative marks a sample without data)")
        if v is not self.values or v.flags.writeable:
            v = v.copy()  # a read-only array is kept as given (read_merl, with_options)
            v.setflags(write=False)
        if self.channel not in CHANNELS:
            raise UsageError(f"channel must be one of {CHANNELS}, got {self.channel!r}")
        if self.lookup not in LOOKUPS:
            raise UsageError(f"lookup must be one of {LOOKUPS}, got {self.lookup!r}")
        object.__setattr__(self, "values", v)
        object.__setattr__(self, "_cache", {})

    def with_options(self, channel: str | None = None, lookup: str | None = None) -> "MERLBRDF":
        """The same data with another ``channel`` and/or ``lookup`` (arrays shared)."""
        return dataclasses.replace(
            self,
            channel=self.channel if channel is None else channel,
            lookup=self.lookup if lookup is None else lookup,
        )

    @property
    def valid(self) -> np.ndarray:
        """(90, 90, 180) True where all three channels hold data (≥ 0)."""
        if "valid" not in self._cache:
            ok = np.all(self.values >= 0, axis=0)
            ok.setflags(write=False)
            self._cache["valid"] = ok
        return self._cache["valid"]

    def samples(self) -> np.ndarray:
        """(90, 90, 180) values of ``channel`` (sr⁻¹; invalid samples negative)."""
        if self.channel not in self._cache:
            if self.channel == "luminance":
                s = np.tensordot(np.asarray(LUMINANCE), self.values, axes=1)
                s[~self.valid] = INVALID
            else:
                s = self.values[CHANNELS.index(self.channel)]
            s.setflags(write=False)
            self._cache[self.channel] = s
        return self._cache[self.channel]

    source: ClassVar[str] = "MERL measured BRDF (Matusik et al. 2003)"
    symmetric: ClassVar[bool] = True  # isotropic: mirroring wo about the plane of incidence

    def params(self) -> dict:
        """``channel``, ``lookup``, ``name``, ``path`` (the model protocol's ``params``)."""
        return {
            "channel": self.channel,
            "lookup": self.lookup,
            "name": self.name,
            "path": self.path,
        }

    def f(self, wi, wo) -> np.ndarray:
        """f(wi, wo) sr⁻¹ of ``channel`` for unit directions (..., 3), by ``lookup``; the model
        protocol's ``f`` (``analytic.models.BRDFModel``)."""
        return self._lookup(wi, wo, self.samples().reshape(1, -1))[..., 0]

    evaluate = f
    __call__ = f

    def rgb(self, wi, wo) -> np.ndarray:
        """(..., 3) red, green, blue f(wi, wo) sr⁻¹ by ``lookup``."""
        return self._lookup(wi, wo, self.values.reshape(3, -1))

    def _lookup(self, wi, wo, data: np.ndarray) -> np.ndarray:
        wi = _checks.directions("wi", wi)
        wo = _checks.directions("wo", wo)
        wi, wo = np.broadcast_arrays(wi, wo)
        up = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        th, td, pd = _rusinkiewicz(wi, wo)
        valid = self.valid.reshape(-1)
        if self.lookup == "reader":
            flat = _reader_index(th, td, pd)
            out = np.where(valid[flat][..., None], np.moveaxis(data[:, flat], 0, -1), 0.0)
        else:
            out = _linear(th, td, pd, data, valid, log=self.lookup == "log-linear")
        return np.where(up[..., None], out, 0.0)

    def table(
        self, theta_i, bins: Bins, rtol: float = 1e-3, lookup: str = "log-linear"
    ) -> BRDFTable:
        """``BRDFTable`` of the bin averages of ``channel`` at incidences ``theta_i``
        (degrees, increasing, < 90) on folded ``bins`` (stderr 0): ``sim.predict``'s adaptive
        quadrature ``bin_average`` with relative tolerance ``rtol`` (a RuntimeWarning counts
        the bins that miss it), evaluated with ``lookup``. Default "log-linear": the reader's
        cells are steps, which the quadrature would resolve edge by edge, and a step biases
        an average by up to half a cell where f is not flat; linear interpolation
        overestimates the convex lobe tails (by ∂²f/∂u²/12 on average), which the logarithm
        of a lobe mostly is not. Every bin touching an invalid sample (looked for on the
        2 × 2 × 80 quadrature nodes of each bin) holds 0: no data."""
        if not isinstance(bins, Bins) or not bins.folded:
            raise UsageError(f"bins must be folded microsim.sim.Bins, got {bins!r}")
        theta = np.atleast_1d(np.asarray(theta_i, dtype=np.float64))
        for th in theta:
            _checks.in_range("theta_i", th, 0.0, 90.0, hi_open=True)
        brdf = self.with_options(lookup=lookup)
        values = np.empty((len(theta),) + bins.shape)
        missed = 0
        for t, th in enumerate(theta):
            wi = vectors.spherical_deg(th, 0.0)
            est = bin_average(wi, bins, brdf.f, 0.0, rtol, symmetric=True)
            touched = (
                bin_average(
                    wi, bins, brdf._invalid_indicator, 0.0, 0.5, max_depth=1, min_depth=1
                ).values
                > 0
            )
            values[t] = np.where(touched, 0.0, est.values)
            missed += int(np.count_nonzero(~est.converged & ~touched))
        if missed:
            warnings.warn(
                f"{self.name}: {missed} bins did not reach rtol={rtol}", RuntimeWarning, 2
            )
        return BRDFTable(
            theta, bins, values, np.zeros_like(values), f"{self.name} ({self.channel})"
        )

    def _invalid_indicator(self, wi, wo) -> np.ndarray:
        """1 where the lookup at (wi, wo), both above the horizon, meets an invalid sample."""
        up = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        th, td, pd = _rusinkiewicz(*np.broadcast_arrays(wi, wo))
        bad = ~self.valid.reshape(-1)
        if self.lookup == "reader":
            hit = bad[_reader_index(th, td, pd)]
        else:
            hit = np.zeros(th.shape, dtype=bool)
            for idx, _ in _corners(th, td, pd):
                hit |= bad[idx]
        return np.where(up & hit, 1.0, 0.0)

    def __repr__(self) -> str:
        return (
            f"MERLBRDF({self.name!r}, channel={self.channel!r}, lookup={self.lookup!r}, "
            f"{int(np.count_nonzero(self.valid)):,} of {MERL_SAMPLES:,} samples valid)"
        )


def _reader_index(th, td, pd) -> np.ndarray:
    """Flat cell index as BRDFRead.cpp computes it (θh square-root mapping, φd folded)."""
    ih = np.floor(np.sqrt(np.maximum(th, 0.0) / (np.pi / 2) * 8100.0))
    ih = np.clip(ih, 0, 89).astype(np.int64)
    jd = np.clip(np.floor(td / (np.pi / 2) * 90.0), 0, 89).astype(np.int64)
    p = np.where(pd < 0.0, pd + np.pi, pd)
    kp = np.clip(np.floor(p / np.pi * 180.0), 0, 179).astype(np.int64)
    return (ih * 90 + jd) * 180 + kp


def _axis(pos, n):
    """Lower index and fraction of positions ``pos`` among centres 0 … n − 1 (clamped)."""
    pos = np.clip(pos, 0.0, n - 1.0)
    i0 = np.minimum(np.floor(pos), n - 2).astype(np.int64)
    return i0, pos - i0


def _corners(th, td, pd):
    """(flat index, weight) of the eight sample centres around each (θh, θd, φd)."""
    ih, th_t = _axis(90.0 * np.sqrt(np.maximum(th, 0.0) / (np.pi / 2)) - 0.5, 90)
    jd, td_t = _axis(td / (np.pi / 2) * 90.0 - 0.5, 90)
    p = np.mod(pd, np.pi) / np.pi * 180.0 - 0.5
    kp = np.floor(p)
    pd_t = p - kp
    kp = kp.astype(np.int64)
    for a in (0, 1):
        wa = th_t if a else 1.0 - th_t
        for b in (0, 1):
            wb = wa * (td_t if b else 1.0 - td_t)
            for c in (0, 1):
                w = wb * (pd_t if c else 1.0 - pd_t)
                yield ((ih + a) * 90 + jd + b) * 180 + np.mod(kp + c, 180), w


def _linear(th, td, pd, data, valid, log: bool = False) -> np.ndarray:
    """Trilinear interpolation (..., C) of ``data`` (C, N) — or of ln max(data, FLOOR),
    exponentiated, with ``log`` — over the valid corners (weights renormalised; 0 if none)."""
    if log:
        data = np.log(np.maximum(data, FLOOR))
    acc = np.zeros(th.shape + (data.shape[0],))
    wsum = np.zeros(th.shape)
    for idx, w in _corners(th, td, pd):
        w = np.where(valid[idx], w, 0.0)
        wsum += w
        acc += w[..., None] * np.moveaxis(data[:, idx], 0, -1)
    ok = wsum[..., None] > 0
    out = np.divide(acc, wsum[..., None], out=np.zeros_like(acc), where=ok)
    if log:
        out = np.where(ok, np.exp(out), 0.0)
        out = np.where(out <= FLOOR * (1 + 1e-9), 0.0, out)
    return out


# --- a table as a Result for the fits ----------------------------------------------------------
def result_of_table(table: BRDFTable, theta_max: float = 90.0) -> Result:
    """A ``Result`` of ``table`` for ``analysis.fits.fit_all``: its incidences at φi = 0, its
    bins and bin averages, ``stderr`` as in the table (0 for a closed form's or a MERL file's
    bin averages: taken as exact) and ``counts`` = ``EXACT_COUNT`` on every bin that holds a
    value > 0 and whose θo upper edge is ≤ ``theta_max`` (degrees), 0 elsewhere — the fits use
    exactly the bins with counts ≥ their ``min_events``. No rays and no ledger: not for the
    statistical verdicts, which need standard errors."""
    if not isinstance(table, BRDFTable):
        raise UsageError(f"table must be a microsim.measured.BRDFTable, got {table!r}")
    theta_max = _checks.in_range("theta_max", theta_max, 0.0, 90.0, lo_open=True)
    keep = table.bins.theta_edges[1:] <= theta_max + 1e-9
    if not keep.any():
        raise UsageError(
            f"theta_max must reach the first θo bin's upper edge "
            f"({table.bins.theta_edges[1]:g}°), got {theta_max:g}"
        )
    used = (table.brdf > 0) & keep[None, :, None]
    counts = np.where(used, EXACT_COUNT, 0).astype(np.int64)
    meta = {
        "surface": {"kind": "table"},
        "table": table.name,
        "theta_max": theta_max,
        "counts": "EXACT_COUNT marks the bins a fit uses; the values are exact bin averages",
    }
    return Result(
        theta_i=np.array(table.theta_i),
        phi_i=np.zeros(len(table.theta_i)),
        bins=table.bins,
        brdf=np.array(table.brdf),
        stderr=np.array(table.stderr),
        counts=counts,
        meta=meta,
    )


def low2012_result(
    brdf: MERLBRDF,
    theta_i=LOW2012_THETA_I,
    bins: Bins = LOW2012_BINS,
    theta_max: float = LOW2012_THETA_MAX,
    rtol: float = 1e-3,
) -> Result:
    """``result_of_table(brdf.table(theta_i, bins, rtol), theta_max)``: by default the data
    Löw et al. 2012 (§5.1) fit a MERL BRDF with — θi in 10° steps, 1° bins in θo and Δφ, θo
    above 80° left out — for ``fit_all(result, ior, ...)``, which fits Löw's E2 (eq. 31–33).
    ``brdf``: a ``MERLBRDF`` (``read_merl``) or an ``RGLBRDF`` (``read_rgl``). (One channel at
    a time; Löw also fit three channels with shared parameters.)"""
    if not callable(getattr(brdf, "table", None)):  # MERLBRDF, RGLBRDF
        raise UsageError(
            f"brdf must be a MERLBRDF (read_merl) or an RGLBRDF (read_rgl), got {brdf!r}"
        )
    return result_of_table(brdf.table(theta_i, bins, rtol), theta_max)
