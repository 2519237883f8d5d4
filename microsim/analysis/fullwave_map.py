"""The rung above Kirchhoff: where scalar Kirchhoff and first-order Rayleigh–Rice hold against
rigorous coupled-wave (RCW) solutions on 1D gratings, and how close the long-period gratings
come to geometric optics (``wave.gratings``, ``wave.fullwave``).

``fullwave_map()`` computes (glass, n = 1.5, λ = 0.5 µm: a lossless dielectric, on which RCW
converges quickly and conserves energy; on aluminium its p (TM) efficiencies converge slowly
and erratically — docs/wave.md):
* symmetric triangular gratings (V-groove profiles) of facet slope α and period Λ, at
  incidences θi: Kirchhoff's per-order error against converged RCW,
  ε = Σ_m |η_K,m − η_RCW,m| / Σ_m η_RCW,m (the share of the reflected power Kirchhoff puts in
  the wrong orders or misses), and the energy ratio, over the orders with θo ≤ 80°
  (``THETA_O_MAX``); at normal incidence also the power
  of the orders within ±α of a facet's mirror direction 2α against geometric optics'
  F(α)/2 (no masking below α = 30°);
* sinusoids of peak-to-valley amplitude a at Λ = 4 λ: first-order Rayleigh–Rice's error on the
  orders ±1 (s and p averaged, unpolarised) against RCW.
Crossovers (``crossovers``): the smallest slope (or a/λ) of the grid at which the error passes
``CRITERION`` (5 %), per period and θi. ``fullwave_section`` renders the index section from the
saved JSON (``FULLWAVE_JSON``, written by ``tools/fullwave_study.py``).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from microsim.analytic.fresnel import fresnel

from .markdown import md_table

__all__ = ["FULLWAVE_JSON", "CRITERION", "fullwave_map", "fullwave_section", "load_fullwave"]

FULLWAVE_JSON = "fullwave.json"
CRITERION = 0.05
LAMBDA = 0.5
GLASS = 1.5
SLOPES = (5.0, 10.0, 15.0, 20.0, 25.0, 30.0)
PERIODS = (4.0, 8.0)  # Λ/λ
THETAS = (0.0, 30.0, 60.0)
AMPLITUDES = (0.01, 0.02, 0.05, 0.1, 0.2, 0.3)  # a/λ of the sinusoids (Λ = 4 λ)


THETA_O_MAX = 80.0
"""Orders beyond this polar angle are left out of the comparison: Kirchhoff's 1/cos θo
obliquity grows without bound towards the horizon (a Rayleigh anomaly carries no flux), and
microsim's wave verdicts exclude θo > 80° for the same reason."""


def _in_domain(e) -> np.ndarray:
    return np.abs(e.wo[:, 0]) < np.sin(np.radians(THETA_O_MAX))


def _order_error(kir, rcw) -> tuple[float, float]:
    """(Σ|η_K − η_RCW| / Σ η_RCW, Σ η_K / Σ η_RCW) over the orders with θo ≤ THETA_O_MAX."""
    k_ok, r_ok = _in_domain(kir), _in_domain(rcw)
    k = dict(zip(kir.orders[k_ok].tolist(), kir.unpolarised[k_ok]))
    r = dict(zip(rcw.orders[r_ok].tolist(), rcw.unpolarised[r_ok]))
    total = sum(r.values())
    wrong = sum(abs(k.get(m, 0.0) - r.get(m, 0.0)) for m in set(k) | set(r))
    return float(wrong / total), float(sum(k.values()) / total)


def fullwave_map(slopes=SLOPES, periods=PERIODS, thetas=THETAS, amplitudes=AMPLITUDES) -> dict:
    """Every figure of the module docstring as a JSON-able dict."""
    from microsim.wave import fullwave
    from microsim.wave.gratings import Grating, kirchhoff_efficiencies, rayleigh_rice_efficiencies

    t_all = time.perf_counter()
    tri = []
    for period in periods:
        for theta in thetas:
            for slope in slopes:
                lam_g = period * LAMBDA
                g = Grating("triangular", lam_g, lam_g * np.tan(np.radians(slope)) / 2, GLASS)
                t0 = time.perf_counter()
                r = fullwave.converged_efficiencies(
                    g, LAMBDA, theta, start=(int(2 * lam_g / LAMBDA) + 5, 20)
                )
                seconds = time.perf_counter() - t0
                k = kirchhoff_efficiencies(g, LAMBDA, theta)
                error, energy = _order_error(k, r)
                row = {
                    "period_over_lambda": period,
                    "theta_i": theta,
                    "slope": slope,
                    "kirchhoff_order_error": error,
                    "kirchhoff_energy_ratio": energy,
                    "rcw_reflected": r.total(),
                    "rcw_order": r.info["order"],
                    "rcw_levels": r.info["levels"],
                    "rcw_converged": r.info["converged"],
                    "rcw_seconds": seconds,
                }
                if theta == 0.0:
                    alpha = np.radians(slope)
                    near = np.abs(np.degrees(np.arcsin(r.wo[:, 0])) - 2 * slope) < slope
                    geo = 0.5 * fresnel(np.array([np.cos(alpha)]), GLASS)[0]
                    row["geometric_group_ratio"] = float(r.unpolarised[near].sum() / geo)
                tri.append(row)
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
                    "rcw_converged": r.info["converged"],
                }
            )
    return {
        "settings": {
            "wavelength_um": LAMBDA,
            "material": f"glass n = {GLASS}",
            "criterion": CRITERION,
            "rcw_tol": 1e-3,
            "sinusoid_period_over_lambda": 4.0,
        },
        "triangular": tri,
        "sinusoidal": sin,
        "seconds": time.perf_counter() - t_all,
    }


def crossovers(doc: dict) -> dict:
    """Smallest slope (triangles, per Λ/λ and θi) and a/λ (sinusoids, per θi) at which the
    error exceeds the criterion; None when it never does on the grid."""
    crit = doc["settings"]["criterion"]
    out = {"kirchhoff": {}, "rayleigh_rice": {}}
    for row in doc["triangular"]:
        key = (row["period_over_lambda"], row["theta_i"])
        if row["kirchhoff_order_error"] > crit and key not in out["kirchhoff"]:
            out["kirchhoff"][key] = row["slope"]
    for row in doc["sinusoidal"]:
        if row["rayleigh_rice_error"] > crit and row["theta_i"] not in out["rayleigh_rice"]:
            out["rayleigh_rice"][row["theta_i"]] = row["amplitude_over_lambda"]
    return out


def load_fullwave(path) -> dict:
    """The saved map (``fullwave_map``'s dict); ValueError naming what is missing."""
    d = json.loads(Path(path).read_text(encoding="utf-8"))
    for key in ("settings", "triangular", "sinusoidal"):
        if key not in d:
            raise ValueError(f"{path}: no {key!r}")
    return d


def fullwave_section(doc: dict, command: str = "tools/fullwave_study.py") -> list[str]:
    """Index subsection "The rung above Kirchhoff" from a saved map."""
    s, crit = doc["settings"], 100 * doc["settings"]["criterion"]
    cross = crossovers(doc)
    periods = sorted({r["period_over_lambda"] for r in doc["triangular"]})
    thetas = sorted({r["theta_i"] for r in doc["triangular"]})
    slopes = sorted({r["slope"] for r in doc["triangular"]})
    by = {(r["period_over_lambda"], r["theta_i"], r["slope"]): r for r in doc["triangular"]}
    rows = []
    for p in periods:
        for t in thetas:
            cells = []
            for a in slopes:
                r = by[(p, t, a)]
                mark = "" if r["rcw_converged"] else " (RCW not converged)"
                cells.append(f"{100 * r['kirchhoff_order_error']:.1f} %{mark}")
            rows.append([f"{p:g}", f"{t:g}°"] + cells)
    geo = [
        [f"{p:g}"]
        + [f"{by[(p, 0.0, a)]['geometric_group_ratio']:.2f}" for a in slopes if (p, 0.0, a) in by]
        for p in periods
        if (p, 0.0, slopes[0]) in by
    ]
    amps = sorted({r["amplitude_over_lambda"] for r in doc["sinusoidal"]})
    sby = {(r["theta_i"], r["amplitude_over_lambda"]): r for r in doc["sinusoidal"]}
    srows = [
        [f"{t:g}°"] + [f"{100 * sby[(t, a)]['rayleigh_rice_error']:.1f} %" for a in amps]
        for t in sorted({r["theta_i"] for r in doc["sinusoidal"]})
    ]
    kcross = "; ".join(
        f"Λ = {p:g} λ, θi {t:g}°: {'beyond the grid' if v is None else f'{v:g}°'}"
        for p in periods
        for t in thetas
        for v in [cross["kirchhoff"].get((p, t))]
    )
    rcross = "; ".join(
        f"θi {t:g}°: {'beyond the grid' if v is None else f'a/λ = {v:g}'}"
        for t in sorted({r["theta_i"] for r in doc["sinusoidal"]})
        for v in [cross["rayleigh_rice"].get(t)]
    )
    return [
        "### The rung above Kirchhoff: rigorous solutions on 1D gratings",
        "",
        f"Scalar Kirchhoff and first-order Rayleigh–Rice against rigorous coupled-wave (RCW) "
        f"efficiencies (NIST SCATMECH, converged until no order moves by "
        f"{s['rcw_tol']:g}) on gratings of {s['material']} at λ = {s['wavelength_um']:g} µm "
        f"(`microsim.wave.gratings`, `microsim.wave.fullwave`; `{command}`, which needs the "
        f"`fullwave` extra, wrote `{FULLWAVE_JSON}` in {doc.get('seconds', 0):.0f} s). "
        f"Error: the share of the reflected power Kirchhoff puts in the wrong orders, "
        f"Σ|η_K − η_RCW| / Σ η_RCW, over the orders with θo ≤ {THETA_O_MAX:g}° (towards the "
        f"horizon Kirchhoff's obliquity factor diverges). Kirchhoff has no shadowing and no "
        f"multiple scattering; RCW has both.",
        "",
        "Kirchhoff on symmetric triangular (V-groove) gratings, by facet slope:",
        "",
        md_table(["Λ/λ", "θi"] + [f"{a:g}°" for a in slopes], rows),
        "",
        f"Kirchhoff departs by more than {crit:g} % from slope: {kcross}.",
        "",
        "Geometric limit: at normal incidence the orders within ±α of a facet's mirror "
        "direction 2α carry this fraction of geometric optics' F(α)/2 (edge diffraction "
        "takes the rest; it falls as the period grows):",
        "",
        md_table(["Λ/λ"] + [f"{a:g}°" for a in slopes], geo),
        "",
        f"First-order Rayleigh–Rice on sinusoids (Λ = {s['sinusoid_period_over_lambda']:g} λ), "
        f"its error on the orders ±1 by peak-to-valley amplitude a/λ:",
        "",
        md_table(["θi"] + [f"{a:g}" for a in amps], srows),
        "",
        f"Rayleigh–Rice departs by more than {crit:g} % from: {rcross}.",
        "",
    ]
