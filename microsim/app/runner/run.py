"""``execute``: one planned run, from the simulation to the published directory.

1. simulate the scene (``tracing``; a ``rays = "auto"`` scene with ``simulate_auto``);
2. evaluate the default closed forms on the same bins and fit the parametric ones;
3. judge every (incidence, model) pair (``verdicts_for_result``);
4. side studies (``side_studies``): stability sweep and speed runs;
4b. a scene with ``[wave]``: the Kirchhoff solver on the same tiles and the wave verdicts
   (``wave_run``; saved in ``kirchhoff/``, verdicts.json ``"wave"``);
4c. a run with ``bounces`` > 1: the scattering orders against the random walk and the
   energy compensations (``orders``; verdicts.json ``"orders"``, report "Scattering orders");
4d. a scene with ``[material] transmission``: the surface lit from inside the medium too, and
   R, T and Walter et al. 2007's verdicts from both sides (``glass``; saved in ``inside/``,
   verdicts.json ``"glass"``, report "Rough glass");
5. write brdf.npz + meta.json, verdicts.json, timings.json, the PNG charts and report.md into
   a staging directory and publish it in one rename (``publishing``).

An interrupted simulation, or an interrupt after it, saves the tallies for ``--resume``
(status 130); so does a Dask scheduler lost during the simulation (``--scheduler``), then an
``EnvironmentFailure`` naming it (status 1). No report is written from partial work, and no
finished result is replaced by it: tallies read from the output (a finished run re-analysed)
are not written again, and a ``--force`` run leaves a finished output as it was. A Ctrl-C while
the finished directory is moved in waits until it is in place (status 130, the result
complete). An output a killed run was replacing is recovered first
(``atomic.recover_publish``).
"""

from __future__ import annotations

import shutil
import sys
import time
import warnings
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ... import atomic
from ...analysis import charts as ch
from ...analysis import report
from ...analysis.anisotropy import anisotropy_summary
from ...analysis.budget import error_budget
from ...analysis.fits import FIT_MODELS, fit_all
from ...analysis.glass_report import glass_chart
from ...analysis.multiple_report import multiple_chart
from ...analysis.pictures import appearance
from ...analysis.report import albedo_stderr
from ...analysis.verdicts import verdicts_for_result
from ...checkpoints import checkpoint
from ...errors import EnvironmentFailure, UsageError
from ...sim import SchedulerLost
from ...sim.schedule import DeferredInterrupt
from ..cluster import connect
from . import glass, orders, side_studies, tracing, wave_run
from .planning import RunPlan, check_replaceable
from .progress import RayProgress, StageProgress
from .publishing import (
    CHARTS,
    OUTSIDE_DOMAIN,
    REPORT_FILE,
    TIMINGS_FILE,
    VERDICTS_FILE,
    holds_finished_result,
    publish_dir,
    save_tallies,
    staging,
    timings_document,
    verdict_document,
)

__all__ = ["RunOutcome", "execute"]


@dataclass(frozen=True)
class RunOutcome:
    """What ``execute`` produced: exit ``status`` (0, or 130 when interrupted), the output
    directory and, for a finished run, the verdict document (``verdicts.json`` content)."""

    status: int
    out: Path
    document: dict | None = None
    ranking: tuple[str, ...] = ()


def execute(
    plan: RunPlan, progress: bool = True, log: Callable[[str], None] | None = None
) -> RunOutcome:
    """Run a validated plan and write its directory (module docstring). The surface
    generators' UserWarnings are silenced: every surface warning is in meta.json and report.md.
    Holds ``atomic.output_lock(plan.out)`` throughout (a concurrent run on the same output is
    refused with a ``UsageError``) and first removes stale staging directories of killed runs."""
    log = log or (lambda s: print(s, file=sys.stderr))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        with atomic.output_lock(plan.out):
            recovered = atomic.recover_publish(plan.out)
            atomic.clean_stale(plan.out)
            if plan.partial_dir is not None:
                atomic.clean_stale(plan.partial_dir)
            if plan.previous is None and plan.out.exists():
                if not plan.force:  # appeared since planning, or put back just now
                    raise UsageError(
                        f"{recovered or f'{plan.out} already exists'}; pass --resume "
                        f"{plan.out} to continue it or --force to replace it"
                    )
                check_replaceable(plan.out)
            if recovered:
                log(f"microsim: {recovered}")
            return _execute(plan, progress, log)


def _execute(plan: RunPlan, progress: bool, log) -> RunOutcome:
    dest = plan.partial_dir or plan.out
    hint = plan.resume_hint or f"--resume {dest}"
    prev = plan.previous
    record = report.auto_realisations(prev.info.run or {}) if prev is not None else None
    from_previous = prev is not None and not prev.is_partial and int(prev.rays[0]) == plan.rays
    if from_previous:
        result = prev.with_models({})  # finished tallies: only the analysis is left
    elif plan.auto:
        result = tracing.simulate_auto_scene(plan, log if progress else None)
    elif plan.auto_realisations and (record is None or record.stage == "pilot"):
        pilot_plan, pilot = plan, _trace(plan, prev, progress)
        record = tracing.realisations_record(plan, plan, None, "pilot")
        result = pilot
        if not pilot.is_partial:
            plan = tracing.choose_realisations(pilot_plan, pilot)
            record = tracing.realisations_record(plan, pilot_plan, pilot, "final")
            if plan.realisations > pilot_plan.realisations:
                log(
                    f"microsim: {plan.scene.name}: {plan.realisations} realisations for a tile "
                    f"scatter ≤ {plan.realisation_target:.1%} (pilot of "
                    f"{pilot_plan.realisations})"
                )
                keep = pilot if tracing.pilot_continues(pilot_plan, plan) else None
                result = _trace(plan, keep, progress)
    else:
        result = _trace(plan, prev, progress)
    run = tracing.run_meta(plan)
    if record is not None:
        run["realisations_auto"] = record
    if plan.auto:
        run["auto"] = tracing.auto_summary(result)
    result = result.with_meta(run=run)
    if result.is_partial and result.info.scheduler_lost:
        kept = _keep(plan, result, dest, "partial tallies", f"continue with {hint}", False)
        raise EnvironmentFailure(
            f"--scheduler {plan.scheduler}: the Dask scheduler was lost mid-run; {kept}"
        )
    if result.is_partial:
        return _interrupted(
            plan, result, dest, log, "", "partial tallies", f"continue with {hint}", from_previous
        )
    result = result.with_meta(error_budget=error_budget(result))
    stage = staging(plan.out)
    try:
        return _analyse(plan, stage, result, log, progress)
    except KeyboardInterrupt:  # the tallies are complete: keep them, no report
        if not stage.exists():  # published: the result is complete
            log(f"microsim: interrupted after {plan.out} was written completely")
            return RunOutcome(130, plan.out)
        shutil.rmtree(stage, ignore_errors=True)
        return _interrupted(
            plan,
            result,
            dest,
            log,
            " after the simulation",
            "tallies",
            f"finish with {hint}",
            from_previous,
        )
    finally:
        if stage.exists():
            shutil.rmtree(stage, ignore_errors=True)


def _interrupted(
    plan: RunPlan, result, dest: Path, log, when: str, what: str, how: str, from_previous: bool
):
    """Status 130 after Ctrl-C, the tallies kept as ``_keep`` says."""
    log(f"microsim: interrupted{when}; {_keep(plan, result, dest, what, how, from_previous)}")
    return RunOutcome(130, plan.out)


def _keep(plan: RunPlan, result, dest: Path, what: str, how: str, from_previous: bool) -> str:
    """Save the tallies of a run cut short in ``dest`` for ``--resume`` unless that would lose
    something, and say what was done: tallies read from ``dest`` (``from_previous``:
    ``result`` derives from ``plan.previous``) are not written again (a finished run
    re-analysed keeps its report), and a run replacing a finished result (``--force``) leaves
    it as it was, dropping its own tallies."""
    if from_previous:
        return f"{dest} is unchanged ({how})"
    if plan.partial_dir is None and plan.previous is None and holds_finished_result(dest):
        return (
            f"{dest} keeps its finished result (this run's tallies are dropped; rerun with "
            f"--force to replace it)"
        )
    save_tallies(result, dest)
    return f"{what} saved in {dest} ({how})"


def _trace(plan: RunPlan, prev, progress: bool):
    """The main simulation of ``plan`` with a progress bar, continuing ``prev``'s tallies; a
    lost scheduler gives its partial result (``info.scheduler_lost``), as an interrupt
    does."""
    bar = RayProgress(tracing.remaining_rays(plan, prev).sum(), plan.scene.name, enabled=progress)
    theta_i, phi_i = plan.incidences
    try:
        with ExitStack() as stack:
            client = None
            if plan.scheduler is not None:  # closed after the tracing: the rest runs here
                client = stack.enter_context(connect(plan.scheduler))
            return tracing.simulate_scene(
                plan,
                theta_i,
                plan.rays,
                plan.seed,
                plan.bins,
                progress=bar,
                resume=prev,
                bounces=plan.scene.simulation.bounces,
                phi_i=phi_i,
                cluster=client,
            )
    except SchedulerLost as lost:
        return lost.partial
    finally:
        bar.close()


def _analyse(plan: RunPlan, stage: Path, result, log, progress: bool) -> RunOutcome:
    """Models, fits, verdicts, side studies, charts and documents into ``stage``, then publish."""
    sc = plan.scene
    t0 = time.perf_counter()
    has_orders = getattr(result, "brdf_orders", None) is not None and not sc.transmission
    stages = StageProgress(
        sc.name,
        enabled=progress,
        extra=int(sc.wave is not None) + int(has_orders) + int(sc.transmission),
    )
    try:
        stages.stage("models")
        specs = side_studies.models_for(plan)
        result = side_studies.attach(result, specs)
        stages.stage("fits")
        checkpoint("fits")
        fits = _fits(plan, result)
        verdicts = verdicts_for_result(result, fitted=fits)
        shown = {**result.models, **{f.name: f.model_values for f in fits.values()}}
        ranking = _ranking(verdicts)
        stages.stage("stability sweep")
        sweep, sweep_verdicts = side_studies.stability(plan)
        notes = side_studies.estimator_warnings(plan, sweep)
        stages.stage("speed runs")
        speed, speed_theta, speed_ref = side_studies.speed_runs(plan, result, shown, verdicts)
        kres, wave, wave_seconds = None, None, None
        if sc.wave is not None:
            stages.stage("wave optics")
            checkpoint("side-studies")
            kres, wave, wave_seconds = wave_run.run_wave(plan, result)
        orders_doc = None
        if has_orders:
            stages.stage("scattering orders")
            orders_doc = orders.orders_study(plan, result, specs)
        inside, glass_doc, glass_models = None, None, {}
        if sc.transmission:
            stages.stage("rough glass")
            inside = glass.trace_inside(plan)
            glass_doc, glass_models = glass.rough_glass(plan, result, inside, specs)
        stages.stage("charts")
        checkpoint("charts")
        files, stability = _charts(
            plan, stage, result, shown, verdicts, ranking, sweep, sweep_verdicts, notes
        )
        comparison = (orders_doc or {}).get("comparison")
        files = _study_charts(plan, stage, files, comparison, (speed, speed_theta, speed_ref))
        if inside is not None:
            path = _chart_path(files, stage, "glass")
            glass_chart(result, inside, glass_models, path, sc.name)
        stages.stage("writing")
        result = result.with_meta(seconds_analysis=time.perf_counter() - t0)
        result.save(stage)
        if kres is not None:
            kres.save(stage / wave_run.WAVE_DIR)
        if inside is not None:
            inside.save(stage / glass.INSIDE_DIR)
        doc = verdict_document(
            plan,
            result,
            ranking,
            verdicts,
            fits,
            speed,
            speed_theta,
            speed_ref,
            sweep,
            stability,
            notes,
            wave,
        )
        aniso = anisotropy_summary(result, verdicts, comparison) if sc.anisotropic else None
        studies = {"orders": orders_doc, "glass": glass_doc, "anisotropy": aniso}
        doc.update({k: atomic.json_safe(v) for k, v in studies.items() if v is not None})
        atomic.write_json(stage / VERDICTS_FILE, doc)
        timings = timings_document(plan, result, speed, speed_theta)
        timings["analysis_stage_seconds"] = dict(stages.seconds)  # the stages before writing
        if wave_seconds is not None:
            timings["wave_seconds"] = wave_seconds
        atomic.write_json(stage / TIMINGS_FILE, timings)
        atomic.write_text(stage / REPORT_FILE, report.scene_report(doc, result, files))
    finally:
        stages.close()
    checkpoint("publish")
    status = _publish(plan, stage, len(files), log)
    return RunOutcome(status, plan.out, doc, tuple(ranking))


def _fits(plan: RunPlan, result) -> dict:
    """The fitted models of the scene's effort (none on a flat mirror: its lobe is a delta,
    narrower than any bin, so fitting a lobe shape is meaningless)."""
    if plan.scene.surface.kind == "flat":
        return {}
    return fit_all(
        result,
        plan.scene.ior,
        names=plan.effort.fit_names or tuple(FIT_MODELS),
        quick=plan.effort.quick_fits,
    )


def _chart_path(files: dict, stage: Path, key: str) -> Path:
    """The path in ``stage`` of chart ``key`` (``CHARTS``), entered in ``files`` (key → file
    name) in the order the report shows them."""
    files[key] = CHARTS[key]
    return stage / CHARTS[key]


def _study_charts(plan: RunPlan, stage: Path, files: dict, comparison, speed_study) -> dict:
    """``files`` with the side studies' charts written into ``stage``: the scattering orders'
    ``comparison`` (first, when the run has one) and the speed chart of ``speed_study`` (the
    speed runs, their θi and the reference they are judged against)."""
    name = plan.scene.name
    speed, speed_theta, speed_ref = speed_study
    first: dict = {}
    if comparison is not None:
        multiple_chart(comparison, _chart_path(first, stage, "multiple"), name)
    files = {**first, **files}
    ch.speed_accuracy(
        speed,
        _chart_path(files, stage, "speed"),
        f"{name}, θi = {speed_theta:g}°",
        f"relative RMS error against {speed_ref}",
    )
    return files


def _publish(plan: RunPlan, stage: Path, charts: int, log) -> int:
    """Move ``stage`` into place as ``plan.out`` (a Ctrl-C meanwhile waits until the directory
    is in place) and say what was written; the status: 130 when a Ctrl-C came, else 0."""
    with DeferredInterrupt() as stop:
        publish_dir(stage, plan.out)
    wrote = (
        f"{plan.out}/ ({REPORT_FILE}, {VERDICTS_FILE}, {TIMINGS_FILE}, brdf.npz, meta.json, "
        f"{charts} charts)"
    )
    if stop.is_set():
        log(f"microsim: interrupted while publishing; wrote {wrote} completely")
        return 130
    log(f"microsim: wrote {wrote}")
    return 0


def _ranking(verdicts) -> list[str]:
    """Model names from best to worst by mean relative RMS error over the incidences."""
    score: dict[str, list[float]] = {}
    for v in verdicts:
        x = v.rel_rms
        score.setdefault(v.model, []).append(x if x is not None and np.isfinite(x) else np.inf)
    return sorted(score, key=lambda m: (np.mean(score[m]), m))


_UNDEFINED_AS_NAN = ("chi2_dof", "p_value", "max_abs_z", "rel_rms", "max_rel_dev")


def _nan_for_none(verdicts) -> list[dict]:
    """Verdicts with undefined numbers (null: no used bins / dof ≤ 0) as NaN, for the charts."""
    return [
        {k: np.nan if x is None and k in _UNDEFINED_AS_NAN else x for k, x in v.items()}
        for v in verdicts
    ]


def _charts(
    plan: RunPlan,
    stage: Path,
    result,
    shown,
    verdicts,
    ranking,
    sweep,
    sweep_verdicts,
    estimator_notes: list[str],
):
    """Write the scene's PNG charts into ``stage``: (name → file name (relative), the
    sweep's rel_rms per model over its θi). ``estimator_notes``: for the stability
    chart."""
    name = plan.scene.name
    files: dict = {}
    ch.inplane_curves(result, shown, _chart_path(files, stage, "inplane"), name)
    judged = {k: v for k, v in shown.items() if k not in OUTSIDE_DOMAIN}
    ranking = [m for m in ranking if m in judged]  # best/worst among models in their domain
    if ranking:
        worst = ranking[-1]
        zs = [
            (v.chi2_dof or 0.0, k) for k, v in enumerate([v for v in verdicts if v.model == worst])
        ]
        t_index = max(zs)[1] if zs else 0
        shown_verdicts = _nan_for_none(verdicts)
        path = _chart_path(files, stage, "hemisphere")
        ch.hemisphere_maps(result, judged, shown_verdicts, path, t_index, name)
        path = _chart_path(files, stage, "appearance")
        appearance(result, judged, shown_verdicts, t_index, path, name)
    grid = np.linspace(0.0, 89.9, 180)
    ch.energy_chart(
        sweep.theta_i,
        sweep.ledger["single_fresnel"],
        albedo_stderr(sweep),
        side_studies.albedo_models(plan, grid),
        {"masked": sweep.ledger["masked_fresnel"], "downward": sweep.ledger["downward_fresnel"]},
        _chart_path(files, stage, "energy"),
        name,
    )
    rel = {
        m: np.array(
            [
                next(
                    (
                        v.rel_rms
                        for v in sweep_verdicts
                        if v.model == m and abs(v.theta_i - t) < 1e-9
                    ),
                    np.nan,
                )
                for t in sweep.theta_i
            ],
            dtype=float,
        )
        for m in sweep.models
    }
    # the sweep's own noise adds its floor² to every model's rel_rms² on average: subtract it
    # so the chart shows the model's error; a model whose excess is below the noise is not drawn
    floor2 = side_studies.noise_floor(sweep) ** 2
    excess = {m: np.sqrt(np.where(r**2 > floor2, r**2 - floor2, np.nan)) for m, r in rel.items()}
    notes = [
        "relative error = energy-weighted rel RMS with the sweep's own noise subtracted in "
        "quadrature; a missing point: not resolved above the noise"
    ] + estimator_notes
    path = _chart_path(files, stage, "stability")
    ch.stability_chart(sweep.theta_i, excess, path, notes, name)
    return files, rel
