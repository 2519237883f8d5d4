"""A tabulated isotropic BRDF: bin averages over incidence angles, evaluated anywhere.

``BRDFTable`` holds f̄(θi, B) — the bin-averaged BRDF (sr⁻¹) of the outgoing bins B of a
``sim.Bins`` grid (θo, Δφ = φo − φi, folded onto [0°, 180°]: the surface is isotropic) at
incidence angles θi (degrees, increasing) — with its standard errors. It is what a dense
``simulate`` run measures and what the exporters write.

Evaluation (``evaluate``): at (θi, θo, |Δφ|) the logarithm of the table is interpolated
linearly in θi between the tabulated incidences and in θo and Δφ between bin centres (a bin
average stands for the BRDF at its centre, to second order in the bin width; lobes fall off
exponentially, which log-linear interpolation follows where linear interpolation overshoots by
orders of magnitude; a bin holding 0 counts as ``FLOOR``); outside the range of centres the
nearest value is kept (θo beyond the last centre, θi beyond the last incidence: clamped — the
table says nothing there, and the exporters say so). Δφ is folded: f(Δφ) = f(−Δφ). Reciprocity
is not imposed (a measured table satisfies it within its noise). Directions below the horizon
give 0.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from microsim import checks as _checks
from microsim import vectors
from microsim.bins import Bins
from microsim.errors import UsageError
from microsim.sim.predict import bin_average
from microsim.surfaces.surface import anisotropy_of

__all__ = ["BRDFTable", "FLOOR"]

_SAVED = ("theta_i", "brdf", "stderr", "bins", "name")
"""The arrays of a table file (``BRDFTable.save``)."""

FLOOR = 1e-12
"""BRDF value (sr⁻¹) a bin of 0 stands for in the log-linear interpolation: below any value a
traced bin can hold (one event of weight 1e-12 would need 10¹² rays), so it reads back as 0."""


@dataclass(frozen=True, eq=False)
class BRDFTable:
    """Bin-averaged isotropic BRDF ``brdf`` (T, Θ, Φ) sr⁻¹ with ``stderr`` (same shape) at
    incidences ``theta_i`` (T,) degrees (increasing, in [0, 90)) on folded ``bins``;
    ``name`` describes it (scene, model). Arrays are copied read-only."""

    theta_i: np.ndarray
    bins: Bins
    brdf: np.ndarray
    stderr: np.ndarray
    name: str = "brdf"

    def __post_init__(self):
        th = np.asarray(self.theta_i, dtype=np.float64).ravel()
        if th.size == 0 or not np.all((th >= 0) & (th < 90)) or np.any(np.diff(th) <= 0):
            raise UsageError(
                f"theta_i must be increasing incidence angles in [0, 90) degrees, got {th!r}"
            )
        if not isinstance(self.bins, Bins) or not self.bins.folded:
            raise UsageError(
                "bins must be folded microsim.sim.Bins (a table of an isotropic BRDF), got "
                f"{self.bins!r}"
            )
        shape = (th.size,) + self.bins.shape
        arrays = {}
        for key in ("brdf", "stderr"):
            a = np.array(getattr(self, key), dtype=np.float64)
            if a.shape != shape:
                raise UsageError(f"{key} must have shape {shape} (θi, θo, Δφ), got {a.shape}")
            if not np.all(np.isfinite(a) & (a >= 0)):
                raise UsageError(f"{key} must be finite and >= 0")
            a.setflags(write=False)
            arrays[key] = a
        th.setflags(write=False)
        object.__setattr__(self, "theta_i", th)
        object.__setattr__(self, "brdf", arrays["brdf"])
        object.__setattr__(self, "stderr", arrays["stderr"])
        object.__setattr__(self, "_interp", None)
        object.__setattr__(self, "_held", None)

    @classmethod
    def from_result(cls, result, model: str | None = None, name: str | None = None):
        """The table of a ``Result`` on folded bins at φi = 0 (all incidences): its simulated
        BRDF — the whole BRDF of every order it traced (``Result.brdf_total``, standard errors
        of the orders added in quadrature), ``brdf`` for a single-bounce run — or the bin
        averages of ``model`` (one of ``result.models``; stderr 0). A result of an anisotropic
        surface (``meta["surface"]``, judged as ``microsim measure`` judges
        a scene: ``surfaces.surface.anisotropy_of``) is refused: its BRDF depends on the
        incidence azimuth, which the table does not hold."""
        if not result.bins.folded or np.any(np.asarray(result.phi_i) != 0.0):
            raise UsageError(
                "result must be of an isotropic surface: folded bins, every φi = 0 (an "
                "anisotropic BRDF needs its incidence azimuth in the table)"
            )
        surface = result.meta.get("surface")
        if isinstance(surface, dict):
            params = surface.get("nominal", surface)  # a ray run's "nominal"; a wave run's own
            kind = surface.get("kind")
            what = anisotropy_of(kind, params) if isinstance(params, dict) else None
            if what is not None:
                raise UsageError(
                    f"result must be of an isotropic surface, got one of an anisotropic {kind} "
                    f"surface ({what}): "
                    "its BRDF depends on the incidence azimuth, which a table over θi and "
                    "folded Δφ does not hold"
                )
        order = np.argsort(result.theta_i)
        if model is None:
            f, se = np.asarray(result.brdf_total()), np.asarray(result.stderr)
            if result.stderr_orders is not None:  # conservative: the orders' sums of one
                # run are anti-correlated (a path ends in one order), never positively
                se = np.sqrt(np.sum(np.asarray(result.stderr_orders) ** 2, axis=0))
        else:
            if model not in result.models:
                raise UsageError(
                    f"model must be one of the result's models {sorted(result.models)}, "
                    f"got {model!r}"
                )
            f = np.asarray(result.models[model])
            se = np.zeros_like(f)
        label = name or (model if model is not None else "simulation")
        return cls(np.asarray(result.theta_i)[order], result.bins, f[order], se[order], label)

    @classmethod
    def from_function(cls, brdf, theta_i, bins: Bins, name: str = "", rtol: float = 1e-3):
        """The table of the bin averages of ``brdf(wi, wo)`` (sr⁻¹, isotropic) at incidences
        ``theta_i`` (degrees, increasing, < 90) on folded ``bins`` (stderr 0): ``sim.predict``'s
        adaptive quadrature ``bin_average`` with relative tolerance ``rtol``, both ±Δφ halves
        folded together."""
        if not isinstance(bins, Bins) or not bins.folded:
            raise UsageError(f"bins must be folded microsim.sim.Bins, got {bins!r}")
        theta = np.atleast_1d(np.asarray(theta_i, dtype=np.float64))
        for th in theta:
            _checks.in_range("theta_i", th, 0.0, 90.0, hi_open=True)
        values = np.stack(
            [
                bin_average(
                    vectors.spherical_deg(th, 0.0), bins, brdf, 0.0, rtol, symmetric=True
                ).values
                for th in theta
            ]
        )
        return cls(theta, bins, values, np.zeros_like(values), name)

    def save(self, path) -> None:
        """Write the table to ``path`` (.npz: theta_i, brdf, stderr, the bins' n_theta, n_phi,
        the name), atomically."""
        from microsim.atomic import atomic_open

        with atomic_open(str(path), "wb") as fh:
            np.savez(
                fh,
                theta_i=self.theta_i,
                brdf=self.brdf,
                stderr=self.stderr,
                bins=np.array([self.bins.n_theta, self.bins.n_phi]),
                name=np.array(self.name),
            )

    @classmethod
    def load(cls, path) -> "BRDFTable":
        """Read a table written by ``save``, checked as any table: a missing, foreign (a .npy
        array, an archive without the table's arrays), truncated or edited file (``bins`` not
        two integers, arrays of the wrong shape or with negative values) is a UsageError
        naming the file and what is wrong."""
        try:
            with open(path, "rb") as fh:  # closed here even when np.load fails on a broken zip
                z = np.load(fh, allow_pickle=False)
                if not isinstance(z, np.lib.npyio.NpzFile):
                    raise UsageError(
                        f"{path}: not a microsim BRDF table (a single array; a table is the "
                        ".npz archive BRDFTable.save writes)"
                    )
                with z:
                    missing = [k for k in _SAVED if k not in z.files]
                    if missing:
                        raise UsageError(f"{path}: not a microsim BRDF table (no {missing} arrays)")
                    a = {k: z[k] for k in _SAVED}
        except UsageError:
            raise
        except (OSError, EOFError, ValueError, zipfile.BadZipFile) as e:
            raise UsageError(
                f"{path}: not a readable microsim BRDF table ({type(e).__name__}: "
                f"{' '.join(str(e).split())})"
            ) from None
        bins = a["bins"]
        if bins.shape != (2,) or not np.issubdtype(bins.dtype, np.integer):
            raise UsageError(
                f"{path}: bins must be the two integers (n_theta, n_phi), got {_checks.short(bins)}"
            )
        try:
            return cls(
                a["theta_i"], Bins(int(bins[0]), int(bins[1])), a["brdf"], a["stderr"],
                str(a["name"]),
            )  # fmt: skip
        except UsageError as e:
            raise UsageError(f"{path}: {e}") from None

    def _values(self) -> np.ndarray:
        """log f̄ on the interpolation grid (a bin of 0 as ``FLOOR``; one incidence repeated,
        so that it is constant in θi)."""
        values = np.log(np.maximum(self.brdf, FLOOR))
        return np.concatenate([values, values]) if len(self.theta_i) == 1 else values

    def _interpolator(self):
        if self._interp is None:
            th_o = self.bins.theta_centers
            phi = self.bins.phi_centers  # 0 … 180 inclusive for folded bins
            ti = self.theta_i
            values = self._values()
            if ti.size == 1:  # one incidence: constant in θi
                ti = np.array([ti[0], ti[0] + 1.0])
            interp = RegularGridInterpolator(
                (ti, th_o, phi), values, method="linear", bounds_error=False, fill_value=None
            )
            lo = np.array([ti[0], th_o[0], 0.0])
            hi = np.array([ti[-1], th_o[-1], 180.0])
            object.__setattr__(self, "_interp", (interp, lo, hi))
        return self._interp

    def _points(self, wi, wo):
        """(interpolation points (…, 3) of (θi, θo, |Δφ|) clamped to the table, whether both
        directions are above the horizon) for unit directions (…, 3)."""
        wi = _checks.directions("wi", wi)
        wo = _checks.directions("wo", wo)
        wi, wo = np.broadcast_arrays(wi, wo)
        ti = np.degrees(np.arccos(np.clip(wi[..., 2], -1.0, 1.0)))
        to = np.degrees(np.arccos(np.clip(wo[..., 2], -1.0, 1.0)))
        dphi = np.degrees(np.arctan2(wo[..., 1], wo[..., 0]) - np.arctan2(wi[..., 1], wi[..., 0]))
        dphi = np.abs(np.mod(dphi + 180.0, 360.0) - 180.0)
        _, lo, hi = self._interpolator()
        up = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        return np.clip(np.stack([ti, to, dphi], axis=-1), lo, hi), up

    source: ClassVar[str] = "a tabulated BRDF (bin averages over incidences)"
    symmetric: ClassVar[bool] = True  # isotropic: mirroring wo about the plane of incidence

    def params(self) -> dict:
        """The table's name, incidences (degrees) and bins (the model protocol's ``params``)."""
        return {"name": self.name, "theta_i": self.theta_i, "bins": self.bins}

    def f(self, wi, wo) -> np.ndarray:
        """f(wi, wo) sr⁻¹ for unit directions (…, 3) pointing away from the surface (module
        docstring: linear between tabulated θi and bin centres, clamped outside them); the
        model protocol's ``f`` (``analytic.models.BRDFModel``)."""
        pts, up = self._points(wi, wo)
        interp = self._interpolator()[0]
        f = np.exp(interp(pts.reshape(-1, 3)).reshape(up.shape))
        f = np.where(f <= FLOOR * (1 + 1e-9), 0.0, f)
        return np.where(up, f, 0.0)

    def resolved(self, wi, wo) -> np.ndarray:
        """Whether ``f(wi, wo)`` is interpolated from bins that all hold events (bool,
        the directions' shape). A bin without events says only that no ray landed there (a
        small bin at the edge of a lobe, the pole bins at large θi): a value interpolated
        from it is pulled towards 0 by the log-linear rule, not measured."""
        pts, up = self._points(wi, wo)
        if self._held is None:
            interp = self._interpolator()[0]
            held = RegularGridInterpolator(
                interp.grid, (self._values() > np.log(FLOOR)).astype(np.float64),
                method="linear", bounds_error=False, fill_value=None,
            )  # fmt: skip
            object.__setattr__(self, "_held", held)
        return up & (self._held(pts.reshape(-1, 3)).reshape(up.shape) >= 1.0 - 1e-9)

    evaluate = f
    __call__ = f
