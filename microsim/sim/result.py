"""Result of a simulation: bin-averaged BRDF, standard errors, energy ledger, raw tallies.

Arrays are indexed (incidence T, θo bin Θ, Δφ bin Φ); angles in degrees, BRDFs in sr⁻¹.
``save(dir)`` writes ``brdf.npz`` and ``meta.json`` atomically (temporary files in the same
directory, then ``os.replace``); ``Result.load(dir)`` reads them back.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

import numpy as np

from microsim.atomic import atomic_open

from .bins import Bins

__all__ = ["Result", "InPlane"]

NPZ, META = "brdf.npz", "meta.json"
_OPTIONAL = (
    "stderr_ray",
    "stderr_realisation",
    "brdf_realisations",
    "rays_realisations",
    "brdf_orders",
    "stderr_orders",
    "brdf_realisations_orders",
)


@dataclass(frozen=True)
class InPlane:
    """Incidence-plane slice: signed θo in degrees (Δφ = 180°, specular side, positive;
    Δφ = 0°, backward side, negative), ``brdf`` and ``stderr`` (T, 2Θ) in sr⁻¹."""

    theta: np.ndarray
    brdf: np.ndarray
    stderr: np.ndarray


@dataclass(eq=False)
class Result:
    """Bin-averaged single-bounce BRDF of one surface (pooled over realisations).

    ``theta_i``/``phi_i`` (T,) deg; ``bins`` the outgoing grid (``theta_edges``/``phi_edges``
    in deg); ``brdf``/``stderr`` (T, Θ, Φ) sr⁻¹ (stderr combines ray noise and, with several
    realisations, realisation scatter: see ``stderr_ray``/``stderr_realisation``); ``rays`` (T,)
    primary rays; ``ledger`` name → (T,) fractions of primary rays (see ``paths.LEDGER``);
    ``ledger_counts`` name → (T,) integer ray counts; ``counts`` (T, Θ, Φ) single-bounce rays
    per bin; ``sum_w``/``sum_w2`` raw Fresnel-weight tallies; ``models`` name → (T, Θ, Φ)
    bin-averaged model predictions (filled by the caller); ``meta`` JSON-able run description.

    Partial runs (interrupted ``simulate``): ``meta["partial"]`` is True (``is_partial``),
    ``rays`` counts the rays of the complete blocks per incidence (0 and NaN estimates for
    incidences not started). ``tallies`` holds the exact running sums needed to resume:
    ``sum_w``/``sum_w2``/``count`` (R, T, Θ·Φ), ``sum_pair`` (R, T, Θ·Φ) Σ_k w_2k w_2k+1 over
    ray pairs (2k, 2k+1) landing in the same bin (the collapsed-strata standard error, see
    ``tallies.bin_estimate``; ``meta["stderr_method"]`` says whether ``stderr`` uses it),
    ``led_n``/``led_f`` (R, T, 5) per realisation and incidence, ``blocks`` (R, T) blocks done
    and ``rays`` (R, T) rays tallied. Saved as ``tally_<name>`` arrays in ``brdf.npz``.

    Scattering orders (``simulate(..., bounces=K)``, K > 1 or "all"; ``meta["bounces"]``):
    ``brdf_orders``/``stderr_orders`` (O, T, Θ, Φ) sr⁻¹, the BRDF of the light leaving after
    exactly 1, 2, 3 and ≥ 4 bounces (O = min(K, 4) slots, labels ``bounces.ORDER_NAMES``),
    ``brdf_realisations_orders`` (O, R, T, Θ, Φ) with several realisations. ``brdf``,
    ``stderr``, ``counts``, ``sum_w``… stay the order-1 (single-scattering) estimate, so every
    single-bounce model keeps being compared with like; the whole BRDF is
    ``brdf_orders.sum(0)`` (``brdf_total``). The ledger then also holds the paths' terminal
    classes (``bounces.TERMINAL``: ``escaped_1`` … ``escaped_4plus``, ``cut_bounces``,
    ``cut_weight``, ``unresolved_path``, ``missed_path`` as fractions of paths, each with
    ``<name>_energy``, the fraction of incident energy it takes away) and
    ``escaped_energy``, ``cut_energy``, ``absorbed_energy`` (Fresnel losses); the tallies
    hold O·Θ·Φ slots and 5 + 8 ledger columns. All None/absent for ``bounces=1``.
    """

    theta_i: np.ndarray
    phi_i: np.ndarray
    bins: Bins
    brdf: np.ndarray
    stderr: np.ndarray
    rays: np.ndarray
    ledger: dict
    ledger_counts: dict
    counts: np.ndarray
    sum_w: np.ndarray
    sum_w2: np.ndarray
    meta: dict
    models: dict = field(default_factory=dict)
    stderr_ray: np.ndarray | None = None
    stderr_realisation: np.ndarray | None = None
    brdf_realisations: np.ndarray | None = None
    rays_realisations: np.ndarray | None = None
    tallies: dict | None = None
    brdf_orders: np.ndarray | None = None
    stderr_orders: np.ndarray | None = None
    brdf_realisations_orders: np.ndarray | None = None

    def __repr__(self) -> str:
        """One line: surface, material, incidences, rays, bins, albedo, models (no arrays)."""
        surface = (self.meta.get("surface") or {}).get("kind", "?")
        material = (self.meta.get("material") or {}).get("name") or "custom ior"
        n_real = len(self.meta.get("realisations") or ()) or 1
        theta = ", ".join(f"{t:g}" for t in self.theta_i)
        rays = ", ".join(f"{int(r):,}" for r in self.rays)
        albedo = ", ".join(f"{a:.4g}" for a in self.albedo())
        state = " PARTIAL" if self.is_partial else ""
        models = f", models=[{', '.join(self.models)}]" if self.models else ""
        return (
            f"<Result{state} {surface}{f' ×{n_real}' if n_real > 1 else ''}, {material}, "
            f"θi=[{theta}]°, rays=[{rays}], bins={self.bins.n_theta}×{self.bins.n_phi}, "
            f"albedo=[{albedo}]{models}>"
        )

    @property
    def is_partial(self) -> bool:
        """True for an interrupted run (resume it with ``simulate(..., resume=result)``)."""
        return bool(self.meta.get("partial", False))

    @property
    def theta_edges(self) -> np.ndarray:
        return self.bins.theta_edges

    @property
    def phi_edges(self) -> np.ndarray:
        return self.bins.phi_edges

    def albedo(self) -> np.ndarray:
        """Σ_B f̄_B Ω_B per incidence (T,): the single-bounce albedo ρ(θi) seen by the bins."""
        return np.sum(self.brdf * self.bins.projected_solid_angle(), axis=(1, 2))

    def brdf_total(self) -> np.ndarray:
        """The BRDF summed over scattering orders (T, Θ, Φ) sr⁻¹: ``brdf_orders.sum(0)``, or
        ``brdf`` for a single-bounce run."""
        return self.brdf if self.brdf_orders is None else self.brdf_orders.sum(axis=0)

    def realisations_traced(self, t: int) -> np.ndarray | None:
        """Indices of the realisations traced at incidence ``t`` — all of them in a complete
        run, a partial one may lack some (their BRDF is still zero) — or None without
        per-realisation BRDFs (one realisation)."""
        if self.brdf_realisations is None:
            return None
        F = self.brdf_realisations[:, t]
        return np.flatnonzero(np.nansum(np.abs(F), axis=(1, 2)) > 0)

    def in_plane(self) -> InPlane:
        """Signed-θo scattering curve in the incidence plane (``InPlane``)."""
        f, b = self.bins.forward_index, self.bins.backward_index
        tc = self.bins.theta_centers
        theta = np.concatenate([-tc[::-1], tc])
        cat = lambda a: np.concatenate([a[:, ::-1, b], a[:, :, f]], axis=1)  # noqa: E731
        return InPlane(theta=theta, brdf=cat(self.brdf), stderr=cat(self.stderr))

    # --- persistence ------------------------------------------------------------------------
    def _arrays(self) -> dict:
        out = {
            "theta_i": self.theta_i,
            "phi_i": self.phi_i,
            "theta_edges": self.theta_edges,
            "phi_edges": self.phi_edges,
            "brdf": self.brdf,
            "stderr": self.stderr,
            "rays": self.rays,
            "counts": self.counts,
            "sum_w": self.sum_w,
            "sum_w2": self.sum_w2,
        }
        out.update({f"ledger_{k}": v for k, v in self.ledger.items()})
        out.update({f"count_{k}": v for k, v in self.ledger_counts.items()})
        out.update({f"model_{k}": v for k, v in self.models.items()})
        out.update({k: getattr(self, k) for k in _OPTIONAL if getattr(self, k) is not None})
        out.update({f"tally_{k}": v for k, v in (self.tallies or {}).items()})
        return {k: np.asarray(v) for k, v in out.items()}

    def save(self, directory) -> None:
        """Write ``brdf.npz`` and ``meta.json`` into ``directory`` (created if needed), atomically
        and with the user's normal file modes (``microsim.atomic``): each is written to a
        temporary file, and nothing is renamed into place unless both were written."""
        meta = {**self.meta, "bins": self.bins.to_dict()}
        with atomic_open(os.path.join(directory, NPZ), "wb") as npz:
            np.savez(npz, **self._arrays())
            with atomic_open(os.path.join(directory, META)) as fh:
                json.dump(meta, fh, indent=1, default=_jsonable)

    @classmethod
    def load(cls, directory) -> "Result":
        """Read a result written by ``save``."""
        with open(os.path.join(directory, META), encoding="utf-8") as fh:
            meta = json.load(fh)
        bins = Bins(**meta.pop("bins"))
        with np.load(os.path.join(directory, NPZ)) as z:
            a = {k: z[k] for k in z.files}
        pick = lambda prefix: {k[len(prefix) :]: v for k, v in a.items() if k.startswith(prefix)}  # noqa: E731
        return cls(
            theta_i=a["theta_i"],
            phi_i=a["phi_i"],
            bins=bins,
            brdf=a["brdf"],
            stderr=a["stderr"],
            rays=a["rays"],
            ledger=pick("ledger_"),
            ledger_counts=pick("count_"),
            counts=a["counts"],
            sum_w=a["sum_w"],
            sum_w2=a["sum_w2"],
            meta=meta,
            models=pick("model_"),
            tallies=pick("tally_") or None,
            **{k: a[k] for k in _OPTIONAL if k in a},
        )


def _jsonable(obj):
    """JSON fallback for numpy scalars/arrays and other objects (their repr)."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, complex):
        return [obj.real, obj.imag]
    return repr(obj)
