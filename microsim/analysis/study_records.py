"""A run's verdict document (verdicts.json, docs/verdicts.md) as typed records: the whole
document (``RunDocument``), its fits (``Fit``, ``FitBound``), the orders study
(``OrdersStudy``: per θi ``BounceNeed``, and the ``OrderComparison`` of the scattering orders
against the multiple-scattering models, ``multiple.order_comparison``, with its parts
``OrderIncidence``, ``SimOrders``, ``ModelEnergy``; the per-θi rows ``OrderEnergy``), the
rough-glass study (``GlassStudy`` and its ``GlassIncidence`` rows), the
wave section (``WaveSection``: a wave scene's closed forms against Kirchhoff, and its
``WaveVerdict`` records, fields ``WAVE_VERDICT_SCHEMA``), ``RegimeMaps`` (what the index prints
of the regime maps), the anisotropy study (``AnisotropyStudy``,
``anisotropy.anisotropy_summary``, and its parts), ``Stability`` and ``Speed``. Each is a
``JsonRecord``: builders read attributes, ``json`` writes it unchanged, and ``from_json``
reads the dict of a file back."""

from __future__ import annotations

from dataclasses import dataclass, field
from dataclasses import fields as dataclass_fields
from typing import ClassVar, Mapping, Sequence

from microsim.errors import UsageError

from .json_record import JsonRecord, MapOf, read_nested
from .verdict_record import Verdict

__all__ = [
    "MODELS",
    "SimOrders",
    "ModelEnergy",
    "OrderIncidence",
    "OrderComparison",
    "OrderEnergy",
    "BounceNeed",
    "OrdersStudy",
    "GlassIncidence",
    "GlassStudy",
    "WAVE_VERDICT_SCHEMA",
    "validate_wave_verdict",
    "WaveVerdict",
    "WaveSection",
    "RegimeMaps",
    "StandIn",
    "VariantVerdict",
    "MissedModel",
    "MissedEnergy",
    "AnisotropyIncidence",
    "AnisotropyStudy",
    "FitBound",
    "Fit",
    "Stability",
    "SpeedRun",
    "Speed",
    "RunDocument",
]


# --- the order comparison (multiple.order_comparison) -----------------------------------------
MODELS = ("random-walk", "kulla-conty", "mikkelsen-eq28")
"""Models of the multiply scattered light an order comparison judges per θi."""


@dataclass(frozen=True, eq=False)
class SimOrders(JsonRecord):
    """The simulated energies of one incidence (fractions of the incident power ± standard
    errors): per order slot, of orders ≥ 2 (``multiple``), absorbed, cut and lost; where the
    errors come from; the specular share of orders ≥ 2 and the size of its 90 % energy set."""

    orders: Sequence[float]
    order_se: Sequence[float]
    multiple: float
    multiple_se: float
    absorbed: float
    absorbed_se: float
    cut: float
    cut_se: float
    lost: float
    lost_se: float
    realisations: int
    se_from: str
    specular_share: float | None
    specular_share_se: float | None
    energy_bins_90: int


@dataclass(frozen=True, eq=False)
class ModelEnergy(JsonRecord):
    """One model's energy of orders ≥ 2 at one incidence, its energy test against the
    simulation (relative deviation (sim − model)/sim ± se, t, p, threshold, agrees) and its
    lobe errors over the energy set; the random walk's also per order (``orders``,
    ``order_se``, ``max_order``, ``cut``; None and absent from the dict for the others)."""

    OMITTED_IF_NONE: ClassVar[tuple[str, ...]] = ("orders", "order_se", "max_order", "cut")

    energy: float
    energy_se: float
    rel_dev: float | None
    rel_dev_se: float | None
    t: float
    dof: int | None
    p_value: float
    t_threshold: float
    agrees: bool
    fitted: bool
    rel_rms: float | None
    shape_rel_rms: float | None
    noise_floor: float | None
    energy_bins: int
    specular_share: float | None
    orders: Sequence[float] | None = None
    order_se: Sequence[float] | None = None
    max_order: int | None = None
    cut: float | None = None


@dataclass(frozen=True, eq=False)
class OrderIncidence(JsonRecord):
    """One incidence of an order comparison: the simulation (``sim``), each model (``models``,
    name → ``ModelEnergy``) and the random walk's BRDF verdicts (``walk_verdicts``, "2" and
    "2+" → ``Verdict``)."""

    OLDER_DEFAULTS: ClassVar[Mapping] = {"phi_i": 0.0}

    theta_i: float
    phi_i: float
    sim: SimOrders
    models: Mapping[str, ModelEnergy]
    walk_verdicts: Mapping[str, Verdict]

    _nested: ClassVar = {
        "sim": SimOrders,
        "models": MapOf(ModelEnergy),
        "walk_verdicts": MapOf(Verdict),
    }


@dataclass(frozen=True, eq=False)
class OrderComparison(JsonRecord):
    """The scattering orders of a run against the random walk, Kulla–Conty and Mikkelsen eq. 28
    (``multiple`` module docstring): the settings (NDF, models, material, bounces, walk paths
    and seed, realisations, family level), Mikkelsen's fitted k_d, Kulla–Conty's E_avg (None
    when the closed forms are left out, ``closed_forms_note`` says why), whether the models are
    expected to hold (``expectation`` says why not) and the ``incidences``."""

    OLDER_DEFAULTS: ClassVar[Mapping] = {
        "expected": True,
        "expectation": None,
        "models": MODELS,
        "closed_forms_note": None,
    }

    expected: bool
    expectation: str | None
    ndf: Mapping
    models: Sequence[str]
    material: str | None
    bounces: int | str
    order_labels: Sequence[str]
    walk_paths: int
    walk_seed: str
    realisations: int
    alpha: float
    alpha_each_energy: float
    kd: float | None
    kd_note: str
    kulla_conty_e_avg: float | None
    closed_forms_note: str | None
    incidences: Sequence[OrderIncidence]
    _nested: ClassVar = {"incidences": OrderIncidence}


@dataclass(frozen=True, eq=False)
class OrderEnergy(JsonRecord):
    """The simulated energy per order slot at one incidence, of orders ≥ 2 (``multiple``) and of
    all orders (``reflected``) ± standard errors, and the absorbed, cut and lost energy."""

    theta_i: float
    phi_i: float
    orders: Sequence[float]
    order_se: Sequence[float]
    multiple: float
    multiple_se: float
    reflected: float
    reflected_se: float
    absorbed: float
    cut: float
    lost: float
    realisations: int


@dataclass(frozen=True, eq=False)
class BounceNeed(JsonRecord):
    """Whether the light of orders ≥ 2 at one incidence exceeds ``threshold`` of the reflected
    energy (``needs``): its fraction ± se and the energy cut at the bounce limit."""

    theta_i: float
    phi_i: float
    multiple_fraction: float
    multiple_fraction_se: float
    cut: float
    threshold: float
    needs: bool


# --- the wave-optics section (runner.wave_run) -------------------------------------------------
_NUM = (int, float)
_OPT_NUM = (int, float, type(None))

WAVE_VERDICT_SCHEMA: dict = {
    "theta_i": (_NUM, "incidence polar angle θi, degrees"),
    "model": ((str,), "closed form judged (one of WAVE_MODELS, or a caller's name)"),
    "reference": ((str,), "what it is judged against: 'kirchhoff' (diffuse part)"),
    "kind": ((str,), "'theory-vs-theory': both are approximations; never 'deviates'"),
    "params": ((dict,), "model parameters (PSD, wavelength, material), no fit"),
    "tol": (_NUM, "relative tolerance of agreement (default 0.02)"),
    "z": (_NUM, "noise multiplier: agreement within tol + z·standard error"),
    "fraction": (_NUM, "share of the diffuse energy the energy set carries (0.9)"),
    "energy_bins": ((int,), "bins in the energy set E"),
    "energy_dev": (_OPT_NUM, "Σ_E Ω(ref − model)/Σ_E Ω ref, signed (null if E is empty)"),
    "energy_dev_se": (_OPT_NUM, "standard error of energy_dev from the reference's stderr"),
    "rel_error": (
        _OPT_NUM,
        "energy-weighted relative RMS error √(Σ_E refΩ e²/Σ_E refΩ), e = (ref − model)/ref",
    ),
    "rel_error_se": (_OPT_NUM, "delta-method standard error of rel_error"),
    "noise_floor": (_OPT_NUM, "rel_error a perfect model would show: √(Σ_E refΩ (se/ref)²/Σ)"),
    "model_rtol": (_NUM, "relative quadrature error of the model's bin averages"),
    "tested_bins": ((int,), "bins with ref·Ω ≥ min_share of the diffuse energy"),
    "min_share": (_NUM, "share of the diffuse energy a bin needs to enter the region test"),
    "theta_o_max": (
        _NUM,
        "bins beyond this θo (degrees) are left out (grazing: outside Kirchhoff)",
    ),
    "region": (
        (dict,),
        "{'forward': [[θo_lo, θo_hi], ...], 'backward': [...]}: θo ranges (degrees) of rows "
        "whose energy-weighted mean relative error is within tol + z·se (forward: Δφ ≥ 90°); "
        "null for a side with no tested row",
    ),
    "outside": (
        (dict,),
        "{'forward': [min ē, max ē] or null, 'backward': ...}: the range of the row errors "
        "outside the region",
    ),
    "rows": ((list,), "[side, θo_lo, θo_hi, ē, se, agrees] per tested row"),
    "status": ((str,), "'agrees' | 'agrees-in-region' | 'differs'"),
    "worst_bin": ((list, type(None)), "[θo, Δφ] bin centre of the largest |e| over E"),
    "max_rel_dev": (_OPT_NUM, "signed e of largest magnitude over E"),
}


def validate_wave_verdict(d) -> dict:
    """Check a wave verdict dict against ``WAVE_VERDICT_SCHEMA`` (keys, types, status);
    returns it, or raises UsageError naming the first problem."""
    if not isinstance(d, Mapping):
        raise UsageError(f"wave verdict must be a dict, got {type(d).__name__}")
    missing = set(WAVE_VERDICT_SCHEMA) - set(d)
    extra = set(d) - set(WAVE_VERDICT_SCHEMA)
    if missing or extra:
        raise UsageError(f"wave verdict keys: missing {sorted(missing)}, unknown {sorted(extra)}")
    for key, (types, _) in WAVE_VERDICT_SCHEMA.items():
        v = d[key]
        if isinstance(v, bool) and bool not in types:
            raise UsageError(f"wave verdict {key!r} must be {types}, got a bool")
        if not isinstance(v, types):
            raise UsageError(f"wave verdict {key!r} must be {types}, got {type(v).__name__}")
    if d["status"] not in ("agrees", "agrees-in-region", "differs"):
        raise UsageError(f"wave verdict status {d['status']!r} is not one of the three")
    return dict(d)


@dataclass(frozen=True, eq=False)
class WaveVerdict(JsonRecord):
    """One wave verdict (every field documented in ``WAVE_VERDICT_SCHEMA``), read by attribute;
    also the read-only dict verdicts.json holds. ``from_json`` reads one back, checked
    (``validate_wave_verdict``)."""

    theta_i: float
    model: str
    reference: str
    kind: str
    params: dict
    tol: float
    z: float
    fraction: float
    energy_bins: int
    model_rtol: float
    min_share: float
    theta_o_max: float
    energy_dev: float | None
    energy_dev_se: float | None
    rel_error: float | None
    rel_error_se: float | None
    noise_floor: float | None
    worst_bin: list | None
    max_rel_dev: float | None
    tested_bins: int
    region: dict
    outside: dict
    rows: list
    status: str

    @classmethod
    def from_json(cls, d: Mapping) -> "WaveVerdict":
        """The record of wave verdict dict ``d``, checked (``validate_wave_verdict``: every
        field present)."""
        if isinstance(d, cls):
            return d
        return super().from_json(validate_wave_verdict(d))


@dataclass(frozen=True, eq=False)
class WaveSection(JsonRecord):
    """A wave scene's closed forms against Kirchhoff (verdicts.json "wave"): the Kirchhoff
    solver's settings (wavelength, surface model, upsample, Fresnel angle, tile and σ in
    lengths and wavelengths, tiles used and traced, how its errors are estimated), per θi the
    roughness g, the specular order's power against Debye–Waller, the ray tracer's masked
    fraction and whether Kirchhoff is in its domain, the diffraction orders, the file of the
    Kirchhoff result and the ``verdicts`` (``wave_verdicts.WaveVerdict``)."""

    reference: str
    kind: str
    wavelength: float
    length_unit: str
    surface_model: str
    upsample: int
    fresnel_angle: str
    tile: Sequence[float]
    tile_over_lambda: Sequence[float]
    sigma_over_lambda: float
    realised_sigma_over_lambda: float
    realisations: int
    run_realisations: int
    stderr_method: str
    theta_i: Sequence[float]
    g: Sequence[float]
    specular_power: Sequence[float]
    debye_waller: Sequence[float]
    masked_fraction: Sequence[float]
    masked_limit: float
    in_domain: Sequence[bool]
    orders: Sequence[int]
    file: str
    verdicts: Sequence
    _nested: ClassVar = {"verdicts": WaveVerdict}


@dataclass(frozen=True, eq=False)
class RegimeMaps(JsonRecord):
    """The regime maps the index prints (``runner.wave_run.regime_maps``): the maps
    (``regimes.RegimeMap``), one line saying which settings were used and the chart's file
    name (None, and absent from the dict, until it is written)."""

    OMITTED_IF_NONE: ClassVar[tuple[str, ...]] = ("chart",)

    maps: Sequence
    settings: str
    chart: str | None = None


# --- the orders study ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class OrdersStudy(JsonRecord):
    """The scattering orders of a run traced with bounces > 1 (verdicts.json "orders"): the
    bounce limit, per θi whether orders ≥ 2 matter (``needs``, ``BounceNeed``), the order
    comparison (``OrderComparison``, None without one) and a note saying why not (or None)."""

    bounces: int | str
    needs: Sequence[BounceNeed]
    comparison: OrderComparison | None
    note: str | None
    _nested: ClassVar = {"needs": BounceNeed, "comparison": OrderComparison}
    OLDER_DEFAULTS: ClassVar[Mapping] = {"needs": ()}


# --- the rough-glass study (glass.glass_study) ----------------------------------------------
@dataclass(frozen=True, eq=False)
class GlassIncidence(JsonRecord):
    """One incidence of a rough-glass study: the ``side`` the light comes from ("air" or
    "medium"), ``theta`` its angle from that side's pole and ``theta_i`` as traced (degrees,
    (90, 180] from the medium); the fractions of the incident flux reflected and transmitted,
    all orders (``reflected``, ``transmitted`` ± se) and at order 1 (``single_*`` ± se;
    ``single`` their sum);
    ``tir`` the paths totally internally reflected at their first interaction; per model
    (name → [R, T]) its single-scattering reflectance and transmittance; the ``verdicts``
    of the models' BRDF and BTDF against order 1 (``Verdict``, the lobe in its model name);
    ``multiple``: per model of every order ("random-walk", "kulla-conty") its
    [R, T, se of R, se of T] (se 0 for a closed form), to set against R and T."""

    side: str
    theta: float
    theta_i: float
    reflected: float
    reflected_se: float
    transmitted: float
    transmitted_se: float
    single_reflected: float
    single_reflected_se: float
    single_transmitted: float
    single_transmitted_se: float
    single: float
    single_se: float
    tir: float
    models: Mapping[str, Sequence[float]]
    verdicts: Sequence[Verdict]
    multiple: Mapping[str, Sequence[float]] = field(default_factory=dict)
    _nested: ClassVar = {"verdicts": Verdict}


@dataclass(frozen=True, eq=False)
class GlassStudy(JsonRecord):
    """A scene traced through a dielectric interface (verdicts.json "glass"): the medium's
    index ``eta``, the microsurface distribution the models use (``ndf``, its text), the
    folder of the run lit from inside (``inside``), and per incidence, from the air then from
    the medium, a ``GlassIncidence``."""

    eta: float
    ndf: str
    inside: str
    incidences: Sequence[GlassIncidence]
    _nested: ClassVar = {"incidences": GlassIncidence}


# --- the anisotropy study (anisotropy.anisotropy_summary) ----------------------------------------
@dataclass(frozen=True, eq=False)
class StandIn(JsonRecord):
    """The isotropic stand-in against the exact Λ: energy deviation and rel RMS."""

    energy_dev: float | None = None
    rel_rms: float | None = None


@dataclass(frozen=True, eq=False)
class VariantVerdict(JsonRecord):
    """An anisotropic variant against the simulation at one incidence: its ``verdict`` kind,
    energy deviation (± its standard error) and rel RMS."""

    rel_rms: float | None = None
    energy_dev: float | None = None
    energy_dev_se: float | None = None
    verdict: str = "agrees"


@dataclass(frozen=True, eq=False)
class MissedModel(JsonRecord):
    """A variant's single-scattering ``energy`` and what it ``missed`` (± ``missed_se``)."""

    energy: float | None = None
    missed: float | None = None
    missed_se: float | None = None


@dataclass(frozen=True, eq=False)
class MissedEnergy(JsonRecord):
    """The energy the single-scattering variants miss at one incidence (``anisotropy`` module
    docstring): the simulated reflected energy of all orders and of orders ≥ 2 ± se, per
    variant label (``models``, ``MissedModel``), and the random walk's orders ≥ 2 ± se (None,
    and absent from the dict, without an order comparison)."""

    OMITTED_IF_NONE: ClassVar[tuple[str, ...]] = ("walk_multiple", "walk_multiple_se")

    reflected: float
    reflected_se: float
    multiple: float
    multiple_se: float
    models: Mapping[str, MissedModel]
    walk_multiple: float | None = None
    walk_multiple_se: float | None = None
    _nested: ClassVar = {"models": MapOf(MissedModel)}


@dataclass(frozen=True, eq=False)
class AnisotropyIncidence(JsonRecord):
    """One incidence of the anisotropy study: the stand-in against the exact Λ (``StandIn``),
    each variant label against the simulation (``VariantVerdict``) and, for a run with
    bounces > 1, the energy each misses (``MissedEnergy``; None, and absent from the dict,
    otherwise)."""

    OMITTED_IF_NONE: ClassVar[tuple[str, ...]] = ("missed",)

    theta_i: float
    phi_i: float
    stand_in_vs_exact: StandIn
    against_simulation: Mapping[str, VariantVerdict]
    missed: MissedEnergy | None = None
    _nested: ClassVar = {
        "stand_in_vs_exact": StandIn,
        "against_simulation": MapOf(VariantVerdict),
        "missed": MissedEnergy,
    }
    OLDER_DEFAULTS: ClassVar[Mapping] = {"phi_i": 0.0}


@dataclass(frozen=True, eq=False)
class AnisotropyStudy(JsonRecord):
    """An anisotropic scene's Smith G variants (verdicts.json "anisotropy"): ``variants``
    (label → model name) and per incidence an ``AnisotropyIncidence``."""

    variants: Mapping[str, str]
    incidences: Sequence[AnisotropyIncidence]
    _nested: ClassVar = {"incidences": AnisotropyIncidence}


# --- the fits, the stability and speed studies, and the whole document -------------------------
@dataclass(frozen=True, eq=False)
class FitBound(JsonRecord):
    """A bound of its box a fit ended on: ``param`` at ``bound`` on its ``side`` ("lower",
    "upper"); ``physical``: a physical bound (else a search limit)."""

    param: str = ""
    bound: float = 0.0
    side: str = "lower"
    physical: bool = True


@dataclass(frozen=True, eq=False)
class Fit(JsonRecord):
    """One fitted model of verdicts.json ``fits`` (``analysis.fits``): its ``params``, Löw's
    √E1 and √E2, whether the optimiser ``success``-ed and the fit ``converged``, its
    ``n_starts`` and the bounds it ended on."""

    model: str = ""
    params: Mapping = field(default_factory=dict)
    sqrt_e1: float | None = None
    sqrt_e2: float | None = None
    success: bool = True
    converged: bool = True
    n_starts: int = 1
    at_bounds: Sequence[FitBound] = ()
    _nested: ClassVar = {"at_bounds": FitBound}


@dataclass(frozen=True, eq=False)
class Stability(JsonRecord):
    """verdicts.json ``stability``: the θi sweep (``rays`` each at ``phi_i``), each model's
    ``rel_rms`` over it, and the estimator's ``warnings``."""

    theta_i: Sequence[float] = ()
    phi_i: float = 0.0
    rays: int | None = None
    rel_rms: Mapping = field(default_factory=dict)
    warnings: Sequence[str] = ()


@dataclass(frozen=True, eq=False)
class SpeedRun(JsonRecord):
    """One origin strategy of the speed study: its ``rays`` counts and their ``rel_rms``."""

    rays: Sequence[int] = ()
    rel_rms: Sequence[float] = ()


@dataclass(frozen=True, eq=False)
class Speed(JsonRecord):
    """verdicts.json ``speed``: the speed runs at ``theta_i``, judged against ``reference``,
    per origin strategy (``runs``)."""

    theta_i: float | None = None
    phi_i: float = 0.0
    reference: str | None = None
    runs: Mapping[str, SpeedRun] = field(default_factory=dict)
    _nested: ClassVar = {"runs": MapOf(SpeedRun)}


@dataclass(frozen=True)
class RunDocument:
    """A run's verdict document (``verdicts.json``, docs/verdicts.md) as the reports read it:
    the scene and its settings (``surface``: its kind, keys and ensemble NDF), the ``verdicts``
    as ``Verdict`` records, the studies as records (``fits``, ``orders``, ``glass``,
    ``anisotropy``, ``stability``, ``speed``; None or empty when the run has none; ``wave``
    stays a JSON object). ``from_json`` reads the dict written (or about to be written) to
    the file; keys of no field are left out."""

    scene: str = ""
    verdicts: Sequence[Verdict] = ()
    scene_file: str | None = None
    description: str = ""
    surface: Mapping | None = None
    quick: bool = False
    rays: int | None = None
    theta_i: Sequence[float] = ()
    phi_i: Sequence[float] = (0.0,)
    seed: int | None = None
    ranking: Sequence[str] = ()
    outside_domain: Mapping = field(default_factory=dict)
    fits: Sequence[Fit] = ()
    wave: Mapping | None = None
    orders: OrdersStudy | None = None
    glass: GlassStudy | None = None
    anisotropy: AnisotropyStudy | None = None
    stability: Stability = field(default_factory=Stability)
    speed: Speed = field(default_factory=Speed)

    @classmethod
    def from_json(cls, doc: Mapping) -> "RunDocument":
        """The record of ``doc`` (a RunDocument as it is); a null study reads as none."""
        if isinstance(doc, cls):
            return doc
        names = {f.name for f in dataclass_fields(cls)}
        given = {k: v for k, v in doc.items() if k in names and v is not None}
        given = {k: read_nested(_DOCUMENT_PARTS.get(k), v) for k, v in given.items()}
        return cls(**given)


_DOCUMENT_PARTS = {
    "verdicts": Verdict,
    "fits": Fit,
    "orders": OrdersStudy,
    "glass": GlassStudy,
    "anisotropy": AnisotropyStudy,
    "stability": Stability,
    "speed": Speed,
}
"""The parts of a verdict document read as records (``read_nested``)."""
