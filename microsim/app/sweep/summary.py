"""Gathering the finished tasks into ``summary.csv``, ``summary.md`` and the error-vs-roughness
chart, every verdict worded by ``verdicts.verdict_kind``."""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import ClassVar, Mapping

from ... import atomic
from ...analysis.json_record import JsonRecord
from ...analysis.verdict_record import Verdict
from ...errors import EnvironmentFailure
from .grid import SweepSpec, fmt_num, material_text
from .task import load_result


@dataclass(frozen=True)
class SummaryFiles:
    """The paths ``write_summary`` wrote."""

    csv: str
    markdown: str
    chart: str


@dataclass(frozen=True, eq=False)
class TaskSettings(JsonRecord):
    """The part of a task's description the summary shows (``grid.Task.to_dict``)."""

    scene: str = ""
    surface: Mapping = field(default_factory=dict)
    ior: object = None
    theta_i: float = 0.0


@dataclass(frozen=True, eq=False)
class TaskRecord(JsonRecord):
    """A finished task's ``tasks/<id>.json`` (``task.run_task``): its ``task`` description,
    ``roughness``, ``rays``, wall ``seconds``, ray-noise floor and ``verdicts``."""

    id: str = ""
    task: TaskSettings = field(default_factory=TaskSettings)
    roughness: float | None = None
    rays: int = 0
    seconds: float = 0.0
    noise_floor: float | None = None
    verdicts: tuple[Verdict, ...] = ()
    _nested: ClassVar = {"task": TaskSettings, "verdicts": Verdict}


@dataclass(frozen=True, eq=False)
class SummaryRow(JsonRecord):
    """One (task, model) row of the summary, its fields the ``COLUMNS`` (``material`` plain
    text; ``verdict`` worded by ``verdicts.verdict_kind``); as a dict, the CSV row."""

    task: str = ""
    scene: str = ""
    params: str = ""
    material: str = ""
    roughness: float | None = None
    theta_i: float = 0.0
    model: str = ""
    rel_rms: float | None = None
    noise_floor: float | None = None
    chi2_dof: float | None = None
    p_value: float | None = None
    max_abs_z: float | None = None
    verdict: str = ""
    tile_departure: float | None = None
    n_bins: int = 0
    rays: int = 0
    seconds: float = 0.0

    @classmethod
    def of(cls, r: TaskRecord, v: Verdict) -> "SummaryRow":
        """The row of verdict ``v`` of task record ``r``."""
        from microsim.analysis.verdicts import verdict_kind

        t = r.task
        return cls.from_json(
            {
                "task": r.id,
                "scene": t.scene,
                "params": _params_text(t.surface),
                "material": material_text(t.ior),
                "roughness": r.roughness,
                "theta_i": t.theta_i,
                "model": v.model,
                "rel_rms": v.rel_rms,
                "noise_floor": r.noise_floor,
                "chi2_dof": v.chi2_dof,
                "p_value": v.p_value,
                "max_abs_z": v.max_abs_z,
                "verdict": verdict_kind(v),
                "tile_departure": v.tile_departure,
                "n_bins": v.n_bins,
                "rays": r.rays,
                "seconds": round(r.seconds, 3),
            }
        )


COLUMNS = tuple(f.name for f in fields(SummaryRow))
"""The summary's columns: the fields of ``SummaryRow``, in order."""


def gather(spec: SweepSpec, out) -> list[TaskRecord]:
    """Complete task records of ``spec`` in ``out``, in task order (missing, unreadable and
    partial ones left out)."""
    records = (load_result(t, Path(out)) for t in spec.tasks)
    return [TaskRecord.from_json(r) for r in records if r is not None]


def _params_text(surface: dict) -> str:
    return " ".join(f"{k}={fmt_num(v)}" for k, v in sorted(surface.items()) if k != "kind")


def summary_table(records) -> list[SummaryRow]:
    """One row per (task, model) of the task ``records`` (``TaskRecord`` or their JSON
    objects): ``SummaryRow``, the rule of every microsim output for the verdict."""
    records = [TaskRecord.from_json(r) for r in records]
    return [SummaryRow.of(r, v) for r in records for v in r.verdicts]


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def write_summary(spec: SweepSpec, out) -> SummaryFiles:
    """Write ``summary.csv``, ``summary.md`` and ``error_vs_roughness.png`` (atomically) from
    the complete task JSONs present; returns their paths."""
    out = Path(out)
    try:
        return _write_summary(spec, out)
    except OSError as e:
        raise EnvironmentFailure(
            f"{e.filename or out}: cannot write the sweep summary ({e.strerror or e})"
        ) from None


def _write_summary(spec: SweepSpec, out: Path) -> SummaryFiles:
    recs = gather(spec, out)
    rows = summary_table(recs)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    atomic.write_text(out / "summary.csv", buf.getvalue())
    cols = [c for c in COLUMNS if c != "task"]
    md = [
        f"# Sweep {spec.name}",
        "",
        spec.description,
        "",
        f"{len(recs)}/{len(spec.tasks)} tasks done. rel_rms: energy-weighted relative RMS "
        "error of the model over the bins carrying 90 % of the energy, ray noise included; "
        "noise_floor: what an exact model would show through the ray noise alone (the "
        "energy-weighted relative standard error over the same bins); chi2_dof, p_value, "
        "max_abs_z: see microsim.analysis.verdicts. verdict: agrees, deviates, or "
        "inconclusive (the model describes the surface's ensemble, one tile was traced, and "
        "its deviation is within what the tile's own departure from the ensemble, "
        "tile_departure, and ray noise explain — or that departure is not computable), "
        "judged as microsim run judges it.",
        "",
        "| " + " | ".join(cols) + " |",
        "|" + "---|" * len(cols),
    ]
    md += ["| " + " | ".join(_fmt(getattr(r, c)) for c in cols) + " |" for r in rows]
    atomic.write_text(out / "summary.md", "\n".join(md) + "\n")
    chart = out / "error_vs_roughness.png"
    _chart(rows, chart, spec.name)
    return SummaryFiles(
        csv=str(out / "summary.csv"), markdown=str(out / "summary.md"), chart=str(chart)
    )


def _chart(rows: list[SummaryRow], path: Path, title: str) -> None:
    """Model relative RMS error against roughness: colour = θi, line style = model, marker =
    scene and material (one line per combination); a hollow marker is an inconclusive
    verdict (its error is within what the one tile's departure from its ensemble may
    explain), a filled one a conclusive verdict."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(8.5, 4.8), layout="constrained")
    groups: dict = {}
    floors: dict = {}
    for r in rows:
        if r.roughness is None or r.rel_rms is None:
            continue
        key = (r.scene, r.material, r.model, r.theta_i)
        groups.setdefault(key, []).append((r.roughness, r.rel_rms, r.verdict == "inconclusive"))
        if r.noise_floor is not None:
            floors.setdefault((r.scene, r.material, r.theta_i), {})[r.roughness] = r.noise_floor
    thetas = sorted({k[3] for k in groups})
    models = sorted({k[2] for k in groups})
    looks = sorted({k[:2] for k in groups})
    cmap = plt.get_cmap("viridis")
    for (scene, mat, model, th), pts in sorted(groups.items()):
        pts.sort()
        x, y, unsure = (np.array(c) for c in zip(*pts))
        colour = cmap(thetas.index(th) / max(1, len(thetas) - 1) * 0.9)
        marker = "osD^v<>"[looks.index((scene, mat)) % 7]
        ax.plot(
            x,
            y,
            color=colour,
            linestyle=("-", "--", ":", "-.")[models.index(model) % 4],
            marker=marker,
            markersize=4,
            markevery=list(np.flatnonzero(~unsure)),
            label=f"{scene} {mat} {model} θi={th:g}°",
        )
        ax.plot(
            x[unsure],
            y[unsure],
            linestyle="none",
            marker=marker,
            markersize=4,
            markerfacecolor="white",
            markeredgecolor=colour,
        )
    for (scene, mat, th), by_x in sorted(floors.items()):
        x = sorted(by_x)
        colour = cmap(thetas.index(th) / max(1, len(thetas) - 1) * 0.9)
        ax.plot(x, [by_x[k] for k in x], color=colour, lw=3.0, alpha=0.25,
                label=f"ray-noise floor {scene} {mat} θi={th:g}°")  # fmt: skip
    ax.set_xlabel("roughness (first NDF parameter)")
    ax.set_ylabel("relative RMS error (90 % energy bins)")
    ax.set_yscale("log")
    ax.set_title(
        f"sweep {title}: model error against roughness and angle\n"
        "filled marker: conclusive verdict; hollow: inconclusive (one tile); wide pale line: "
        "the ray-noise floor (an exact model's error)",
        fontsize=9,
    )
    if groups:
        fig.legend(fontsize=6, loc="outside lower center", ncol=2)
    try:
        with atomic.atomic_open(path, "wb") as fh:
            fig.savefig(fh, format="png", dpi=120)
    finally:
        plt.close(fig)
