"""The RGL ".bsdf" format (Dupuy & Jakob 2018): write a tabulated isotropic BRDF, read one back.

Dupuy & Jakob 2018 ("An adaptive parameterization for efficient material acquisition and
representation", ACM TOG 37(6)) store a measured BRDF in the coordinates of its own visible
normal distribution: the outgoing direction is reached through the half vector m, and m
through a warp that makes the distribution of visible normals (VNDF) of the incidence wi
uniform on the unit square. In those coordinates the rest of the BRDF is smooth and a small
grid holds it. It is the format of the RGL material database, read by Mitsuba 3's
``measured`` BSDF and pbrt-v4's ``measured`` material. This module writes it for any
microsim BRDF (a ``BRDFTable``, a closed form's ``.f``) together with the microsim NDF that
drives the warp, and reads it with the readers' evaluation, so that RGL files can serve as
references.

Conventions (microsim's): n = +z, unit directions pointing away from the surface, wi the
incidence (the file's parameter direction), f in sr⁻¹ without the cosine. The readers return
f cos θo (Mitsuba's ``BSDF.eval`` includes the cosine); ``RGLBRDF.evaluate`` divides it out.

Tensor file (the container; Mitsuba's ``TensorFile``), little-endian:
    12 bytes "tensor_file\\0", 2 bytes version (1, 0), uint32 number of fields; per field
    uint16 name length, the name (UTF-8), uint16 ndim, uint8 dtype code (1 uint8, 2 int8,
    3 uint16, 4 int16, 5 uint32, 6 int32, 7 uint64, 8 int64, 9 float16, 10 float32,
    11 float64), uint64 byte offset of the data, ndim × uint64 shape; then the data of each
    field, C order (last axis fastest), at its offset (this module aligns offsets to 8 bytes).

Unit coordinates: a direction of polar angle θ and azimuth φ (radians) has
u_θ = √(2θ/π) ∈ [0, 1] (θ = u_θ² π/2: nodes crowd towards the pole, where lobes are narrow)
and u_φ = (φ + π)/(2π) ∈ [0, 1]. For an isotropic file the half vector's azimuth is taken
relative to the incidence's, φm − φi, wrapped into u_φ ∈ [0, 1) (Δφ = 0 is u_φ = ½).

Fields (dtype, shape; the readers check every one; P = len(phi_i), T = len(theta_i)):
    description  uint8 (n,)       UTF-8 text naming the material.
    jacobian     uint8 (1,)       1: f cos θo = ρ D(m)/(4 σ(wi)) below; 0: f cos θo = ρ.
    theta_i      float32 (T,)     incidence polar angles (radians, increasing): the nodes of
                                  the linear interpolation in θi (clamped outside them).
    phi_i        float32 (P,)     incidence azimuths (radians); P ≤ 2 marks an isotropic file
                                  (this module writes P = 1, φi = 0).
    ndf          float32 (Pn, Nn) the NDF D(m) (sr⁻¹, ∫ D cos θm dω = 1) on the node grid
                                  u_φ = j/(Pn−1) (rows), u_θ = i/(Nn−1) (columns); read by
                                  bilinear interpolation in (u_θ, u_φ) at the half vector.
    sigma        float32 (Pn, Nn) the projected area σ(ω) = ∫ ⟨ω, m⟩⁺ D(m) dm on the same
                                  grid, read at the incidence.
    vndf         float32 (P, T, Hv, Wv)  per incidence, the VNDF density over the half
                                  vector's unit square, u_φ rows × u_θ columns: the
                                  distribution the warp makes uniform.
    luminance    float32 (P, T, H, W)    per incidence, the density over the warped square s
                                  that Mitsuba and pbrt-v4 sample before the warp
                                  (importance sampling only; it does not enter f).
    rgb          float32 (P, T, 3, H, W) ρ per channel at the nodes s = (i/(W−1), j/(H−1))
                                  of the warped square (the RGB flavour), or
    wavelengths  float32 (L,)     and spectra float32 (P, T, L, H, W): ρ per wavelength
                                  (nm; the spectral flavour, interpolated linearly in λ).
There are no stored marginals: each reader builds the CDFs of vndf and luminance itself.

Evaluation (Mitsuba 3 ``measured.cpp``, pbrt-v4, powitacq — all the same), for wi, wo above
the horizon: m = (wi + wo)/|wi + wo|; θ = 2 asin(|d − n|/2) for the polar angles of wi and m;
u_wi = (u_θ(θi), u_φ(φi)), u_m = (u_θ(θm), u_φ(φm − φi)) wrapped to [0, 1); s = the inverse
VNDF warp of u_m (below); ρ = bilinear interpolation of the rgb/spectra grid at s, linear in
θi (and φi, λ) between slices; f cos θo = ρ · ndf(u_m)/(4 sigma(u_wi)) when jacobian = 1.

The warp (Mitsuba's continuous ``Marginal2D``): a grid of values v on the unit square, read
bilinearly, normalised per slice to integrate to 1, is a density p(x, y). Its map from
(x, y) to the square is (F_y(y), F_{x|y}(x)): the marginal CDF of y (rows) and the CDF of x
(columns) along the row at y, both exact for the bilinear density (piecewise quadratic); CDFs
of neighbouring θi slices are interpolated linearly, like every other table. Sampling runs
the map backwards. The readers evaluate with the inverse map only.

What ``write_rgl`` stores (exact where microsim knows the quantity):
    * ndf: ``ndf.D_cos`` at the nodes θ = u_θ² π/2, Pn = 2 identical rows (isotropic) —
      with ``floor`` > 0 the mixture (1 − floor) D + floor/π, for BRDFs with a diffuse term;
    * sigma: σ = (1 + Λ(θ)) cos θ (the Smith projected area of an isotropic NDF,
      ``analytic.shadowing.smith_lambda``: closed form or the numerical projected-area
      identity; finite at θ = 90°, where Λ cos θ has a finite limit; the mixture's adds
      floor · (1 + cos θ)/2, the projected area of the uniform NDF 1/π);
    * vndf: at each node of slice θi (φi = 0), p(u) = D(m)⟨wi, m⟩⁺/σ(wi) · 2π² u_θ sin θm,
      the VNDF density D_wi(m) = ⟨wi, m⟩⁺ D(m)/σ(wi) per unit area of (u_θ, u_φ)
      (dω = 2π² u_θ sin θ du_θ du_φ);
    * rgb / spectra: at each node s of slice θi, m = the forward warp of s (the exact inverse
      of the readers' inverse map), wo = 2(wi·m)m − wi and
      ρ = f(wi, wo) cos θo · 4 σ̂(wi)/D̂(m), with σ̂, D̂ the file's own interpolants as the
      readers see them, so that a reader returns f exactly (to float32) at the nodes; ρ = 0
      where wo is below the horizon. For a Torrance–Sparrow BRDF ρ = F G2 (1 + Λi): smooth
      and ≤ 1, which is why the grid can be small;
    * luminance: the luminance of ρ (0.212671 R + 0.715160 G + 0.072169 B, the weights of
      Mitsuba's ``luminance``; ρ itself for a grey BRDF, which the spectral flavour writes
      as a constant spectrum); a slice that is 0 everywhere gets a uniform density (a reader
      would divide by its zero integral);
    * description: the text given, UTF-8; jacobian: 1.
A grey BRDF (f returns shape (M,)) gets equal channels; an RGB one ((M, 3)) its three
channels (RGB flavour only). Spectral flavour: ``SPECTRAL_WAVELENGTHS_NM`` (the grey value at
every wavelength; pbrt-v4 reads spectral files only, Mitsuba 3 spectral files in its spectral
variants and RGB files in its RGB variants).

Interpolation error: the file reproduces f at its nodes; between them the error is that of
linear interpolation (second order in the node spacings of s, θi and the NDF's u_θ) plus a
first-order kink where wo crosses the horizon. ``interpolation_error`` measures the
energy-weighted relative RMS error against the exported function (see there); for
``TorranceSparrow(GGX(0.3), Smith(correlated=True), "aluminium")`` at ``DEFAULT_RESOLUTION``
``pytest tests/test_rgl.py -k falls -s`` prints it (docs/python.md gives the figure).

Reading (``read_rgl``): isotropic files (P ≤ 2) of either flavour, jacobian 0 or 1; the
result's ``evaluate`` follows the readers' evaluation above in float64 on the file's float32
tables. Anisotropic files (P > 2: Mitsuba mirrors them by the symmetry ``phi_i`` spans) are
refused. A missing, foreign, truncated or malformed file is a ``UsageError`` naming it, and so
is one whose ndf, sigma, vndf, luminance or rgb/spectra field holds a NaN, an infinite or a
negative value (each is a density or a BRDF value: finite and >= 0).
"""

from __future__ import annotations

import os
import stat
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, ClassVar

import numpy as np

from microsim import checks as _checks
from microsim.analytic.ndf import NDF
from microsim.analytic.shadowing import smith_lambda
from microsim.atomic import atomic_open
from microsim.errors import UsageError
from microsim.vectors import spherical

from .merl import brdf_rgb

__all__ = [
    "RGLResolution",
    "DEFAULT_RESOLUTION",
    "RHO_LIMIT",
    "FLAVOURS",
    "SPECTRAL_WAVELENGTHS_NM",
    "RGLBRDF",
    "write_rgl",
    "read_rgl",
    "interpolation_error",
    "read_tensor_file",
    "tensor_file_bytes",
]

FLAVOURS = ("rgb", "spectral")
"""``write_rgl``'s ``flavour``: an "rgb" field (Mitsuba 3 RGB variants) or "wavelengths" and
"spectra" (Mitsuba 3 spectral variants, pbrt-v4)."""

SPECTRAL_WAVELENGTHS_NM = (360.0, 1000.0)
"""Wavelengths (nm) of a spectral-flavour file of a grey BRDF: the range of the RGL database's
spectral measurements; the value is the same at both, so every wavelength reads the same."""

LUMINANCE_WEIGHTS = (0.212671, 0.715160, 0.072169)
"""Luminance of linear sRGB/Rec. 709 (R, G, B), as Mitsuba's ``luminance``."""

_MAGIC = b"tensor_file\x00"
_VERSION = (1, 0)
_ALIGN = 8
_CODE_OF = {
    np.dtype(np.uint8): 1,
    np.dtype(np.int8): 2,
    np.dtype(np.uint16): 3,
    np.dtype(np.int16): 4,
    np.dtype(np.uint32): 5,
    np.dtype(np.int32): 6,
    np.dtype(np.uint64): 7,
    np.dtype(np.int64): 8,
    np.dtype(np.float16): 9,
    np.dtype(np.float32): 10,
    np.dtype(np.float64): 11,
}
_DTYPE_OF = {code: dt.newbyteorder("<") for dt, code in _CODE_OF.items()}


# --- the tensor-file container ----------------------------------------------------------------
def tensor_file_bytes(fields: dict) -> bytes:
    """The tensor file (module docstring) holding ``fields`` (name → array; a str is stored as
    its UTF-8 bytes), in the given order, data aligned to 8 bytes."""
    arrays = {}
    for name, value in fields.items():
        if isinstance(value, str):
            value = np.frombuffer(value.encode("utf-8"), dtype=np.uint8)
        a = np.ascontiguousarray(value)
        if a.dtype.newbyteorder("=") not in _CODE_OF:
            raise UsageError(
                f"field {name!r} has dtype {a.dtype}; a tensor file holds "
                f"{sorted(str(d) for d in _CODE_OF)}"
            )
        arrays[name] = a.astype(a.dtype.newbyteorder("<"), copy=False)
    head = len(_MAGIC) + 2 + 4
    head += sum(2 + len(k.encode("utf-8")) + 2 + 1 + 8 + 8 * a.ndim for k, a in arrays.items())
    offsets, pos = {}, head
    for name, a in arrays.items():
        pos = -(-pos // _ALIGN) * _ALIGN
        offsets[name] = pos
        pos += a.nbytes
    out = bytearray(pos)
    out[: len(_MAGIC)] = _MAGIC
    cursor = len(_MAGIC)
    struct.pack_into("<BBI", out, cursor, *_VERSION, len(arrays))
    cursor += 6
    for name, a in arrays.items():
        label = name.encode("utf-8")
        struct.pack_into(f"<H{len(label)}sHBQ", out, cursor, len(label), label, a.ndim,
                         _CODE_OF[a.dtype.newbyteorder("=")], offsets[name])  # fmt: skip
        cursor += 2 + len(label) + 2 + 1 + 8
        struct.pack_into(f"<{a.ndim}Q", out, cursor, *a.shape)
        cursor += 8 * a.ndim
        out[offsets[name] : offsets[name] + a.nbytes] = a.tobytes()
    return bytes(out)


def _fail(path, what: str) -> UsageError:
    return UsageError(f"{path}: {what}")


def read_tensor_file(path) -> dict:
    """The fields (name → array, native byte order) of the tensor file ``path``; a
    ``UsageError`` naming the file for a missing, foreign or truncated one."""
    path = Path(os.fspath(path))
    try:
        st = path.stat()
    except FileNotFoundError:
        raise _fail(path, "no such RGL .bsdf file") from None
    if not stat.S_ISREG(st.st_mode):
        raise _fail(path, "not a regular file (an RGL BRDF is a .bsdf tensor file)")
    data = path.read_bytes()
    size = len(data)
    if size < len(_MAGIC) + 6:
        raise _fail(
            path,
            f"truncated: {size} bytes, shorter than the 18-byte tensor-file header "
            f"(not an RGL .bsdf file)",
        )
    if data[: len(_MAGIC)] != _MAGIC:
        raise _fail(
            path,
            f"not a tensor file: it starts with {data[:12]!r}, an RGL .bsdf file with {_MAGIC!r}",
        )
    version = tuple(data[12:14])
    if version != _VERSION:
        raise _fail(path, f"tensor-file version {version}, only {_VERSION} is defined")
    (n_fields,) = struct.unpack_from("<I", data, 14)
    cursor, fields = 18, {}

    def take(fmt: str, what: str):
        nonlocal cursor
        need = struct.calcsize(fmt)
        if cursor + need > size:
            raise _fail(
                path,
                f"truncated: the header of {n_fields} fields ends inside {what} at byte "
                f"{cursor} of {size}",
            )
        values = struct.unpack_from(fmt, data, cursor)
        cursor += need
        return values

    for k in range(n_fields):
        (n_name,) = take("<H", f"field {k}'s name length")
        (raw,) = take(f"<{n_name}s", f"field {k}'s name")
        name = raw.decode("utf-8", errors="replace")
        ndim, code, offset = take("<HBQ", f"field {name!r}'s description")
        shape = take(f"<{ndim}Q", f"field {name!r}'s shape")
        if code not in _DTYPE_OF:
            raise _fail(path, f"field {name!r} has the unknown dtype code {code} (1 … 11)")
        dtype = _DTYPE_OF[code]
        nbytes = dtype.itemsize * int(np.prod(shape, dtype=np.uint64))
        if offset + nbytes > size:
            raise _fail(
                path,
                f"truncated: field {name!r} {tuple(shape)} {dtype.name} needs bytes "
                f"[{offset}, {offset + nbytes}), the file has {size}",
            )
        a = np.frombuffer(data, dtype=dtype, count=nbytes // dtype.itemsize, offset=offset)
        fields[name] = a.reshape(shape).astype(dtype.newbyteorder("="))
    return fields


# --- the parameterisation ---------------------------------------------------------------------
def _theta2u(theta):
    return np.sqrt(np.maximum(theta, 0.0) * (2.0 / np.pi))


def _u2theta(u):
    return u * u * (0.5 * np.pi)


def _phi2u(phi):
    return (phi + np.pi) / (2.0 * np.pi)


def _u2phi(u):
    return (2.0 * u - 1.0) * np.pi


def _elevation(d):
    """Polar angle 2 asin(|d − n|/2): accurate near the pole (the readers' formula)."""
    dist = np.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2 + (d[..., 2] - 1.0) ** 2)
    return 2.0 * np.arcsin(np.clip(0.5 * dist, 0.0, 1.0))


def _lerp(a, b, t):
    return a + (b - a) * t


# --- piecewise-linear 2D tables (the readers' Marginal2D, continuous variant) -----------------
class _Table2D:
    """A stack of 2D grids ``data`` (params…, H, W) on the unit square (nodes i/(W−1),
    j/(H−1); x ↔ columns, y ↔ rows), linear in each parameter between ``param_values``
    (clamped outside). ``warp=True``: normalised per slice and with the CDFs of the
    continuous marginal–conditional map (module docstring); else raw values."""

    def __init__(self, data, param_values=(), warp: bool = False):
        data = np.asarray(data, dtype=np.float64)
        self.H, self.W = data.shape[-2:]
        self.params = [np.asarray(p, dtype=np.float64) for p in param_values]
        res = data.shape[:-2]
        v = data.reshape(-1, self.H, self.W)
        strides, slices = [0] * len(res), 1
        for i in range(len(res) - 1, -1, -1):
            strides[i] = slices if res[i] > 1 else 0
            slices *= res[i]
        self.strides = strides
        if warp:
            dx, dy = 1.0 / (self.W - 1), 1.0 / (self.H - 1)
            cond = np.cumsum(0.5 * dx * (v[:, :, :-1] + v[:, :, 1:]), axis=2)  # (S, H, W−1)
            rows = cond[:, :, -1]
            marg = np.cumsum(0.5 * dy * (rows[:, :-1] + rows[:, 1:]), axis=1)  # (S, H−1)
            with np.errstate(divide="ignore"):
                norm = 1.0 / marg[:, -1]
            self.cond = (cond * norm[:, None, None]).reshape(len(v), -1)
            self.marg = marg * norm[:, None]
            v = v * norm[:, None, None]
        self.data = v.reshape(len(v), -1)

    def _weights(self, params):
        """Slice indices (N, C) and weights (N, C) of the 2^D corners around ``params``."""
        n = np.broadcast_shapes(*(np.shape(p) for p in params)) if params else ()
        idx, wts = [np.zeros(n, dtype=np.intp)], [np.ones(n)]
        for d, values in enumerate(self.params):
            if values.size == 1:
                continue
            x = np.broadcast_to(np.asarray(params[d], dtype=np.float64), n).reshape(-1)
            i = np.clip(np.sum(values[:-1, None] < x[None, :], axis=0) - 1, 0, values.size - 2)
            w1 = np.clip((x - values[i]) / (values[i + 1] - values[i]), 0.0, 1.0).reshape(n)
            i = i.reshape(n)
            st = self.strides[d]
            idx = [a + k * st for a in idx for k in (i, i + 1)]
            wts = [w * f for w in wts for f in (1.0 - w1, w1)]
        return np.stack(idx, axis=-1), np.stack(wts, axis=-1)

    @staticmethod
    def _get(table, corners, index):
        sl, wt = corners
        return np.sum(table[sl, index[..., None]] * wt, axis=-1)

    def _at(self, table, corners, index, n):
        return self._get(table, corners, np.clip(index, 0, n - 1))

    def eval(self, pos, params=()):
        """Bilinear value at ``pos`` (N, 2) = (x, y) ∈ [0, 1]² (clipped)."""
        corners = self._weights(params)
        W, H = self.W, self.H
        p = np.clip(pos, 0.0, 1.0) * (W - 1, H - 1)
        o = np.minimum(p.astype(np.intp), (W - 2, H - 2))
        t = p - o
        i = o[..., 0] + o[..., 1] * W
        n = W * H
        v00, v10 = self._at(self.data, corners, i, n), self._at(self.data, corners, i + 1, n)
        v01 = self._at(self.data, corners, i + W, n)
        v11 = self._at(self.data, corners, i + W + 1, n)
        return _lerp(_lerp(v00, v10, t[..., 0]), _lerp(v01, v11, t[..., 0]), t[..., 1])

    def invert(self, u, params=()):
        """The warp of ``u`` (N, 2) in the half vector's square to s (N, 2) ∈ [0, 1]² and the
        density there (the readers' ``invert``)."""
        corners = self._weights(params)
        W, H = self.W, self.H
        nd, nc, nm = W * H, (W - 1) * H, H - 1
        p = np.clip(u, 0.0, 1.0) * (W - 1, H - 1)
        o = np.minimum(p.astype(np.intp), (W - 2, H - 2))
        t = p - o
        px, py = o[..., 0], o[..., 1]
        tx, ty = t[..., 0], t[..., 1]
        i = py * W + px
        v00, v10 = self._at(self.data, corners, i, nd), self._at(self.data, corners, i + 1, nd)
        v01 = self._at(self.data, corners, i + W, nd)
        v11 = self._at(self.data, corners, i + W + 1, nd)
        c0, c1 = _lerp(v00, v01, ty), _lerp(v10, v11, ty)
        pdf = _lerp(c0, c1, tx)
        x = tx * _lerp(c0, c1, 0.5 * tx) / (W - 1)
        oc = py * (W - 1)
        left = _lerp(
            self._at(self.cond, corners, oc + px - 1, nc),
            self._at(self.cond, corners, oc + (W - 1) + px - 1, nc),
            ty,
        )
        x = x + np.where(px > 0, left, 0.0)
        r0 = self._at(self.cond, corners, oc + W - 2, nc)
        r1 = self._at(self.cond, corners, oc + 2 * (W - 1) - 1, nc)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = x / _lerp(r0, r1, ty)
        y = ty * _lerp(r0, r1, 0.5 * ty) / (H - 1)
        below = self._at(self.marg, corners, py - 1, nm)
        y = y + np.where(py > 0, below, 0.0)
        return np.stack([x, y], axis=-1), pdf

    def sample(self, s, params=()):
        """The forward warp: s (N, 2) ∈ [0, 1]² to u in the half vector's square, the exact
        inverse of ``invert`` (the readers' ``sample`` up to their shortcut for nearly
        constant patches)."""
        corners = self._weights(params)
        W, H = self.W, self.H
        nc, nm, nd = (W - 1) * H, H - 1, W * H
        s = np.clip(np.asarray(s, dtype=np.float64), 0.0, 1.0)
        sx, sy = s[..., 0], s[..., 1]
        row = _search(nm, lambda k: self._at(self.marg, corners, k, nm) < sy, sy.shape)
        sy = sy - np.where(row > 0, self._at(self.marg, corners, row - 1, nm), 0.0)
        oc = row * (W - 1)
        r0 = self._at(self.cond, corners, oc + W - 2, nc)
        r1 = self._at(self.cond, corners, oc + 2 * (W - 1) - 1, nc)
        ty = _segment(sy * (H - 1), r0, r1)
        sx = sx * _lerp(r0, r1, ty)

        def cdf_x(k):
            return _lerp(
                self._at(self.cond, corners, oc + k, nc),
                self._at(self.cond, corners, oc + (W - 1) + k, nc),
                ty,
            )

        col = np.minimum(_search(W - 1, lambda k: cdf_x(k) < sx, sx.shape), W - 2)
        sx = sx - np.where(col > 0, cdf_x(col - 1), 0.0)
        i = row * W + col
        v00, v10 = self._at(self.data, corners, i, nd), self._at(self.data, corners, i + 1, nd)
        v01 = self._at(self.data, corners, i + W, nd)
        v11 = self._at(self.data, corners, i + W + 1, nd)
        c0, c1 = _lerp(v00, v01, ty), _lerp(v10, v11, ty)
        tx = _segment(sx * (W - 1), c0, c1)
        u = np.stack([(col + tx) / (W - 1), (row + ty) / (H - 1)], axis=-1)
        return u, _lerp(c0, c1, tx)


def _search(n: int, below, shape) -> np.ndarray:
    """Smallest k ∈ [0, n − 1] with ``below(k)`` false (n − 1 if none), per point of
    ``shape``: bisection on a vectorised predicate monotone in k (Dr.Jit's ``binary_search``
    on [0, n − 1])."""
    lo = np.zeros(shape, dtype=np.intp)
    hi = np.full_like(lo, n - 1)
    for _ in range(int(np.ceil(np.log2(max(n, 2)))) + 1):
        mid = (lo + hi) >> 1
        go = below(mid)
        lo = np.where(go, np.minimum(mid + 1, hi), lo)
        hi = np.where(go, hi, mid)
    return lo


def _segment(a, v0, v1) -> np.ndarray:
    """t ∈ [0, 1] with ∫₀ᵗ lerp(v0, v1, τ) dτ = a (a in patch units): the stable root
    2a/(v0 + √(v0² + 2a(v1 − v0)))."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = 2.0 * a / (v0 + np.sqrt(np.maximum(v0 * v0 + 2.0 * a * (v1 - v0), 0.0)))
    return np.clip(np.where(np.isfinite(t), t, 0.0), 0.0, 1.0)


# --- the BRDF a file holds ---------------------------------------------------------------------
_RGB_LABELS = ("red", "green", "blue")


@dataclass(frozen=True, eq=False)
class RGLBRDF:
    """An isotropic RGL BRDF as the readers evaluate it (module docstring).

    ``fields``: the file's arrays (read-only); ``channel``: what ``evaluate`` returns —
    for an RGB file "luminance" (``LUMINANCE_WEIGHTS``) or "red", "green", "blue"; for a
    spectral file a wavelength in nm within ``wavelengths`` (linear between them);
    ``path``: where it was read. ``values(wi, wo)`` gives every stored channel.
    """

    fields: dict
    channel: object = "luminance"
    path: str = ""

    def __post_init__(self):
        f = self.fields
        spectral = "wavelengths" in f
        object.__setattr__(self, "spectral", spectral)
        object.__setattr__(
            self,
            "wavelengths",
            np.asarray(f["wavelengths"], dtype=np.float64) if spectral else None,
        )
        spectra = f["spectra"] if spectral else f["rgb"]
        chans = self.wavelengths if spectral else np.arange(3.0)
        params_i = (f["phi_i"], f["theta_i"])
        object.__setattr__(self, "_ndf", _Table2D(f["ndf"]))
        object.__setattr__(self, "_sigma", _Table2D(f["sigma"]))
        object.__setattr__(self, "_vndf", _Table2D(f["vndf"], params_i, warp=True))
        object.__setattr__(self, "_spectra", _Table2D(spectra, params_i + (chans,)))
        object.__setattr__(self, "_chans", chans)
        object.__setattr__(self, "jacobian", bool(f["jacobian"][0]))
        object.__setattr__(self, "description", bytes(f["description"]).decode("utf-8", "replace"))
        object.__setattr__(self, "_select", self._channel_weights(self.channel))

    def _channel_weights(self, channel):
        """What ``evaluate`` takes from the channels: weights over R, G, B, or a wavelength."""
        if not self.spectral:
            if isinstance(channel, str) and channel == "luminance":
                return np.asarray(LUMINANCE_WEIGHTS)
            if isinstance(channel, str) and channel in _RGB_LABELS:
                return np.eye(3)[_RGB_LABELS.index(channel)]
            raise UsageError(
                f"channel must be 'luminance', 'red', 'green' or 'blue' for an RGB RGL file "
                f"({self.path}), got {channel!r}"
            )
        lo, hi = float(self.wavelengths.min()), float(self.wavelengths.max())
        if isinstance(channel, (str, bool)) or not isinstance(channel, (int, float, np.number)):
            raise UsageError(
                f"channel must be a wavelength in nm within [{lo:g}, {hi:g}] for the spectral "
                f"RGL file {self.path}, got {channel!r}"
            )
        lam = _checks.in_range("channel", channel, lo, hi)
        return lam

    @property
    def channels(self) -> tuple:
        """The stored channels: ("red", "green", "blue") or the wavelengths (nm)."""
        return tuple(self.wavelengths) if self.spectral else _RGB_LABELS

    def _setup(self, wi, wo):
        wi = _checks.directions("wi", wi)
        wo = _checks.directions("wo", wo)
        _checks.broadcast({"wi": wi, "wo": wo})
        wi, wo = np.broadcast_arrays(wi, wo)
        shape = wi.shape[:-1]
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        up = (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)
        s = wi + wo
        m = s / np.maximum(np.linalg.norm(s, axis=-1, keepdims=True), 1e-300)
        theta_i, phi_i = _elevation(wi), np.arctan2(wi[:, 1], wi[:, 0])
        theta_m, phi_m = _elevation(m), np.arctan2(m[:, 1], m[:, 0])
        u_wi = np.stack([_theta2u(theta_i), _phi2u(phi_i)], axis=-1)
        um_y = _phi2u(phi_m - phi_i)
        u_m = np.stack([_theta2u(theta_m), um_y - np.floor(um_y)], axis=-1)
        params = (phi_i, theta_i)
        sample, _ = self._vndf.invert(u_m, params)
        scale = np.ones(len(wi))
        if self.jacobian:
            with np.errstate(divide="ignore", invalid="ignore"):
                scale = self._ndf.eval(u_m) / (4.0 * self._sigma.eval(u_wi))
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(up, scale / np.where(up, wo[:, 2], 1.0), 0.0)
        return shape, sample, params, scale, up

    def _channel_values(self, sample, params, chan):
        c = np.broadcast_to(chan, params[0].shape)
        return self._spectra.eval(sample, params + (c,))

    def values(self, wi, wo) -> np.ndarray:
        """f(wi, wo) sr⁻¹ per stored channel, shape (..., C) (C = 3 or len(wavelengths));
        0 where wi or wo is at or below the horizon."""
        shape, sample, params, scale, up = self._setup(wi, wo)
        out = np.stack([self._channel_values(sample, params, c) for c in self._chans], -1)
        out = np.where(up[:, None], out * scale[:, None], 0.0)
        return out.reshape(shape + (len(self._chans),))

    source: ClassVar[str] = "RGL measured BSDF (Dupuy & Jakob 2018)"
    symmetric: ClassVar[bool] = True  # isotropic: mirroring wo about the plane of incidence

    def params(self) -> dict:
        """``channel`` and ``path`` (the model protocol's ``params``)."""
        return {"channel": self.channel, "path": self.path}

    def f(self, wi, wo) -> np.ndarray:
        """f(wi, wo) sr⁻¹ of ``channel`` for unit directions (..., 3) away from the surface;
        the model protocol's ``f`` (``analytic.models.BRDFModel``)."""
        shape, sample, params, scale, up = self._setup(wi, wo)
        if self.spectral:
            v = self._channel_values(sample, params, float(self._select))
        else:
            v = sum(
                w * self._channel_values(sample, params, c)
                for w, c in zip(self._select, self._chans)
                if w != 0.0
            )
        return np.where(up, v * scale, 0.0).reshape(shape)

    evaluate = f
    __call__ = f

    def table(self, theta_i, bins, rtol: float = 1e-3):
        """``BRDFTable`` of the bin averages of ``evaluate`` at incidences ``theta_i``
        (degrees) on folded ``bins`` (``BRDFTable.from_function``)."""
        from .table import BRDFTable

        return BRDFTable.from_function(self.f, theta_i, bins, self.description, rtol)


# --- reading ----------------------------------------------------------------------------------
_REQUIRED = ("description", "jacobian", "theta_i", "phi_i", "ndf", "sigma", "vndf", "luminance")


def _check_fields(path, f: dict) -> None:
    """The readers' structure check, one message per defect naming the field."""
    spectral = "wavelengths" in f
    need = _REQUIRED + (("wavelengths", "spectra") if spectral else ("rgb",))
    missing = [k for k in need if k not in f]
    if missing:
        raise _fail(
            path,
            f"not an RGL BRDF file: missing the field(s) {missing} (an RGL .bsdf file has "
            f"{list(_REQUIRED)} and 'rgb', or 'wavelengths' and 'spectra')",
        )
    kinds = {"description": np.uint8, "jacobian": np.uint8}
    spec = "spectra" if spectral else "rgb"
    for k in need:
        want = np.dtype(kinds.get(k, np.float32))
        if f[k].dtype != want:
            raise _fail(path, f"field {k!r} has dtype {f[k].dtype}, the format wants {want}")
    ndims = {"description": 1, "jacobian": 1, "theta_i": 1, "phi_i": 1, "wavelengths": 1,
             "ndf": 2, "sigma": 2, "vndf": 4, "luminance": 4, spec: 5}  # fmt: skip
    for k in need:
        if f[k].ndim != ndims[k]:
            raise _fail(
                path, f"field {k!r} has shape {f[k].shape}, the format wants {ndims[k]} axes"
            )
    P, T = f["phi_i"].shape[0], f["theta_i"].shape[0]
    C = f["wavelengths"].shape[0] if spectral else 3
    lum, sp = f["luminance"].shape, f[spec].shape
    checks = [
        (f["jacobian"].shape == (1,), "jacobian must hold one value"),
        (P >= 1 and T >= 1 and C >= 1, "theta_i, phi_i (and wavelengths) must not be empty"),
        (f["vndf"].shape[:2] == (P, T),
         f"vndf must start with (len(phi_i), len(theta_i)) = {(P, T)}"),
        (lum[:2] == (P, T), f"luminance must start with {(P, T)}"),
        (sp[:3] == (P, T, C), f"{spec} must start with {(P, T, C)}"),
        (sp[3:] == lum[2:], f"{spec} and luminance must share their last two axes"),
        (sp[3] == sp[4], f"{spec}'s grid must be square (the readers' check)"),
        (min(f["ndf"].shape + f["sigma"].shape + f["vndf"].shape[2:] + lum[2:]) >= 2,
         "every 2D grid must have at least 2 × 2 nodes"),
    ]  # fmt: skip
    for ok, what in checks:
        if not ok:
            shapes = {k: tuple(f[k].shape) for k in need}
            raise _fail(path, f"malformed RGL BRDF file: {what}; shapes {shapes}")
    if P > 2:
        raise _fail(
            path,
            f"an anisotropic RGL file (phi_i has {P} entries): microsim reads isotropic ones "
            f"(phi_i of 1 or 2 entries) only",
        )
    for k in ("theta_i", "phi_i") + (("wavelengths",) if spectral else ()):
        a = f[k]
        if not np.all(np.isfinite(a)) or np.any(np.diff(a) <= 0):
            raise _fail(path, f"field {k!r} must be finite and increasing, got {a!r}")
    what = {"ndf": "an NDF", "sigma": "a projected area", "vndf": "a density",
            "luminance": "a density", spec: "BRDF values (ρ)"}  # fmt: skip
    for k, meaning in what.items():
        if not np.all(np.isfinite(f[k])):
            raise _fail(path, f"field {k!r} holds NaN or infinite values")
        negative = np.count_nonzero(f[k] < 0)
        if negative:
            raise _fail(
                path,
                f"field {k!r} holds {negative:,} negative values (down to {f[k].min():.4g}): "
                f"{meaning} must be >= 0",
            )


def read_rgl(path, channel="luminance") -> RGLBRDF:
    """The ``RGLBRDF`` of the RGL .bsdf file ``path`` (``channel``: see ``RGLBRDF``); a
    ``UsageError`` naming the file and the field for a missing, foreign, truncated or
    malformed one — a table field holding NaN, infinite or negative values included."""
    path = Path(os.fspath(path))
    fields = read_tensor_file(path)
    _check_fields(path, fields)
    for a in fields.values():
        a.setflags(write=False)
    return RGLBRDF(fields, channel, str(path))


# --- writing ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class RGLResolution:
    """Grid sizes of a file ``write_rgl`` makes.

    ``theta_i``: number of incidences, θi_k = ``theta_max_deg`` · k/(n − 1) (uniform in θ:
    the warp and ρ change fastest towards grazing, where u_θ spacing would be coarsest);
    ``vndf``: (rows u_φ, columns u_θ) of the VNDF grid; ``samples``: nodes per side of the
    square ρ/luminance grid (the readers want it square); ``ndf``: u_θ nodes of ndf and sigma.
    """

    theta_i: int = 32
    theta_max_deg: float = 88.0
    vndf: tuple = (64, 64)
    samples: int = 64
    ndf: int = 512

    def __post_init__(self):
        object.__setattr__(self, "theta_i", _checks.integer("resolution.theta_i", self.theta_i, 2))
        object.__setattr__(
            self,
            "theta_max_deg",
            _checks.in_range("resolution.theta_max_deg", self.theta_max_deg, 0.0, 90.0,
                             lo_open=True, hi_open=True),
        )  # fmt: skip
        v = tuple(self.vndf) if isinstance(self.vndf, (tuple, list)) else (self.vndf,)
        if len(v) != 2:
            raise UsageError(f"resolution.vndf must be (rows, columns), got {self.vndf!r}")
        object.__setattr__(self, "vndf", tuple(_checks.integer("resolution.vndf", n, 3) for n in v))
        object.__setattr__(self, "samples", _checks.integer("resolution.samples", self.samples, 2))
        object.__setattr__(self, "ndf", _checks.integer("resolution.ndf", self.ndf, 2))

    def theta_i_rad(self) -> np.ndarray:
        """The incidence nodes (radians) as stored (float32 values)."""
        t = np.radians(self.theta_max_deg) * np.linspace(0.0, 1.0, self.theta_i)
        return t.astype(np.float32).astype(np.float64)


DEFAULT_RESOLUTION = RGLResolution()


def _check_ndf(ndf):
    if not isinstance(ndf, NDF) or not ndf.isotropic:
        raise UsageError(
            f"ndf must be an isotropic microsim NDF (microsim.analytic.ndf: Beckmann, GGX, "
            f"BlinnPhong, VonMisesFisher, ABC), got {_checks.short(ndf)}"
        )
    return ndf


def _sigma(ndf, theta) -> np.ndarray:
    """σ(θ) = (1 + Λ) cos θ (finite up to θ = 90°: cos θ is never exactly 0 in float64 here)."""
    c = np.maximum(np.cos(np.minimum(theta, 0.5 * np.pi)), 1e-300)
    w = np.stack([np.sqrt((1 - c) * (1 + c)), np.zeros_like(c), c], axis=-1)
    return c * (1.0 + smith_lambda(w, ndf))


class _WarpNDF:
    """The NDF a file stores and warps by: (1 − floor) D + floor/π (a Lambertian share, whose
    projected area is (1 + cos θ)/2), normalised like D (∫ D cos θm dω = 1)."""

    def __init__(self, ndf, floor: float):
        self.ndf, self.floor = ndf, floor

    def D_cos(self, c):
        d = np.asarray(self.ndf.D_cos(c), dtype=np.float64)
        return (1.0 - self.floor) * d + self.floor / np.pi

    def sigma(self, theta):
        lam = 0.5 * (1.0 + np.cos(np.minimum(theta, 0.5 * np.pi)))
        return (1.0 - self.floor) * _sigma(self.ndf, theta) + self.floor * lam


RHO_LIMIT = 1e3
"""Largest ρ = f cos θo · 4σ/D a file may hold: a microfacet BRDF's is F G2 (1 + Λi), a few at
most; far larger values mean energy where the warp's NDF has almost none (a diffuse term, or
an NDF narrower than the BRDF's lobe), which the file cannot interpolate."""


def _fields(
    brdf, ndf, res: RGLResolution, description: str, flavour: str, floor: float = 0.0
) -> dict:
    theta_i = res.theta_i_rad()
    T, (Hv, Wv), n, Nn = len(theta_i), res.vndf, res.samples, res.ndf
    ndf = _WarpNDF(ndf, floor)
    # NDF and projected area on the u_θ nodes
    th = _u2theta(np.linspace(0.0, 1.0, Nn))
    ndf_row = ndf.D_cos(np.cos(th))
    sigma_row = ndf.sigma(th)
    ndf_t = np.tile(ndf_row, (2, 1)).astype(np.float32)
    sigma_t = np.tile(sigma_row, (2, 1)).astype(np.float32)
    ndf_tab, sigma_tab = _Table2D(ndf_t), _Table2D(sigma_t)
    sigma_i = ndf.sigma(theta_i)
    wi = spherical(theta_i, 0.0)  # (T, 3), φi = 0
    # VNDF density on its grid (per unit area of (u_θ, u_φ))
    ux, uy = np.meshgrid(np.linspace(0, 1, Wv), np.linspace(0, 1, Hv))  # (Hv, Wv)
    tm, pm = _u2theta(ux), _u2phi(uy)
    m = spherical(tm, pm)  # (Hv, Wv, 3)
    dot = np.einsum("tk,hwk->thw", wi, m)
    vndf = (
        ndf.D_cos(np.cos(tm))[None]
        * np.maximum(dot, 0.0)
        / sigma_i[:, None, None]
        * (2.0 * np.pi**2 * ux * np.sin(tm))[None]
    )
    vndf32 = vndf.astype(np.float32)[None]  # (1, T, Hv, Wv)
    warp = _Table2D(vndf32, (np.zeros(1), theta_i.astype(np.float32)), warp=True)
    # ρ at the nodes of the warped square, per incidence
    sx, sy = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    s = np.broadcast_to(np.stack([sx, sy], -1), (T, n, n, 2)).reshape(-1, 2)
    ti = np.repeat(theta_i, n * n)
    u_m, _ = warp.sample(s, (np.zeros_like(ti), ti))
    m = spherical(_u2theta(u_m[:, 0]), _u2phi(u_m[:, 1]))
    wi_s = np.repeat(wi, n * n, axis=0)
    wim = np.einsum("ij,ij->i", wi_s, m)
    wo = 2.0 * wim[:, None] * m - wi_s
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    ok = (wo[:, 2] > 0.0) & (wim > 0.0)
    d_hat = ndf_tab.eval(u_m)
    u_wi = np.stack([_theta2u(theta_i), np.full(T, 0.5)], -1)
    s_hat = np.repeat(sigma_tab.eval(u_wi), n * n)
    ok &= d_hat > 0.0
    rho = np.zeros((len(s), 3))
    if np.any(ok):
        f = brdf_rgb(brdf, wi_s[ok], wo[ok])
        rho[ok] = f * (wo[ok, 2] * 4.0 * s_hat[ok] / d_hat[ok])[:, None]
    if rho.max() > RHO_LIMIT:
        raise UsageError(
            f"brdf has energy where the NDF has almost none (ρ = f cos θo 4σ/D up to "
            f"{rho.max():.3g}, a microfacet BRDF's is a few): a diffuse term or a lobe wider "
            f"than the NDF; pass floor > 0 (a Lambertian share of the warp's NDF, e.g. 0.05) "
            f"or a wider ndf"
        )
    grey = bool(np.all(rho[:, 0] == rho[:, 1]) and np.all(rho[:, 0] == rho[:, 2]))
    rho = rho.reshape(T, n, n, 3)
    lum = rho @ np.asarray(LUMINANCE_WEIGHTS) if not grey else rho[..., 0].copy()
    empty = ~np.any(lum > 0, axis=(1, 2))
    lum[empty] = 1.0
    fields = {
        "description": description,
        "jacobian": np.array([1], dtype=np.uint8),
        "theta_i": theta_i.astype(np.float32),
        "phi_i": np.zeros(1, dtype=np.float32),
        "ndf": ndf_t,
        "sigma": sigma_t,
        "vndf": vndf32,
        "luminance": lum.astype(np.float32)[None],
    }
    if flavour == "rgb":
        fields["rgb"] = np.moveaxis(rho, -1, 1).astype(np.float32)[None]  # (1, T, 3, n, n)
    else:
        if not grey:
            raise UsageError(
                "flavour='spectral' needs a grey brdf (one value per direction pair): an RGB "
                "BRDF has no spectrum to write; use flavour='rgb'"
            )
        L = len(SPECTRAL_WAVELENGTHS_NM)
        fields["wavelengths"] = np.asarray(SPECTRAL_WAVELENGTHS_NM, dtype=np.float32)
        fields["spectra"] = np.repeat(rho[:, None, :, :, 0], L, axis=1).astype(np.float32)[None]
    return fields


def write_rgl(
    path,
    brdf: Callable,
    ndf,
    *,
    resolution: RGLResolution = DEFAULT_RESOLUTION,
    description: str | None = None,
    flavour: str = "rgb",
    floor: float = 0.0,
) -> None:
    """Write ``brdf(wi, wo)`` (sr⁻¹; wi, wo (M, 3) unit; returns (M,) grey or (M, 3) RGB) to
    the RGL .bsdf file ``path``, warped by the VNDF of the isotropic microsim NDF ``ndf``
    (module docstring: what each field holds), atomically: nothing is written on an error.

    ``resolution``: an ``RGLResolution``; ``description``: the file's text (default: the
    brdf's and the NDF's repr); ``flavour``: one of ``FLAVOURS``; ``floor`` ∈ [0, 1): the
    Lambertian share of the NDF the file stores and warps by, (1 − floor) D + floor/π — 0
    (the surface's exact NDF) for a microfacet BRDF, > 0 for one with a diffuse term, which an
    exact narrow NDF leaves unrepresentable (a ``UsageError`` says so: ``RHO_LIMIT``).
    ``brdf`` is called at wi at the incidence nodes and wo reflected about each node's half
    vector; a ``BRDFTable``'s clamping beyond its last incidence carries into the file."""
    if not callable(brdf):
        raise UsageError(f"brdf must be a callable f(wi, wo) -> sr⁻¹, got {_checks.short(brdf)}")
    ndf = _check_ndf(ndf)
    if not isinstance(resolution, RGLResolution):
        raise UsageError(
            f"resolution must be an RGLResolution (e.g. RGLResolution(theta_i=32, samples=32)), "
            f"got {_checks.short(resolution)}"
        )
    if flavour not in FLAVOURS:
        raise UsageError(f"flavour must be one of {FLAVOURS}, got {flavour!r}")
    if description is None:
        description = f"microsim export: {_checks.short(brdf, 160)}; NDF {ndf!r}"
    if not isinstance(description, str):
        raise UsageError(f"description must be a str, got {_checks.short(description)}")
    floor = _checks.in_range("floor", floor, 0.0, 1.0, hi_open=True)
    blob = tensor_file_bytes(_fields(brdf, ndf, resolution, description, flavour, floor))
    with atomic_open(path, "wb") as fh:
        fh.write(blob)


# --- the format's error ------------------------------------------------------------------------
def interpolation_error(rgl, brdf: Callable, n: int = 1 << 16, seed: int = 0) -> dict:
    """Energy-weighted relative RMS error of ``rgl.evaluate`` against ``brdf`` (sr⁻¹), the
    relative L2 error of the energy-transfer kernel f cos θi cos θo (what a renderer
    integrates; the readers return f cos θo):

        ε² = ∫∫ (f̂ − f)² cos²θi cos²θo dωi dωo / ∫∫ f² cos²θi cos²θo dωi dωo

    over the upper hemispheres, estimated with ``n`` pairs whose wi is cosine-distributed and
    whose wo is drawn half and half from the cosine density and from the file's own sampling
    density (luminance, then the VNDF warp, as Mitsuba samples: the estimator follows the
    lobe). Returns {"rel_rms", "stderr" (of rel_rms, delta method over the pairs), "n"}."""
    n = _checks.integer("n", n, 16)
    rng = np.random.default_rng(seed)
    wi = _cosine(rng.random(n), rng.random(n))
    wo_cos = _cosine(rng.random(n), rng.random(n))
    wo_lobe, _ = _sample_file(rgl, wi, rng.random((n, 2)))
    pick = rng.random(n) < 0.5
    wo = np.where(pick[:, None], wo_cos, wo_lobe)
    up = wo[:, 2] > 0
    wo = np.where(up[:, None], wo, (0.0, 0.0, 1.0))
    dens = 0.5 * wo[:, 2] / np.pi + 0.5 * _file_pdf(rgl, wi, wo)
    # cos²θi / (cos θi/π) ∝ cos θi for wi, cos²θo / p(wo) for wo
    w = np.where(up, wi[:, 2] * wo[:, 2] ** 2 / np.maximum(dens, 1e-300), 0.0)
    f = np.asarray(brdf(wi, wo), dtype=np.float64).reshape(n)
    g = np.asarray(rgl.f(wi, wo), dtype=np.float64)
    a, b = w * (g - f) ** 2, w * f**2
    A, B = a.mean(), b.mean()
    rel = np.sqrt(A / B)
    cov = np.cov(np.stack([a, b]))  # delta method for √(A/B)
    var = (cov[0, 0] / B**2 - 2 * A * cov[0, 1] / B**3 + A**2 * cov[1, 1] / B**4) / n
    return {"rel_rms": float(rel), "stderr": float(np.sqrt(max(var, 0.0)) / (2 * rel)), "n": n}


def _cosine(u1, u2) -> np.ndarray:
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1 - u1, 0.0))], -1)


def _lum_table(rgl: RGLBRDF) -> _Table2D:
    tab = getattr(rgl, "_lum", None)
    if tab is None:
        f = rgl.fields
        tab = _Table2D(f["luminance"], (f["phi_i"], f["theta_i"]), warp=True)
        object.__setattr__(rgl, "_lum", tab)
    return tab


def _sample_file(rgl: RGLBRDF, wi, u) -> tuple[np.ndarray, np.ndarray]:
    """wo drawn as the readers sample (luminance, then the VNDF warp), and the half vector."""
    theta_i, phi_i = _elevation(wi), np.arctan2(wi[:, 1], wi[:, 0])
    params = (phi_i, theta_i)
    s, _ = _lum_table(rgl).sample(u, params)
    u_m, _ = rgl._vndf.sample(s, params)
    m = spherical(_u2theta(u_m[:, 0]), _u2phi(u_m[:, 1]) + phi_i)
    wo = 2.0 * np.einsum("ij,ij->i", wi, m)[:, None] * m - wi
    return wo / np.linalg.norm(wo, axis=-1, keepdims=True), m


def _file_pdf(rgl: RGLBRDF, wi, wo) -> np.ndarray:
    """The readers' sampling density of wo (sr⁻¹): vndf · luminance / Jacobian."""
    s = wi + wo
    m = s / np.linalg.norm(s, axis=-1, keepdims=True)
    theta_i, phi_i = _elevation(wi), np.arctan2(wi[:, 1], wi[:, 0])
    theta_m, phi_m = _elevation(m), np.arctan2(m[:, 1], m[:, 0])
    uy = _phi2u(phi_m - phi_i)
    u_m = np.stack([_theta2u(theta_m), uy - np.floor(uy)], -1)
    params = (phi_i, theta_i)
    sample, vndf_pdf = rgl._vndf.invert(u_m, params)
    lum_pdf = _lum_table(rgl).eval(sample, params)
    jac = (
        np.maximum(2 * np.pi**2 * u_m[:, 0] * np.sin(theta_m), 1e-6)
        * 4
        * np.einsum("ij,ij->i", wi, m)
    )
    return np.where((wi[:, 2] > 0) & (wo[:, 2] > 0), vndf_pdf * lum_pdf / jac, 0.0)
