"""One task: ``run_task`` simulates it and judges every model as ``microsim run`` judges its
scene (``judged_models`` names them), writing ``OUT/tasks/<id>.json`` atomically; ``is_done``
and ``load_result`` tell a complete result of that very task from a missing, damaged or
partial one."""

from __future__ import annotations

import functools
import json
import math
import multiprocessing
import os
import signal
import stat
import threading
import time
from pathlib import Path

from ... import atomic
from ...errors import EnvironmentFailure
from ...sim.compare import ORIENTED_MODEL
from ..scene import RANDOM_KINDS
from .grid import ORIENTED_SHADOWING, Task, fail, is_int, is_oriented, scene_from_table


def _roughness(ndf) -> tuple[str, float | None]:
    """(parameter name, value) of the scene NDF's first parameter, e.g. ("m", 0.3)."""
    if ndf is None:
        return "", None
    params = ndf.params()
    key = next(iter(params))
    return key, float(params[key])


def judged_models(task: Task) -> tuple[str, ...]:
    """Names of the models ``task`` is judged by, one verdict each, as ``microsim run`` judges
    the scene: Torrance–Sparrow with the surface's ensemble NDF and each shadowing of
    ``task.models`` ("ts-vgroove", "ts-smith", …); on oriented V-grooves, which have no
    ensemble NDF, run's ``ts-vgroove-oriented`` (the grooves' own V-groove shadowing over
    their continuum of tilts) for "vgroove", the one shadowing with an oriented form; none on
    a surface that is no ensemble's draw (flat, file)."""
    if task.surface.get("kind") not in RANDOM_KINDS:
        return ()
    if is_oriented(task.surface):
        return (ORIENTED_MODEL,) if ORIENTED_SHADOWING in task.models else ()
    return tuple(f"ts-{g}" for g in task.models)


def _models(task: Task, scene, surface, ndf) -> tuple[list, list]:
    """(``judged_models``' specs, the models giving the tile's departure from its ensemble
    that are not among them, ``compare.departure_models``); ``ndf``: the scene's."""
    from microsim.analytic.models import TorranceSparrow
    from microsim.sim.compare import departure_models
    from microsim.sim.predict import Predictor

    pair = departure_models(surface, scene.ior, ndf) if judged_models(task) else []
    if ndf is None:  # oriented V-grooves: the judged model is the pair's ensemble form
        specs = [s for s in pair if s.name in judged_models(task)]
    else:
        specs = [Predictor(f"ts-{g}", TorranceSparrow(ndf, g, scene.ior)) for g in task.models]
    asked = {s.name for s in specs}
    return specs, [s for s in pair if s.name not in asked]


@functools.lru_cache(maxsize=2)
def _task_surface(name: str, surface_json: str, seed: int):
    """The surface of a task, kept for the next tasks of this process on the same surface
    (its materials and incidences follow one another in ``expand_tasks``): ``simulate`` then
    reuses the surface's tracer instead of building the surface and its BVH again."""
    scene = scene_from_table(name, json.loads(surface_json), None, f"task {name}")
    return scene.build_surface(seed=seed)


_WORKER = {"pool": False, "stop": False}  # in a local worker process: interrupted yet?


def worker_init() -> None:
    """Local worker processes: Ctrl-C between tasks only stops them from starting new ones
    (inside ``simulate`` it makes the simulation return partial, see ``run_task``); a worker
    whose sweep process is gone (SIGKILL, the out-of-memory killer) exits instead of waiting
    for tasks that will never come."""
    _WORKER.update(pool=True, stop=False)
    signal.signal(signal.SIGINT, lambda signum, frame: _WORKER.update(stop=True))
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # the pool terminates broken workers with it
    parent = multiprocessing.parent_process()
    if parent is not None:
        threading.Thread(
            target=_exit_after, args=(parent,), name="exit-with-sweep", daemon=True
        ).start()


def _exit_after(parent) -> None:
    """Wait for the sweep process ``parent`` to end, then end this worker at once."""
    parent.join()
    os._exit(1)


def run_task(task: Task, out_dir) -> dict:
    """Simulate one task, judge every model, write ``out_dir/tasks/<id>.json`` atomically and
    return the record. An interrupted simulation (``Result.is_partial``, e.g. Ctrl-C) writes
    nothing and returns ``{"id", "partial": True, "rays", "requested"}``."""
    if _WORKER["stop"]:
        return {"id": task.id, "partial": True, "rays": 0, "requested": task.rays}
    from microsim.analysis.verdicts import verdicts_for_result
    from microsim.sim import Bins, simulate
    from microsim.sim.auto import relative_standard_error
    from microsim.sim.compare import attach_models

    t0 = time.perf_counter()
    scene = scene_from_table(task.scene, task.surface, task.ior, f"task {task.scene}")
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
    specs, pair = _models(task, scene, surface, ndf)
    verdicts = []
    if specs:  # as microsim run: on V-grooves, with the tile's departure from its ensemble
        judged = attach_models(res, specs + pair)
        asked = {s.name for s in specs}
        verdicts = [v for v in verdicts_for_result(judged) if v["model"] in asked]
    key, value = _roughness(ndf if ndf is not None else surface.tilt_ndf)
    floor = relative_standard_error(
        res.brdf[0], res.stderr[0], res.counts[0], bins.projected_solid_angle()
    )
    record = {
        "id": task.id,
        "task": task.to_dict(),
        "roughness_param": key,
        "roughness": value,
        "rays": int(res.rays[0]),
        "seconds": time.perf_counter() - t0,
        "ledger": {k: float(v[0]) for k, v in res.ledger.items()},
        "verdicts": verdicts,
        "noise_floor": floor if math.isfinite(floor) else None,
    }
    path = Path(out_dir) / "tasks" / f"{task.id}.json"
    try:
        atomic.write_json(path, record)
    except OSError as e:
        raise EnvironmentFailure(
            f"{path}: cannot write the task result ({e.strerror or e})"
        ) from None
    return record


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
    """Is ``rec`` a complete result of ``task`` (its description, every ray, one verdict of
    each model it is judged by)?"""
    if not isinstance(rec, dict) or rec.get("id") != task.id or rec.get("partial"):
        return False
    if rec.get("task") != json.loads(json.dumps(task.to_dict())):
        return False
    rays, verdicts = rec.get("rays"), rec.get("verdicts")
    if not is_int(rays) or rays != task.rays or not isinstance(verdicts, list):
        return False
    if not isinstance(rec.get("seconds"), (int, float)) or "roughness" not in rec:
        return False
    if not all(isinstance(v, dict) and all(k in v for k in _VERDICT_KEYS) for v in verdicts):
        return False
    return sorted(v["model"] for v in verdicts) == sorted(judged_models(task))


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
        fail(
            str(path),
            f"is {kind}, not a task result (a JSON file written by the sweep); "
            f"remove it and rerun the sweep",
        )


def load_result(task: Task, out: Path) -> dict | None:
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


def is_done(task: Task, out_dir: Path) -> bool:
    """Is a complete, readable result of ``task`` on disk?"""
    return load_result(task, out_dir) is not None
