"""`microsim sweep SWEEP.toml`: a grid of scenes × parameters × incidences, one verdict table.

Sweep file (TOML)::

    name = "vgroove-roughness"          # default: the file stem
    description = "..."
    rays = 200_000                      # primary rays per task (one task = one θi)
    seed = 0
    theta_bins = 45                     # outgoing bins (folded Δφ)
    phi_bins = 37
    models = ["vgroove", "smith"]       # Torrance–Sparrow shadowing variants to judge
    masking = "traced"                  # or "exact" (V-grooves only)
    theta_i = [0, 30, 60, 80]           # degrees: the incidence axis

    [[scenes]]                          # one or more; every list value is a grid axis
    name = "vgroove-beckmann"
    ior = ["aluminium", 1.5]            # material axis (names, n, or [n, k] — not a list of lists)
    [scenes.surface]                    # a scene file's [surface] table (microsim.scene)
    kind = "vgrooves"
    n_grooves = 1000
    ndf = "beckmann"
    m = [0.05, 0.1, 0.3, 0.5, 1.0]      # roughness axis

A task is one (scene, parameter combination, material, θi). Its result — the verdict of each
model (``microsim.analysis.verdicts.verdict``: χ²/dof, p, max |z|, relative RMS error over the
bins carrying 90 % of the energy, …) against the bin-averaged Torrance–Sparrow prediction with
the scene's NDF — is written as ``OUT/tasks/<id>.json`` as soon as the task finishes
(temporary file + ``os.replace``: atomic). The id is a hash of the task's full description, so
rerunning the sweep computes only the tasks whose JSON is missing. Finally every task JSON is
gathered into ``OUT/summary.csv``, ``OUT/summary.md`` and ``OUT/error_vs_roughness.png``.

Execution: local worker processes (``concurrent.futures.ProcessPoolExecutor``, ``--workers``),
or, with ``--scheduler ADDRESS``, the same task function on a Dask distributed cluster
(``dask.distributed.Client(ADDRESS)``). Each task traces on one thread.
"""
from __future__ import annotations

from microsim.errors import UsageError
import csv
import hashlib
import io
import itertools
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from . import atomic

__all__ = ["SweepSpec", "Task", "load_sweep", "expand_tasks", "run_task", "run_sweep",
           "gather", "summary_table", "write_summary", "add_sweep_command"]

_TOP = ("name", "description", "rays", "seed", "theta_bins", "phi_bins", "models", "masking",
        "theta_i", "scenes")
_SHADOWING = ("vgroove", "smith", "smith-correlated", "none")
COLUMNS = ("task", "scene", "params", "material", "roughness", "theta_i", "model", "rel_rms",
           "chi2_dof", "p_value", "max_abs_z", "agrees", "n_bins", "rays", "seconds")


@dataclass(frozen=True)
class Task:
    """One unit of work (JSON-able fields): ``surface`` a concrete [surface] table, ``ior``
    (name, number or [n, k]), θi in degrees, and the shared run settings."""

    scene: str
    surface: dict
    ior: object
    theta_i: float
    rays: int
    seed: int
    theta_bins: int
    phi_bins: int
    models: tuple
    masking: str

    @property
    def id(self) -> str:
        """Stable id: readable prefix + hash of the full description."""
        blob = json.dumps(self.to_dict(), sort_keys=True)
        return f"{self.scene}-{hashlib.sha1(blob.encode()).hexdigest()[:12]}"

    def to_dict(self) -> dict:
        return {"scene": self.scene, "surface": self.surface, "ior": self.ior,
                "theta_i": self.theta_i, "rays": self.rays, "seed": self.seed,
                "theta_bins": self.theta_bins, "phi_bins": self.phi_bins,
                "models": list(self.models), "masking": self.masking}


@dataclass(frozen=True)
class SweepSpec:
    """A loaded sweep file: its name and the expanded task list."""

    name: str
    description: str
    tasks: tuple


def _fail(where: str, msg: str):
    raise UsageError(f"{where}: {msg}")


def _axis(v) -> list:
    """A grid axis: lists are axes, anything else a single value. ``[n, k]`` pairs of a
    complex index must be written as ``[[n, k]]`` when they are an axis of one value."""
    return list(v) if isinstance(v, list) else [v]


def expand_tasks(data: dict, where: str = "sweep") -> list[Task]:
    """Tasks of a parsed sweep table (module docstring), in grid order."""
    extra = sorted(set(data) - set(_TOP))
    if extra:
        _fail(where, f"{extra[0]}: unknown key; allowed keys: {', '.join(_TOP)}")
    rays, seed = data.get("rays", 200_000), data.get("seed", 0)
    if isinstance(rays, bool) or not isinstance(rays, int) or rays < 1:
        _fail(where, f"rays: must be an integer >= 1, got {rays!r}")
    if isinstance(seed, bool) or not isinstance(seed, int):
        _fail(where, f"seed: must be an integer, got {seed!r}")
    models = tuple(_axis(data.get("models", ["vgroove", "smith"])))
    bad = [m for m in models if m not in _SHADOWING]
    if bad or not models:
        _fail(where, f"models: must be a non-empty list of {', '.join(_SHADOWING)}, got {models!r}")
    masking = data.get("masking", "traced")
    if masking not in ("traced", "exact"):
        _fail(where, f"masking: must be traced or exact, got {masking!r}")
    nt, npf = data.get("theta_bins", 45), data.get("phi_bins", 37)
    for key, v in (("theta_bins", nt), ("phi_bins", npf)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 2:
            _fail(where, f"{key}: must be an integer >= 2, got {v!r}")
    thetas = _axis(data.get("theta_i", [0.0, 30.0, 60.0, 80.0]))
    if not thetas or not all(isinstance(t, (int, float)) and 0 <= t < 90 for t in thetas):
        _fail(where, f"theta_i: must be degrees in [0, 90), got {thetas!r}")
    scenes = data.get("scenes")
    if not isinstance(scenes, list) or not scenes:
        _fail(where, "scenes: required; a non-empty array of [[scenes]] tables")
    tasks = []
    for k, sc in enumerate(scenes):
        w = f"{where}: scenes[{k}]"
        if not isinstance(sc, dict) or not isinstance(sc.get("surface"), dict):
            _fail(w, "must be a table with a [scenes.surface] table")
        extra = sorted(set(sc) - {"name", "ior", "surface"})
        if extra:
            _fail(w, f"{extra[0]}: unknown key; allowed keys: name, ior, surface")
        name = sc.get("name", f"scene{k}")
        surf = sc["surface"]
        keys = sorted(surf)
        for values in itertools.product(*(_axis(surf[key]) for key in keys)):
            concrete = dict(zip(keys, values))
            _scene(name, concrete, None, w)                     # validate early
            for ior in _axis(sc.get("ior", "aluminium")):
                for t in thetas:
                    tasks.append(Task(name, concrete, ior, float(t), rays, seed, nt, npf,
                                      models, masking))
    return tasks


def load_sweep(path) -> SweepSpec:
    """Read and validate a sweep file; ValueError names the file and the key."""
    from .scene import read_toml
    path = Path(path)
    data = read_toml(path, "sweep")
    tasks = expand_tasks(data, str(path))
    return SweepSpec(str(data.get("name", path.stem)), str(data.get("description", "")),
                     tuple(tasks))


def _scene(name: str, surface: dict, ior, where: str):
    """A ``microsim.scene.Scene`` from a concrete [surface] table (validated like a scene file)."""
    from microsim import scene as sc
    spec = sc._surface_spec(where, dict(surface))
    mat = None if ior is None else sc._material(where, {"ior": ior})
    return sc.Scene(name=name, path=None, description="", surface=spec, ior=mat,
                    simulation=sc.SimSettings())


def _roughness(ndf) -> tuple[str, float | None]:
    """(parameter name, value) of the scene NDF's first parameter, e.g. ("m", 0.3)."""
    if ndf is None:
        return "", None
    params = ndf.params()
    key = next(iter(params))
    return key, float(params[key])


def run_task(task: Task, out_dir) -> dict:
    """Simulate one task, judge every model, write ``out_dir/tasks/<id>.json`` atomically and
    return the record."""
    from microsim.analysis.verdicts import verdict
    from microsim.sim import Bins, simulate
    from microsim.sim.predict import ModelSpec, predict
    t0 = time.perf_counter()
    scene = _scene(task.scene, task.surface, task.ior, f"task {task.scene}")
    surface = scene.build_surface(seed=task.seed)
    bins = Bins(task.theta_bins, task.phi_bins)
    res = simulate(surface, scene.ior, task.theta_i, rays=task.rays, bins=bins, seed=task.seed,
                   threads=1, masking=task.masking)
    ndf = scene.ndf()
    specs = [ModelSpec.torrance_sparrow(f"ts-{g}", ndf, g, scene.ior) for g in task.models]
    preds = predict(specs, [task.theta_i], bins) if ndf is not None else {}
    omega = bins.projected_solid_angle()
    verdicts = [verdict(res.brdf[0], res.stderr[0], res.counts[0], preds[s.name][0], omega,
                        bins.theta_edges, phi_edges=bins.phi_edges, theta_i=task.theta_i,
                        name=s.name, n_tests=len(specs)) for s in specs if s.name in preds]
    key, value = _roughness(ndf)
    record = {"id": task.id, "task": task.to_dict(), "roughness_param": key, "roughness": value,
              "rays": int(res.rays[0]), "seconds": time.perf_counter() - t0,
              "ledger": {k: float(v[0]) for k, v in res.ledger.items()}, "verdicts": verdicts}
    atomic.write_json(Path(out_dir) / "tasks" / f"{task.id}.json", record)
    return record


def _done(task: Task, out_dir: Path) -> bool:
    """Is a complete, readable result of ``task`` on disk?"""
    try:
        with open(out_dir / "tasks" / f"{task.id}.json", encoding="utf-8") as fh:
            return json.load(fh).get("id") == task.id
    except (OSError, ValueError):
        return False


def run_sweep(spec: SweepSpec, out, *, scheduler=None, workers: int = 2,
              limit: int | None = None, progress: Callable[[str], None] | None = None) -> dict:
    """Run the tasks of ``spec`` that have no result in ``out`` yet, then ``write_summary``.

    ``scheduler``: None (local processes, ``workers`` of them) or a Dask scheduler address
    (anything ``dask.distributed.Client`` accepts, e.g. "tcp://host:8786" or a LocalCluster).
    ``limit``: run at most this many of the missing tasks (then stop, as if interrupted).
    Returns {"computed": [ids], "skipped": [ids], "summary": paths}.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    todo = [t for t in spec.tasks if not _done(t, out)]
    skipped = [t.id for t in spec.tasks if t not in todo]
    if limit is not None:
        todo = todo[:int(limit)]
    computed = []
    if todo:
        if scheduler is None:
            with ProcessPoolExecutor(max_workers=int(workers)) as pool:
                futures = [pool.submit(run_task, t, str(out)) for t in todo]
                for fut in as_completed(futures):
                    rec = fut.result()
                    computed.append(rec["id"])
                    if progress:
                        progress(f"{len(computed)}/{len(todo)} {rec['id']}")
        else:
            from dask.distributed import Client
            from dask.distributed import as_completed as dask_completed
            with Client(scheduler) as client:
                futures = [client.submit(run_task, t, str(out), key=f"microsim-{t.id}", pure=False)
                           for t in todo]
                for fut in dask_completed(futures):
                    rec = fut.result()
                    computed.append(rec["id"])
                    if progress:
                        progress(f"{len(computed)}/{len(todo)} {rec['id']}")
    paths = write_summary(spec, out)
    return {"computed": computed, "skipped": skipped, "summary": paths}


def gather(spec: SweepSpec, out) -> list[dict]:
    """Task records of ``spec`` found in ``out`` (in task order; missing ones left out)."""
    recs = []
    for t in spec.tasks:
        p = Path(out) / "tasks" / f"{t.id}.json"
        if p.exists():
            with open(p, encoding="utf-8") as fh:
                recs.append(json.load(fh))
    return recs


def _params_text(surface: dict) -> str:
    return " ".join(f"{k}={v}" for k, v in sorted(surface.items()) if k != "kind")


def summary_table(records: list[dict]) -> list[dict]:
    """One row per (task, model) with the ``COLUMNS`` fields."""
    rows = []
    for r in records:
        t = r["task"]
        for v in r["verdicts"]:
            rows.append({"task": r["id"], "scene": t["scene"], "params": _params_text(t["surface"]),
                         "material": json.dumps(t["ior"]), "roughness": r["roughness"],
                         "theta_i": t["theta_i"], "model": v["model"], "rel_rms": v["rel_rms"],
                         "chi2_dof": v["chi2_dof"], "p_value": v["p_value"],
                         "max_abs_z": v["max_abs_z"], "agrees": v["agrees"],
                         "n_bins": v["n_bins"], "rays": r["rays"],
                         "seconds": round(r["seconds"], 3)})
    return rows


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def write_summary(spec: SweepSpec, out) -> dict:
    """Write ``summary.csv``, ``summary.md`` and ``error_vs_roughness.png`` (atomically) from
    the task JSONs present; returns their paths."""
    out = Path(out)
    recs = gather(spec, out)
    rows = summary_table(recs)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    atomic.write_text(out / "summary.csv", buf.getvalue())
    cols = [c for c in COLUMNS if c != "task"]
    md = [f"# Sweep {spec.name}", "", spec.description, "",
          f"{len(recs)}/{len(spec.tasks)} tasks done. rel_rms: energy-weighted relative RMS "
          "error of the model over the bins carrying 90 % of the energy; chi2_dof, p_value, "
          "max_abs_z: see microsim.analysis.verdicts.", "",
          "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    md += ["| " + " | ".join(_fmt(r[c]) for c in cols) + " |" for r in rows]
    atomic.write_text(out / "summary.md", "\n".join(md) + "\n")
    chart = out / "error_vs_roughness.png"
    _chart(rows, chart, spec.name)
    return {"csv": str(out / "summary.csv"), "markdown": str(out / "summary.md"),
            "chart": str(chart)}


def _chart(rows: list[dict], path: Path, title: str) -> None:
    """Model relative RMS error against roughness: colour = θi, line style = model, marker =
    scene and material (one line per combination)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    groups: dict = {}
    for r in rows:
        if r["roughness"] is None or r["rel_rms"] is None:
            continue
        key = (r["scene"], r["material"], r["model"], r["theta_i"])
        groups.setdefault(key, []).append((r["roughness"], r["rel_rms"]))
    thetas = sorted({k[3] for k in groups})
    models = sorted({k[2] for k in groups})
    looks = sorted({k[:2] for k in groups})
    cmap = plt.get_cmap("viridis")
    for (scene, mat, model, th), pts in sorted(groups.items()):
        pts.sort()
        x, y = zip(*pts)
        ax.plot(x, y, color=cmap(thetas.index(th) / max(1, len(thetas) - 1) * 0.9),
                linestyle=("-", "--", ":", "-.")[models.index(model) % 4],
                marker="osD^v<>"[looks.index((scene, mat)) % 7], markersize=4,
                label=f"{scene} {json.loads(mat)} {model} θi={th:g}°")
    ax.set_xlabel("roughness (first NDF parameter)")
    ax.set_ylabel("relative RMS error (90 % energy bins)")
    ax.set_yscale("log")
    ax.set_title(f"sweep {title}: model error against roughness and angle")
    if groups:
        ax.legend(fontsize=5.5, ncol=2)
    fig.tight_layout()
    try:
        with atomic.atomic_open(path, "wb") as fh:
            fig.savefig(fh, format="png", dpi=120)
    finally:
        plt.close(fig)


def _cmd_sweep(args) -> int:
    spec = load_sweep(args.sweep)
    out = args.out or os.path.join("sweeps", "out", spec.name)
    res = run_sweep(spec, out, scheduler=args.scheduler, workers=args.workers,
                    progress=lambda s: print(s, file=sys.stderr))
    print(f"{len(res['computed'])} tasks computed, {len(res['skipped'])} already done; "
          f"{res['summary']['markdown']}, {res['summary']['csv']}, {res['summary']['chart']}")
    return 0


def add_sweep_command(subparsers) -> None:
    """Register ``microsim sweep SWEEP.toml [--scheduler ADDRESS] [--out DIR] [--workers N]``."""
    p = subparsers.add_parser("sweep", help="run a grid of scenes x parameters x incidences "
                                            "and gather the verdicts into one table and chart")
    p.add_argument("sweep", help="sweep file (TOML), e.g. sweeps/vgroove-roughness.toml")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="Dask distributed scheduler address (default: local worker processes)")
    p.add_argument("--out", help="output directory (default sweeps/out/<name>)")
    p.add_argument("--workers", type=int, default=2, help="local worker processes (default 2)")
    p.set_defaults(func=_cmd_sweep)
