"""The sweep file and its grid: ``load_sweep`` reads and validates a sweep file (format in
``microsim.app.sweep``), ``expand_tasks`` expands scenes × parameters × materials × incidences
into frozen ``Task``s, ``task_label`` names a task by its varying values."""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

from microsim.bins import MAX_BINS, Bins  # MAX_BINS: theta_bins × phi_bins at most

from ...errors import UsageError
from ...sim.arguments import MAX_RAYS
from ...sim.identity import RunDescription
from .. import scene as sc

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
ORIENTED_SHADOWING = "vgroove"
"""The one shadowing of ``models`` with a form for oriented V-grooves (``oriented = true``):
they have no ensemble NDF, and ``microsim run`` judges them by ``ts-vgroove-oriented``, the
grooves' own V-groove shadowing over their continuum of tilts (``task.judged_models``)."""
MAX_TASKS = 100_000  # tasks per sweep file (each is seconds to minutes of tracing)
_NAME_RULE = "1-100 characters from letters, digits, '.', '_', '-', not starting with '.'"


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
        """Stable id: the scene's name + the key of the task's run (``run``) and the models
        that judge it."""
        return f"{self.scene}-{self.run().key({'models': list(self.models)})[:12]}"

    def run(self) -> RunDescription:
        """The run the task traces (``microsim.sim.identity``): its surface by the scene's
        name and [surface] table, one incidence at φi = 0, one realisation."""
        return RunDescription(
            material=sc.material_ior(self.scene, {"ior": self.ior}),
            theta_i=(self.theta_i,),
            phi_i=(0.0,),
            bins=Bins(self.theta_bins, self.phi_bins),
            rays=self.rays,
            seed=self.seed,
            surfaces={"scene": self.scene, "surface": self.surface},
            masking=self.masking,
        )

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
    """A loaded sweep file: its name and the expanded task list; ``path`` the file read
    (None for a spec built in code)."""

    name: str
    description: str
    tasks: tuple
    path: Path | None = None


def fail(where: str, msg: str):
    raise UsageError(f"{where}: {msg}")


def _axis(v) -> list:
    """A grid axis: lists are axes, anything else a single value. ``[n, k]`` pairs of a
    complex index must be written as ``[[n, k]]`` when they are an axis of one value."""
    return list(v) if isinstance(v, list) else [v]


def is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _check_name(where: str, key: str, name) -> str:
    """A name used as a path component (task files, default output directory)."""
    if not isinstance(name, str) or not sc.NAME_PATTERN.fullmatch(name):
        fail(where, f"{key}: must be {_NAME_RULE}, got {name!r}")
    return name


def is_oriented(surface: dict) -> bool:
    """Whether a concrete [surface] table is of oriented V-grooves."""
    return surface.get("kind") == "vgrooves" and surface.get("oriented") is True


def expand_tasks(data: dict, where: str = "sweep", base=None) -> list[Task]:
    """Tasks of a parsed sweep table (module docstring), in grid order. ``base``: directory
    that relative heightfield ``path``s of ``kind = "file"`` surfaces are relative to (the
    sweep file's; default the working directory). Every value is checked before any task
    exists; UsageError names ``where`` and the key."""
    if not isinstance(data, dict):
        fail(where, "must be a table of sweep settings")
    extra = sorted(set(data) - set(_TOP))
    if extra:
        fail(where, f"{extra[0]}: unknown key; allowed keys: {', '.join(_TOP)}")
    shared = _shared_settings(data, where)
    grid = _scene_grid(data.get("scenes"), len(shared.thetas), where)
    tasks, first_scene, checked = [], {}, set()
    for k, (name, keys, axes, iors) in enumerate(grid):
        w = f"{where}: scenes[{k}]"
        for values in itertools.product(*axes):
            concrete = _resolve_paths(dict(zip(keys, values)), base)
            _check_surface(w, name, concrete, shared.models, checked)
            for ior in iors:
                for t in shared.thetas:
                    task = shared.task(name, concrete, ior, t)
                    j = first_scene.setdefault(task.id, k)
                    if j != k:
                        fail(
                            w,
                            f"duplicate of a task of scenes[{j}] ({task_label(task)}); every "
                            f"task must be distinct: remove the repeated scene or rename it",
                        )
                    tasks.append(task)
    return tasks


@dataclass(frozen=True)
class _Shared:
    """The settings every task of a sweep shares, and its θi axis ``thetas``."""

    rays: int
    seed: int
    theta_bins: int
    phi_bins: int
    models: tuple
    masking: str
    thetas: list

    def task(self, scene: str, surface: dict, ior, theta_i: float) -> Task:
        return Task(
            scene, surface, ior, float(theta_i), self.rays, self.seed, self.theta_bins,
            self.phi_bins, self.models, self.masking,
        )  # fmt: skip


def _shared_settings(data: dict, where: str) -> _Shared:
    """The sweep's rays, seed, models, masking, bins and θi axis, each checked."""
    rays, seed = data.get("rays", 200_000), data.get("seed", 0)
    if not is_int(rays) or not 1 <= rays <= MAX_RAYS:
        fail(where, f"rays: must be an integer in [1, {MAX_RAYS:,}] (per task), got {rays!r}")
    if not is_int(seed) or seed < 0:
        fail(where, f"seed: must be an integer >= 0, got {seed!r}")
    models = tuple(_axis(data.get("models", ["vgroove", "smith"])))
    bad = [m for m in models if not isinstance(m, str) or m not in _SHADOWING]
    if not models:
        fail(where, f"models: empty; must be a non-empty list of {', '.join(_SHADOWING)}")
    if bad or len(set(models)) != len(models):
        fail(
            where,
            f"models: must be a list of distinct {', '.join(_SHADOWING)}, got {list(models)!r}",
        )
    masking = data.get("masking", "traced")
    if masking not in ("traced", "exact"):
        fail(where, f"masking: must be traced or exact, got {masking!r}")
    nt, npf = data.get("theta_bins", 45), data.get("phi_bins", 37)
    _check_bins(where, nt, npf)
    return _Shared(rays, seed, nt, npf, models, masking, _thetas(data, where))


def _check_bins(where: str, nt, npf) -> None:
    """theta_bins and phi_bins: integers >= 2, at most ``MAX_BINS`` bins, a valid grid."""
    for key, v in (("theta_bins", nt), ("phi_bins", npf)):
        if not is_int(v) or v < 2:
            fail(where, f"{key}: must be an integer >= 2, got {v!r}")
    if nt * npf > MAX_BINS:
        fail(
            where,
            f"theta_bins × phi_bins: at most {MAX_BINS:,} bins (every task keeps "
            f"several float64 tallies of that size, {8 * nt * npf / 2**20:,.0f} MiB "
            f"each here), got {nt} × {npf} = {nt * npf:,}",
        )
    try:
        Bins(nt, npf)
    except ValueError as e:
        fail(where, f"theta_bins/phi_bins: {e}")


def _thetas(data: dict, where: str) -> list:
    """The θi axis: distinct degrees in [0, ``scene.MAX_THETA_I``]."""
    allowed = f"degrees in [0, {sc.MAX_THETA_I:g}] (as in a scene file)"
    thetas = _axis(data.get("theta_i", [0.0, 30.0, 60.0, 80.0]))
    if not thetas:
        fail(where, f"theta_i: empty; must be one or more {allowed}")
    if not all(
        isinstance(t, (int, float)) and not isinstance(t, bool) and 0 <= t <= sc.MAX_THETA_I
        for t in thetas
    ):
        fail(where, f"theta_i: must be {allowed}, got {thetas!r}")
    _check_distinct(where, "theta_i", thetas)
    return thetas


def _scene_grid(scenes, n_thetas: int, where: str) -> list:
    """(name, surface keys, their axes, materials) of each [[scenes]] table, checked; at most
    ``MAX_TASKS`` tasks in all."""
    if scenes is None:
        fail(where, "scenes: required; one or more [[scenes]] tables")
    if not isinstance(scenes, list) or not scenes:
        fail(
            where,
            f"scenes: must be a non-empty array of [[scenes]] tables (empty or "
            f"missing runs nothing), got {scenes!r}",
        )
    grid, n_tasks = [], 0
    for k, entry in enumerate(scenes):
        w = f"{where}: scenes[{k}]"
        if not isinstance(entry, dict) or not isinstance(entry.get("surface"), dict):
            fail(w, "must be a table with a [scenes.surface] table")
        extra = sorted(set(entry) - {"name", "ior", "surface"})
        if extra:
            fail(w, f"{extra[0]}: unknown key; allowed keys: name, ior, surface")
        name = _check_name(w, "name", entry.get("name", f"scene{k}"))
        surf = entry["surface"]
        keys = sorted(surf)
        axes = [_axis(surf[key]) for key in keys]
        for key, ax in zip(keys, axes):
            if not ax:
                fail(w, f"surface.{key}: empty axis; give one or more values")
            _check_distinct(w, f"surface.{key}", ax)
        iors = _axis(entry.get("ior", "aluminium"))
        if not iors:
            fail(w, "ior: empty axis; give one or more materials")
        _check_distinct(w, "ior", iors)
        n_tasks += math.prod(len(a) for a in axes) * len(iors) * n_thetas
        if n_tasks > MAX_TASKS:
            fail(
                w,
                f"the grid has more than {MAX_TASKS:,} tasks (the product of the axis "
                f"lengths); split the sweep",
            )
        for ior in iors:
            _check_ior(w, ior)
        grid.append((name, keys, axes, iors))
    return grid


def _check_surface(where: str, name: str, concrete: dict, models, checked: set) -> None:
    """A concrete [surface] table: valid as a scene's, its heightfield file readable, and
    oriented V-grooves judged by the V-groove model."""
    spec = scene_from_table(name, concrete, None, where).surface
    if spec.kind == "file":
        _check_heightfield_file(where, spec, checked)
    if is_oriented(concrete) and ORIENTED_SHADOWING not in models:
        fail(
            where,
            f"surface.oriented: oriented V-grooves have no ensemble NDF and are judged "
            f"by the V-groove model alone (ts-vgroove-oriented, as microsim run judges "
            f'them); models must include "{ORIENTED_SHADOWING}", got {list(models)!r}',
        )


def _check_distinct(where: str, key: str, values: list) -> None:
    """An axis lists each value once (a repeated value would compute one task twice; 30 and
    30.0 are the same value)."""
    seen = set()
    for v in values:
        if _value_key(v) in seen:
            fail(where, f"{key}: duplicate value {v!r}; the values of an axis must be distinct")
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
    the (path, dx, periodic, form) already checked."""
    key = (spec.path, spec.dx, spec.periodic, spec.form)
    if key in checked:
        return
    sc.check_heightfield(where, Path(spec.path), spec)
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
        fail(
            where,
            f"name: the file stem {name!r} cannot name the output directory; set "
            f'name = "..." ({_NAME_RULE})',
        )
    description = data.get("description", "")
    if not isinstance(description, str):
        fail(where, f"description: must be a string, got {description!r}")
    tasks = expand_tasks(data, where, base=path.parent)
    return SweepSpec(name, description, tuple(tasks), path)


def fmt_num(x) -> str:
    return f"{x:.12g}" if isinstance(x, float) else str(x)


def material_text(ior) -> str:
    """A material as plain text: a name as is, ``1.5``, or ``n+ki`` for ``[n, k]``."""
    if isinstance(ior, (list, tuple)) and len(ior) == 2:
        return f"{fmt_num(ior[0])}+{fmt_num(ior[1])}i"
    return fmt_num(ior)


def varying_values(tasks) -> dict:
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
    params = " ".join(f"{k}={fmt_num(task.surface[k])}" for k in keys)
    return (
        f"{task.scene}{' ' + params if params else ''}, {material_text(task.ior)}, "
        f"θi={task.theta_i:g}°"
    )


def scene_from_table(name: str, surface: dict, ior, where: str):
    """A ``microsim.app.scene.Scene`` from a concrete [surface] table (validated like a scene
    file)."""
    spec = sc.surface_spec(where, dict(surface))
    mat = None if ior is None else sc.material_ior(where, {"ior": ior})
    return sc.Scene(
        name=name, path=None, description="", surface=spec, ior=mat, simulation=sc.SimSettings()
    )


def with_effort(spec: SweepSpec, rays: int | None = None, quick: bool = False) -> SweepSpec:
    """``spec`` with every task's rays set to ``rays`` (``--rays``), and with ``quick``
    (``--quick``) the effort of ``microsim run --quick`` (``runner.planning.QUICK``): at most
    its rays per incidence unless ``rays`` is given, and at most its bins. Tasks changed this
    way get new ids (a quick result never stands in for a full one)."""
    from ..runner.planning import QUICK

    changes = []
    for t in spec.tasks:
        new = {}
        if rays is not None:
            new["rays"] = int(rays)
        elif quick:
            new["rays"] = min(t.rays, QUICK.max_rays)
        if quick:
            nt, nphi = QUICK.max_bins
            new["theta_bins"], new["phi_bins"] = min(t.theta_bins, nt), min(t.phi_bins, nphi)
        changes.append(replace(t, **new) if new else t)
    return replace(spec, tasks=tuple(changes))
