"""Result of a simulation: bin-averaged BRDF, standard errors, energy ledger, raw tallies.

A ``Result`` is immutable: a frozen dataclass whose arrays are read-only views, whose
``meta`` is a deep read-only copy (``FrozenDict``/``FrozenList``: dict and list subclasses, so
``json``, ``isinstance`` and ``==`` keep working) and whose ``models`` is a read-only mapping.
Derivations return new objects (``with_meta``, ``with_models``, ``dataclasses.replace``).

``meta`` is the run description in its JSON form, exactly as ``meta.json`` holds it (it stays
readable by key for users and older scripts); code reads it typed, through ``Result.info``
(a ``RunInfo``: one attribute per key, None where the run did not record it).

Arrays are indexed (incidence T, θo bin Θ, Δφ bin Φ); angles in degrees, BRDFs in sr⁻¹.
``save(dir)`` writes ``brdf.npz`` and ``meta.json`` atomically (temporary files in the same
directory, then ``os.replace``); ``Result.load(dir)`` reads them back.
"""

from __future__ import annotations

import dataclasses
import json
import os
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from microsim.atomic import atomic_open, read_json, read_npz
from microsim.bins import Bins
from microsim.errors import UsageError

from .ledger import LEDGER

__all__ = ["Result", "RunInfo", "InPlane", "FrozenDict", "FrozenList"]

NPZ, META = "brdf.npz", "meta.json"
_OPTIONAL = (
    "stderr_ray",
    "stderr_realisation",
    "brdf_realisations",
    "rays_realisations",
    "brdf_orders",
    "stderr_orders",
    "brdf_realisations_orders",
    "btdf_orders",
    "stderr_btdf_orders",
    "btdf_realisations_orders",
)


def _ior_text(ior) -> str:
    """[n, k] as "n = 0.769+6.08i" (how microsim writes an unnamed material), "ior ?" if absent."""
    if ior is None or isinstance(ior, str):
        return ior or "ior ?"
    try:
        n, k = (float(ior), 0.0) if not hasattr(ior, "__len__") else (float(x) for x in ior)
    except (TypeError, ValueError):
        return str(ior)
    return f"n = {n:g}" if k == 0 else f"n = {n:g}+{k:g}i"


def _refuse(self, *args, **kwargs):
    raise TypeError(f"{type(self).__name__} is read-only (derive a new one instead)")


class FrozenDict(dict):
    """A read-only dict (every mutating method raises TypeError); copies (``dict(d)``,
    ``{**d}``, ``d | e``) are plain dicts."""

    __setitem__ = __delitem__ = __ior__ = clear = pop = popitem = setdefault = update = _refuse

    def __reduce__(self):
        return (type(self), (dict(self),))


class FrozenList(list):
    """A read-only list (every mutating method raises TypeError); ``list(x)`` copies."""

    __setitem__ = __delitem__ = __iadd__ = __imul__ = _refuse
    append = extend = insert = pop = remove = clear = sort = reverse = _refuse

    def __reduce__(self):
        return (type(self), (list(self),))


def _readonly(a):
    """A read-only view of array ``a`` (the caller's array itself stays writeable); None as is."""
    if a is None:
        return None
    v = np.asarray(a)
    v = v.view() if v is a else v
    v.flags.writeable = False
    return v


def _freeze(obj):
    """Deep read-only copy of a JSON-like value: dicts → FrozenDict, lists → FrozenList,
    tuples keep their type, arrays → read-only views, anything else as is."""
    if isinstance(obj, dict):
        return FrozenDict({k: _freeze(v) for k, v in obj.items()})
    if isinstance(obj, list):
        return FrozenList(_freeze(v) for v in obj)
    if isinstance(obj, tuple) and type(obj) is tuple:
        return tuple(_freeze(v) for v in obj)
    if isinstance(obj, np.ndarray):
        return _readonly(obj)
    return obj


def _arrays_of(mapping):
    """name → read-only array view (a FrozenDict), or None."""
    return None if mapping is None else FrozenDict({k: _readonly(v) for k, v in mapping.items()})


_ARRAY_FIELDS = (
    "theta_i",
    "phi_i",
    "brdf",
    "stderr",
    "rays",
    "counts",
    "sum_w",
    "sum_w2",
) + _OPTIONAL


@dataclass(frozen=True)
class RunInfo:
    """The run description of a ``Result``, typed: one attribute per key of ``meta.json``
    (``Result.meta`` is its JSON form; ``from_meta`` reads it, nothing writes it back). A key
    the run did not record reads as the default (None, False or empty); nested records
    (``surface``, ``material``, ``run``…) stay read-only mappings in their JSON form.

    What every run records: ``surface`` (the generator's record: ``kind``, ``tile_size``,
    ``triangles``, ``nominal``, ``warnings``…), ``realisations`` (one such record per tile, or
    Kirchhoff's count; None for one tile), ``material`` (``name``, ``ior`` [n, k]; absent ior:
    a mirror), ``seed``, ``rays`` per incidence, ``stderr_method``, ``partial``/
    ``interrupted`` (an interrupted run) and the wall ``seconds``. The ray tracer's settings:
    ``masking``, ``origins``, ``isotropic``, ``block``, ``bounces`` (1, K or "all") and
    ``max_bounces``, ``transmission`` (a dielectric interface: the Result also holds the
    BTDF), with ``seconds_scene_build`` and ``rays_per_second``. What ``microsim
    run`` adds: ``run`` (the scene's settings: ``bins``, ``realisations_auto``…),
    ``error_budget``, ``realisation_models`` (models built per tile, judged against ray
    noise), ``model_params``, ``model_warnings``, ``tile_departure`` and
    ``seconds_analysis``; an adaptive run: ``auto``; a cluster run: ``scheduler_lost``. The
    Kirchhoff solver's (``method = "kirchhoff"``): ``wavelength``, ``tile``, ``orders``,
    ``qz_nodes``, ``specular_power``/``specular_bin`` per incidence. ``extra``: every other
    key, as recorded."""

    surface: Mapping | None = None
    realisations: Sequence | int | None = None
    material: Mapping | None = None
    seed: int | None = None
    rays: int | None = None
    stderr_method: str | None = None
    partial: bool = False
    interrupted: bool = False
    seconds: float | None = None
    method: str | None = None
    masking: str | None = None
    origins: str | None = None
    isotropic: bool = False
    block: int | None = None
    bounces: int | str | None = None
    max_bounces: int | None = None
    transmission: bool = False
    seconds_scene_build: float | None = None
    rays_per_second: float | None = None
    run: Mapping | None = None
    error_budget: Sequence[Mapping] | None = None
    realisation_models: Sequence[str] = ()
    model_params: Mapping | None = None
    model_warnings: Sequence[str] = ()
    tile_departure: Mapping | None = None
    seconds_analysis: float | None = None
    auto: Mapping | None = None
    scheduler_lost: int | None = None
    wavelength: float | None = None
    tile: Sequence[float] | None = None
    orders: Sequence[int] | None = None
    qz_nodes: int | None = None
    specular_power: Sequence[float] | None = None
    specular_bin: Sequence[int] | None = None
    extra: Mapping = field(default_factory=lambda: FrozenDict())

    @classmethod
    def from_meta(cls, meta: Mapping) -> "RunInfo":
        """The typed reading of ``meta`` (values as they are; keys of no attribute in
        ``extra``)."""
        names = {f.name for f in dataclasses.fields(cls)} - {"extra"}
        known = {k: v for k, v in meta.items() if k in names}
        rest = FrozenDict({k: v for k, v in meta.items() if k not in names})
        return cls(**known, extra=rest)

    @property
    def material_text(self) -> str:
        """The material in words: its name, else "n = 0.769+6.08i", "ior ?" if unknown."""
        mat = self.material or {}
        return mat.get("name") or _ior_text(mat.get("ior"))

    @property
    def n_realisations(self) -> int:
        """How many tiles the run traced (the ray tracer's list, Kirchhoff's count; 1 if
        absent)."""
        reals = self.realisations
        return reals if isinstance(reals, int) else len(reals or ()) or 1


@dataclass(frozen=True)
class InPlane:
    """Incidence-plane slice: signed θo in degrees (Δφ = 180°, specular side, positive;
    Δφ = 0°, backward side, negative), ``brdf`` and ``stderr`` (T, 2Θ) in sr⁻¹."""

    theta: np.ndarray
    brdf: np.ndarray
    stderr: np.ndarray


@dataclass(frozen=True, eq=False)
class Result:
    """Bin-averaged single-bounce BRDF of one surface (pooled over realisations), measured by
    any method (ray tracer, Kirchhoff solver). Immutable (module docstring).

    ``theta_i``/``phi_i`` (T,) deg; ``bins`` the outgoing grid (``theta_edges``/``phi_edges``
    in deg); ``brdf``/``stderr`` (T, Θ, Φ) sr⁻¹ (stderr combines ray noise and, with several
    realisations, realisation scatter: see ``stderr_ray``/``stderr_realisation``); ``meta``
    JSON-able run description (read-only; ``info`` reads it typed, a ``RunInfo``); ``models``
    name → (T, Θ, Φ) bin-averaged model predictions (read-only; ``compare.attach_models``
    returns a Result holding them).

    Ray tallies, an optional part (None for a method without rays, e.g. Kirchhoff: see
    ``has_ray_tallies``): ``rays`` (T,) primary rays; ``ledger`` name → (T,) fractions of
    primary rays (see ``paths.LEDGER``); ``ledger_counts`` name → (T,) integer ray counts.
    Per-bin tallies, also optional: ``counts`` (T, Θ, Φ) events per bin (single-bounce rays;
    Kirchhoff: diffraction orders); ``sum_w``/``sum_w2`` raw sums of the events' weights
    (Fresnel weights; Kirchhoff: order powers) and of their squares.

    Partial runs (interrupted ``simulate``): ``info.partial`` is True (``is_partial``),
    ``rays`` counts the rays of the complete blocks per incidence (0 and NaN estimates for
    incidences not started). ``tallies`` holds the exact running sums needed to resume:
    ``sum_w``/``sum_w2``/``count`` (R, T, Θ·Φ), ``sum_pair`` (R, T, Θ·Φ) Σ_k w_2k w_2k+1 over
    ray pairs (2k, 2k+1) landing in the same bin (the paired-strata standard error, see
    ``tallies.bin_estimate``; ``info.stderr_method`` says whether ``stderr`` uses it),
    ``sum_block2``/``sum_block_rays`` (R, T, Θ·Φ) Σ_b S_b² and Σ_b m_b S_b over the blocks
    (the "blocks" error of ``isotropic`` runs), ``led_n``/``led_f`` (R, T, 5) per realisation
    and incidence, ``blocks`` (R, T) blocks done and ``rays`` (R, T) rays tallied. Saved as
    ``tally_<name>`` arrays in ``brdf.npz``.

    Scattering orders (``simulate(..., bounces=K)``, K > 1 or "all"; ``info.bounces``):
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

    A dielectric interface (``simulate(..., transmission=True)``, ``info.transmission``;
    module ``dielectric``): ``brdf_orders`` hold the light leaving on the incidence's side
    (reflected), ``btdf_orders``/``stderr_btdf_orders`` (O, T, Θ, Φ) sr⁻¹ the light leaving on
    the other side (transmitted), on the same bins with θo measured from the pole of the side
    it leaves by (−z for light refracted into the medium from above) and Δφ = φo − φi of the
    direction itself (specular reflection and refraction both at Δφ = 180°); radiance
    convention: Σ_B f̄_B Ω_B over both is the fraction of the incident flux (``albedo`` R,
    ``transmittance`` T). O ≥ 1 even for ``bounces=1``; ``btdf_realisations_orders`` with
    several realisations. The ledger adds ``transmitted_1`` … ``transmitted_4plus`` (with
    ``_energy``), ``transmitted_energy`` and ``tir_1`` … ``tir_4plus``; the tallies hold
    2O·Θ·Φ slots (reflected, then transmitted) and 5 + 12 + 4 ledger columns.
    """

    theta_i: np.ndarray
    phi_i: np.ndarray
    bins: Bins
    brdf: np.ndarray
    stderr: np.ndarray
    rays: np.ndarray | None = None
    ledger: dict | None = None
    ledger_counts: dict | None = None
    counts: np.ndarray | None = None
    sum_w: np.ndarray | None = None
    sum_w2: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    models: dict = field(default_factory=dict)
    stderr_ray: np.ndarray | None = None
    stderr_realisation: np.ndarray | None = None
    brdf_realisations: np.ndarray | None = None
    rays_realisations: np.ndarray | None = None
    tallies: dict | None = None
    brdf_orders: np.ndarray | None = None
    stderr_orders: np.ndarray | None = None
    brdf_realisations_orders: np.ndarray | None = None
    btdf_orders: np.ndarray | None = None
    stderr_btdf_orders: np.ndarray | None = None
    btdf_realisations_orders: np.ndarray | None = None
    info: RunInfo = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        """Store read-only views of the arrays and deep read-only copies of the mappings."""
        put = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        for k in _ARRAY_FIELDS:
            put(k, _readonly(getattr(self, k)))
        for k in ("ledger", "ledger_counts", "tallies"):
            put(k, _arrays_of(getattr(self, k)))
        put("models", _arrays_of(self.models))
        put("meta", _freeze(dict(self.meta)))
        put("info", RunInfo.from_meta(self.meta))

    @property
    def has_ray_tallies(self) -> bool:
        """True if the result carries the ray ledger (``rays``, ``ledger``, ``ledger_counts``)."""
        return self.rays is not None and self.ledger is not None

    def with_meta(self, **entries) -> "Result":
        """A new Result with ``meta`` updated by ``entries`` (this one is unchanged)."""
        return dataclasses.replace(self, meta={**self.meta, **entries})

    def with_models(self, models) -> "Result":
        """A new Result whose ``models`` is ``models`` (name → (T, Θ, Φ) sr⁻¹)."""
        return dataclasses.replace(self, models=dict(models))

    def __repr__(self) -> str:
        """One line: surface, material, incidences, rays, bins, albedo, models (no arrays)."""
        surface = (self.info.surface or {}).get("kind", "?")
        material = self.info.material_text
        n_real = self.info.n_realisations
        theta = ", ".join(f"{t:g}" for t in self.theta_i)
        rays = (
            "" if self.rays is None else f"rays=[{', '.join(f'{int(r):,}' for r in self.rays)}], "
        )
        albedo = ", ".join(f"{a:.4g}" for a in self.albedo())
        state = " PARTIAL" if self.is_partial else ""
        models = f", models=[{', '.join(self.models)}]" if self.models else ""
        return (
            f"<Result{state} {surface}{f' ×{n_real}' if n_real > 1 else ''}, {material}, "
            f"θi=[{theta}]°, {rays}bins={self.bins.n_theta}×{self.bins.n_phi}, "
            f"albedo=[{albedo}]{models}>"
        )

    def _repr_html_(self) -> str:
        """A notebook's view: one row per incidence (θi, rays, albedo; each model's albedo),
        under a caption of surface, material and bins — no arrays."""
        from microsim.display import html_table

        surface = (self.info.surface or {}).get("kind", "?")
        albedo = self.albedo()
        omega = self.bins.projected_solid_angle()
        names = list(self.models)
        rows = []
        for t, th in enumerate(self.theta_i):
            rays = "–" if self.rays is None else f"{int(self.rays[t]):,}"
            model_albedo = [f"{float(np.sum(self.models[n][t] * omega)):.4g}" for n in names]
            rows.append([f"{th:g}°", rays, f"{albedo[t]:.4g}", *model_albedo])
        caption = (
            f"Result{' (PARTIAL)' if self.is_partial else ''}: {surface}, "
            f"{self.info.material_text}, bins "
            f"{self.bins.n_theta} × {self.bins.n_phi} (θo × Δφ); albedo = Σ f̄Ω"
        )
        header = ["θi", "rays", "albedo (simulation)", *[f"albedo ({n})" for n in names]]
        return html_table(header, rows, caption)

    @property
    def is_partial(self) -> bool:
        """True for an interrupted run (resume it with ``simulate(..., resume=result)``)."""
        return bool(self.info.partial)

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

    def btdf_total(self) -> np.ndarray | None:
        """A dielectric interface's BTDF summed over scattering orders (T, Θ, Φ) sr⁻¹
        (``btdf_orders.sum(0)``), None without transmission."""
        return None if self.btdf_orders is None else self.btdf_orders.sum(axis=0)

    def reflectance(self) -> np.ndarray:
        """Σ_B f̄_B Ω_B of the whole BRDF (all orders traced) per incidence (T,): the fraction
        of the incident flux the bins see reflected (R)."""
        return np.sum(self.brdf_total() * self.bins.projected_solid_angle(), axis=(1, 2))

    def transmittance(self) -> np.ndarray | None:
        """Σ_B f̄_B Ω_B of the whole BTDF per incidence (T,): the fraction of the incident flux
        the bins see transmitted (T), None without transmission."""
        t = self.btdf_total()
        return None if t is None else np.sum(t * self.bins.projected_solid_angle(), axis=(1, 2))

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
        }
        for k in ("rays", "counts", "sum_w", "sum_w2"):
            if getattr(self, k) is not None:
                out[k] = getattr(self, k)
        out.update({f"ledger_{k}": v for k, v in (self.ledger or {}).items()})
        out.update({f"count_{k}": v for k, v in (self.ledger_counts or {}).items()})
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
        """Read a result written by ``save``. Everything read back is checked (``read_json``,
        ``read_npz``: missing, cut short, not JSON or not an archive; ``_check_meta``: the
        types of the keys a Result relies on; ``_check_saved``: shapes, types, signs,
        finiteness, tallies against the ledger): a damaged or edited file is a ``UsageError``
        naming the file and what is wrong."""
        meta_path, npz_path = os.path.join(directory, META), os.path.join(directory, NPZ)
        meta = read_json(meta_path)
        _check_meta(meta, meta_path)
        grid = meta.pop("bins", None)
        if not isinstance(grid, dict):
            raise UsageError(
                f"{meta_path}: bins must be an object {{n_theta, n_phi, folded}}, got {grid!r}"
            )
        try:
            bins = Bins(**grid)
        except (TypeError, UsageError) as e:
            raise UsageError(f"{meta_path}: bins {grid!r}: {' '.join(str(e).split())}") from None
        a = read_npz(npz_path)
        _check_saved(a, meta, bins, npz_path, meta_path)
        pick = lambda prefix: {k[len(prefix) :]: v for k, v in a.items() if k.startswith(prefix)}  # noqa: E731
        return cls(
            theta_i=a["theta_i"],
            phi_i=a["phi_i"],
            bins=bins,
            brdf=a["brdf"],
            stderr=a["stderr"],
            rays=a.get("rays"),
            ledger=pick("ledger_") or None,
            ledger_counts=pick("count_") or None,
            counts=a.get("counts"),
            sum_w=a.get("sum_w"),
            sum_w2=a.get("sum_w2"),
            meta=meta,
            models=pick("model_"),
            tallies=pick("tally_") or None,
            **{k: a[k] for k in _OPTIONAL if k in a},
        )


_META_TYPES = {
    "surface": ((dict,), "an object"),
    "material": ((dict,), "an object"),
    "realisations": ((list, int), "a list of surfaces or a count"),
    "partial": ((bool,), "true or false"),
}
"""The keys of meta.json a Result and its readers rely on (each may be absent or null), with
the JSON types they must have."""


def _check_meta(meta: dict, meta_path: str) -> None:
    """UsageError naming ``meta_path`` and the key unless each ``_META_TYPES`` key present in
    ``meta`` has its type (``bins`` is checked by ``Bins``)."""
    for key, (kinds, name) in _META_TYPES.items():
        value = meta.get(key)
        if value is None:
            continue
        if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
            raise UsageError(f"{meta_path}: {key} must be {name}, got {value!r:.80}")


_REQUIRED = ("theta_i", "phi_i", "theta_edges", "phi_edges", "brdf", "stderr")
_RAY_REQUIRED = ("rays", "counts", "sum_w", "sum_w2")
_TALLIES = ("blocks", "rays", "sum_w", "sum_w2", "count", "led_n", "led_f")


def _check_saved(a: dict, meta: dict, bins: Bins, npz: str, meta_path: str) -> None:
    """UsageError (naming ``npz``/``meta_path`` and the array) unless the arrays ``a`` read
    from ``npz`` form a Result on ``bins``: every array of its shape and kind, counts and
    sums non-negative and finite, the ledger closing on the rays, and the raw tallies
    (``tally_*``) agreeing with the blocks done, the rays and the per-bin counts."""

    def fail(msg):
        raise UsageError(f"{npz}: {msg}")

    # the ray tallies are optional, but a result with any ray ledger or raw tallies has them all
    rayed = any(k.startswith(("ledger_", "count_", "tally_")) for k in a) or "rays" in a
    for k in _REQUIRED + (_RAY_REQUIRED if rayed else ()):
        if k not in a:
            fail(f"no {k} array")
    for k, v in a.items():
        if v.dtype.kind not in "fiu":
            fail(f"{k} must hold real numbers, got dtype {v.dtype}")

    def integers(k, v):
        if v.dtype.kind not in "iu" or np.any(v < 0):
            fail(f"{k} must hold integers >= 0")

    def sums(k, v):
        if not np.all(np.isfinite(v)) or np.any(v < 0):
            fail(f"{k} must hold finite sums >= 0")

    def shape(k, want):
        if a[k].shape != tuple(want):
            fail(f"{k} has shape {a[k].shape}, expected {tuple(want)}")

    n = a["theta_i"].size
    shape("theta_i", (n,))
    shape("phi_i", (n,))
    if not (np.all(np.isfinite(a["theta_i"])) and np.all(np.isfinite(a["phi_i"]))):
        fail("theta_i and phi_i must be finite angles")
    for k, edges in (("theta_edges", bins.theta_edges), ("phi_edges", bins.phi_edges)):
        if a[k].shape != edges.shape or not np.allclose(a[k], edges, rtol=0, atol=1e-9):
            raise UsageError(
                f"{meta_path}: bins {bins.n_theta} × {bins.n_phi} do not match the "
                f"{k} of {npz} ({a[k].size - 1} bins)"
            )
    grid = (n,) + bins.shape
    for k in ("brdf", "stderr", "counts", "sum_w", "sum_w2", "stderr_ray", "stderr_realisation"):
        if k in a:
            shape(k, grid)
    for k in (k for k in a if k.startswith("model_")):
        shape(k, grid)
    for k in ("brdf", "stderr"):
        if np.any(np.isinf(a[k])) or np.any(a[k] < 0):
            fail(f"{k} must be finite and >= 0 (NaN where no ray was traced)")
    if "rays" in a:
        shape("rays", (n,))
        integers("rays", a["rays"])
    if "counts" in a:
        integers("counts", a["counts"])
    for k in ("sum_w", "sum_w2"):
        if k in a:
            sums(k, a[k])
    for k in (k for k in a if k.startswith(("ledger_", "count_"))):
        shape(k, (n,))
        if k.startswith("count_"):
            integers(k, a[k])
    if all(f"count_{c}" in a for c in LEDGER):
        closed = sum(a[f"count_{c}"] for c in LEDGER)
        if not np.array_equal(closed, a["rays"]):
            fail(
                f"the ledger (count_{', count_'.join(LEDGER)}) sums to "
                f"{closed.tolist()} rays, but rays is {a['rays'].tolist()}"
            )
    if "brdf_realisations" in a:
        r = a["brdf_realisations"].shape[0]
        shape("brdf_realisations", (r,) + grid)
        if "rays_realisations" in a:
            shape("rays_realisations", (r,))
            integers("rays_realisations", a["rays_realisations"])
    if "brdf_orders" in a:
        o = a["brdf_orders"].shape[0]
        shape("brdf_orders", (o,) + grid)
        if "stderr_orders" in a:
            shape("stderr_orders", (o,) + grid)
        if "brdf_realisations_orders" in a and "brdf_realisations" in a:
            shape("brdf_realisations_orders", (o, a["brdf_realisations"].shape[0]) + grid)
        for k in ("btdf_orders", "stderr_btdf_orders"):
            if k in a:
                shape(k, (o,) + grid)
        if "btdf_realisations_orders" in a and "brdf_realisations" in a:
            shape("btdf_realisations_orders", (o, a["brdf_realisations"].shape[0]) + grid)
    if any(k.startswith("tally_") for k in a):
        _check_tallies(a, meta, n, bins.shape[0] * bins.shape[1], fail)


def _check_tallies(a: dict, meta: dict, n: int, nbin: int, fail) -> None:
    """The raw running sums of ``_check_saved``: (R, T, ·) arrays, blocks and rays (R, T)
    consistent with each other and with ``rays``, every ray in one first-bounce ledger class,
    the pooled order-1 event counts equal to ``counts``."""
    for k in _TALLIES:
        if f"tally_{k}" not in a:
            fail(f"no tally_{k} array (the raw tallies are incomplete)")
    t = {k[len("tally_") :]: v for k, v in a.items() if k.startswith("tally_")}
    r = t["blocks"].shape[0] if t["blocks"].ndim == 2 else -1
    if t["blocks"].shape != (r, n) or r < 1:
        fail(f"tally_blocks has shape {t['blocks'].shape}, expected (realisations, {n})")
    slots = t["sum_w"].shape[-1] if t["sum_w"].ndim == 3 else 0
    if slots < nbin or slots % nbin:
        fail(f"tally_sum_w has shape {t['sum_w'].shape}, expected ({r}, {n}, k × {nbin})")
    classes = t["led_n"].shape[-1] if t["led_n"].ndim == 3 else 0
    want = {"rays": (r, n), "sum_w2": (r, n, slots), "count": (r, n, slots)}
    want.update(led_n=(r, n, max(classes, len(LEDGER))), led_f=(r, n, classes))
    optional = [k for k in ("sum_pair", "sum_block2", "sum_block_rays") if k in t]
    want.update({k: (r, n, slots) for k in optional})
    for k, s in want.items():
        if t[k].shape != s:
            fail(f"tally_{k} has shape {t[k].shape}, expected {s}")
    for k in ("blocks", "rays", "count", "led_n"):
        if t[k].dtype.kind not in "iu" or np.any(t[k] < 0):
            fail(f"tally_{k} must hold integers >= 0")
    for k in ("sum_w", "sum_w2", "led_f"):
        if not np.all(np.isfinite(t[k])) or np.any(t[k] < 0):
            fail(f"tally_{k} must hold finite sums >= 0")
    for k in optional:
        if not np.all(np.isfinite(t[k])):
            fail(f"tally_{k} must be finite")
    block = meta.get("block")
    if (
        isinstance(block, int)
        and block > 0
        and not np.array_equal(-(-t["rays"] // block), t["blocks"])
    ):
        fail(f"tally_rays and tally_blocks disagree (blocks of {block} rays)")
    if not np.array_equal(t["rays"].sum(axis=0), a["rays"]):
        fail(f"tally_rays sums to {t['rays'].sum(axis=0).tolist()}, rays is {a['rays'].tolist()}")
    if not np.array_equal(t["led_n"][..., : len(LEDGER)].sum(axis=-1), t["rays"]):
        fail("tally_led_n does not close on tally_rays (every ray is in one ledger class)")
    counts = t["count"].sum(axis=0)[:, :nbin].reshape(a["counts"].shape)
    if not np.array_equal(counts, a["counts"]):
        fail("tally_count does not sum to counts")


def _jsonable(obj):
    """JSON fallback for numpy scalars/arrays and other objects (their repr)."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, complex):
        return [obj.real, obj.imag]
    return repr(obj)
