"""Planning a run: what it spends (``Effort``, ``FULL``, ``QUICK``) and ``plan_run``, which
validates every option and path before anything is written (each problem a one-line
``UsageError``), including the checks that a saved run may be resumed or an output replaced.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

from ...analysis.budget import AUTO_TARGET as REALISATION_TARGET
from ...analysis.budget import MAX_AUTO, MIN_AUTO
from ...atomic import json_safe
from ...checks import file_path
from ...errors import UsageError
from ...sim import Bins, Result
from ...sim.identity import RunDescription, saved_identity
from ..cluster import check_address
from ..scene import incidence_pairs, load_scene
from .wave_run import check_wave_plan

__all__ = [
    "AUTO_TARGET",
    "AUTO_MAX_RAYS",
    "Effort",
    "FULL",
    "QUICK",
    "effort_for",
    "RunPlan",
    "plan_run",
    "check_replaceable",
    "check_output_path",
    "tally_settings",
    "run_description",
    "RESULT_FILES",
]

AUTO_TARGET = 0.01
"""Energy-weighted relative standard error a ``rays = "auto"`` scene is traced to."""
AUTO_MAX_RAYS = 100_000_000
"""Cap on the rays per incidence of a ``rays = "auto"`` scene."""
RESULT_FILES = ("meta.json", "verdicts.json", "report.md", "brdf.npz")
"""A directory holding one of these is a microsim result (``--force`` may replace it)."""


@dataclass(frozen=True)
class Effort:
    """What a run spends beyond the scene's own settings.

    ``max_rays``: cap on primary rays per incidence (None: the scene's ``rays``);
    ``scale``: surface size factor per surface kind for ``Scene.build_surface(scale=…)``
    (V-groove count, heightfield grid n at fixed dx); ``quick_fits``: ``fit_all(quick=…)``
    (fewer multi-starts); ``sweep_theta``/``sweep_rays``/``sweep_bins``: the θi sweep of the
    stability and energy charts (rays per θi; (θ, φ) bins, None = the scene's);
    ``albedo_nodes``: (n_theta, n_grazing, n_gl_phi) of the model ρ(θ) tables
    (``AlbedoTable``); ``speed_rays``: ray counts of the speed-vs-accuracy runs (per estimator
    variant, one incidence);
    ``fig6_theta``/``fig6_rays``: the Mikkelsen Fig. 6 sweep of ``microsim report``;
    ``fit_names``: the models to fit (None: every ``fits.FIT_MODELS``); ``sweep_facets``:
    include the surface's own facets (``ts-facets``) in the stability sweep; ``max_bins``:
    cap on the main run's (θo, Δφ) bin counts (None: the scene's);
    ``max_realisations``/``realisation_target_floor``: cap on the realisations of a
    ``realisations = "auto"`` scene and the loosest target it may be given (the scene's
    ``realisation_target`` is raised to at least this).
    """

    max_rays: int | None = None
    scale: tuple[tuple[str, float], ...] = ()
    quick_fits: bool = False
    sweep_theta: tuple[float, ...] = (0, 10, 20, 30, 40, 50, 60, 70, 75, 80, 85, 89)
    sweep_rays: int = 200_000
    sweep_bins: tuple[int, int] | None = None
    albedo_nodes: tuple[int, int, int] = (46, 24, 16)
    speed_rays: tuple[int, ...] = (10_000, 100_000, 1_000_000)
    fig6_theta: tuple[float, ...] = (0, 10, 20, 30, 40, 50, 60, 70, 75, 80, 85, 89)
    fig6_rays: int = 200_000
    fit_names: tuple[str, ...] | None = None
    sweep_facets: bool = True
    max_bins: tuple[int, int] | None = None
    max_realisations: int = MAX_AUTO
    realisation_target_floor: float = 0.0

    def scale_for(self, kind: str) -> float:
        return dict(self.scale).get(kind, 1.0)


FULL = Effort()
QUICK = Effort(
    max_rays=200_000,
    scale=(
        ("vgrooves", 0.25),
        ("gaussian", 0.5),
        ("abc", 0.5),
        ("student-t-transform", 0.5),
        ("student-t-mixture", 0.5),
    ),
    quick_fits=True,
    sweep_theta=(0, 30, 60, 75, 85, 89),
    sweep_rays=200_000,
    sweep_bins=(30, 37),
    albedo_nodes=(16, 16, 8),
    speed_rays=(10_000, 30_000, 100_000),
    fig6_theta=(0, 30, 50, 65, 75, 82, 89),
    fig6_rays=20_000,
    fit_names=("cook-torrance", "low-microfacet", "low-smooth"),
    sweep_facets=False,
    max_bins=(30, 37),
    max_realisations=8,
    realisation_target_floor=0.03,
)
"""``--quick``: ≤ 2e5 rays per incidence on at most 30 × 37 bins (3° in θo, 5° in Δφ); 1/4 of
the V-grooves and half the heightfield grid (same dx, so the statistics stay, the tile shrinks);
quick fits (2 starts) of Cook–Torrance and Löw's two models (the Edwards fit, 10–30 s a scene,
only in full runs); a 6-angle sweep with 2e5 rays on 30 × 37 bins without ``ts-facets``;
coarser albedo tables (16 + 16 nodes in θ, 8 in φ: ρ within 1e-4 of the full table for vMF
κ = 1024); speed runs at 1e4, 3e4 and 1e5 rays; Mikkelsen Fig. 6 at 7 angles with 2e4 rays;
``realisations = "auto"`` stops at its pilot of 8 realisations (its ensemble
verdicts are weaker than a full run's: the report's ✓ ±x% says by how much)."""


def effort_for(quick: bool) -> Effort:
    """``QUICK`` for ``--quick``, else ``FULL``."""
    return QUICK if quick else FULL


@dataclass(frozen=True)
class RunPlan:
    """A validated run: the scene, where it goes, and what to spend."""

    scene: object
    out: Path
    rays: int
    theta_i: tuple[float, ...]
    seed: int
    threads: int
    effort: Effort
    quick: bool
    previous: object | None = None  # Result loaded for --resume
    force: bool = False
    auto: bool = False  # rays = "auto": ``rays`` is then the cap
    realisations: int = 1  # realisations traced (the pilot's for realisations = "auto")
    auto_realisations: bool = False  # realisations = "auto": a pilot decides the count
    partial_dir: Path | None = None  # where interrupted tallies go (None: ``out``)
    resume_hint: str | None = None  # how to continue, for the interrupt message
    scheduler: str | None = None  # Dask scheduler address: the main tracing on its workers

    @property
    def bins(self) -> Bins:
        """The run's outgoing bins: folded onto Δφ ∈ [0°, 180°], or over the whole circle for
        a scene with ``full_azimuth`` (anisotropic surfaces)."""
        return Bins(*bins_shape(self.scene, self.effort), folded=not self.scene.full_azimuth)

    @property
    def phi_i(self) -> tuple[float, ...]:
        """The scene's incidence azimuths, degrees."""
        return self.scene.simulation.phi_i

    @property
    def incidences(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(θi, φi) per traced incidence, degrees (``scene.incidence_pairs``)."""
        return incidence_pairs(self.theta_i, self.phi_i)

    @property
    def realisation_target(self) -> float:
        """Tile-scatter target of ``realisations = "auto"`` (``analysis.budget``)."""
        target = self.scene.simulation.realisation_target or REALISATION_TARGET
        return max(target, self.effort.realisation_target_floor)

    @property
    def side_realisations(self) -> int:
        """Realisations of the side studies: the run's, at most the auto pilot's count."""
        return min(self.realisations, MIN_AUTO)


def bins_shape(scene, effort: Effort) -> tuple[int, int]:
    """(θo, Δφ) bin counts: the scene's, capped by ``effort.max_bins``."""
    shape = (scene.simulation.theta_bins, scene.simulation.phi_bins)
    if effort.max_bins is None:
        return shape
    nt, nphi = (min(a, b) for a, b in zip(shape, effort.max_bins))
    if scene.full_azimuth:  # the cap over the whole circle: twice the folded one, even
        nphi = min(scene.simulation.phi_bins, 2 * (effort.max_bins[1] - 1))
    return nt, nphi


def _int_option(name, value, lo):
    if value is None:
        return None
    if isinstance(value, bool) or int(value) != value or value < lo:
        raise UsageError(f"--{name} must be an integer >= {lo}, got {value!r}")
    return int(value)


def plan_run(
    scene_path,
    *,
    rays=None,
    theta_i=None,
    out=None,
    threads=2,
    seed=None,
    quick=False,
    resume=None,
    force=False,
    tallies=None,
    partial_dir=None,
    resume_hint=None,
    scheduler=None,
) -> RunPlan:
    """Validate a run without touching the disk; every problem is a one-line ``UsageError``.

    ``out`` defaults to ``runs/<scene name>`` (or ``resume``). An existing ``out`` is refused
    unless ``resume`` names it (continue its tallies, made with the same scene and options,
    ``_check_resumable``) or ``force`` (replace it; only an empty directory or a microsim
    result, never the current directory, one of its parents or one holding the scene file;
    files in it that microsim does not write are kept, ``publishing.publish_dir``). A dangling
    symbolic link, or a name too long for the file system and the temporaries beside it, is
    refused. ``tallies`` (``microsim report --resume``): a directory of saved
    partial tallies to continue into ``out``; ``partial_dir``: where tallies go if the run is
    interrupted (default ``out``); ``resume_hint``: how to continue, for that message;
    ``scheduler``: a Dask scheduler address whose workers trace the main simulation
    (``sim.cluster``: the result is the local run's bit for bit; the side studies stay
    local)."""
    scene = load_scene(scene_path)
    effort = effort_for(quick)
    rays = _int_option("rays", rays, 1)
    threads = _int_option("threads", threads, 1)
    seed = _int_option("seed", seed, 0)
    auto = rays is None and scene.simulation.rays == "auto"
    auto_real = scene.simulation.realisations == "auto"
    n_real = MIN_AUTO if auto_real else scene.simulation.realisations
    _check_auto(scene, auto, scheduler, resume)
    if rays is None:
        rays = AUTO_MAX_RAYS if auto else scene.simulation.rays
        if effort.max_rays is not None:
            rays = min(rays, effort.max_rays)
    if rays < n_real:
        raise UsageError(f"--rays must be >= the scene's realisations ({n_real}), got {rays}")
    theta_i = _theta_option(scene.simulation.theta_i if theta_i is None else theta_i)
    seed = scene.simulation.seed if seed is None else seed
    Bins(scene.simulation.theta_bins, scene.simulation.phi_bins)  # validates the grid
    check_wave_plan(scene, effort.scale_for(scene.surface.kind), seed, n_real, theta_i)
    out, saved, option = _output(scene, out, resume, tallies, force)
    previous = None
    if saved is not None:
        previous = _load_saved(saved, option)
        if auto_real:
            n_real, rays = _auto_realisations_of(previous, saved, rays)
        description = run_description(scene, theta_i, seed, bool(quick), rays, effort, n_real)
        _check_resumable(previous, description, saved)
    return RunPlan(
        scene=scene,
        out=Path(out),
        rays=rays,
        theta_i=theta_i,
        seed=seed,
        threads=threads,
        effort=effort,
        quick=bool(quick),
        previous=previous,
        force=bool(force),
        auto=auto,
        realisations=n_real,
        auto_realisations=auto_real,
        partial_dir=None if partial_dir is None else Path(partial_dir),
        resume_hint=resume_hint,
        scheduler=scheduler,
    )


def _output(scene, out, resume, tallies, force) -> tuple[Path, Path | None, str]:
    """(output directory, saved run to continue or None, the option naming it), checked
    (``plan_run``)."""
    if resume is not None:
        resume = Path(resume)
        if out is not None and Path(out) != resume:
            raise UsageError(f"--out {out} and --resume {resume} must name the same directory")
        check_output_path(resume, "--resume", scene.path)
        return resume, resume, "--resume"
    out = Path(out) if out is not None else Path("runs") / scene.name
    check_output_path(out, "--out", scene.path)
    if out.exists() and not force:
        raise UsageError(
            f"{out} already exists; pass --resume {out} to continue it or --force to replace it"
        )
    if out.exists():
        check_replaceable(out)
    return out, (None if tallies is None else Path(tallies)), "saved tallies"


def _check_auto(scene, auto: bool, scheduler, resume) -> None:
    """A ``rays = "auto"`` scene traces one realisation, locally, and is not resumed; a
    ``--scheduler`` address is checked."""
    if auto and scene.simulation.realisations != 1:
        raise UsageError(
            f'rays = "auto" needs realisations = 1 (scene {scene.name} has '
            f"{scene.simulation.realisations}); give --rays instead"
        )
    if scheduler is not None:
        check_address(scheduler)
    if auto and scheduler is not None:
        raise UsageError(
            f'--scheduler is not available for a rays = "auto" scene ({scene.name}): its '
            f"batches are decided one after another; give --rays"
        )
    if auto and resume is not None:
        raise UsageError(
            '--resume is not available for a rays = "auto" scene; use --force to run it again'
        )


def _theta_option(theta_i) -> tuple[float, ...]:
    """``--theta-i`` (or the scene's θi) as a tuple of degrees, each in [0, 90)."""
    theta_i = tuple(float(t) for t in theta_i)
    if not theta_i or not all(math.isfinite(t) and 0 <= t < 90 for t in theta_i):
        raise UsageError(
            f"--theta-i must be angles in degrees, each in [0, 90), got {list(theta_i)}"
        )
    return theta_i


def _auto_realisations_of(previous, where, rays: int) -> tuple[int, int]:
    """(realisations, rays) a saved ``realisations = "auto"`` run was traced with: its pilot
    chose them, and its continuation must trace the same (``--rays`` was the pilot's)."""
    auto = previous.meta.get("run", {}).get("realisations_auto") or {}
    n, total = auto.get("realisations"), auto.get("rays")
    if not (isinstance(n, int) and isinstance(total, int) and n >= 1 and total >= n):
        raise UsageError(
            f"{where}: the saved run does not record the realisations its pilot chose "
            f'(realisations = "auto"); rerun with --force'
        )
    if auto.get("pilot_rays") != rays:
        raise UsageError(
            f"{where}: the saved run's pilot traced {auto.get('pilot_rays')} rays per "
            f"incidence, this run asks for {rays}; use the same --rays or --force"
        )
    return n, total


def check_output_path(out: Path, option: str, scene_file=None) -> None:
    """Refuse (``UsageError`` naming ``option``) an output path that is not a usable
    directory name: the current directory or one of its parents, a directory holding
    ``scene_file`` (the scene or sweep file read), an existing non-directory, one whose
    parent is not a directory, or a name too long for its temporaries. ``microsim run`` and
    ``microsim sweep`` check their ``--out`` with it."""
    norm = Path(os.path.normpath(file_path(option, out)))
    if norm.name in ("", ".", ".."):
        raise UsageError(
            f"{option} {out}: must name a directory of its own, not the current "
            f"directory or a parent of it"
        )
    _check_name_lengths(norm, option)
    if norm.is_symlink() and not norm.exists():
        raise UsageError(
            f"{option} {out}: is a symbolic link to {os.readlink(norm)}, which is not an "
            f"existing directory; remove the link or choose another directory"
        )
    try:
        target = norm.resolve()
        cwd = Path.cwd().resolve()
    except OSError as e:
        raise UsageError(f"{option} {out}: cannot resolve the path ({e.strerror})") from None
    if target == cwd or target in cwd.parents:
        raise UsageError(
            f"{option} {out}: is the current directory or one of its parents; "
            f"choose a directory of its own"
        )
    if scene_file is not None:
        spath = Path(scene_file).resolve()
        if target == spath or target in spath.parents:
            raise UsageError(
                f"{option} {out}: holds the scene file {scene_file}; choose another directory"
            )
    if out.exists() and not out.is_dir():
        raise UsageError(f"{option} {out}: exists and is not a directory")
    parent = norm.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if parent.exists() and not parent.is_dir():
        raise UsageError(f"{option} {out}: {parent} is not a directory")


TEMP_NAME_ROOM = 40
"""Characters the temporaries beside an output (``.OUT.tmp-<pid>-*``, ``.OUT.lock``,
``OUT.unpublished-<pid>-*``) add to its name."""


def _check_name_lengths(norm: Path, option: str) -> None:
    """Refuse a path with a component the file system cannot hold, or an output name that
    leaves no room for its temporaries (``TEMP_NAME_ROOM``), or a path over PATH_MAX."""
    parent = norm.parent
    while not os.path.isdir(parent) and parent != parent.parent:
        parent = parent.parent
    try:
        name_max = os.pathconf(parent, "PC_NAME_MAX")
        path_max = os.pathconf(parent, "PC_PATH_MAX")
    except (OSError, ValueError):
        name_max, path_max = 255, 4096
    size = lambda text: len(os.fsencode(text))  # noqa: E731
    shown = lambda part: part if len(part) <= 40 else f"{part[:20]}…{part[-12:]}"  # noqa: E731
    for part in norm.parts[:-1]:
        if size(part) > name_max:
            raise UsageError(
                f"{option} {shown(str(norm))}: the folder name {shown(part)!r} is "
                f"{size(part)} bytes long; the file system allows {name_max}"
            )
    limit = name_max - TEMP_NAME_ROOM
    if size(norm.name) > limit:
        raise UsageError(
            f"{option} {shown(str(norm))}: the name {shown(norm.name)!r} is "
            f"{size(norm.name)} bytes long; at most {limit} (the file system allows "
            f"{name_max}, less room for the temporaries beside it)"
        )
    if size(os.path.abspath(norm)) + TEMP_NAME_ROOM > path_max:
        raise UsageError(
            f"{option} {shown(str(norm))}: the path is {size(os.path.abspath(norm))} bytes "
            f"long; the file system allows {path_max - TEMP_NAME_ROOM} here"
        )


def check_replaceable(out: Path) -> None:
    """``--force`` replaces only an empty directory or a microsim result (the user's own files
    in it are carried over, ``publishing.publish_dir``)."""
    try:
        names = set(os.listdir(out))
    except OSError as e:
        raise UsageError(f"--out {out}: cannot list it ({e.strerror})") from None
    if names and not names & set(RESULT_FILES):
        raise UsageError(
            f"--force {out}: not a microsim result (none of "
            f"{', '.join(RESULT_FILES)}); refusing to replace it"
        )


def _load_saved(where: Path, what: str) -> Result:
    """``Result.load(where)`` of a microsim run (its meta.json holds the run record); a
    missing, damaged or edited brdf.npz/meta.json is a one-line ``UsageError`` naming the
    file."""
    for f in (where / "meta.json", where / "brdf.npz"):
        if not f.is_file():
            raise UsageError(f"{what} {where}: no saved run there ({f.name} missing)")
    try:
        saved = Result.load(where)
    except UsageError as e:
        raise UsageError(f"{what} {where}: {e}; rerun with --force") from None
    if not isinstance(saved.meta.get("run"), dict):
        raise UsageError(
            f"{what} {where}: {where / 'meta.json'} has no run record (run is "
            f"{saved.meta.get('run')!r}, a microsim run writes an object); rerun with --force"
        )
    return saved


def tally_settings(scene) -> dict:
    """What a scene's tallies depend on besides the run's options (``meta["run"]``, compared
    by ``--resume``): the surface (kind and parameters; a heightfield file by the SHA-256 of
    its content, not its path), the material's index (None: mirror) and the bounces."""
    surface = {"kind": scene.surface.kind, **scene.surface.params}
    if not scene.anisotropic:  # isotropic surfaces keep the settings they always had
        for key in ("oriented", "corr_len_y", "B_y", "rotation"):
            surface.pop(key, None)
    if scene.surface.kind == "file":
        if surface["form"] == "none":  # heightfield arrays keep the settings they always had
            del surface["form"]
        path = Path(surface.pop("path"))
        path = path if path.is_absolute() or scene.path is None else scene.path.parent / path
        digest = hashlib.sha256()
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)
        surface["sha256"] = digest.hexdigest()
    ior = None if scene.ior is None else [complex(scene.ior).real, complex(scene.ior).imag]
    record = {"surface": surface, "ior": ior, "bounces": scene.simulation.bounces}
    if scene.anisotropic or any(scene.simulation.phi_i):  # absent otherwise: older runs resume
        record.update(phi_i=scene.simulation.phi_i_record, full_azimuth=scene.full_azimuth)
    if scene.transmission:  # absent otherwise, as in the run's identity
        record["transmission"] = True
    return json.loads(json.dumps(json_safe(record)))


RESUME_KEYS = {
    "material": "material.ior",
    "bounces": "simulation.bounces",
    "transmission": "material.transmission",
    "phi_i": "simulation.phi_i",
    "bins": "bins (simulation.theta_bins, phi_bins, full_azimuth)",
    "scene": "scene",
    "quick": "--quick",
}
"""How ``--resume`` names a field of the run's identity (``sim.identity``) by its scene key
or option."""


def run_description(scene, theta_i, seed, quick, rays, effort, realisations) -> RunDescription:
    """The description (``sim.identity``) of the run a plan traces: the scene's surfaces by
    their recipe (scene, [surface] settings, ``--quick``), the incidences θi × the scene's
    φi, the effort's bins, traced masking and stratified origins as ``microsim run`` traces
    them."""
    theta, phi = incidence_pairs(theta_i, scene.simulation.phi_i)
    recipe = {"scene": scene.name, "surface": tally_settings(scene)["surface"], "quick": quick}
    return RunDescription(
        material=scene.ior,
        theta_i=theta,
        phi_i=phi,
        bins=Bins(*bins_shape(scene, effort), folded=not scene.full_azimuth),
        rays=rays,
        seed=seed,
        surfaces=recipe,
        bounces=scene.simulation.bounces,
        realisations=realisations,
        transmission=scene.transmission,
    )


def _check_resumable(saved: Result, description: RunDescription, where) -> None:
    """The saved run is the run ``description`` asks for (or its first realisations): a
    one-line ``UsageError`` naming the first setting that differs, or that it does not
    record (saved by an older microsim)."""
    old = saved_identity(saved)
    for key, have, now in description.mismatches(old):
        if key in ("theta_i", "phi_i"):  # the traced pairs: name the scene's axis that differs
            key, have, now = _incidence_axis(old, description.identity())
        name = RESUME_KEYS.get(key, key)
        if key == "surfaces":  # name the recipe's key, and the surface's
            key = next(k for k in now if (have or {}).get(k) != now[k])
            have, now, name = (have or {}).get(key), now[key], RESUME_KEYS.get(key, key)
            if isinstance(have, dict) and isinstance(now, dict):
                sub = next(k for k in sorted({*have, *now}) if have.get(k) != now.get(k))
                have, now, name = have.get(sub), now.get(sub), f"surface.{sub}"
        if have is None:
            raise UsageError(
                f"--resume {where}: the saved run does not record its {name} (saved by an "
                f"older microsim); rerun with --force"
            )
        raise UsageError(
            f"--resume {where}: {name} is {have!r} there but {now!r} now; resume with the "
            f"same settings or rerun with --force"
        )


def _incidence_axis(old: dict, new: dict) -> tuple[str, list, list]:
    """(key, saved axis, this run's axis) of the incidence setting that differs between two
    identities whose (θi, φi) pairs differ: the φi axis if it differs, else the θi axis."""
    axes = {k: [list(dict.fromkeys(d[k])) for d in (old, new)] for k in ("phi_i", "theta_i")}
    key = "phi_i" if axes["phi_i"][0] != axes["phi_i"][1] else "theta_i"
    return key, *axes[key]
