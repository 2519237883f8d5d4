"""The scattering-order comparison in words and pictures: the report section "How much light
single scattering misses" (``multiple_section``), its chart (``multiple_chart``) and the
deviation of a model's multiple scattering as the tables write it (``deviation_text``), from
an ``analysis.multiple.order_comparison`` (``OrderComparison``)."""

from __future__ import annotations

import os
from typing import Mapping

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from microsim.atomic import atomic_open
from microsim.errors import UsageError

from . import incidence
from .chart_style import DPI, SIM_COLOUR, model_colour
from .markdown import percent
from .study_records import OrderComparison, OrderIncidence

__all__ = ["RESOLVED_SE", "deviation_text", "multiple_section", "multiple_chart"]


def _pm(x, se, digits=4) -> str:
    if x is None:
        return "–"
    if se is None:
        return f"{x:.{digits}f}"
    return f"{x:.{digits}f} ± {se:.{digits}f}"


def _pct(x, se=None, unit=" %") -> str:
    """A signed percentage (3 significant figures) ± its standard error (2)."""
    if x is None or se is None:
        return percent(x, 3, signed=True, unit=unit)
    return f"{percent(x, 3, signed=True, unit='')} ± {percent(se, unit=unit)}"


RESOLVED_SE = 2.0
"""The simulated energy of orders ≥ 2 is resolved from this many standard errors on: only then
do the tables give a model's relative deviation (module docstring)."""


def deviation_text(inc: Mapping, name: str, with_se: bool = True) -> str:
    """Model ``name``'s energy deviation of orders ≥ 2 at one incidence of an
    ``order_comparison``: relative, (sim − model)/sim, when the simulated energy is resolved
    (≥ ``RESOLVED_SE`` standard errors); else the absolute difference sim − model in
    percentage points of the incident power ("+0.003 pp"). ``with_se``: ± its standard error.
    ``inc``: an ``OrderIncidence`` (or its dict)."""
    inc = OrderIncidence.from_json(inc)
    s, m = inc.sim, inc.models[name]
    if s.multiple >= RESOLVED_SE * s.multiple_se and m.rel_dev is not None:
        return _pct(m.rel_dev, m.rel_dev_se if with_se else None)
    diff_se = float(np.hypot(s.multiple_se, m.energy_se)) if with_se else None
    return _pct(s.multiple - m.energy, diff_se, unit=" pp")


def multiple_section(comparison: Mapping) -> list[str]:
    """Markdown lines of the report section "How much light single scattering misses" from an
    ``order_comparison`` dict: per θi a table of the simulated energy per order (± se), absorbed
    and cut, and per model the energy of orders ≥ 2, its relative deviation ± se with the
    verdict, the lobe's relative RMS (and the noise floor) and the specular share.
    ``comparison``: an ``OrderComparison`` (or its dict)."""
    c = OrderComparison.from_json(comparison)
    names = c.models
    rough = ", ".join(
        f"{k.replace('alpha', 'α').replace('_', '')} = {v:.4g}"
        for k, v in c.ndf.items()
        if k != "kind"
    )
    closed = (
        f", Kulla & Conty 2017 (E from Torrance–Sparrow with height-correlated Smith G, E_avg = "
        f"{c.kulla_conty_e_avg:.4f}) and Mikkelsen 2009 eq. 28 (k_d = {c.kd:.4g}, "
        f"{c.kd_note})"
        if "kulla-conty" in names
        else f" ({c.closed_forms_note})"
    )
    with_phi = incidence.several_azimuths(c.incidences)
    lines = [
        "## How much light single scattering misses",
        "",
        (
            f"Orders of scattering on the explicit surface (bounces = {c.bounces}, "
            f"{c.realisations} realisation(s); ± one standard error, "
            f"{'from the realisations' if c.realisations >= 2 else 'ray noise of one tile'})"
            f" against the Heitz et al. 2016 random walk ({c.ndf['kind']}, {rough}, "
            f"{c.walk_paths:,} paths per incidence){closed}. Energies are fractions of the "
            f"incident power; deviations "
            f"(sim − model)/sim, or, where the simulated energy of orders ≥ 2 is below "
            f"{RESOLVED_SE:g} standard errors (not resolved: its relative deviation would be "
            f"noise), sim − model in percentage points (pp) of the incident power; 'agrees' "
            f"at the Šidák level of {len(names)} "
            f"model{'s' if len(names) > 1 else ''} × "
            f"{len(c.incidences)} incidences (family α = {c.alpha:g}). Lobe error: the "
            "energy-weighted relative RMS of (model − simulation)/simulation over the bins "
            "carrying 90 % of the simulated order-≥ 2 energy; shape error: the same after "
            "scaling the model to the simulated energy of those bins (its shape alone); noise "
            "floor: what the standard errors alone give. Specular share: energy at Δφ > 90°."
        ),
        "",
    ]
    if c.expectation:
        lines += [f"*{c.expectation[0].upper()}{c.expectation[1:]}.*", ""]
    for inc in c.incidences:
        lines += [f"### {incidence.label(inc.theta_i, inc.phi_i, with_phi)}", ""]
        lines += _incidence_tables(inc, c.order_labels, names)
        walk = _walk_verdicts_text(inc.walk_verdicts)
        lines += ["", "Random-walk BRDF verdicts: " + walk + ".", ""]
    return lines


def _incidence_tables(inc: OrderIncidence, labels, names) -> list[str]:
    """One incidence of ``multiple_section``: the energy per order of the simulation and the
    walk, then per model its energy of orders ≥ 2, deviation, verdict and lobe errors."""
    s = inc.sim
    lines = []
    head = [f"order {k}" for k in labels] + ["orders ≥ 2", "absorbed", "cut"]
    lines.append("| | " + " | ".join(head) + " |")
    lines.append("|---" * (len(head) + 1) + "|")
    sim_row = [_pm(x, e) for x, e in zip(s.orders, s.order_se)]
    sim_row += [_pm(s.multiple, s.multiple_se), _pm(s.absorbed, s.absorbed_se)]
    sim_row += [_pm(s.cut, s.cut_se)]
    lines.append("| simulation | " + " | ".join(sim_row) + " |")
    w = inc.models["random-walk"]
    w_row = [_pm(x, e) for x, e in zip(w.orders, w.order_se)]
    w_row += [_pm(w.energy, w.energy_se), "–", _pm(w.cut, None)]
    lines.append("| random walk | " + " | ".join(w_row) + " |")
    lines += ["", "| model | energy ≥ 2 | deviation (sim − model)/sim or pp | verdict | "
              "lobe error | shape error | noise floor | specular share |",
              "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    lines.append(
        f"| simulation | {_pm(s.multiple, s.multiple_se)} | | | | | | "
        f"{_pm(s.specular_share, None, 3)} |"
    )
    for name in names:
        m = inc.models[name]
        verdict_txt = "agrees" if m.agrees else f"deviates (t = {m.t:.1f})"
        lobe, shape, floor = (
            percent(x, 3, unit=" %") for x in (m.rel_rms, m.shape_rel_rms, m.noise_floor)
        )
        lines.append(
            f"| {name}{' (k_d fitted)' if m.fitted else ''} | "
            f"{_pm(m.energy, m.energy_se or None)} | "
            f"{deviation_text(inc, name)} | {verdict_txt} | {lobe} | {shape} | "
            f"{floor} | {_pm(m.specular_share, None, 3)} |"
        )
    return lines


def _walk_verdicts_text(walk_verdicts: Mapping) -> str:
    """The random walk's BRDF verdicts of orders 2 and ≥ 2, in words."""
    parts = []
    for key, v in walk_verdicts.items():
        if v.n_bins == 0 or v.energy_dev is None or v.rel_rms is None:
            parts.append(
                f"order {key}: not testable (no bin with ≥ {v.min_events} simulated "
                "events receives light from the walk)"
            )
            continue
        parts.append(
            f"order {key}: {v.kind} (energy (sim − walk)/walk "
            f"{_pct(v.energy_dev, v.energy_dev_se)} over the walk's 90 % bins, rel "
            f"RMS {percent(v.rel_rms, 3, unit=' %')} over {v.energy_bins} bins, "
            f"{v.reference})"
        )
    return "; ".join(parts)


def multiple_chart(comparison: Mapping, path=None, title: str = "", *, ax=None) -> Figure:
    """Energy of orders ≥ 2 (fraction of incident power) against θi (degrees): the simulation
    (points, ±1σ) and each model's prediction (random walk ±1σ, Kulla–Conty, Mikkelsen eq. 28
    with its fitted k_d). ``ax``: one matplotlib Axes to draw into (else a new 6.4 × 4.6 in
    Figure, Agg canvas); ``path``: also write a PNG. ``comparison``: an ``OrderComparison``
    (or its dict). Returns the Figure."""
    c = OrderComparison.from_json(comparison)
    phis = list(dict.fromkeys(i.phi_i for i in c.incidences))
    with_phi = len(phis) > 1
    if ax is None:
        fig = Figure(figsize=(6.4, 4.6), dpi=DPI, layout="constrained")
        FigureCanvasAgg(fig)
        ax = fig.subplots()
        own = True
    else:
        if not isinstance(ax, Axes):
            raise UsageError(f"ax must be one matplotlib Axes, got {ax!r}")
        fig, own = ax.figure, False
    for g, phi in enumerate(phis):  # one series per incidence azimuth
        inc = [i for i in c.incidences if i.phi_i == phi]
        th = np.array([i.theta_i for i in inc])
        at = f", φi = {phi:g}°" if with_phi else ""
        for k, name in enumerate(c.models):
            e = np.array([i.models[name].energy for i in inc])
            es = np.array([i.models[name].energy_se for i in inc])
            ax.errorbar(
                th + 0.4 * (k - 1),
                e,
                yerr=es if np.any(es > 0) else None,
                marker="s^v"[k],
                ms=4,
                lw=1.4,
                ls=("-", "--", ":", "-.")[g % 4],
                capsize=2,
                color=model_colour(name),
                label=name + (" (k_d fitted)" if name == "mikkelsen-eq28" else "") + at,
            )
        ax.errorbar(
            th,
            [i.sim.multiple for i in inc],
            yerr=[i.sim.multiple_se for i in inc],
            fmt="os^D"[g % 4],
            ms=5,
            capsize=2,
            color=SIM_COLOUR,
            mfc=SIM_COLOUR if g == 0 else "white",
            label="simulation ±1σ" + at,
            zorder=5,
        )
    ax.set_xlabel("θi (°)")
    ax.set_ylabel("energy in orders ≥ 2 (fraction of incident)")
    ax.set_xlim(0, 90)
    ax.set_ylim(bottom=0)
    ax.set_xticks(np.arange(0, 91, 15))
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    if own:
        ax.set_title(title or "How much light single scattering misses")
    if path is not None:
        with atomic_open(os.fspath(path), "wb") as fh:
            fig.savefig(fh, format="png", dpi=DPI)
    return fig
