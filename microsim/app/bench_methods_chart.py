"""What `microsim bench --methods` shows of its study: the study read back as typed records
(``MethodsStudy``), its chart and its table."""

from __future__ import annotations

from dataclasses import dataclass, fields

__all__ = [
    "MethodPoint",
    "Panel",
    "StudyMachine",
    "MethodsStudy",
    "methods_chart",
    "format_methods",
]


def _fields_of(cls, doc: dict) -> dict:
    """``cls``'s fields read from the JSON object ``doc`` (absent ones None)."""
    return {f.name: doc.get(f.name) for f in fields(cls)}


@dataclass(frozen=True)
class MethodPoint:
    """What the chart and the table read of one point of a panel (the JSON holds more)."""

    method: str
    key: str
    kind: str  # "curve" (one of a series over a size) or "closed-form"
    setting: str
    seconds: float
    error: float | None
    error_se: float | None


@dataclass(frozen=True)
class Panel:
    """What the chart and the table read of one panel: its title, reference, error measure,
    the reference's own uncertainty (the wave panel's) and its points."""

    key: str
    title: str
    reference: str
    error_measure: str
    reference_se: float | None
    points: tuple


@dataclass(frozen=True)
class StudyMachine:
    """Where and when the study ran (``methods.json``'s ``machine``)."""

    cpus: int
    load_average_start: list
    load_average_end: list
    threads: int
    commit: str | None
    worktree_modified: bool | None


@dataclass(frozen=True)
class MethodsStudy:
    """The study as the chart and the table read it: ``MethodsStudy.from_json`` of
    ``methods_study``'s JSON object."""

    quick: bool
    seconds: float
    machine: StudyMachine
    panels: tuple

    @classmethod
    def from_json(cls, doc: dict) -> MethodsStudy:
        def panel(d):
            points = tuple(MethodPoint(**_fields_of(MethodPoint, p)) for p in d.get("points"))
            return Panel(**{**_fields_of(Panel, d), "points": points})

        return cls(
            quick=doc.get("quick"),
            seconds=doc.get("seconds"),
            machine=StudyMachine(**_fields_of(StudyMachine, doc.get("machine"))),
            panels=tuple(panel(d) for d in doc.get("panels")),
        )


_MARKERS = {
    "ts-smith": ("C2", "^"),
    "ts-vgroove": ("C3", "v"),
    "rayleigh-rice": ("C0", "o"),
    "low-smooth": ("C1", "s"),
    "kirchhoff-first-order": ("C5", "D"),
    "ray-traced": ("C4", "o"),
    "ray-analytic": ("C6", "s"),
    "kirchhoff": ("C9", "h"),
    "rcw": ("C7", "P"),
    "kirchhoff-1d": ("C9", "*"),
}


def methods_chart(study: dict, path) -> None:
    """Two log–log panels (geometric, wave) of error against wall seconds, written to ``path``
    (PNG, atomically): curves for the methods with a size (rays, tile), single markers for
    the closed forms, error bars where a point has an uncertainty; the wave panel's reference
    uncertainty as a dotted line."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from ..atomic import atomic_open

    study = MethodsStudy.from_json(study)
    panels = study.panels
    fig, axes = plt.subplots(1, len(panels), figsize=(6.2 * len(panels), 4.8), squeeze=False)
    for ax, panel in zip(axes[0], panels):
        by: dict[str, list] = {}
        for p in panel.points:
            by.setdefault(p.key, []).append(p)
        for key, pts in by.items():
            pts = [p for p in pts if p.error is not None and p.error > 0]
            if not pts:
                continue
            colour, marker = _MARKERS.get(key, ("k", "x"))
            x = [p.seconds for p in pts]
            y = [p.error for p in pts]
            yerr = [p.error_se or 0.0 for p in pts]
            # an error bar below zero is drawn down to 1/10 of the point on the log axis
            lo = [min(e, 0.9 * v) for e, v in zip(yerr, y)]
            curve = pts[0].kind == "curve"
            ax.errorbar(
                x,
                y,
                yerr=[lo, yerr],
                color=colour,
                marker=marker,
                ls="-" if curve else "none",
                ms=6 if curve else 9,
                capsize=2,
                label=pts[0].method,
            )
            if curve:
                ax.annotate(pts[0].setting, (x[0], y[0]), fontsize=7, xytext=(3, 3),
                            textcoords="offset points")  # fmt: skip
                ax.annotate(pts[-1].setting, (x[-1], y[-1]), fontsize=7, xytext=(3, 3),
                            textcoords="offset points")  # fmt: skip
        if panel.key == "wave" and panel.reference_se:
            ax.axhline(panel.reference_se, color="grey", ls=":", lw=1)
            ax.annotate("reference speckle (1 se)", (0.02, panel.reference_se),
                        xycoords=("axes fraction", "data"), fontsize=7, color="grey",
                        xytext=(0, 2), textcoords="offset points")  # fmt: skip
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time for one incidence (s)")
        ax.set_ylabel({"geometric": "energy-weighted rel. RMS error",
                       "fullwave": "share of power in the wrong orders"}.get(
                           panel.key, "|energy deviation|"))  # fmt: skip
        ax.set_title(f"{panel.title}\nreference: {panel.reference}", fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    m = study.machine
    fig.suptitle(
        f"What each method costs: wall time for one incidence on {m.cpus} cores, "
        f"{m.threads} threads, load {m.load_average_start[0]:.2f}, commit "
        f"{(m.commit or '?')[:7]}{' (quick)' if study.quick else ''}",
        fontsize=9,
    )
    fig.tight_layout()
    try:
        with atomic_open(path, "wb") as fh:
            fig.savefig(fh, format="png", dpi=100)
    finally:
        plt.close(fig)


def _num(x, fmt="{:.3g}") -> str:
    return "–" if x is None else fmt.format(x)


def format_methods(study: dict) -> str:
    """A short table: per panel, method, setting, seconds, error ± uncertainty."""
    study = MethodsStudy.from_json(study)
    m = study.machine
    lines = [
        f"methods study{' (quick)' if study.quick else ''}: {m.cpus} CPUs, "
        f"{m.threads} threads, load average {m.load_average_start[0]:.2f} → "
        f"{m.load_average_end[0]:.2f}, commit {(m.commit or '?')[:10]}, "
        f"{study.seconds:.1f} s"
    ]
    for panel in study.panels:
        lines += [
            "",
            f"{panel.title} — reference: {panel.reference}",
            f"error: {panel.error_measure}",
            f"{'method':30s}{'setting':26s}{'seconds':>10s}{'error':>10s}{'± se':>10s}",
        ]
        for p in panel.points:
            lines.append(
                f"{p.method[:29]:30s}{p.setting[:25]:26s}{p.seconds:10.3g}"
                f"{_num(p.error):>10s}{_num(p.error_se):>10s}"
            )
    return "\n".join(lines)
