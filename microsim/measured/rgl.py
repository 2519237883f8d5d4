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

The container is a tensor file (``tensor_file``); the unit coordinates of directions and the
warp are in ``rgl_warp``; what ``write_rgl`` stores in ``rgl_write``; ``interpolation_error``
(how far a file is from the function it was written from) in ``rgl_error``.

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

Reading (``read_rgl``): isotropic files (P ≤ 2) of either flavour, jacobian 0 or 1; the
result's ``evaluate`` follows the readers' evaluation above in float64 on the file's float32
tables. Anisotropic files (P > 2: Mitsuba mirrors them by the symmetry ``phi_i`` spans) are
refused. A missing, foreign, truncated or malformed file is a ``UsageError`` naming it, and so
is one whose ndf, sigma, vndf, luminance or rgb/spectra field holds a NaN, an infinite or a
negative value (each is a density or a BRDF value: finite and >= 0).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from microsim import checks as _checks
from microsim.errors import UsageError

from .rgl_error import interpolation_error
from .rgl_warp import Table2D, elevation, phi2u, theta2u
from .rgl_write import (
    DEFAULT_RESOLUTION,
    FLAVOURS,
    LUMINANCE_WEIGHTS,
    RHO_LIMIT,
    SPECTRAL_WAVELENGTHS_NM,
    RGLResolution,
    write_rgl,
)
from .tensor_file import file_error, read_tensor_file, tensor_file_bytes

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
        object.__setattr__(self, "_ndf", Table2D(f["ndf"]))
        object.__setattr__(self, "_sigma", Table2D(f["sigma"]))
        object.__setattr__(self, "_vndf", Table2D(f["vndf"], params_i, warp=True))
        object.__setattr__(self, "_spectra", Table2D(spectra, params_i + (chans,)))
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
        theta_i, phi_i = elevation(wi), np.arctan2(wi[:, 1], wi[:, 0])
        theta_m, phi_m = elevation(m), np.arctan2(m[:, 1], m[:, 0])
        u_wi = np.stack([theta2u(theta_i), phi2u(phi_i)], axis=-1)
        um_y = phi2u(phi_m - phi_i)
        u_m = np.stack([theta2u(theta_m), um_y - np.floor(um_y)], axis=-1)
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
        raise file_error(
            path,
            f"not an RGL BRDF file: missing the field(s) {missing} (an RGL .bsdf file has "
            f"{list(_REQUIRED)} and 'rgb', or 'wavelengths' and 'spectra')",
        )
    kinds = {"description": np.uint8, "jacobian": np.uint8}
    spec = "spectra" if spectral else "rgb"
    for k in need:
        want = np.dtype(kinds.get(k, np.float32))
        if f[k].dtype != want:
            raise file_error(path, f"field {k!r} has dtype {f[k].dtype}, the format wants {want}")
    ndims = {"description": 1, "jacobian": 1, "theta_i": 1, "phi_i": 1, "wavelengths": 1,
             "ndf": 2, "sigma": 2, "vndf": 4, "luminance": 4, spec: 5}  # fmt: skip
    for k in need:
        if f[k].ndim != ndims[k]:
            raise file_error(
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
            raise file_error(path, f"malformed RGL BRDF file: {what}; shapes {shapes}")
    if P > 2:
        raise file_error(
            path,
            f"an anisotropic RGL file (phi_i has {P} entries): microsim reads isotropic ones "
            f"(phi_i of 1 or 2 entries) only",
        )
    for k in ("theta_i", "phi_i") + (("wavelengths",) if spectral else ()):
        a = f[k]
        if not np.all(np.isfinite(a)) or np.any(np.diff(a) <= 0):
            raise file_error(path, f"field {k!r} must be finite and increasing, got {a!r}")
    what = {"ndf": "an NDF", "sigma": "a projected area", "vndf": "a density",
            "luminance": "a density", spec: "BRDF values (ρ)"}  # fmt: skip
    for k, meaning in what.items():
        if not np.all(np.isfinite(f[k])):
            raise file_error(path, f"field {k!r} holds NaN or infinite values")
        negative = np.count_nonzero(f[k] < 0)
        if negative:
            raise file_error(
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
