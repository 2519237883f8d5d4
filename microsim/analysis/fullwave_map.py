"""The rung above Kirchhoff: where scalar Kirchhoff and first-order Rayleigh–Rice hold against
rigorous coupled-wave (RCW) solutions on 1D gratings, and how close the long-period gratings
come to geometric optics (``wave.gratings``, ``wave.fullwave``).

``fullwave_map()`` computes, at λ = 0.5 µm:
* symmetric triangular gratings (V-groove profiles) of glass (n = 1.5: a lossless dielectric,
  on which RCW converges quickly and conserves energy) of facet slope α and period Λ, at
  incidences θi: Kirchhoff's per-order error against converged RCW,
  ε = Σ_m |η_K,m − η_RCW,m| / Σ_m η_RCW,m (the share of the reflected power Kirchhoff puts in
  the wrong orders or misses), and the energy ratio, over the orders with θo ≤ 80°
  (``THETA_O_MAX``), unpolarised and in s and p (Kirchhoff with R_s or R_p at the half-vector
  angle); at normal incidence also the power of the orders within ±α of a facet's mirror
  direction 2α against geometric optics' F(α)/2 (no masking below α = 30°);
* the same triangles on aluminium in s (TE) only: RCW's p (TM) efficiencies on a metal converge
  slowly and erratically (``AL_TM_LIMIT``: the study that shows it is kept as
  ``aluminium_tm_study``);
* sinusoids of peak-to-valley amplitude a at Λ = 4 λ: first-order Rayleigh–Rice's error on the
  orders ±1 (unpolarised) against RCW;
* periodic Gaussian random glass profiles (``wave.random_profiles``; ``RANDOM_*``): Kirchhoff's
  error over every order and Rayleigh–Rice's over the diffuse ones, by rms slope and σ/λ.

Crossovers (``crossovers``): the smallest slope (or a/λ) of the grid at which the error passes
``CRITERION`` (5 %), per period and θi. ``fullwave_section`` renders the index section from the
saved JSON (``FULLWAVE_JSON``, written by ``tools/fullwave_study.py``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, fields
from typing import Mapping

import numpy as np

from microsim.analytic.fresnel import fresnel
from microsim.atomic import read_json
from microsim.errors import UsageError

from .json_record import JsonRecord
from .markdown import md_table

__all__ = [
    "FULLWAVE_JSON",
    "FULLWAVE_COMMAND",
    "FULLWAVE_CHART",
    "CRITERION",
    "fullwave_map",
    "fullwave_section",
    "fullwave_chart",
    "order_error",
    "load_fullwave",
]

FULLWAVE_JSON = "fullwave.json"
FULLWAVE_COMMAND = "tools/fullwave_study.py"
"""The command that writes ``FULLWAVE_JSON`` and its chart."""
CRITERION = 0.05
LAMBDA = 0.5
GLASS = 1.5
SLOPES = (5.0, 10.0, 15.0, 20.0, 25.0, 30.0)
PERIODS = (4.0, 8.0)  # Λ/λ
THETAS = (0.0, 30.0, 60.0)
AMPLITUDES = (0.01, 0.02, 0.05, 0.1, 0.2, 0.3)  # a/λ of the sinusoids (Λ = 4 λ)
RANDOM_SLOPES = (0.05, 0.1, 0.2, 0.3)  # nominal rms slope √2 σ/ℓ of the random profiles
# ℓ/λ: at ℓ = 2 λ (Λ = 8 λ, 32 samples) RCW did not converge to 10⁻³ by 108 orders × 325
# slices (each raise moved an order by 1.5–7·10⁻³; minutes per solve), so it is left out
RANDOM_CORRS = (0.5, 1.0)
RANDOM_PERIODS, RANDOM_SAMPLES, RANDOM_SEED = 4, 32, 0  # Λ = 4 ℓ, sampled every ℓ/8
RANDOM_LIMIT = (80, 220)  # how far RCW is raised on them (order, levels)
AL_TM_LIMIT = (70, 110)  # aluminium's p study: how far it is raised (it does not converge)
AL_TE_LIMIT = (100, 160)  # aluminium TE: beyond this a solve takes minutes


THETA_O_MAX = 80.0
"""Orders beyond this polar angle are left out of the comparison: Kirchhoff's 1/cos θo
obliquity grows without bound towards the horizon (a Rayleigh anomaly carries no flux), and
microsim's wave verdicts exclude θo > 80° for the same reason."""


def _in_domain(e) -> np.ndarray:
    return np.abs(e.wo[:, 0]) < np.sin(np.radians(THETA_O_MAX))


def order_error(model, rcw, pol: str = "unpolarised", diffuse: bool = False):
    """(Σ|η_model − η_RCW| / Σ η_RCW, Σ η_model / Σ η_RCW) in polarisation ``pol`` over the
    orders with θo ≤ THETA_O_MAX (``diffuse``: the non-specular ones only)."""
    k_ok, r_ok = _in_domain(model), _in_domain(rcw)
    if diffuse:
        k_ok, r_ok = k_ok & (model.orders != 0), r_ok & (rcw.orders != 0)
    k = dict(zip(model.orders[k_ok].tolist(), getattr(model, pol)[k_ok]))
    r = dict(zip(rcw.orders[r_ok].tolist(), getattr(rcw, pol)[r_ok]))
    total = sum(r.values())
    wrong = sum(abs(k.get(m, 0.0) - r.get(m, 0.0)) for m in set(k) | set(r))
    return float(wrong / total), float(sum(k.values()) / total)


def _triangles(material, pol, slopes, periods, thetas, progress, limit=(160, 320)) -> list[dict]:
    """Kirchhoff against converged RCW on the triangular gratings, polarisation ``pol``, RCW
    raised up to ``limit`` (order, levels)."""
    from microsim.wave import fullwave
    from microsim.wave.gratings import Grating, kirchhoff_efficiencies

    pols = ("s", "p") if pol == "unpolarised" else (pol,)
    rows = []
    for period in periods:
        for theta in thetas:
            for slope in slopes:
                lam_g = period * LAMBDA
                g = Grating("triangular", lam_g, lam_g * np.tan(np.radians(slope)) / 2, material)
                t0 = time.perf_counter()
                r = fullwave.converged_efficiencies(
                    g, LAMBDA, theta, start=(int(2 * lam_g / LAMBDA) + 5, 20), limit=limit,
                    polarisations=pols,
                )  # fmt: skip
                seconds = time.perf_counter() - t0
                k = kirchhoff_efficiencies(g, LAMBDA, theta)
                error, energy = order_error(k, r, pol)
                row = {
                    "period_over_lambda": period,
                    "theta_i": theta,
                    "slope": slope,
                    "kirchhoff_order_error": error,
                    "kirchhoff_energy_ratio": energy,
                    "rcw_reflected": float(getattr(r, pol).sum()),
                    **_rcw_fields(r, "order", "levels", "converged"),
                    "rcw_seconds": seconds,
                }
                if pol == "unpolarised":  # both polarisations, converged in both
                    for q in pols:
                        row[f"kirchhoff_order_error_{q}"] = order_error(k, r, q)[0]
                progress(f"{material} {pol} Λ/λ {period:g} θi {theta:g}° slope {slope:g}°: "
                         f"{seconds:.1f} s, converged {r.info['converged']}")  # fmt: skip
                if theta == 0.0 and pol == "unpolarised":
                    alpha = np.radians(slope)
                    near = np.abs(np.degrees(np.arcsin(r.wo[:, 0])) - 2 * slope) < slope
                    geo = 0.5 * fresnel(np.array([np.cos(alpha)]), material)[0]
                    row["geometric_group_ratio"] = float(r.unpolarised[near].sum() / geo)
                rows.append(row)
    return rows


def _rcw_fields(r, *keys) -> dict:
    """How RCW ran for efficiencies ``r``, as map-row fields: ``rcw_<key>`` of each of the
    ``keys`` of its ``info``."""
    return {f"rcw_{k}": r.info[k] for k in keys}


def _random_profiles(slopes, corrs, thetas, progress) -> list[dict]:
    """Kirchhoff and Rayleigh–Rice against converged RCW on periodic Gaussian glass profiles
    (``RANDOM_*``): Kirchhoff over every order, Rayleigh–Rice over the diffuse ones."""
    from microsim.wave import fullwave
    from microsim.wave.gratings import kirchhoff_efficiencies, rayleigh_rice_efficiencies
    from microsim.wave.random_profiles import RandomProfile, random_grating

    rows = []
    for corr in corrs:
        for slope in slopes:
            ell = corr * LAMBDA
            prof = RandomProfile("gaussian", RANDOM_PERIODS * ell, slope * ell / np.sqrt(2),
                                 corr_len=ell, n=RANDOM_SAMPLES, seed=RANDOM_SEED)  # fmt: skip
            g = random_grating(prof, GLASS)
            facets = np.diff(np.append(g.h, g.h[0])) * g.h.size / g.period
            for theta in thetas:
                t0 = time.perf_counter()
                r = fullwave.converged_efficiencies(
                    g, LAMBDA, theta, start=(int(2 * g.period / LAMBDA) + 5, 20),
                    limit=RANDOM_LIMIT,
                )  # fmt: skip
                seconds = time.perf_counter() - t0
                k_err, k_energy = order_error(kirchhoff_efficiencies(g, LAMBDA, theta), r)
                rr = rayleigh_rice_efficiencies(g, LAMBDA, theta)
                rr_err, _ = order_error(rr, r, diffuse=True)
                rows.append(
                    {
                        "corr_over_lambda": corr,
                        "rms_slope_nominal": slope,
                        "rms_slope": float(np.sqrt(np.mean(facets**2))),
                        "sigma_over_lambda": g.rms_height / LAMBDA,
                        "theta_i": theta,
                        "kirchhoff_order_error": k_err,
                        "kirchhoff_energy_ratio": k_energy,
                        "rayleigh_rice_error": rr_err,
                        **_rcw_fields(r, "order", "slices", "converged"),
                        "rcw_seconds": seconds,
                    }
                )
                progress(f"random ℓ/λ {corr:g} slope {slope:g} θi {theta:g}°: {seconds:.1f} s")
    return rows


def _aluminium_tm_study() -> dict:
    """The p (TM) convergence study of aluminium that keeps it out of the unpolarised map:
    a 10° triangle at Λ = 4 λ, normal incidence, raised to ``AL_TM_LIMIT``."""
    from microsim.wave import fullwave
    from microsim.wave.gratings import Grating

    lam_g = 4 * LAMBDA
    g = Grating("triangular", lam_g, lam_g * np.tan(np.radians(10.0)) / 2, "aluminium")
    r = fullwave.converged_efficiencies(g, LAMBDA, 0.0, start=(13, 20), limit=AL_TM_LIMIT)
    return {
        "grating": "triangular, slope 10°, Λ = 4 λ, θi = 0°",
        "limit": list(AL_TM_LIMIT),
        "converged": r.info["converged"],
        "study": [[o, lv, ch] for o, lv, _, ch, _ in r.info["study"]],
    }


def fullwave_map(
    slopes=SLOPES, periods=PERIODS, thetas=THETAS, amplitudes=AMPLITUDES, progress=None
) -> dict:
    """Every figure of the module docstring as a JSON-able dict; ``progress(text)`` is told
    of each grating solved."""
    progress = progress or (lambda text: None)
    from microsim.wave import fullwave
    from microsim.wave.gratings import Grating, rayleigh_rice_efficiencies

    t_all = time.perf_counter()
    tri = _triangles(GLASS, "unpolarised", slopes, periods, thetas, progress)
    tri_al = _triangles("aluminium", "s", slopes, periods, thetas, progress, AL_TE_LIMIT)
    sin = []
    for theta in thetas:
        for amp in amplitudes:
            g = Grating("sinusoidal", 4 * LAMBDA, amp * LAMBDA, GLASS)
            r = fullwave.converged_efficiencies(g, LAMBDA, theta)
            rr = rayleigh_rice_efficiencies(g, LAMBDA, theta)
            errs = [abs(rr.at(m) / r.at(m) - 1) for m in (-1, 1) if r.at(m) > 0]
            sin.append(
                {
                    "theta_i": theta,
                    "amplitude_over_lambda": amp,
                    "rayleigh_rice_error": float(max(errs)),
                    **_rcw_fields(r, "converged"),
                }
            )
    rnd = _random_profiles(RANDOM_SLOPES, RANDOM_CORRS, thetas, progress)
    return {
        "settings": {
            "wavelength_um": LAMBDA,
            "material": f"glass n = {GLASS}",
            "criterion": CRITERION,
            "rcw_tol": 1e-3,
            "sinusoid_period_over_lambda": 4.0,
            "random": f"Gaussian, Λ = {RANDOM_PERIODS} ℓ, {RANDOM_SAMPLES} samples per period, "
            f"seed {RANDOM_SEED}, glass n = {GLASS}",
        },
        "triangular": tri,
        "triangular_aluminium_te": tri_al,
        "aluminium_te_limit": list(AL_TE_LIMIT),
        "aluminium_tm_study": _aluminium_tm_study(),
        "sinusoidal": sin,
        "random": rnd,
        "seconds": time.perf_counter() - t_all,
    }


@dataclass(frozen=True)
class MapRow:
    """One grating of the map (``fullwave.json``: a row of ``triangular``,
    ``triangular_aluminium_te``, ``sinusoidal`` or ``random``): its geometry, the closed
    forms' errors against RCW (shares of the reflected power, module docstring) and how RCW
    was run. What a kind of grating does not have is None."""

    theta_i: float
    period_over_lambda: float | None = None
    slope: float | None = None
    amplitude_over_lambda: float | None = None
    corr_over_lambda: float | None = None
    rms_slope: float | None = None
    rms_slope_nominal: float | None = None
    sigma_over_lambda: float | None = None
    kirchhoff_order_error: float | None = None
    kirchhoff_order_error_s: float | None = None
    kirchhoff_order_error_p: float | None = None
    kirchhoff_energy_ratio: float | None = None
    geometric_group_ratio: float | None = None
    rayleigh_rice_error: float | None = None
    rcw_converged: bool = True
    rcw_order: int | None = None
    rcw_levels: int | None = None
    rcw_slices: int | None = None
    rcw_reflected: float | None = None
    rcw_seconds: float | None = None


@dataclass(frozen=True)
class MapSettings:
    """How the map was made: wavelength (µm), material, criterion (a fraction), RCW's
    tolerance, the sinusoids' period (in λ) and the random profiles' description."""

    wavelength_um: float
    material: str
    criterion: float
    rcw_tol: float
    sinusoid_period_over_lambda: float
    random: str = "Gaussian"


@dataclass(frozen=True)
class TmStudy:
    """Aluminium's p (TM) convergence study: the ``grating``, RCW's ``limit``, whether it
    ``converged`` and its ``study`` steps [orders, levels, largest change or None]."""

    grating: str
    converged: bool
    study: tuple = ()
    limit: tuple = ()


@dataclass(frozen=True)
class FullwaveMap:
    """``fullwave.json`` read as records (``from_json``); the dict ``fullwave_map`` returns
    and ``load_fullwave`` reads is its JSON form."""

    settings: MapSettings
    triangular: tuple[MapRow, ...]
    sinusoidal: tuple[MapRow, ...]
    random: tuple[MapRow, ...] = ()
    triangular_aluminium_te: tuple[MapRow, ...] = ()
    aluminium_tm_study: TmStudy | None = None
    seconds: float | None = None

    @classmethod
    def from_json(cls, doc) -> "FullwaveMap":
        """The records of ``doc`` (a ``fullwave_map`` dict; a FullwaveMap as it is); keys
        of no field are ignored."""
        if isinstance(doc, cls):
            return doc
        rows = lambda key: tuple(_record(MapRow, r) for r in doc.get(key) or ())  # noqa: E731
        tm = doc.get("aluminium_tm_study")
        return cls(
            settings=_record(MapSettings, doc["settings"]),
            triangular=rows("triangular"),
            sinusoidal=rows("sinusoidal"),
            random=rows("random"),
            triangular_aluminium_te=rows("triangular_aluminium_te"),
            aluminium_tm_study=_record(TmStudy, tm) if tm else None,
            seconds=doc.get("seconds"),
        )


def _record(cls, d: dict):
    """``cls`` from the keys of ``d`` that name its fields."""
    names = {f.name for f in fields(cls)}
    return cls(**{k: v for k, v in d.items() if k in names})


def _first_over(rows, key, value, error, crit) -> dict:
    """{key(row): value(row)} of the first converged row per key whose ``error`` exceeds
    ``crit`` (rows in increasing ``value`` per key); unconverged rows are never counted."""
    out = {}
    for row in rows:
        k = key(row)
        if row.rcw_converged and getattr(row, error) > crit and k not in out:
            out[k] = value(row)
    return out


@dataclass(frozen=True, eq=False)
class Crossovers(JsonRecord):
    """Where each closed form departs from RCW by more than the criterion (``crossovers``):
    grid key → first value over it. Also the dict of the same names."""

    kirchhoff: Mapping = field(default_factory=dict)
    kirchhoff_aluminium_te: Mapping = field(default_factory=dict)
    kirchhoff_s: Mapping = field(default_factory=dict)
    kirchhoff_p: Mapping = field(default_factory=dict)
    kirchhoff_random: Mapping = field(default_factory=dict)
    rayleigh_rice: Mapping = field(default_factory=dict)
    rayleigh_rice_random: Mapping = field(default_factory=dict)


def crossovers(doc: dict) -> Crossovers:
    """Smallest slope (triangles, per Λ/λ and θi, unpolarised and in s and p; random profiles,
    the realised rms slope per ℓ/λ and θi), a/λ (sinusoids, per θi) and σ/λ (Rayleigh–Rice on
    random profiles) at which the error exceeds the criterion, over the converged rows;
    absent when it never does on the grid."""
    doc = FullwaveMap.from_json(doc)
    crit = doc.settings.criterion
    by_period = lambda r: (r.period_over_lambda, r.theta_i)  # noqa: E731
    by_corr = lambda r: (r.corr_over_lambda, r.theta_i)  # noqa: E731
    err, rr = "kirchhoff_order_error", "rayleigh_rice_error"
    rnd = doc.random
    found = {
        "kirchhoff": _first_over(doc.triangular, by_period, lambda r: r.slope, err, crit),
        "kirchhoff_aluminium_te": _first_over(
            doc.triangular_aluminium_te, by_period, lambda r: r.slope, err, crit
        ),
        **{
            f"kirchhoff_{q}": _first_over(
                [r for r in doc.triangular if getattr(r, f"{err}_{q}") is not None],
                by_period,
                lambda r: r.slope,
                f"{err}_{q}",
                crit,
            )  # fmt: skip
            for q in ("s", "p")
        },
        "kirchhoff_random": _first_over(rnd, by_corr, lambda r: round(r.rms_slope, 3), err, crit),
        "rayleigh_rice": _first_over(
            doc.sinusoidal,
            lambda r: r.theta_i,
            lambda r: r.amplitude_over_lambda,
            rr,
            crit,
        ),  # fmt: skip
        "rayleigh_rice_random": _first_over(
            rnd, by_corr, lambda r: round(r.sigma_over_lambda, 3), rr, crit
        ),
    }
    return Crossovers.from_json(found)


def load_fullwave(path) -> dict:
    """The saved map (``fullwave_map``'s dict); a ``UsageError`` naming the file and what is
    wrong when it is damaged (``atomic.read_json``) or lacks a part."""
    d = read_json(path)
    for key in ("settings", "triangular", "sinusoidal"):
        if key not in d:
            raise UsageError(f"{path}: no {key!r}")
    return d


def _cell(value: str, row) -> str:
    return value if row.rcw_converged else f"{value} (RCW not converged)"


def _triangle_table(rows) -> tuple[list, list, dict]:
    """(slopes, table rows, rows by (Λ/λ, θi, slope)) of Kirchhoff's error on triangles."""
    periods = sorted({r.period_over_lambda for r in rows})
    thetas = sorted({r.theta_i for r in rows})
    slopes = sorted({r.slope for r in rows})
    by = {(r.period_over_lambda, r.theta_i, r.slope): r for r in rows}
    table = [
        [f"{p:g}", f"{t:g}°"]
        + [
            _cell(f"{100 * by[(p, t, a)].kirchhoff_order_error:.1f} %", by[(p, t, a)])
            for a in slopes
            if (p, t, a) in by
        ]  # fmt: skip
        for p in periods
        for t in thetas
    ]
    return slopes, table, by


def _crossing_text(first: Mapping, keys, name, unit) -> str:
    """Each key of ``keys`` named with the crossover value ``first`` holds for it."""
    return "; ".join(
        f"{name(k)}: {'beyond the grid' if first.get(k) is None else unit(first[k])}" for k in keys
    )


def _pct(x: float) -> str:
    """An error as a percentage: one decimal below 10 %, none above."""
    return f"{100 * x:.1f} %" if 100 * x < 10 else f"{100 * x:.0f} %"


def _summary(doc: dict, cross: Crossovers, crit: float) -> list[str]:
    """The section's crossovers in one paragraph: per θi, the smallest grid value over the
    periods (ℓ) at which each method departs by more than the criterion."""

    thetas = sorted({r.theta_i for r in doc.triangular})

    def per_theta(c: dict, unit: str = "") -> str:
        by = {}
        for k, v in c.items():
            t = k[1] if isinstance(k, tuple) else k
            by[t] = min(v, by.get(t, v))
        text = ", ".join(f"{by[t]:.3g}{unit} at θi {t:g}°" for t in thetas if t in by)
        never = [f"{t:g}°" for t in thetas if t not in by]
        if never:
            text += (
                f"{' ' if by else ''}(within {crit:g} % on the whole grid at θi {', '.join(never)})"
            )
        return text

    sin = {t: v / (2 * np.sqrt(2)) for t, v in cross.rayleigh_rice.items()}
    parts = [
        f"In short — the smallest value of the grid at which a method departs from RCW by more "
        f"than {crit:g} % (over the periods and correlation lengths mapped): scalar Kirchhoff "
        f"on glass V-groove gratings from facet slope {per_theta(cross.kirchhoff, '°')} "
        f"(s: {per_theta(cross.kirchhoff_s, '°')}; p: {per_theta(cross.kirchhoff_p, '°')})",
    ]
    if cross.kirchhoff_aluminium_te:
        parts.append(f"on aluminium in TE from {per_theta(cross.kirchhoff_aluminium_te, '°')}")
    if doc.random:
        parts.append(
            f"on glass Gaussian random profiles from rms slope {per_theta(cross.kirchhoff_random)}"
        )
    text = "; ".join(parts) + (
        f". First-order Rayleigh–Rice from σ/λ {per_theta(sin)} on sinusoids (σ = a/(2√2))"
    )
    if doc.random:
        text += f" and {per_theta(cross.rayleigh_rice_random)} on the random profiles"
    return [text + ".", ""]


def _random_lines(doc: dict, cross: Crossovers, crit: float) -> list[str]:
    """The random-profile part of the section (empty without ``random`` rows)."""
    rnd = doc.random
    if not rnd:
        return []
    corrs = sorted({r.corr_over_lambda for r in rnd})
    thetas = sorted({r.theta_i for r in rnd})
    slopes = sorted({r.rms_slope_nominal for r in rnd})
    by = {(r.corr_over_lambda, r.theta_i, r.rms_slope_nominal): r for r in rnd}
    realised = {a: by[(corrs[0], thetas[0], a)].rms_slope for a in slopes}
    table = []
    for c in corrs:
        for t in thetas:
            cells = []
            for a in slopes:
                r = by[(c, t, a)]
                text = (f"K {_pct(r.kirchhoff_order_error)}, RR "
                        f"{_pct(r.rayleigh_rice_error)} (σ/λ "
                        f"{r.sigma_over_lambda:.3f})")  # fmt: skip
                cells.append(_cell(text, r))
            table.append([f"{c:g}", f"{t:g}°"] + cells)
    keys = [(c, t) for c in corrs for t in thetas]
    name = lambda k: f"ℓ = {k[0]:g} λ, θi {k[1]:g}°"  # noqa: E731
    return [
        f"Periodic random profiles ({doc.settings.random}; "
        f"`microsim.wave.random_profiles`, RCW through SCATMECH's `Generic_Grating`; one "
        f"realisation, scaled: the same shape in units of ℓ at every slope), by the rms slope "
        f"of the profile's linear pieces (nominal √2 σ/ℓ: "
        f"{', '.join(f'{a:g}' for a in slopes)}): Kirchhoff's error (K) over every order and "
        f"first-order Rayleigh–Rice's (RR) over the diffuse ones (it has no specular order), "
        f"with the profile's rms height σ/λ (below the nominal: the period holds no "
        f"wavelength longer than Λ):",
        "",
        md_table(["ℓ/λ", "θi"] + [f"{realised[a]:.3g}" for a in slopes], table),
        "",
        f"Kirchhoff departs by more than {crit:g} % from rms slope: "
        + _crossing_text(cross.kirchhoff_random, keys, name, lambda v: f"{v:g}")
        + f". Rayleigh–Rice departs by more than {crit:g} % from: "
        + _crossing_text(cross.rayleigh_rice_random, keys, name, lambda v: f"σ/λ = {v:g}")
        + ".",
        "",
    ]


def _polarisation_lines(doc: dict, cross: Crossovers, crit: float) -> list[str]:
    """Glass triangles in s and p separately (empty when the rows lack them): Kirchhoff with
    R_s or R_p at the half-vector angle against RCW's s or p efficiencies."""
    rows = [r for r in doc.triangular if r.kirchhoff_order_error_s is not None]
    if not rows:
        return []
    slopes = sorted({r.slope for r in rows})
    by = {(r.period_over_lambda, r.theta_i, r.slope): r for r in rows}
    keys = sorted({(r.period_over_lambda, r.theta_i) for r in rows})
    table = [
        [f"{p:g}", f"{t:g}°"]
        + [
            _cell(
                f"{100 * by[(p, t, a)].kirchhoff_order_error_s:.1f} / "
                f"{100 * by[(p, t, a)].kirchhoff_order_error_p:.1f} %",
                by[(p, t, a)],
            )
            for a in slopes
            if (p, t, a) in by
        ]  # fmt: skip
        for p, t in keys
    ]
    name = lambda k: f"Λ = {k[0]:g} λ, θi {k[1]:g}°"  # noqa: E731
    return [
        "The same gratings in s / p (TE / TM) polarisation, Kirchhoff with R_s or R_p at the "
        "half-vector angle against RCW's s or p efficiencies:",
        "",
        md_table(["Λ/λ", "θi"] + [f"{a:g}°" for a in slopes], table),
        "",
        *[
            f"Kirchhoff in {q} departs by more than {crit:g} % from slope: "
            + _crossing_text(getattr(cross, f"kirchhoff_{q}"), keys, name, lambda v: f"{v:g}°")
            + "."
            for q in ("s", "p")
        ],
        "",
    ]


def _aluminium_lines(doc: dict, cross: Crossovers, crit: float) -> list[str]:
    """The aluminium part of the section: TE rows, and the TM study that keeps it out."""
    rows = doc.triangular_aluminium_te
    if not rows:
        return []
    slopes, table, _ = _triangle_table(rows)
    keys = sorted({(r.period_over_lambda, r.theta_i) for r in rows})
    name = lambda k: f"Λ = {k[0]:g} λ, θi {k[1]:g}°"  # noqa: E731
    lines = [
        "Aluminium, s (TE) polarisation, Kirchhoff with R_s at the half-vector angle against "
        "RCW's s efficiencies (converged in s):",
        "",
        md_table(["Λ/λ", "θi"] + [f"{a:g}°" for a in slopes], table),
        "",
        f"Kirchhoff (TE) departs by more than {crit:g} % from slope: "
        + _crossing_text(cross.kirchhoff_aluminium_te, keys, name, lambda v: f"{v:g}°")
        + ".",
        "",
    ]
    tm = doc.aluminium_tm_study
    if tm:
        steps = ", ".join(f"{o}×{lv}: {'—' if ch is None else f'{ch:.1e}'}"
                          for o, lv, ch in tm.study)  # fmt: skip
        verdict = "converged" if tm.converged else "did **not** converge"
        lines += [
            f"Aluminium in p (TM) {verdict} to {doc.settings.rcw_tol:g} ({tm.grating}; "
            f"orders × levels: largest change — {steps}), so aluminium appears in TE only "
            f"and its unpolarised efficiencies are not mapped.",
            "",
        ]
    return lines


def fullwave_section(
    doc: dict, command: str = FULLWAVE_COMMAND, chart: str | None = None
) -> list[str]:
    """Index subsection "The rung above Kirchhoff" from a saved map; ``chart`` the file name
    of ``fullwave_chart``'s PNG beside the index, if there is one."""
    doc = FullwaveMap.from_json(doc)
    s, crit = doc.settings, 100 * doc.settings.criterion
    cross = crossovers(doc)
    slopes, rows, by = _triangle_table(doc.triangular)
    periods = sorted({r.period_over_lambda for r in doc.triangular})
    thetas = sorted({r.theta_i for r in doc.triangular})
    geo = [
        [f"{p:g}"]
        + [f"{by[(p, 0.0, a)].geometric_group_ratio:.2f}" for a in slopes if (p, 0.0, a) in by]
        for p in periods
        if (p, 0.0, slopes[0]) in by
    ]
    amps = sorted({r.amplitude_over_lambda for r in doc.sinusoidal})
    sby = {(r.theta_i, r.amplitude_over_lambda): r for r in doc.sinusoidal}
    sthetas = sorted({r.theta_i for r in doc.sinusoidal})
    srows = [
        [f"{t:g}°"]
        + [_cell(f"{100 * sby[(t, a)].rayleigh_rice_error:.1f} %", sby[(t, a)]) for a in amps]
        for t in sthetas
    ]
    kcross = _crossing_text(
        cross.kirchhoff, [(p, t) for p in periods for t in thetas],
        lambda k: f"Λ = {k[0]:g} λ, θi {k[1]:g}°", lambda v: f"{v:g}°",
    )  # fmt: skip
    rcross = _crossing_text(
        cross.rayleigh_rice, sthetas, lambda t: f"θi {t:g}°", lambda v: f"a/λ = {v:g}"
    )
    picture = [] if chart is None else [f"![Kirchhoff and Rayleigh–Rice against RCW]({chart})", ""]
    return [
        "### The rung above Kirchhoff: rigorous solutions on 1D gratings",
        "",
        f"Scalar Kirchhoff and first-order Rayleigh–Rice against rigorous coupled-wave (RCW) "
        f"efficiencies (NIST SCATMECH, converged until no order moves by "
        f"{s.rcw_tol:g}) on gratings of {s.material} (and aluminium in TE) at "
        f"λ = {s.wavelength_um:g} µm "
        f"(`microsim.wave.gratings`, `microsim.wave.fullwave`; `{command}`, which needs the "
        f"`fullwave` extra, wrote `{FULLWAVE_JSON}` and the chart in "
        f"{doc.seconds or 0:.0f} s). "
        f"Error: the share of the reflected power Kirchhoff puts in the wrong orders, "
        f"Σ|η_K − η_RCW| / Σ η_RCW, over the orders with θo ≤ {THETA_O_MAX:g}° (towards the "
        f"horizon Kirchhoff's obliquity factor diverges). Kirchhoff has no shadowing and no "
        f"multiple scattering; RCW has both.",
        "",
        *picture,
        *_summary(doc, cross, crit),
        "Kirchhoff on symmetric triangular (V-groove) gratings of glass, by facet slope:",
        "",
        md_table(["Λ/λ", "θi"] + [f"{a:g}°" for a in slopes], rows),
        "",
        f"Kirchhoff departs by more than {crit:g} % from slope: {kcross}.",
        "",
        *_polarisation_lines(doc, cross, crit),
        *_aluminium_lines(doc, cross, crit),
        "Geometric limit: at normal incidence the orders within ±α of a facet's mirror "
        "direction 2α carry this fraction of geometric optics' F(α)/2 (edge diffraction "
        "takes the rest; it falls as the period grows):",
        "",
        md_table(["Λ/λ"] + [f"{a:g}°" for a in slopes], geo),
        "",
        f"First-order Rayleigh–Rice on sinusoids (Λ = {s.sinusoid_period_over_lambda:g} λ), "
        f"its error on the orders ±1 by peak-to-valley amplitude a/λ:",
        "",
        md_table(["θi"] + [f"{a:g}" for a in amps], srows),
        "",
        f"Rayleigh–Rice departs by more than {crit:g} % from: {rcross}.",
        "",
        *_random_lines(doc, cross, crit),
    ]


FULLWAVE_CHART = "fullwave-map.png"


def _error_panel(ax, curves, crit: float, xlabel: str, log_x: bool = False) -> None:
    """One panel: each curve (label, style, x, error, converged) as % on a log axis, the
    criterion band shaded; unconverged points hollow."""
    ax.axhspan(1e-2, 100 * crit, color="0.9", zorder=0)
    ax.axhline(100 * crit, color="0.4", lw=0.8, ls=":")
    for label, (colour, ls, marker), x, err, ok in curves:
        y = np.maximum(100 * np.asarray(err), 1e-2)
        ax.plot(x, y, color=colour, ls=ls, marker=marker, ms=4, label=label)
        bad = ~np.asarray(ok, dtype=bool)
        if bad.any():
            ax.plot(np.asarray(x)[bad], y[bad], ls="", marker="o", ms=8, mfc="none", mec="red")
    ax.set_yscale("log")
    if log_x:
        from matplotlib.ticker import NullFormatter

        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel(xlabel)
    ax.grid(True, which="major", lw=0.3)


def fullwave_chart(doc: dict):
    """Chart of the map: per θi (columns), the error against RCW (%, log) of Kirchhoff on
    triangular gratings by facet slope (glass unpolarised and aluminium TE, per Λ/λ), of
    Kirchhoff on the random profiles by rms slope (per ℓ/λ), and of Rayleigh–Rice by σ/λ
    (sinusoids, σ = a/(2√2), and the random profiles); the band where the method holds
    (≤ the criterion) shaded. Returns the matplotlib Figure (no pyplot)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    doc = FullwaveMap.from_json(doc)
    crit = doc.settings.criterion
    thetas = sorted({r.theta_i for r in doc.triangular})
    rnd = doc.random
    fig = Figure(figsize=(4.0 * len(thetas) + 2.6, 9.0), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    grid = fig.subplots(3, len(thetas), squeeze=False, sharey="row")
    dash = ["-", "--", ":", "-."]

    def series(rows, key, x, colour, marker, label, theta):
        out = []
        for n, v in enumerate(sorted({getattr(r, key) for r in rows})):
            sel = sorted((r for r in rows if getattr(r, key) == v and r.theta_i == theta), key=x)
            if sel:
                out.append((label(v), (colour, dash[n % 4], marker), [x(r) for r in sel],
                            [r.kirchhoff_order_error for r in sel],
                            [r.rcw_converged for r in sel]))  # fmt: skip
        return out

    for c, t in enumerate(thetas):
        tri = series(doc.triangular, "period_over_lambda", lambda r: r.slope, "tab:blue",
                     "o", lambda v: f"glass, Λ = {v:g} λ", t)  # fmt: skip
        tri += series(doc.triangular_aluminium_te, "period_over_lambda",
                      lambda r: r.slope, "tab:orange", "s",
                      lambda v: f"aluminium TE, Λ = {v:g} λ", t)  # fmt: skip
        _error_panel(grid[0, c], tri, crit, "facet slope α (°)")
        grid[0, c].set_title(f"θi = {t:g}°\nKirchhoff, triangular gratings")
        ran = series(rnd, "corr_over_lambda", lambda r: r.rms_slope, "tab:green", "^",
                     lambda v: f"glass, ℓ = {v:g} λ (Λ = 4 ℓ)", t)  # fmt: skip
        _error_panel(grid[1, c], ran, crit, "rms slope of the profile")
        grid[1, c].set_title("Kirchhoff, Gaussian random profiles")
        sin = sorted((r for r in doc.sinusoidal if r.theta_i == t),
                     key=lambda r: r.amplitude_over_lambda)  # fmt: skip
        rr = [("sinusoid, Λ = 4 λ", ("tab:purple", "-", "D"),
               [r.amplitude_over_lambda / (2 * np.sqrt(2)) for r in sin],
               [r.rayleigh_rice_error for r in sin],
               [r.rcw_converged for r in sin])]  # fmt: skip
        for n, v in enumerate(sorted({r.corr_over_lambda for r in rnd})):
            sel = sorted((r for r in rnd if r.corr_over_lambda == v and r.theta_i == t),
                         key=lambda r: r.sigma_over_lambda)  # fmt: skip
            rr.append((f"random, ℓ = {v:g} λ", ("tab:green", dash[(n + 1) % 4], "^"),
                       [r.sigma_over_lambda for r in sel],
                       [r.rayleigh_rice_error for r in sel],
                       [r.rcw_converged for r in sel]))  # fmt: skip
        _error_panel(grid[2, c], rr, crit, "rms height σ/λ", log_x=True)
        grid[2, c].set_title("Rayleigh–Rice (first order)")
    for r, what in enumerate(("Kirchhoff", "Kirchhoff", "Rayleigh–Rice")):
        grid[r, 0].set_ylabel(f"{what}'s error against RCW (%)")
        handles, labels = grid[r, 0].get_legend_handles_labels()
        grid[r, -1].legend(handles, labels, loc="center left", bbox_to_anchor=(1.02, 0.5),
                           fontsize=8, title=f"grey: within {100 * crit:g} %",
                           title_fontsize=8)  # fmt: skip
    fig.suptitle(
        "Where scalar Kirchhoff and first-order Rayleigh–Rice hold against rigorous RCW\n"
        f"(1D gratings, λ = {doc.settings.wavelength_um:g} µm; error = share of the "
        "reflected power in the wrong orders; red rings: RCW not converged)"
    )
    return fig
