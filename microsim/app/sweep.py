"""`microsim sweep SWEEP.toml`: a grid of scenes × parameters × incidences, one verdict table.

Sweep file (TOML, UTF-8)::

    name = "vgroove-roughness"          # default: the file stem; names the default output
    description = "..."                 #   directory sweeps/out/<name>
    rays = 200_000                      # primary rays per task (one task = one θi)
    seed = 0
    theta_bins = 45                     # outgoing bins (folded Δφ)
    phi_bins = 37
    models = ["vgroove", "smith"]       # Torrance–Sparrow shadowing variants to judge
    masking = "traced"                  # or "exact" (V-grooves only)
    theta_i = [0, 30, 60, 80]           # degrees: the incidence axis

    [[scenes]]                          # one or more; every list value is a grid axis
    name = "vgroove-beckmann"           # letters, digits, '.', '_', '-' (not starting with '.')
    ior = ["aluminium", 1.5]            # material axis (names, n, or [n, k] — not a list of lists)
    [scenes.surface]                    # a scene file's [surface] table (microsim.app.scene)
    kind = "vgrooves"
    n_grooves = 1000
    ndf = "beckmann"
    m = [0.05, 0.1, 0.3, 0.5, 1.0]      # roughness axis (an empty list is an error)

A task is one (scene, parameter combination, material, θi). Its result — the verdict of each
model (``microsim.analysis.verdicts.verdicts_for_result``: χ²/dof, p, max |z|, relative RMS
error over the bins carrying 90 % of the energy, …) against the bin-averaged Torrance–Sparrow
prediction with the scene's NDF, judged exactly as ``microsim run`` judges it: an ensemble
model on the one traced tile, with the tile's own departure from its ensemble computed where
the surface allows (V-grooves), so the ``verdict`` column reads "agrees", "deviates" or
"inconclusive" (``verdicts.verdict_kind``) as the run's table would — is written as
``OUT/tasks/<id>.json`` as soon as the task finishes, and only
if its simulation is complete (an interrupted simulation writes nothing); writes are atomic
(``microsim.atomic``). The id is a hash of the task's full description. A rerun computes every
task whose JSON is missing, unreadable, or not a complete result of that very task (fewer rays
than requested, marked partial, no verdicts); ``gather`` ignores such files too. Finally every
task JSON is gathered into ``OUT/summary.csv``, ``OUT/summary.md`` and
``OUT/error_vs_roughness.png``.

Interrupts (Ctrl-C, or SIGTERM to the sweep's process): the finished tasks stay in
``OUT/tasks``, tasks in flight are stopped and leave nothing, no summary is written, and
``run_sweep`` raises ``SweepInterrupted`` (a ``KeyboardInterrupt``); the CLI prints one line
telling to rerun the same command, exit 130 (143 for SIGTERM). A local worker process that
dies (SIGKILL, out of memory) has its unfinished tasks run again in a fresh pool; two pools
in a row breaking before any task finishes is an ``EnvironmentFailure``.

Execution: local worker processes (``concurrent.futures.ProcessPoolExecutor``, ``--workers``),
or, with ``--scheduler ADDRESS``, the same task function on a Dask distributed cluster
(``dask.distributed.Client(ADDRESS)``; the cluster's workers must see ``OUT``). Each task
traces on one thread. One sweep at a time may write to an output directory (a lock file
``OUT/.sweep.lock``).
"""

from __future__ import annotations

import csv
import functools
import hashlib
import io
import itertools
import json
import math
import os
import signal
import stat
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .. import atomic
from ..checkpoints import checkpoint
from ..errors import EnvironmentFailure, UsageError
from ..sim.arguments import MAX_RAYS
from ..sim.bins import MAX_BINS  # theta_bins × phi_bins at most
from . import scene as sc

__all__ = [
    "SweepSpec",
    "Task",
    "SweepInterrupted",
    "load_sweep",
    "expand_tasks",
    "run_task",
    "run_sweep",
    "gather",
    "summary_table",
    "write_summary",
    "task_label",
    "add_sweep_command",
]

_TOP = (
    "name",
    "description",
    "rays",
    "seed",
    "theta_bins",
    "phi_bins",
    "models",
    "masking",
    "theta_i",
    "scenes",
)
_SHADOWING = ("vgroove", "smith", "smith-correlated", "none")
COLUMNS = (
    "task",
    "scene",
    "params",
    "material",
    "roughness",
    "theta_i",
    "model",
    "rel_rms",
    "chi2_dof",
    "p_value",
    "max_abs_z",
    "verdict",
    "tile_departure",
    "n_bins",
    "rays",
    "seconds",
)
MAX_TASKS = 100_000  # tasks per sweep file (each is seconds to minutes of tracing)
LOCK_FILE = ".sweep.lock"
"""The lock file inside a sweep's output directory (``atomic.output_lock``)."""
_NAME_RULE = "1-100 characters from letters, digits, '.', '_', '-', not starting with '.'"


class SweepInterrupted(KeyboardInterrupt):
    """A sweep stopped by Ctrl-C (``signum`` SIGINT) or SIGTERM: ``done`` of ``total`` tasks
    have complete results in ``out`` (kept; a rerun computes the rest)."""

    def __init__(self, out, done: int, total: int, signum: int = signal.SIGINT):
        super().__init__(f"sweep interrupted: {done}/{total} tasks done in {out}")
        self.out, self.done, self.total = str(out), int(done), int(total)
        self.signum = int(signum)


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
        return {
            "scene": self.scene,
            "surface": self.surface,
            "ior": self.ior,
            "theta_i": self.theta_i,
            "rays": self.rays,
            "seed": self.seed,
            "theta_bins": self.theta_bins,
            "phi_bins": self.phi_bins,
            "models": list(self.models),
            "masking": self.masking,
        }


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


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _check_name(where: str, key: str, name) -> str:
    """A name used as a path component (task files, default output directory)."""
    if not isinstance(name, str) or not sc.NAME_PATTERN.fullmatch(name):
        _fail(where, f"{key}: must be {_NAME_RULE}, got {name!r}")
    return name


def expand_tasks(data: dict, where: str = "sweep", base=None) -> list[Task]:
    """Tasks of a parsed sweep table (module docstring), in grid order. ``base``: directory
    that relative heightfield ``path``s of ``kind = "file"`` surfaces are relative to (the
    sweep file's; default the working directory). Every value is checked before any task
    exists; UsageError names ``where`` and the key."""
    if not isinstance(data, dict):
        _fail(where, "must be a table of sweep settings")
    extra = sorted(set(data) - set(_TOP))
    if extra:
        _fail(where, f"{extra[0]}: unknown key; allowed keys: {', '.join(_TOP)}")
    rays, seed = data.get("rays", 200_000), data.get("seed", 0)
    if not _is_int(rays) or not 1 <= rays <= MAX_RAYS:
        _fail(where, f"rays: must be an integer in [1, {MAX_RAYS:,}] (per task), got {rays!r}")
    if not _is_int(seed) or seed < 0:
        _fail(where, f"seed: must be an integer >= 0, got {seed!r}")
    models = tuple(_axis(data.get("models", ["vgroove", "smith"])))
    bad = [m for m in models if not isinstance(m, str) or m not in _SHADOWING]
    if not models:
        _fail(where, f"models: empty; must be a non-empty list of {', '.join(_SHADOWING)}")
    if bad or len(set(models)) != len(models):
        _fail(
            where,
            f"models: must be a list of distinct {', '.join(_SHADOWING)}, got {list(models)!r}",
        )
    masking = data.get("masking", "traced")
    if masking not in ("traced", "exact"):
        _fail(where, f"masking: must be traced or exact, got {masking!r}")
    nt, npf = data.get("theta_bins", 45), data.get("phi_bins", 37)
    for key, v in (("theta_bins", nt), ("phi_bins", npf)):
        if not _is_int(v) or v < 2:
            _fail(where, f"{key}: must be an integer >= 2, got {v!r}")
    if nt * npf > MAX_BINS:
        _fail(
            where,
            f"theta_bins × phi_bins: at most {MAX_BINS:,} bins (every task keeps "
            f"several float64 tallies of that size, {8 * nt * npf / 2**20:,.0f} MiB "
            f"each here), got {nt} × {npf} = {nt * npf:,}",
        )
    from microsim.sim import Bins

    try:
        Bins(nt, npf)
    except ValueError as e:
        _fail(where, f"theta_bins/phi_bins: {e}")
    allowed = f"degrees in [0, {sc.MAX_THETA_I:g}] (as in a scene file)"
    thetas = _axis(data.get("theta_i", [0.0, 30.0, 60.0, 80.0]))
    if not thetas:
        _fail(where, f"theta_i: empty; must be one or more {allowed}")
    if not all(
        isinstance(t, (int, float)) and not isinstance(t, bool) and 0 <= t <= sc.MAX_THETA_I
        for t in thetas
    ):
        _fail(where, f"theta_i: must be {allowed}, got {thetas!r}")
    _check_distinct(where, "theta_i", thetas)
    scenes = data.get("scenes")
    if scenes is None:
        _fail(where, "scenes: required; one or more [[scenes]] tables")
    if not isinstance(scenes, list) or not scenes:
        _fail(
            where,
            f"scenes: must be a non-empty array of [[scenes]] tables (empty or "
            f"missing runs nothing), got {scenes!r}",
        )
    grid, n_tasks = [], 0
    for k, entry in enumerate(scenes):
        w = f"{where}: scenes[{k}]"
        if not isinstance(entry, dict) or not isinstance(entry.get("surface"), dict):
            _fail(w, "must be a table with a [scenes.surface] table")
        extra = sorted(set(entry) - {"name", "ior", "surface"})
        if extra:
            _fail(w, f"{extra[0]}: unknown key; allowed keys: name, ior, surface")
        name = _check_name(w, "name", entry.get("name", f"scene{k}"))
        surf = entry["surface"]
        keys = sorted(surf)
        axes = [_axis(surf[key]) for key in keys]
        for key, ax in zip(keys, axes):
            if not ax:
                _fail(w, f"surface.{key}: empty axis; give one or more values")
            _check_distinct(w, f"surface.{key}", ax)
        iors = _axis(entry.get("ior", "aluminium"))
        if not iors:
            _fail(w, "ior: empty axis; give one or more materials")
        _check_distinct(w, "ior", iors)
        n_tasks += math.prod(len(a) for a in axes) * len(iors) * len(thetas)
        if n_tasks > MAX_TASKS:
            _fail(
                w,
                f"the grid has more than {MAX_TASKS:,} tasks (the product of the axis "
                f"lengths); split the sweep",
            )
        for ior in iors:
            _check_ior(w, ior)
        grid.append((name, keys, axes, iors))
    tasks, first_scene, checked = [], {}, set()
    for k, (name, keys, axes, iors) in enumerate(grid):
        w = f"{where}: scenes[{k}]"
        for values in itertools.product(*axes):
            concrete = _resolve_paths(dict(zip(keys, values)), base)
            spec = _scene(name, concrete, None, w).surface
            if spec.kind == "file":
                _check_heightfield_file(w, spec, checked)
            for ior in iors:
                for t in thetas:
                    task = Task(name, concrete, ior, float(t), rays, seed, nt, npf, models, masking)
                    j = first_scene.setdefault(task.id, k)
                    if j != k:
                        _fail(
                            w,
                            f"duplicate of a task of scenes[{j}] ({task_label(task)}); every "
                            f"task must be distinct: remove the repeated scene or rename it",
                        )
                    tasks.append(task)
    return tasks


def _check_distinct(where: str, key: str, values: list) -> None:
    """An axis lists each value once (a repeated value would compute one task twice; 30 and
    30.0 are the same value)."""
    seen = set()
    for v in values:
        if _value_key(v) in seen:
            _fail(where, f"{key}: duplicate value {v!r}; the values of an axis must be distinct")
        seen.add(_value_key(v))


def _value_key(v):
    """A hashable stand-in for a TOML value, equal for equal values (``True`` is not 1)."""
    if isinstance(v, bool):
        return ("bool", v)
    if isinstance(v, list):
        return ("list", *map(_value_key, v))
    if isinstance(v, dict):
        return ("table", *sorted((k, _value_key(x)) for k, x in v.items()))
    return v


def _check_ior(where: str, ior) -> None:
    try:
        sc.material_ior(where, {"ior": ior})
    except ValueError as e:
        raise UsageError(str(e).replace("material.ior", "ior")) from None


def _resolve_paths(surface: dict, base) -> dict:
    """``kind = "file"``: a relative heightfield path made relative to ``base``."""
    if surface.get("kind") == "file" and isinstance(surface.get("path"), str) and base:
        p = Path(surface["path"]).expanduser()
        if not p.is_absolute():
            surface = {**surface, "path": str(Path(base) / p)}
    return surface


def _check_heightfield_file(where: str, spec, checked: set) -> None:
    """The heightfield file of a ``kind = "file"`` surface, read and checked as a scene file's
    (``microsim.app.scene``; an OS error such as permission denied propagates); ``checked`` holds
    the (path, dx, periodic) already checked."""
    key = (spec.params["path"], spec.params["dx"], spec.params["periodic"])
    if key in checked:
        return
    sc.check_heightfield(where, Path(key[0]), key[1], key[2])
    checked.add(key)


def load_sweep(path) -> SweepSpec:
    """Read and validate a sweep file; UsageError (one line) names the file and the key."""
    path = Path(path)
    data = sc.read_toml(path, "sweep")
    where = str(path)
    name = data.get("name", path.stem)
    if "name" in data:
        _check_name(where, "name", name)
    elif not sc.NAME_PATTERN.fullmatch(name):
        _fail(
            where,
            f"name: the file stem {name!r} cannot name the output directory; set "
            f'name = "..." ({_NAME_RULE})',
        )
    description = data.get("description", "")
    if not isinstance(description, str):
        _fail(where, f"description: must be a string, got {description!r}")
    tasks = expand_tasks(data, where, base=path.parent)
    return SweepSpec(name, description, tuple(tasks))


def _scene(name: str, surface: dict, ior, where: str):
    """A ``microsim.app.scene.Scene`` from a concrete [surface] table (validated like a scene
    file)."""
    spec = sc.surface_spec(where, dict(surface))
    mat = None if ior is None else sc.material_ior(where, {"ior": ior})
    return sc.Scene(
        name=name, path=None, description="", surface=spec, ior=mat, simulation=sc.SimSettings()
    )


def _roughness(ndf) -> tuple[str, float | None]:
    """(parameter name, value) of the scene NDF's first parameter, e.g. ("m", 0.3)."""
    if ndf is None:
        return "", None
    params = ndf.params()
    key = next(iter(params))
    return key, float(params[key])


@functools.lru_cache(maxsize=2)
def _task_surface(name: str, surface_json: str, seed: int):
    """The surface of a task, kept for the next tasks of this process on the same surface
    (its materials and incidences follow one another in ``expand_tasks``): ``simulate`` then
    reuses the surface's tracer instead of building the surface and its BVH again."""
    scene = _scene(name, json.loads(surface_json), None, f"task {name}")
    return scene.build_surface(seed=seed)


_WORKER = {"pool": False, "stop": False}  # in a local worker process: interrupted yet?


def _worker_init() -> None:
    """Local worker processes: Ctrl-C between tasks only stops them from starting new ones
    (inside ``simulate`` it makes the simulation return partial, see ``run_task``)."""
    _WORKER.update(pool=True, stop=False)
    signal.signal(signal.SIGINT, lambda signum, frame: _WORKER.update(stop=True))
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # the pool terminates broken workers with it


def run_task(task: Task, out_dir) -> dict:
    """Simulate one task, judge every model, write ``out_dir/tasks/<id>.json`` atomically and
    return the record. An interrupted simulation (``Result.is_partial``, e.g. Ctrl-C) writes
    nothing and returns ``{"id", "partial": True, "rays", "requested"}``."""
    if _WORKER["stop"]:
        return {"id": task.id, "partial": True, "rays": 0, "requested": task.rays}
    from microsim.analysis.verdicts import verdicts_for_result
    from microsim.sim import Bins, simulate
    from microsim.sim.compare import attach_models
    from microsim.sim.predict import ModelSpec

    t0 = time.perf_counter()
    scene = _scene(task.scene, task.surface, task.ior, f"task {task.scene}")
    surface = _task_surface(task.scene, json.dumps(task.surface, sort_keys=True), task.seed)
    bins = Bins(task.theta_bins, task.phi_bins)
    res = simulate(
        surface,
        scene.ior,
        task.theta_i,
        rays=task.rays,
        bins=bins,
        seed=task.seed,
        threads=1,
        masking=task.masking,
    )
    if res.is_partial or int(res.rays[0]) < task.rays:
        _WORKER["stop"] = _WORKER["pool"]  # a pool worker starts no further task
        return {"id": task.id, "partial": True, "rays": int(res.rays[0]), "requested": task.rays}
    ndf = scene.ndf()
    specs = [ModelSpec.torrance_sparrow(f"ts-{g}", ndf, g, scene.ior) for g in task.models]
    verdicts = []
    if ndf is not None:
        judged = attach_models(res, specs + _departure_specs(surface, scene.ior, ndf, specs))
        asked = {s.name for s in specs}
        verdicts = [v for v in verdicts_for_result(judged) if v["model"] in asked]
    key, value = _roughness(ndf)
    record = {
        "id": task.id,
        "task": task.to_dict(),
        "roughness_param": key,
        "roughness": value,
        "rays": int(res.rays[0]),
        "seconds": time.perf_counter() - t0,
        "ledger": {k: float(v[0]) for k, v in res.ledger.items()},
        "verdicts": verdicts,
    }
    path = Path(out_dir) / "tasks" / f"{task.id}.json"
    try:
        atomic.write_json(path, record)
    except OSError as e:
        raise EnvironmentFailure(
            f"{path}: cannot write the task result ({e.strerror or e})"
        ) from None
    return record


def _departure_specs(surface, ior, ndf, specs) -> list:
    """The models ``microsim run`` adds to judge an ensemble model on one tile whose exact
    shadowing is known (V-grooves): the tile's own closed form ``ts-facets`` and the same form
    with the ensemble NDF, whose ratio is the tile's departure from its ensemble
    (``verdicts.tile_departure``); none for other surfaces (their ensemble verdicts on one
    tile stay inconclusive where they reject, as in ``microsim run``)."""
    if surface.exact_shadowing in (None, "none"):
        return []
    from microsim.sim.compare import default_models

    standard = default_models(surface, ior, ndf)
    facets = standard[-1]
    asked = {s.name for s in specs}
    ensemble = [s for s in standard if s.name == facets.params["ensemble"] and s.name not in asked]
    return ensemble + [facets]


_VERDICT_KEYS = (
    "model",
    "rel_rms",
    "chi2_dof",
    "p_value",
    "max_abs_z",
    "agrees",
    "conclusive",
    "tile_departure",
    "n_bins",
)


def _complete(rec, task: Task) -> bool:
    """Is ``rec`` a complete result of ``task`` (its description, every ray, every verdict)?"""
    if not isinstance(rec, dict) or rec.get("id") != task.id or rec.get("partial"):
        return False
    if rec.get("task") != json.loads(json.dumps(task.to_dict())):
        return False
    rays, verdicts = rec.get("rays"), rec.get("verdicts")
    if not _is_int(rays) or rays != task.rays or not isinstance(verdicts, list):
        return False
    if not isinstance(rec.get("seconds"), (int, float)) or "roughness" not in rec:
        return False
    return all(isinstance(v, dict) and all(k in v for k in _VERDICT_KEYS) for v in verdicts)


_NOT_REGULAR = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
)


def _refuse_non_regular(path: Path, mode: int) -> None:
    """UsageError naming ``path`` unless ``mode`` is a regular file's."""
    if not stat.S_ISREG(mode):
        kind = next((what for test, what in _NOT_REGULAR if test(mode)), "not a regular file")
        _fail(
            str(path),
            f"is {kind}, not a task result (a JSON file written by the sweep); "
            f"remove it and rerun the sweep",
        )


def _load(task: Task, out: Path) -> dict | None:
    """The complete record of ``task`` in ``out``, or None (missing, unreadable, truncated,
    partial, or another task's). Anything but a regular file there (a FIFO, a directory) is
    a UsageError naming it, and never opened for reading."""
    path = Path(out) / "tasks" / f"{task.id}.json"
    try:
        _refuse_non_regular(path, os.stat(path).st_mode)
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError:
        return None
    with open(fd, encoding="utf-8") as fh:
        _refuse_non_regular(path, os.fstat(fd).st_mode)
        try:
            rec = json.load(fh)
        except (OSError, ValueError):
            return None
    return rec if _complete(rec, task) else None


def _done(task: Task, out_dir: Path) -> bool:
    """Is a complete, readable result of ``task`` on disk?"""
    return _load(task, out_dir) is not None


def _fmt_num(x) -> str:
    return f"{x:.12g}" if isinstance(x, float) else str(x)


def material_text(ior) -> str:
    """A material as plain text: a name as is, ``1.5``, or ``n+ki`` for ``[n, k]``."""
    if isinstance(ior, (list, tuple)) and len(ior) == 2:
        return f"{_fmt_num(ior[0])}+{_fmt_num(ior[1])}i"
    return _fmt_num(ior)


def _varying(tasks) -> dict:
    """scene → the [surface] keys whose value differs between that scene's tasks."""
    seen: dict = {}
    for t in tasks:
        for k, v in t.surface.items():
            seen.setdefault(t.scene, {}).setdefault(k, set()).add(json.dumps(v))
    return {s: {k for k, vals in d.items() if len(vals) > 1} for s, d in seen.items()}


def task_label(task: Task, varying=None) -> str:
    """Readable task description, e.g. "vg m=0.3, aluminium, θi=30°": the scene, its surface
    parameters (only the ``varying`` ones if given), the material and the incidence."""
    keys = sorted(k for k in task.surface if k != "kind" and (varying is None or k in varying))
    params = " ".join(f"{k}={_fmt_num(task.surface[k])}" for k in keys)
    return (
        f"{task.scene}{' ' + params if params else ''}, {material_text(task.ior)}, "
        f"θi={task.theta_i:g}°"
    )


def _check_out(out: Path) -> None:
    """Refuse, before anything runs or is written, an output path that cannot work."""
    try:
        if out.exists() and not out.is_dir():
            _fail(str(out), "exists and is not a directory; --out must be a directory")
        anc = out
        while not anc.exists() and anc != anc.parent:
            anc = anc.parent
        if not anc.is_dir():
            _fail(str(out), f"{anc} is a file, not a directory")
        tasks = out / "tasks"
        if tasks.exists() and not tasks.is_dir():
            _fail(str(out), f"{tasks} exists and is not a directory")
        if out.is_dir() and not tasks.is_dir() and any(out.iterdir()):
            _fail(
                str(out),
                "not empty and not a sweep output (no tasks/ folder); choose a new "
                "or empty --out directory",
            )
    except OSError as e:
        _fail(str(out), f"unusable output path ({e.strerror or e})")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise EnvironmentFailure(
            f"{out}: {anc} is not writable (permission denied or a read-only file system)"
        )


@contextmanager
def _sigterm_interrupts():
    """While active (main thread, SIGTERM not ignored), SIGTERM raises KeyboardInterrupt as
    Ctrl-C does, so the sweep stops its workers before it exits; yields {"signal": the
    signal that interrupted, SIGINT unless a SIGTERM arrived}."""
    received = {"signal": signal.SIGINT}

    def terminate(signum, frame):
        received["signal"] = signum
        raise KeyboardInterrupt

    main = threading.current_thread() is threading.main_thread()
    old = signal.getsignal(signal.SIGTERM) if main else None
    if old is not signal.SIG_DFL:
        yield received
        return
    signal.signal(signal.SIGTERM, terminate)
    try:
        yield received
    finally:
        signal.signal(signal.SIGTERM, old)


def _client(scheduler, timeout: float):
    """A ``dask.distributed.Client``; one-line errors for a bad or unreachable address."""
    try:
        from dask.distributed import Client
    except ImportError:
        raise EnvironmentFailure(
            "--scheduler needs dask.distributed, an optional extra: pip install 'microsim[cluster]'"
        ) from None
    try:
        return Client(scheduler, timeout=timeout)
    except ValueError as e:
        _fail(f"--scheduler {scheduler}", f"not a Dask scheduler address ({e})")
    except (OSError, TimeoutError) as e:
        raise EnvironmentFailure(
            f"--scheduler {scheduler}: no Dask scheduler reachable "
            f"there within {timeout:g} s ({' '.join(str(e).split())})"
        ) from None


def _local(todo, out: Path, workers: int, collect, notice: Callable[[str], None]) -> None:
    """Run ``todo`` in local worker processes; ``collect(record)`` for each finished one.

    A worker process that dies (SIGKILL, the out-of-memory killer) breaks the pool: the tasks
    without a complete result then run again in a fresh pool (``notice`` says so); when two
    pools in a row break before any task finishes, ``BrokenProcessPool`` is raised."""
    fruitless = 0
    while todo:
        finished = set()

        def note(rec: dict) -> None:
            collect(rec)
            finished.add(rec["id"])

        try:
            _local_pool(todo, out, workers, note)
            return
        except BrokenProcessPool:
            pass
        rest = []
        for task in todo:
            if task.id in finished:
                continue
            rec = _load(task, out)
            if rec is None:
                rest.append(task)
            else:  # written just before the pool broke
                note(rec)
        fruitless = 0 if finished else fruitless + 1
        if fruitless == 2:
            raise BrokenProcessPool("worker processes died twice in a row")
        notice(f"a worker process died; running its {len(rest)} unfinished tasks again")
        todo = rest


def _local_pool(todo, out: Path, workers: int, collect) -> None:
    """One process pool for ``todo`` (``_local``). On any exception (Ctrl-C included) the
    queued tasks are cancelled, the running ones asked to stop (SIGINT: their simulation
    returns partial and writes nothing), and the exception re-raised once they have; a second
    Ctrl-C kills them."""
    pool = ProcessPoolExecutor(max_workers=min(int(workers), len(todo)), initializer=_worker_init)
    futures = []
    try:
        futures = [pool.submit(run_task, t, str(out)) for t in todo]
        for fut in as_completed(futures):
            collect(fut.result())
    except BaseException:
        for f in futures:
            f.cancel()
        for proc in list((getattr(pool, "_processes", None) or {}).values()):
            if proc.is_alive():  # never a pid the pool has already reaped
                try:
                    os.kill(proc.pid, signal.SIGINT)
                except OSError:
                    pass
        try:
            pool.shutdown(wait=True, cancel_futures=True)
        except KeyboardInterrupt:
            for p in list((getattr(pool, "_processes", None) or {}).values()):
                p.kill()
            pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def _dask(todo, out: Path, client, collect) -> None:
    from dask.distributed import as_completed as dask_completed

    futures = [
        client.submit(run_task, t, str(out), key=f"microsim-{t.id}", pure=False) for t in todo
    ]
    try:
        for fut in dask_completed(futures):
            collect(fut.result())
    except BaseException:
        client.cancel(futures)  # tasks already running finish and store complete results
        raise


def run_sweep(
    spec: SweepSpec,
    out,
    *,
    scheduler=None,
    workers: int = 2,
    limit: int | None = None,
    progress: Callable[[str], None] | None = None,
    connect_timeout: float = 10.0,
) -> dict:
    """Run the tasks of ``spec`` that have no complete result in ``out`` yet, then
    ``write_summary``.

    ``scheduler``: None (local processes, ``workers`` of them) or a Dask scheduler address
    (anything ``dask.distributed.Client`` accepts, e.g. "tcp://host:8786" or a LocalCluster),
    reached within ``connect_timeout`` seconds or EnvironmentFailure. ``limit``: run at most
    this many of the missing tasks, then summarise what is done. ``progress``: receives one
    line per finished task ("k/N done: <scene params, material, θi> (s)"), and one at the start.
    Ctrl-C or SIGTERM: raises ``SweepInterrupted`` (the workers stopped, finished tasks
    kept, no summary written). Local worker processes that die: their tasks run again
    (``_local``), or EnvironmentFailure. Returns {"computed": [ids], "skipped": [ids],
    "summary": paths}.
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        _fail("--workers", f"must be an integer >= 1, got {workers!r}")
    if not (isinstance(connect_timeout, (int, float)) and 0 < connect_timeout <= 3600):
        _fail("--scheduler-timeout", f"must be seconds in (0, 3600], got {connect_timeout!r}")
    out = Path(out).absolute()
    _check_out(out)
    with ExitStack() as stack:
        received = stack.enter_context(_sigterm_interrupts())
        client = None
        if scheduler is not None:
            client = stack.enter_context(_client(scheduler, float(connect_timeout)))
        try:
            (out / "tasks").mkdir(parents=True, exist_ok=True)
            stack.enter_context(atomic.output_lock(out, out / LOCK_FILE, holder="sweep"))
        except OSError as e:
            raise EnvironmentFailure(
                f"{out}: cannot create the sweep output ({e.strerror or e})"
            ) from None
        for d in (out, out / "tasks"):  # left by interrupted writes of earlier sweeps
            atomic.clean_temp_files(d)
        todo = [t for t in spec.tasks if not _done(t, out)]
        skipped = [t.id for t in spec.tasks if t not in todo]
        if limit is not None:
            todo = todo[: int(limit)]
        varying = _varying(spec.tasks)
        total, computed = len(spec.tasks), []
        by_id = {t.id: t for t in todo}
        if progress and todo:
            where = (
                f"{len(by_id)} on {min(workers, len(todo))} local workers"
                if client is None
                else f"{len(by_id)} on the Dask cluster"
            )
            progress(
                f"sweep {spec.name}: {total} tasks, {len(skipped)} already done, running {where}"
            )

        def collect(rec: dict) -> None:
            if rec.get("partial"):  # a worker was interrupted
                raise KeyboardInterrupt
            computed.append(rec["id"])
            if progress:
                progress(
                    f"sweep {spec.name}: {len(skipped) + len(computed)}/{total} done: "
                    f"{task_label(by_id[rec['id']], varying.get(rec['task']['scene']))} "
                    f"({rec['seconds']:.1f} s)"
                )
            checkpoint("sweep-task")

        def done() -> int:
            return sum(_done(t, out) for t in spec.tasks)

        try:
            if todo and client is None:
                _local(todo, out, workers, collect, progress or (lambda line: None))
            elif todo:
                _dask(todo, out, client, collect)
            paths = write_summary(spec, out)
        except KeyboardInterrupt:
            raise SweepInterrupted(out, done(), total, received["signal"]) from None
        except BrokenProcessPool:
            raise EnvironmentFailure(
                f"{out}: sweep worker processes died twice in a row before finishing a task "
                f"(killed, e.g. by the out-of-memory killer); {done()}/{total} tasks done and "
                f"kept in {out / 'tasks'}, summary not written; rerun the same command to "
                f"compute the rest"
            ) from None
    return {"computed": computed, "skipped": skipped, "summary": paths}


def gather(spec: SweepSpec, out) -> list[dict]:
    """Complete task records of ``spec`` in ``out``, in task order (missing, unreadable and
    partial ones left out)."""
    return [r for r in (_load(t, Path(out)) for t in spec.tasks) if r is not None]


def _params_text(surface: dict) -> str:
    return " ".join(f"{k}={_fmt_num(v)}" for k, v in sorted(surface.items()) if k != "kind")


def summary_table(records: list[dict]) -> list[dict]:
    """One row per (task, model) with the ``COLUMNS`` fields (``material`` plain text;
    ``verdict`` worded by ``verdicts.verdict_kind``, the rule of every microsim output)."""
    from microsim.analysis.verdicts import verdict_kind

    rows = []
    for r in records:
        t = r["task"]
        for v in r["verdicts"]:
            rows.append(
                {
                    "task": r["id"],
                    "scene": t["scene"],
                    "params": _params_text(t["surface"]),
                    "material": material_text(t["ior"]),
                    "roughness": r["roughness"],
                    "theta_i": t["theta_i"],
                    "model": v["model"],
                    "rel_rms": v["rel_rms"],
                    "chi2_dof": v["chi2_dof"],
                    "p_value": v["p_value"],
                    "max_abs_z": v["max_abs_z"],
                    "verdict": verdict_kind(v),
                    "tile_departure": v["tile_departure"],
                    "n_bins": v["n_bins"],
                    "rays": r["rays"],
                    "seconds": round(r["seconds"], 3),
                }
            )
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
    the complete task JSONs present; returns their paths."""
    out = Path(out)
    try:
        return _write_summary(spec, out)
    except OSError as e:
        raise EnvironmentFailure(
            f"{e.filename or out}: cannot write the sweep summary ({e.strerror or e})"
        ) from None


def _write_summary(spec: SweepSpec, out: Path) -> dict:
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
        "error of the model over the bins carrying 90 % of the energy; chi2_dof, p_value, "
        "max_abs_z: see microsim.analysis.verdicts. verdict: agrees, deviates, or "
        "inconclusive (the model describes the surface's ensemble, one tile was traced, and "
        "its deviation is within what the tile's own departure from the ensemble, "
        "tile_departure, and ray noise explain — or that departure is not computable), "
        "judged as microsim run judges it.",
        "",
        "| " + " | ".join(cols) + " |",
        "|" + "---|" * len(cols),
    ]
    md += ["| " + " | ".join(_fmt(r[c]) for c in cols) + " |" for r in rows]
    atomic.write_text(out / "summary.md", "\n".join(md) + "\n")
    chart = out / "error_vs_roughness.png"
    _chart(rows, chart, spec.name)
    return {
        "csv": str(out / "summary.csv"),
        "markdown": str(out / "summary.md"),
        "chart": str(chart),
    }


def _chart(rows: list[dict], path: Path, title: str) -> None:
    """Model relative RMS error against roughness: colour = θi, line style = model, marker =
    scene and material (one line per combination); a hollow marker is an inconclusive
    verdict (its error is within what the one tile's departure from its ensemble may
    explain), a filled one a conclusive verdict."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    groups: dict = {}
    for r in rows:
        if r["roughness"] is None or r["rel_rms"] is None:
            continue
        key = (r["scene"], r["material"], r["model"], r["theta_i"])
        groups.setdefault(key, []).append(
            (r["roughness"], r["rel_rms"], r["verdict"] == "inconclusive")
        )
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
    ax.set_xlabel("roughness (first NDF parameter)")
    ax.set_ylabel("relative RMS error (90 % energy bins)")
    ax.set_yscale("log")
    ax.set_title(
        f"sweep {title}: model error against roughness and angle\n"
        "filled marker: conclusive verdict; hollow: inconclusive (one tile)",
        fontsize=9,
    )
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
    try:
        res = run_sweep(
            spec,
            out,
            scheduler=args.scheduler,
            workers=args.workers,
            progress=lambda s: print(s, file=sys.stderr, flush=True),
            connect_timeout=args.scheduler_timeout,
        )
    except SweepInterrupted as e:
        how = "interrupted" if e.signum == signal.SIGINT else "terminated"
        print(
            f"microsim: {how}: {e.done}/{e.total} tasks done and kept in "
            f"{os.path.join(out, 'tasks')}, summary not written; rerun the same command "
            f"(microsim sweep {args.sweep}{' --out ' + args.out if args.out else ''}) "
            f"to compute the rest",
            file=sys.stderr,
        )
        return 128 + e.signum
    print(
        f"{len(res['computed'])} tasks computed, {len(res['skipped'])} already done; "
        f"{res['summary']['markdown']}, {res['summary']['csv']}, {res['summary']['chart']}"
    )
    return 0


def add_sweep_command(subparsers) -> None:
    """Register ``microsim sweep SWEEP.toml [--scheduler ADDRESS] [--scheduler-timeout S]
    [--out DIR] [--workers N]``."""
    p = subparsers.add_parser(
        "sweep",
        help="run a grid of scenes x parameters x incidences "
        "and gather the verdicts into one table and chart",
    )
    p.add_argument("sweep", help="sweep file (TOML), e.g. sweeps/vgroove-roughness.toml")
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="Dask distributed scheduler address (default: local worker processes)",
    )
    p.add_argument(
        "--scheduler-timeout",
        type=float,
        default=10.0,
        metavar="SECONDS",
        help="give up connecting to --scheduler after this long (default 10)",
    )
    p.add_argument("--out", help="output directory (default sweeps/out/<name>)")
    p.add_argument("--workers", type=int, default=2, help="local worker processes (default 2)")
    p.set_defaults(func=_cmd_sweep)
