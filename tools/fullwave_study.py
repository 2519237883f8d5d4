"""The full-wave rung's figures (docs/wave.md, the index's "The rung above Kirchhoff"): RCW
convergence studies and energy balance, the first-order limit, and the map of where scalar
Kirchhoff and Rayleigh–Rice hold against RCW (``microsim.analysis.fullwave_map``) with its
chart. Needs the `fullwave` extra (pySCATMECH), except ``--chart-only``.

    .venv/bin/python tools/fullwave_study.py [--map-only] [--json reports/fullwave.json]
    .venv/bin/python tools/fullwave_study.py --chart-only --json reports/fullwave.json

``--json`` also writes the chart beside the JSON (``fullwave-map.png``); ``--chart-only``
redraws it, and rewrites the index's section, from a saved JSON without solving anything.
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from microsim import atomic
from microsim.analysis.fullwave_map import (
    FULLWAVE_CHART,
    crossovers,
    fullwave_chart,
    fullwave_map,
    fullwave_section,
    load_fullwave,
)
from microsim.wave import fullwave
from microsim.wave.gratings import Grating, rayleigh_rice_efficiencies
from microsim.wave.random_profiles import RandomProfile, random_grating

LAMBDA = 0.5


def convergence(g: Grating, theta: float) -> None:
    r = fullwave.converged_efficiencies(g, LAMBDA, theta)
    print(f"  {g.profile} Λ {g.period} µm a {g.amplitude} µm, n {g.index}, θi {theta:g}°:")
    for order, levels, slices, change, seconds in r.info["study"]:
        ch = "—" if change is None else f"{change:.1e}"
        print(
            f"    order {order:4d} levels {levels:4d} ({slices} slices): largest change {ch}, "
            f"{seconds:.2f} s"
        )
    print(f"    converged: {r.info['converged']} (tol {r.info['tol']:g})")
    if g.index.imag == 0:
        o, lv = r.info["order"], r.info["levels"]
        t = fullwave.rcw_efficiencies(g, LAMBDA, theta, o, lv, "transmission")
        print(
            f"    R + T − 1: s {r.s.sum() + t.s.sum() - 1:.1e}, p {r.p.sum() + t.p.sum() - 1:.1e}"
        )


def first_order() -> None:
    print("First order (a = λ/50, Λ = 4 λ, θi 30°; orders ±1, RCW/RR − 1, 15 orders × 120 levels):")
    for mat in (1.5, "aluminium"):
        g = Grating("sinusoidal", 2.0, LAMBDA / 50, mat)
        r = fullwave.rcw_efficiencies(g, LAMBDA, 30.0, 15, 120)
        rr = rayleigh_rice_efficiencies(g, LAMBDA, 30.0)
        for m in (-1, 1):
            i, j = (np.flatnonzero(e.orders == m)[0] for e in (r, rr))
            x = 2 * np.pi / LAMBDA * (np.cos(np.radians(30)) + rr.wo[j, 2]) * g.amplitude / 2
            s, p = r.s[i] / rr.s[j] - 1, r.p[i] / rr.p[j] - 1
            print(f"  {mat!s:9s} m {m:+d}: s {s:+.2e}, p {p:+.2e} (next order: {-x * x / 4:+.2e})")


def write_chart(json_path: str) -> None:
    """The chart beside the JSON, and the index's section rewritten in reports/index.md when
    the JSON is the index's."""
    doc = load_fullwave(json_path)
    out = Path(json_path).parent / FULLWAVE_CHART
    with atomic.atomic_open(str(out), "wb") as fh:
        fullwave_chart(doc).savefig(fh, format="png", dpi=100)
    print(f"wrote {out}")
    index = Path(json_path).parent / "index.md"
    if index.is_file():
        text = index.read_text(encoding="utf-8")
        head = "### The rung above Kirchhoff: rigorous solutions on 1D gratings"
        start = text.find(head)
        end = text.find("\n### ", start + len(head))
        if start >= 0 and end >= 0:
            section = "\n".join(fullwave_section(doc, chart=FULLWAVE_CHART))
            atomic.write_text(str(index), text[:start] + section + text[end:])
            print(f"rewrote the section {head[4:]!r} of {index}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", help="write the map here (reports/fullwave.json for the index)")
    ap.add_argument(
        "--map-only", action="store_true", help="skip the convergence studies (5 min: aluminium)"
    )
    ap.add_argument(
        "--chart-only", action="store_true", help="redraw the chart and section from --json"
    )
    args = ap.parse_args()
    if args.chart_only:
        write_chart(args.json)
        return
    if not args.map_only:
        print("Convergence (order and levels raised ×1.5 in turn until no efficiency moves 1e-3):")
        convergence(Grating("sinusoidal", 2.0, 0.3, 1.5), 30.0)
        convergence(Grating("triangular", 2.0, 0.35, 1.5), 30.0)
        convergence(Grating("sinusoidal", 2.0, 0.1, "aluminium"), 30.0)
        prof = RandomProfile("gaussian", 2.0, 0.04, corr_len=0.5, n=32, seed=1)
        convergence(random_grating(prof, 1.5), 30.0)
        first_order()
    doc = fullwave_map(progress=lambda text: print("  solved", text, file=sys.stderr, flush=True))
    print(f"Map ({doc['seconds']:.0f} s): Kirchhoff's per-order error on triangular glass gratings")
    for row in doc["triangular"]:
        geo = row.get("geometric_group_ratio")
        print(
            f"  Λ/λ {row['period_over_lambda']:g} θi {row['theta_i']:2g}° slope "
            f"{row['slope']:2g}°: {100 * row['kirchhoff_order_error']:5.1f} % (energy ratio "
            f"{row['kirchhoff_energy_ratio']:.3f}; RCW {row['rcw_order']}×{row['rcw_levels']}, "
            f"{row['rcw_seconds']:.1f} s{'' if row['rcw_converged'] else ', NOT converged'})"
            + ("" if geo is None else f"; geometric group ratio {geo:.3f}")
        )
    for row in doc["sinusoidal"]:
        print(
            f"  sinusoid θi {row['theta_i']:2g}° a/λ {row['amplitude_over_lambda']:g}: "
            f"Rayleigh–Rice off by {100 * row['rayleigh_rice_error']:.1f} %"
        )
    for row in doc["triangular_aluminium_te"]:
        print(
            f"  aluminium TE Λ/λ {row['period_over_lambda']:g} θi {row['theta_i']:2g}° slope "
            f"{row['slope']:2g}°: {100 * row['kirchhoff_order_error']:5.1f} % (RCW "
            f"{row['rcw_order']}×{row['rcw_levels']}, {row['rcw_seconds']:.1f} s"
            f"{'' if row['rcw_converged'] else ', NOT converged'})"
        )
    print("  aluminium TM study:", doc["aluminium_tm_study"])
    for row in doc["random"]:
        print(
            f"  random ℓ/λ {row['corr_over_lambda']:g} θi {row['theta_i']:2g}° rms slope "
            f"{row['rms_slope']:.3f} σ/λ {row['sigma_over_lambda']:.3f}: Kirchhoff "
            f"{100 * row['kirchhoff_order_error']:.1f} %, Rayleigh–Rice "
            f"{100 * row['rayleigh_rice_error']:.1f} % (RCW {row['rcw_order']} orders × "
            f"{row['rcw_slices']} slices, {row['rcw_seconds']:.1f} s"
            f"{'' if row['rcw_converged'] else ', NOT converged'})"
        )
    print("Crossovers (> 5 %):", crossovers(doc))
    if args.json:
        atomic.write_text(args.json, json.dumps(doc, indent=1) + "\n")
        print(f"wrote {args.json}")
        write_chart(args.json)


if __name__ == "__main__":
    main()
