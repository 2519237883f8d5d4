"""`microsim run` and `microsim report`: simulate scenes, compare, fit, judge and write reports.

One run (``plan_run`` → ``execute``):

1. simulate the scene (``microsim.sim.simulate``; random surfaces over the scene's realisations,
   realisation r built with seed ``seed + r``);
2. evaluate the default closed forms on the same bins (``compare.default_models`` /
   ``attach_models``) and fit the parametric ones (``fits.fit_all``);
3. judge every (incidence, model) pair (``verdicts.verdicts_for_result``);
4. side studies for the charts: a θi sweep 0°…89° with fewer rays (stability and energy
   charts) and the estimator variants at a few ray counts (speed vs accuracy);
5. write ``brdf.npz`` + ``meta.json`` (``Result.save``), ``verdicts.json``, the PNG charts and
   ``report.md`` into a staging directory, then move it to ``DIR`` in one rename.

Ctrl-C during the simulation keeps the tallies so far: they are saved with
``meta["partial"] = True`` (exit status 130) and ``--resume DIR`` continues them to the requested
ray count, giving the same tallies as an uninterrupted run. Ctrl-C after the simulation (side
studies, fits, charts, publishing) saves the complete tallies the same way (130); a side study
cut short is never used for a report. ``microsim report`` keeps the tallies of an interrupted
scene in ``OUT/.<scene>.partial/`` (the previous report of that scene stays in place) and
``report --resume`` continues: finished scenes are skipped, the interrupted one resumed.

Safety: a run holds ``atomic.output_lock(DIR)`` for its whole duration (a second run on the
same DIR is refused), removes stale ``.DIR.tmp-<pid>-*`` left by killed runs, never replaces the
current directory, one of its parents or a directory holding the scene file, and replaces an
existing DIR (``--force``) only if it is empty or a microsim result. Wall times go to
``timings.json`` only, so report.md, verdicts.json and index.md are reproducible.

A scene with ``rays = "auto"`` (and no ``--rays``) is traced with ``sim.auto.simulate_auto``
until the energy-weighted relative standard error is ≤ ``AUTO_TARGET`` (1 %) per incidence, at
most ``AUTO_MAX_RAYS`` rays (``Effort.max_rays`` if smaller); the rays and seconds each
incidence used are in ``meta.json`` (``auto``, ``run.auto``) and ``verdicts.json``
(``rays_auto``). Such runs need one realisation and cannot be resumed.

``Effort`` says what a run spends; ``QUICK`` is exactly what ``--quick`` changes.
"""
from __future__ import annotations

from microsim.errors import UsageError
import json
import math
import os
import re
import shutil
import sys
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from . import atomic
from .checkpoints import checkpoint

from .analysis.report import albedo_stderr

__all__ = ["Effort", "FULL", "QUICK", "AUTO_TARGET", "AUTO_MAX_RAYS", "RunPlan", "RunOutcome", "plan_run",
           "execute", "run_report", "publish_dir", "write_json_atomic", "VERDICTS_FILE",
           "REPORT_FILE", "TIMINGS_FILE", "REPORT_STATE"]

AUTO_TARGET = 0.01
"""Energy-weighted relative standard error a ``rays = "auto"`` scene is traced to."""
AUTO_MAX_RAYS = 100_000_000
"""Cap on the rays per incidence of a ``rays = "auto"`` scene."""
VERDICTS_FILE, REPORT_FILE, TIMINGS_FILE = "verdicts.json", "report.md", "timings.json"
REPORT_STATE = ".report-state.json"
"""``microsim report``'s progress file in OUT (finished scenes), for ``report --resume``."""
SCHEMA_VERSION = 1
SWEEP_SEED, SPEED_SEED = 7919, 104729
"""Seed offsets of the side studies (added to the run's seed): independent of the main run."""


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
    cap on the main run's (θo, Δφ) bin counts (None: the scene's).
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

    def scale_for(self, kind: str) -> float:
        return dict(self.scale).get(kind, 1.0)


FULL = Effort()
QUICK = Effort(max_rays=200_000, scale=(("vgrooves", 0.25), ("gaussian", 0.5), ("abc", 0.5)),
               quick_fits=True, sweep_theta=(0, 30, 60, 75, 85, 89), sweep_rays=200_000,
               sweep_bins=(30, 37), albedo_nodes=(16, 16, 8), speed_rays=(10_000, 30_000, 100_000),
               fig6_theta=(0, 30, 50, 65, 75, 82, 89), fig6_rays=20_000,
               fit_names=("cook_torrance", "low_microfacet", "low_smooth"), sweep_facets=False,
               max_bins=(30, 37))
"""``--quick``: ≤ 2e5 rays per incidence on at most 30 × 37 bins (3° in θo, 5° in Δφ); 1/4 of the V-grooves and half the heightfield grid
(same dx, so the statistics stay, the tile shrinks); quick fits (2 starts) of Cook–Torrance and
Löw's two models (the Edwards fit, 10–30 s a scene, only in full runs); a 6-angle sweep with
2e5 rays on 30 × 37 bins without ``ts-facets``; coarser albedo tables (16 + 16 nodes in θ, 8 in
φ: ρ within 1e-4 of the full table for vMF κ = 1024); speed runs at 1e4, 3e4 and 1e5 rays; Mikkelsen Fig. 6 at 7 angles with 2e4 rays."""


# --- planning (all validation happens here, before anything is written) ----------------------
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
    previous: object | None = None        # Result loaded for --resume
    force: bool = False
    auto: bool = False                    # rays = "auto": ``rays`` is then the cap
    partial_dir: Path | None = None       # where interrupted tallies go (None: ``out``)
    resume_hint: str | None = None        # how to continue, for the interrupt message

    @property
    def bins(self):
        from .sim import Bins
        return Bins(*_bins_shape(self.scene, self.effort))


def _bins_shape(scene, effort: Effort) -> tuple[int, int]:
    """(θo, Δφ) bin counts: the scene's, capped by ``effort.max_bins``."""
    shape = (scene.simulation.theta_bins, scene.simulation.phi_bins)
    if effort.max_bins is None:
        return shape
    return tuple(min(a, b) for a, b in zip(shape, effort.max_bins))


def _int_option(name, value, lo):
    if value is None:
        return None
    if isinstance(value, bool) or int(value) != value or value < lo:
        raise UsageError(f"--{name} must be an integer >= {lo}, got {value!r}")
    return int(value)


def plan_run(scene_path, *, rays=None, theta_i=None, out=None, threads=2, seed=None,
             quick=False, resume=None, force=False, tallies=None, partial_dir=None,
             resume_hint=None) -> RunPlan:
    """Validate a run without touching the disk; every problem is a one-line ``UsageError``.

    ``out`` defaults to ``runs/<scene name>`` (or ``resume``). An existing ``out`` is refused
    unless ``resume`` names it (continue its tallies) or ``force`` (replace it; only an empty
    directory or a microsim result, never the current directory, one of its parents or one
    holding the scene file). ``tallies`` (``microsim report --resume``): a directory of saved
    partial tallies to continue into ``out``; ``partial_dir``: where tallies go if the run is
    interrupted (default ``out``); ``resume_hint``: how to continue, for that message."""
    from .scene import load_scene
    from .sim import Bins, Result
    scene = load_scene(scene_path)
    effort = QUICK if quick else FULL
    rays = _int_option("rays", rays, 1)
    threads = _int_option("threads", threads, 1)
    seed = _int_option("seed", seed, 0)
    auto = rays is None and scene.simulation.rays == "auto"
    if auto and scene.simulation.realisations != 1:
        raise UsageError(f"rays = \"auto\" needs realisations = 1 (scene {scene.name} has "
                         f"{scene.simulation.realisations}); give --rays instead")
    if auto and resume is not None:
        raise UsageError("--resume is not available for a rays = \"auto\" scene; "
                         "use --force to run it again")
    if rays is None:
        rays = AUTO_MAX_RAYS if auto else scene.simulation.rays
        if effort.max_rays is not None:
            rays = min(rays, effort.max_rays)
    if rays < scene.simulation.realisations:
        raise UsageError(f"--rays must be >= the scene's realisations "
                         f"({scene.simulation.realisations}), got {rays}")
    if theta_i is None:
        theta_i = scene.simulation.theta_i
    theta_i = tuple(float(t) for t in theta_i)
    if not theta_i or not all(math.isfinite(t) and 0 <= t < 90 for t in theta_i):
        raise UsageError(f"--theta-i must be angles in degrees, each in [0, 90), got {list(theta_i)}")
    seed = scene.simulation.seed if seed is None else seed
    Bins(scene.simulation.theta_bins, scene.simulation.phi_bins)      # validates the grid
    previous = None
    if resume is not None:
        resume = Path(resume)
        if out is not None and Path(out) != resume:
            raise UsageError(f"--out {out} and --resume {resume} must name the same directory")
        out = resume
        _check_out(out, scene, "--resume")
        previous = _load_saved(resume, "--resume")
        _check_resumable(previous, scene, theta_i, seed, quick, rays, effort, resume)
    else:
        out = Path(out) if out is not None else Path("runs") / scene.name
        _check_out(out, scene, "--out")
        if out.exists() and not force:
            raise UsageError(f"{out} already exists; pass --resume {out} to continue it or "
                             f"--force to replace it")
        if out.exists():
            _check_replaceable(out)
        if tallies is not None:
            previous = _load_saved(Path(tallies), "saved tallies")
            _check_resumable(previous, scene, theta_i, seed, quick, rays, effort, tallies)
    return RunPlan(scene=scene, out=Path(out), rays=rays, theta_i=theta_i, seed=seed,
                   threads=threads, effort=effort, quick=bool(quick), previous=previous,
                   force=bool(force), auto=auto,
                   partial_dir=None if partial_dir is None else Path(partial_dir),
                   resume_hint=resume_hint)


_RESULT_FILES = ("meta.json", "verdicts.json", "report.md", "brdf.npz")


def _check_out(out: Path, scene, option: str) -> None:
    """Refuse an output path that is not a usable directory name: the current directory or
    one of its parents, a directory holding the scene file, an existing non-directory, or
    one whose parent is not a directory."""
    norm = Path(os.path.normpath(out))
    if norm.name in ("", ".", ".."):
        raise UsageError(f"{option} {out}: must name a directory of its own, not the current "
                         f"directory or a parent of it")
    try:
        target = norm.resolve()
        cwd = Path.cwd().resolve()
    except OSError as e:
        raise UsageError(f"{option} {out}: cannot resolve the path ({e.strerror})") from None
    if target == cwd or target in cwd.parents:
        raise UsageError(f"{option} {out}: is the current directory or one of its parents; "
                         f"choose a directory of its own")
    if scene.path is not None:
        spath = Path(scene.path).resolve()
        if target == spath or target in spath.parents:
            raise UsageError(f"{option} {out}: holds the scene file {scene.path}; choose "
                             f"another directory")
    if out.exists() and not out.is_dir():
        raise UsageError(f"{option} {out}: exists and is not a directory")
    parent = norm.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if parent.exists() and not parent.is_dir():
        raise UsageError(f"{option} {out}: {parent} is not a directory")


def _check_replaceable(out: Path) -> None:
    """``--force`` replaces only an empty directory or a microsim result."""
    try:
        names = set(os.listdir(out))
    except OSError as e:
        raise UsageError(f"--out {out}: cannot list it ({e.strerror})") from None
    if names and not names & set(_RESULT_FILES):
        raise UsageError(f"--force {out}: not a microsim result (none of "
                         f"{', '.join(_RESULT_FILES)}); refusing to replace it")


def _load_saved(where: Path, what: str):
    """``Result.load(where)``; a missing, truncated or corrupt brdf.npz/meta.json is a
    one-line ``UsageError`` naming the file."""
    import zipfile
    from .sim import Result
    meta, npz = where / "meta.json", where / "brdf.npz"
    for f in (meta, npz):
        if not f.is_file():
            raise UsageError(f"{what} {where}: no saved run there ({f.name} missing)")
    try:
        with open(meta, encoding="utf-8") as fh:
            m = json.load(fh)
        if not isinstance(m, dict):
            raise ValueError("not a JSON object")
    except (ValueError, UnicodeDecodeError) as e:
        raise UsageError(f"{what} {where}: {meta} is unreadable ({' '.join(str(e).split())})"
                         f"; rerun with --force") from None
    try:
        with np.load(npz, allow_pickle=False) as z:
            for k in z.files:
                z[k]
    except (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile) as e:
        raise UsageError(f"{what} {where}: {npz} is unreadable ({' '.join(str(e).split())})"
                         f"; rerun with --force") from None
    try:
        return Result.load(where)
    except (ValueError, KeyError, TypeError, IndexError, EOFError, zipfile.BadZipFile) as e:
        raise UsageError(f"{what} {where}: the saved run is inconsistent "
                         f"({type(e).__name__}: {' '.join(str(e).split())}); rerun with "
                         f"--force") from None


def _check_resumable(prev, scene, theta_i, seed, quick, rays, effort, where):
    run = prev.meta.get("run", {})
    want = {"scene": scene.name, "seed": seed, "quick": bool(quick), "rays": rays,
            "theta_i": list(theta_i),
            "bins": list(_bins_shape(scene, effort))}
    have = {k: run.get(k) for k in want}
    for key in want:
        if have[key] != want[key]:
            raise UsageError(f"--resume {where}: {key} is {have[key]!r} there but "
                             f"{want[key]!r} now; resume with the same settings")


# --- simulation ----------------------------------------------------------------------------
def _surface_source(scene, seed: int, scale: float):
    """(surface, realisations) arguments of ``simulate`` for the scene."""
    n = scene.simulation.realisations
    if n == 1:
        return scene.build_surface(seed=seed, scale=scale), None
    return None, (lambda s: scene.build_surface(seed=s, scale=scale), [seed + r for r in range(n)])


class RayProgress:
    """tqdm bar on stderr over the primary rays still to trace (rays/s and time left).

    ``simulate`` calls it with a ``microsim.sim.progress.RaysDone`` event per chunk of rays
    tallied: the bar advances by ``event.rays``. The older text form, one line
    "realisation r/R, theta_i = θ°: done" per finished pair, is still understood: the bar then
    advances by what that pair still had (``remaining`` (R, T): all its rays, or what a resumed
    partial run had left) minus what its chunk events already counted."""

    def __init__(self, remaining: np.ndarray, theta_i, desc: str, enabled: bool = True):
        from tqdm import tqdm
        self.remaining = np.asarray(remaining, dtype=np.int64)
        self.counted = np.zeros_like(self.remaining)
        self.labels = [f"{t:g}" for t in theta_i]
        self.bar = tqdm(total=int(self.remaining.sum()), unit="ray", unit_scale=True, desc=desc,
                        file=sys.stderr, disable=not enabled, dynamic_ncols=True, smoothing=0.1)

    def _advance(self, r: int, t: int, n: int) -> None:
        if 0 <= r < self.remaining.shape[0] and 0 <= t < self.remaining.shape[1]:
            n = int(max(0, min(n, self.remaining[r, t] - self.counted[r, t])))
            self.counted[r, t] += n
            if n:
                self.bar.update(n)

    def __call__(self, event) -> None:
        from .sim.progress import RaysDone
        if isinstance(event, RaysDone):
            self._advance(event.realisation, event.incidence, event.rays)
            return
        m = re.match(r"realisation (\d+)/\d+, theta_i = ([^°]+)°", str(event))
        if m and m.group(2) in self.labels:
            self._advance(int(m.group(1)) - 1, self.labels.index(m.group(2)), 1 << 62)

    def close(self) -> None:
        self.bar.close()


class StageProgress:
    """The analysis after the simulation as a second bar on stderr, one step per stage
    (models, fits, stability sweep, speed runs, charts, writing), the current one named."""

    STAGES = ("models", "fits", "stability sweep", "speed runs", "charts", "writing")

    def __init__(self, desc: str, enabled: bool = True):
        from tqdm import tqdm
        self.bar = tqdm(total=len(self.STAGES), desc=f"{desc} analysis", unit="stage",
                        file=sys.stderr, disable=not enabled, dynamic_ncols=True,
                        bar_format="{desc}: {n_fmt}/{total_fmt} {bar} {postfix} [{elapsed}]")
        self.current = None

    def stage(self, name: str) -> None:
        if self.current is not None:
            self.bar.update(1)
        self.current = name
        self.bar.set_postfix_str(name)

    def close(self) -> None:
        if self.current is not None:
            self.bar.update(1)
        self.bar.close()


def _remaining_rays(plan: RunPlan) -> np.ndarray:
    """(R, T) rays each (realisation, incidence) still has to trace."""
    n = plan.scene.simulation.realisations
    per_real = np.array([plan.rays // n + (r < plan.rays % n) for r in range(n)], dtype=np.int64)
    todo = np.repeat(per_real[:, None], len(plan.theta_i), axis=1)
    prev = plan.previous
    if prev is not None and prev.tallies is not None and "rays" in prev.tallies:
        todo = todo - np.asarray(prev.tallies["rays"], dtype=np.int64).reshape(todo.shape)
    return np.maximum(todo, 0)


def _simulate(plan: RunPlan, theta_i, rays, seed, bins, progress=None, resume=None,
              origins="stratified", realisations=True):
    from .sim import simulate
    sc = plan.scene
    scale = plan.effort.scale_for(sc.surface.kind)
    if realisations:
        surface, reals = _surface_source(sc, seed, scale)
    else:
        surface, reals = sc.build_surface(seed=seed, scale=scale), None
    return simulate(surface, sc.ior, list(theta_i), rays=rays, bins=bins, seed=seed,
                    threads=plan.threads, realisations=reals, progress=progress,
                    origins=origins, resume=resume)


def _complete(result):
    """A side study's ``Result``, or ``KeyboardInterrupt`` when it was cut short: ``simulate``
    returns partial tallies on Ctrl-C, and a side study must never feed a report from them."""
    if result.is_partial:
        raise KeyboardInterrupt
    return result


def _simulate_auto(plan: RunPlan, log):
    """``simulate_auto`` to ``AUTO_TARGET`` on the scene's surface, at most ``plan.rays`` rays
    per incidence; one progress line per batch through ``log`` (None: silent)."""
    from .sim.auto import simulate_auto
    sc = plan.scene
    surface = sc.build_surface(seed=plan.seed, scale=plan.effort.scale_for(sc.surface.kind))
    return simulate_auto(surface, sc.ior, list(plan.theta_i), target=AUTO_TARGET,
                         bins=plan.bins, seed=plan.seed, threads=plan.threads,
                         max_rays=plan.rays, progress=log)


def _auto_summary(result) -> dict | None:
    """Rays, seconds, achieved rse and convergence per incidence of an auto run (or None)."""
    auto = result.meta.get("auto")
    if not auto:
        return None
    keys = ("theta_i", "rays", "seconds", "rse", "converged", "batches")
    return {"target": auto["target"], "seconds": float(result.meta.get("seconds", 0.0)),
            "incidences": [{k: d[k] for k in keys} for d in auto["incidences"]]}


def _run_meta(plan: RunPlan) -> dict:
    sc = plan.scene
    rays = {"rays": "auto", "max_rays": plan.rays} if plan.auto else {"rays": plan.rays}
    return {"scene": sc.name, "scene_file": str(sc.path), "description": sc.description,
            **rays, "theta_i": list(plan.theta_i), "seed": plan.seed,
            "quick": plan.quick, "bins": [plan.bins.n_theta, plan.bins.n_phi],
            "realisations": sc.simulation.realisations,
            "surface_scale": plan.effort.scale_for(sc.surface.kind),
            "effort": asdict(plan.effort)}


# --- analysis ------------------------------------------------------------------------------
def _models_for(plan: RunPlan):
    """The default model set; for a random scene ``ts-facets`` and the realised m pool every
    realisation the simulation averaged over (``compare.default_models``)."""
    from .sim.compare import default_models
    sc = plan.scene
    single, reals = _surface_source(sc, plan.seed, plan.effort.scale_for(sc.surface.kind))
    surfaces = single if reals is None else [reals[0](s) for s in reals[1]]
    return default_models(surfaces, sc.ior, ndf=sc.ndf())


def _attach(result, specs) -> None:
    """``attach_models``; quadrature bins that miss their tolerance (predict's RuntimeWarning)
    are recorded in ``result.meta["model_warnings"]`` for the report instead of stderr."""
    from .sim.compare import attach_models
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        attach_models(result, specs)
    result.meta["model_warnings"] = sorted({str(w.message) for w in caught})


def _energy_rel_rms(sim, ref, omega) -> float:
    """Energy-weighted relative RMS of ``sim`` against a reference ``ref`` over the bins
    carrying 90 % of ref's energy (the verdicts' rel_rms with the roles of sim and model
    swapped: here the reference is the noise-free one)."""
    from .analysis.verdicts import energy_set
    e = np.nan_to_num(ref * omega).ravel()
    keep = energy_set(e) & (ref.ravel() > 0)
    r, s = ref.ravel()[keep], np.nan_to_num(sim.ravel()[keep])
    return float(np.sqrt(np.sum(e[keep] * ((s - r) / r) ** 2) / np.sum(e[keep])))


def _ranking(verdicts) -> list[str]:
    """Model names from best to worst by mean relative RMS error over the incidences."""
    score: dict[str, list[float]] = {}
    for v in verdicts:
        x = v.get("rel_rms")
        score.setdefault(v["model"], []).append(x if x is not None and np.isfinite(x) else np.inf)
    return sorted(score, key=lambda m: (np.mean(score[m]), m))


def _noise_floor(result) -> np.ndarray:
    """(T,) relative RMS error a perfect model would show from the simulation's own noise:
    √(Σ_E sim·Ω (se/sim)² / Σ_E sim·Ω) over the energy set E (90 % of the energy)."""
    from .analysis.verdicts import energy_set
    omega = result.bins.projected_solid_angle().ravel()
    out = []
    for sim, se in zip(result.brdf, result.stderr):
        sim, se = np.nan_to_num(sim.ravel()), np.nan_to_num(se.ravel())
        e = sim * omega
        k = energy_set(e) & (sim > 0)
        out.append(np.sqrt(np.sum(e[k] * (se[k] / sim[k]) ** 2) / np.sum(e[k]))
                   if k.any() else np.nan)
    return np.array(out)


def _warnings_for(plan: RunPlan, sweep) -> list[str]:
    """Estimator warnings for the stability chart: unresolved rays, lobes narrower than a bin,
    incidences where the sweep's own noise is not far below the 5 % failure line."""
    out = []
    for t, floor in zip(sweep.theta_i, _noise_floor(sweep)):
        if not floor < 0.01:
            out.append(f"θi = {t:g}°: the sweep's own noise alone gives a relative error of "
                       f"≈ {floor:.1%} ({int(sweep.rays[0])} rays): smaller model errors are not "
                       f"resolved there")
    for t, u in zip(sweep.theta_i, sweep.ledger["unresolved"]):
        if u > 0:
            out.append(f"θi = {t:g}°: {u:.2%} of the rays were unresolved (wrap cap or "
                       f"back-facing hits); their energy is missing from the estimate")
    bin_w = 90.0 / sweep.bins.n_theta
    ndf = plan.scene.ndf()
    if ndf is None:
        out.append(f"the reflection lobe of a flat surface is a delta: narrower than any bin "
                   f"({bin_w:g}° wide); relative errors are bin averages of a spike")
    else:
        lobe = 2.0 * math.degrees(float(ndf.tilt_quantile(0.5)))     # median lobe half-width
        if lobe < bin_w:
            out.append(f"the reflection lobe (median half-width ≈ {lobe:.2g}°, twice the median "
                       f"facet tilt) is narrower than a {bin_w:g}° bin: bin averages smear it")
    return out


def _stability(plan: RunPlan):
    """θi sweep with fewer rays: (sweep Result with models, its verdicts)."""
    from .analysis.verdicts import verdicts_for_result
    from .sim import Bins
    e = plan.effort
    bins = Bins(*e.sweep_bins) if e.sweep_bins else plan.bins
    checkpoint("side-studies")
    sweep = _complete(_simulate(plan, e.sweep_theta,
                                max(e.sweep_rays, plan.scene.simulation.realisations),
                                plan.seed + SWEEP_SEED, bins))
    specs = [m for m in _models_for(plan) if e.sweep_facets or m.kind != "facets"]
    _attach(sweep, specs)
    return sweep, verdicts_for_result(sweep)


def _speed_runs(plan: RunPlan, result, shown, verdicts):
    """Estimator variants at a few ray counts: name → (wall times s, relative RMS errors).

    Reference (noise-free): the prescribed model that agrees best (lowest rel_rms) at that
    incidence; without one, the main run (whose own noise then floors the error)."""
    t_index = int(np.argmin(np.abs(np.asarray(plan.theta_i) - 30.0)))
    theta = plan.theta_i[t_index]
    ok = [v for v in verdicts if v.get("agrees") and not v.get("fitted")
          and abs(v["theta_i"] - theta) < 1e-9 and v.get("rel_rms") is not None]
    best = min(ok, key=lambda v: v["rel_rms"])["model"] if ok else None
    ref = shown[best][t_index] if best else result.brdf[t_index]
    label = f"{best} (agrees)" if best else "the main run"
    omega = result.bins.projected_solid_angle()
    runs = {}
    for origins in ("stratified", "independent"):
        times, errs = [], []
        for n in plan.effort.speed_rays:
            checkpoint("side-studies")
            t0 = time.perf_counter()
            r = _complete(_simulate(plan, [theta], n, plan.seed + SPEED_SEED, result.bins,
                                    origins=origins, realisations=False))
            times.append(time.perf_counter() - t0)
            errs.append(_energy_rel_rms(r.brdf[0], ref, omega))
        runs[origins] = (times, errs)
    return runs, theta, label


def _albedo_models(plan: RunPlan, theta_grid):
    """Model ρ(θ) for each Torrance–Sparrow shadowing variant: name → (θ grid, ρ)."""
    from . import analytic as an
    ndf = plan.scene.ndf()
    cos = np.cos(np.radians(theta_grid))
    if ndf is None:
        return {"Fresnel (flat mirror)": (theta_grid, an.fresnel(cos, plan.scene.ior))}
    n_t, n_g, n_p = plan.effort.albedo_nodes
    return {f"TS {kind}": (theta_grid, an.AlbedoTable(ndf, kind, plan.scene.ior, n_theta=n_t,
                                                      n_grazing=n_g, n_gl_phi=n_p).rho(cos))
            for kind in ("vgroove", "smith", "smith-correlated")}


def _nan_for_none(verdicts) -> list[dict]:
    """Verdicts with undefined numbers (null: no used bins / dof ≤ 0) as NaN, for the charts."""
    return [{k: (np.nan if v is None and k in ("chi2_dof", "p_value", "max_abs_z", "rel_rms",
                                                "max_rel_dev") else v) for k, v in d.items()}
            for d in verdicts]


def _charts(plan: RunPlan, stage: Path, result, shown, verdicts, ranking, sweep, sweep_verdicts):
    """Write the scene's PNG charts into ``stage``: name → file name (relative)."""
    from .analysis import charts as ch
    name = plan.scene.name
    files = {}
    files["inplane"] = "inplane.png"
    ch.inplane_curves(result, shown, stage / files["inplane"], name)
    if ranking:
        worst = ranking[-1]
        zs = [(v.get("chi2_dof") or 0.0, k) for k, v in enumerate(
            [v for v in verdicts if v["model"] == worst])]
        t_index = max(zs)[1] if zs else 0
        files["hemisphere"] = "hemisphere.png"
        ch.hemisphere_maps(result, shown, _nan_for_none(verdicts), stage / files["hemisphere"],
                           t_index, name)
    grid = np.linspace(0.0, 89.9, 180)
    files["energy"] = "energy.png"
    ch.energy_chart(sweep.theta_i, sweep.ledger["single_fresnel"], albedo_stderr(sweep),
                    _albedo_models(plan, grid),
                    {"masked": sweep.ledger["masked_fresnel"],
                     "downward": sweep.ledger["downward_fresnel"]},
                    stage / files["energy"], name)
    rel = {m: np.array([next((v["rel_rms"] for v in sweep_verdicts
                              if v["model"] == m and abs(v["theta_i"] - t) < 1e-9), np.nan)
                        for t in sweep.theta_i], dtype=float)
           for m in sweep.models}
    # the sweep's own noise adds its floor² to every model's rel_rms² on average: subtract it
    # so the chart shows the model's error; a model whose excess is below the noise is not drawn
    floor2 = _noise_floor(sweep) ** 2
    excess = {m: np.sqrt(np.where(r ** 2 > floor2, r ** 2 - floor2, np.nan)) for m, r in rel.items()}
    notes = ["relative error = energy-weighted rel RMS with the sweep's own noise subtracted in "
             "quadrature; a missing point: not resolved above the noise"] + _warnings_for(plan, sweep)
    files["stability"] = "stability.png"
    ch.stability_chart(sweep.theta_i, excess, stage / files["stability"], notes, name)
    return files, rel


# --- writing -------------------------------------------------------------------------------
def _clean(obj):
    """JSON-safe copy: numpy → Python, NaN/inf → None, tuples → lists."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, complex):
        return [obj.real, obj.imag]
    return obj


def write_json_atomic(path: Path, data) -> None:
    """Strict JSON (NaN → null) of ``data`` written atomically (``microsim.atomic``)."""
    atomic.write_json(path, _clean(data), allow_nan=False)


def _staging(out: Path) -> Path:
    return atomic.make_staging(out)


def publish_dir(stage: Path, out: Path) -> None:
    """Move the finished ``stage`` directory to ``out`` (``atomic.publish_dir``: the old
    result is removed only once the new one is in place)."""
    atomic.publish_dir(stage, out)


def fit_record(fit) -> dict:
    """JSON form of a ``FitResult`` (Löw E1/E2 with their square roots, as Löw Table II)."""
    e1, e2 = fit.e1, fit.e2
    root = lambda e: math.sqrt(e) if e is not None and np.isfinite(e) and e >= 0 else None  # noqa: E731
    return {"model": fit.name, "params": dict(fit.params), "cost": fit.cost, "e1": e1, "e2": e2,
            "sqrt_e1": root(e1), "sqrt_e2": root(e2), "success": bool(fit.success),
            "n_starts": int(fit.n_starts)}


@dataclass(frozen=True)
class RunOutcome:
    """What ``execute`` produced: exit ``status`` (0, or 130 when interrupted), the output
    directory and, for a finished run, the verdict document (``verdicts.json`` content)."""

    status: int
    out: Path
    document: dict | None = None
    ranking: tuple[str, ...] = ()


def execute(plan: RunPlan, progress: bool = True, log: Callable[[str], None] | None = None) -> RunOutcome:
    """Run a validated plan and write its directory (module docstring). The surface
    generators' UserWarnings are silenced: every surface warning is in meta.json and report.md.
    Holds ``atomic.output_lock(plan.out)`` throughout (a concurrent run on the same output is
    refused with a ``UsageError``) and first removes stale staging directories of killed runs."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        with atomic.output_lock(plan.out):
            atomic.clean_stale(plan.out)
            if plan.partial_dir is not None:
                atomic.clean_stale(plan.partial_dir)
            if plan.previous is None and plan.out.exists():
                if not plan.force:          # appeared since planning
                    raise UsageError(f"{plan.out} already exists; pass --resume {plan.out} to "
                                     f"continue it or --force to replace it")
                _check_replaceable(plan.out)
            return _execute(plan, progress, log)


def _save_tallies(result, dest: Path) -> None:
    """Publish the tallies of ``result`` (brdf.npz + meta.json, no models) to ``dest``."""
    result.models.clear()
    stage = _staging(dest)
    try:
        result.save(stage)
        publish_dir(stage, dest)
    finally:
        if stage.exists():
            shutil.rmtree(stage, ignore_errors=True)


def _execute(plan: RunPlan, progress: bool, log) -> RunOutcome:
    from .analysis import report
    from .analysis.fits import fit_all
    from .analysis.verdicts import verdicts_for_result
    log = log or (lambda s: print(s, file=sys.stderr))
    dest = plan.partial_dir or plan.out
    hint = plan.resume_hint or f"--resume {dest}"
    prev = plan.previous
    done = prev is not None and not prev.is_partial and int(prev.rays[0]) == plan.rays
    if done:
        result = prev
        result.models.clear()
    elif plan.auto:
        result = _simulate_auto(plan, log if progress else None)
    else:
        bar = RayProgress(_remaining_rays(plan), plan.theta_i, plan.scene.name,
                          enabled=progress)
        try:
            result = _simulate(plan, plan.theta_i, plan.rays, plan.seed, plan.bins,
                               progress=bar, resume=prev)
        finally:
            bar.close()
    result.meta["run"] = _run_meta(plan)
    if plan.auto:
        result.meta["run"]["auto"] = _auto_summary(result)
    if result.is_partial:
        _save_tallies(result, dest)
        log(f"microsim: interrupted; partial tallies saved in {dest} (continue with {hint})")
        return RunOutcome(130, plan.out)
    stage = _staging(plan.out)
    try:
        return _analyse(plan, stage, result, report, fit_all, verdicts_for_result, log,
                        progress)
    except KeyboardInterrupt:            # the tallies are complete: keep them, no report
        shutil.rmtree(stage, ignore_errors=True)
        _save_tallies(result, dest)
        log(f"microsim: interrupted after the simulation; tallies saved in {dest} "
            f"(finish with {hint})")
        return RunOutcome(130, plan.out)
    finally:
        if stage.exists():
            shutil.rmtree(stage, ignore_errors=True)


def _analyse(plan, stage, result, report, fit_all, verdicts_for_result, log,
             progress=False) -> RunOutcome:
    sc = plan.scene
    t0 = time.perf_counter()
    stages = StageProgress(sc.name, enabled=progress)
    try:
        stages.stage("models")
        _attach(result, _models_for(plan))
        from .analysis.fits import FIT_MODELS
        stages.stage("fits")
        checkpoint("fits")
        # a flat mirror's lobe is a delta, narrower than any bin: fitting a lobe shape is
        # meaningless
        fits = {} if sc.surface.kind == "flat" else fit_all(
            result, sc.ior, names=plan.effort.fit_names or tuple(FIT_MODELS),
            quick=plan.effort.quick_fits)
        verdicts = verdicts_for_result(result, fitted=fits)
        shown = {**result.models, **{f.name: f.model_values for f in fits.values()}}
        ranking = _ranking(verdicts)
        stages.stage("stability sweep")
        sweep, sweep_verdicts = _stability(plan)
        stages.stage("speed runs")
        speed, speed_theta, speed_ref = _speed_runs(plan, result, shown, verdicts)
        stages.stage("charts")
        checkpoint("charts")
        files, stability = _charts(plan, stage, result, shown, verdicts, ranking, sweep,
                                   sweep_verdicts)
        from .analysis import charts as ch
        files["speed"] = "speed.png"
        ch.speed_accuracy(speed, stage / files["speed"],
                          f"{sc.name}, θi = {speed_theta:g}°",
                          f"relative RMS error against {speed_ref}")
        stages.stage("writing")
        result.meta["seconds_analysis"] = time.perf_counter() - t0
        result.save(stage)
        doc = {"schema_version": SCHEMA_VERSION, "scene": sc.name, "scene_file": str(sc.path),
               "description": sc.description, "quick": plan.quick,
               "rays": int(result.rays.max()) if plan.auto else plan.rays,
               "theta_i": list(plan.theta_i), "seed": plan.seed, "ranking": ranking,
               "verdicts": verdicts, "fits": [fit_record(f) for f in fits.values()],
               "speed": {"theta_i": speed_theta, "reference": speed_ref,
                         "runs": {k: {"rays": list(plan.effort.speed_rays), "rel_rms": e}
                                  for k, (t, e) in speed.items()}},
               "stability": {"theta_i": sweep.theta_i, "rays": plan.effort.sweep_rays,
                             "rel_rms": stability, "warnings": _warnings_for(plan, sweep)}}
        if plan.auto:
            doc["rays_auto"] = _auto_summary(result)
        doc = _clean(doc)
        timings = _clean({"simulation_seconds": result.meta.get("seconds"),
                          "rays_per_second": result.meta.get("rays_per_second"),
                          "analysis_seconds": result.meta["seconds_analysis"],
                          "speed": {"theta_i": speed_theta,
                                    "runs": {k: {"rays": list(plan.effort.speed_rays),
                                                 "seconds": t} for k, (t, e) in speed.items()}}})
        write_json_atomic(stage / VERDICTS_FILE, doc)
        write_json_atomic(stage / TIMINGS_FILE, timings)
        atomic.write_text(stage / REPORT_FILE, report.scene_report(doc, result, files))
    finally:
        stages.close()
    checkpoint("publish")
    publish_dir(stage, plan.out)
    log(f"microsim: wrote {plan.out}/ ({REPORT_FILE}, {VERDICTS_FILE}, {TIMINGS_FILE}, "
        f"brdf.npz, meta.json, {len(files)} charts)")
    return RunOutcome(0, plan.out, doc, tuple(ranking))


# --- the catalogue report --------------------------------------------------------------------
def _fig6_curves(scenes, effort: Effort, threads: int, log) -> list[dict]:
    """Mikkelsen Fig. 6(c)(d) data: the catalogue's vMF V-groove surfaces (κ = 17, 1024) with
    methanol and aluminium: simulated 1 − ρ(θ) (single-bounce albedo, Mikkelsen eq. 27) against
    the model's (V-groove G) and the Fresnel transmittance."""
    from . import analytic as an
    from .sim import Bins, simulate
    vmf = [s for s in scenes if s.surface.kind == "vgrooves" and s.surface.params["ndf"] == "vmf"]
    grid = np.linspace(0.0, 89.9, 180)
    cos = np.cos(np.radians(grid))
    curves = []
    for sc in sorted(vmf, key=lambda s: s.surface.params["kappa"]):
        surface = sc.build_surface(scale=effort.scale_for("vgrooves"))
        for material in ("methanol", "aluminium"):
            ior = an.resolve_material(material)
            checkpoint("side-studies")
            res = _complete(simulate(surface, ior, list(effort.fig6_theta),
                                     rays=effort.fig6_rays, bins=Bins(9, 5),
                                     seed=sc.simulation.seed, threads=threads))
            n_t, n_g, n_p = effort.albedo_nodes
            table = an.AlbedoTable(sc.ndf(), "vgroove", ior, n_theta=n_t, n_grazing=n_g,
                                   n_gl_phi=n_p)
            curves.append({"label": f"{material} κ={sc.surface.params['kappa']:g}",
                           "material": material, "theta": grid,
                           "one_minus_rho_model": 1.0 - table.rho(cos),
                           "fresnel_T": an.fresnel_transmittance(cos, ior),
                           "sim_theta": res.theta_i,
                           "sim_one_minus_rho": 1.0 - res.ledger["single_fresnel"],
                           "sim_err": albedo_stderr(res)})
    return curves


def _read_state(out: Path) -> dict | None:
    path = out / REPORT_STATE
    if not path.is_file():
        return None
    try:
        state = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(state, dict) or not isinstance(state.get("done"), list):
            raise ValueError("not a report state")
        return state
    except (ValueError, UnicodeDecodeError) as e:
        raise UsageError(f"--resume: {path} is unreadable ({' '.join(str(e).split())}); run "
                         f"`microsim report` without --resume") from None


def run_report(catalogue="surfaces", out="reports", quick=False, threads=2, progress=True,
               log: Callable[[str], None] | None = None, resume=False) -> int:
    """Run every ``*.toml`` of ``catalogue`` into ``out/<scene>/`` (each folder replaced in one
    rename) and write ``out/index.md``. All scene files are validated before anything runs.

    Ctrl-C (status 130): finished scenes stay; the interrupted scene's previous report stays
    in place and its tallies are kept in ``out/.<scene>.partial/``; ``resume=True``
    (``report --resume``, same options) skips the scenes finished since the interrupted report
    started (``out/.report-state.json``), continues the interrupted one from its tallies and
    runs the rest. Holds ``atomic.output_lock(out)`` throughout."""
    from .analysis import charts as ch
    from .analysis import report
    from .scene import load_scene
    log = log or (lambda s: print(s, file=sys.stderr))
    catalogue, out = Path(catalogue), Path(out)
    if not catalogue.is_dir():
        raise UsageError(f"--catalogue {catalogue}: not a directory")
    paths = sorted(catalogue.glob("*.toml"))
    if not paths:
        raise UsageError(f"--catalogue {catalogue}: no *.toml scene files")
    scenes = [load_scene(p) for p in paths]
    names = [s.name for s in scenes]
    if len(set(names)) != len(names):
        raise UsageError(f"--catalogue {catalogue}: scene names must be unique, got {names}")
    norm = Path(os.path.normpath(out))
    cwd, cat = Path.cwd().resolve(), catalogue.resolve()
    if (norm.name in ("", ".", "..") or norm.resolve() in (cwd, *cwd.parents)
            or norm.resolve() == cat or norm.resolve() in cat.parents):
        raise UsageError(f"--out {out}: must be a directory of its own, not the current "
                         f"directory, a parent of it or the catalogue's")
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: exists and is not a directory")
    hint = (f"`microsim report --resume{' --quick' if quick else ''} --catalogue {catalogue} "
            f"--out {out}`")
    with atomic.output_lock(out):
        state = _read_state(out) if resume else None
        if resume:
            if state is None:
                raise UsageError(f"--resume: no interrupted report in {out} ({REPORT_STATE} "
                                 f"missing); run `microsim report` without --resume")
            if state.get("quick") != bool(quick) or state.get("catalogue") != str(catalogue):
                raise UsageError(f"--resume: the interrupted report in {out} ran with quick = "
                                 f"{state.get('quick')}, catalogue {state.get('catalogue')}; "
                                 f"resume with the same options")
        done = set(state["done"]) if state else set()
        plans = []
        for p, s in zip(paths, scenes):
            scene_out, partial = out / s.name, out / f".{s.name}.partial"
            if s.name in done and (scene_out / VERDICTS_FILE).is_file():
                plans.append(scene_out)
                continue
            tallies = partial if resume and (partial / "meta.json").is_file() else None
            plans.append(plan_run(p, out=scene_out, threads=threads, quick=quick, force=True,
                                  tallies=tallies, partial_dir=partial, resume_hint=hint))
        state = {"quick": bool(quick), "catalogue": str(catalogue), "done": sorted(done)}
        atomic.write_json(out / REPORT_STATE, state)
        try:
            docs = []
            for k, plan in enumerate(plans, 1):
                checkpoint("report-scene")
                if isinstance(plan, Path):
                    log(f"[{k}/{len(plans)}] {plan.name}: finished earlier, kept")
                    docs.append(json.loads((plan / VERDICTS_FILE).read_text(encoding="utf-8")))
                    continue
                log(f"[{k}/{len(plans)}] {plan.scene.name}")
                outcome = execute(plan, progress=progress, log=log)
                if outcome.status != 0:
                    return outcome.status
                shutil.rmtree(plan.partial_dir, ignore_errors=True)
                docs.append(outcome.document)
                state["done"] = sorted({*state["done"], plan.scene.name})
                atomic.write_json(out / REPORT_STATE, state)
            checkpoint("report-index")
            effort = QUICK if quick else FULL
            fig6 = None
            curves = _fig6_curves(scenes, effort, threads, log)
            if curves:
                fig6 = "mikkelsen-fig6.png"
                ch.mikkelsen_fig6(curves, out / fig6, "V-grooves, vMF NDF")
            atomic.write_text(out / "index.md", report.index_report(docs, fig6, quick))
        except KeyboardInterrupt:
            log(f"microsim: interrupted; finished scene reports kept in {out}; continue with "
                f"{hint}")
            return 130
        (out / REPORT_STATE).unlink(missing_ok=True)
    log(f"microsim: wrote {out}/index.md ({len(docs)} scenes)")
    return 0
