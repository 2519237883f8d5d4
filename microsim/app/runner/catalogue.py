"""``run_report``: ``microsim report``, every scene of a catalogue into ``OUT/<scene>/`` and
the catalogue index ``OUT/index.md`` with the Mikkelsen Fig. 6 chart and, when the catalogue
has a scene with a wavelength, the section "Where each method holds" (the wave scenes'
verdicts against Kirchhoff, the regime chart ``regimes.png`` and the crossover table,
``wave_run.regime_maps``)."""

from __future__ import annotations

import dataclasses
import hashlib
import os
import shutil
import sys
from pathlib import Path
from typing import Callable

from ... import atomic
from ...analysis import charts as ch
from ...analysis import report
from ...analysis.fullwave_map import FULLWAVE_JSON
from ...analysis.study_records import RegimeMaps
from ...checkpoints import checkpoint
from ...errors import UsageError
from ..bench_methods import METHODS_JSON, METHODS_PNG
from ..cluster import check_address, connect
from ..scene import catalogue_dir, load_scene
from . import planning
from .publishing import (
    REPORT_STATE,
    VERDICTS_FILE,
    ReportState,
    read_report_state,
    write_report_state,
)
from .run import execute
from .side_studies import fig6_curves
from .wave_run import regime_maps

__all__ = ["run_report"]

INDEX_FILE, FIG6_CHART, REGIME_CHART = "index.md", "mikkelsen-fig6.png", "regimes.png"
RESERVED_NAMES = frozenset((INDEX_FILE, FIG6_CHART, REGIME_CHART, METHODS_JSON, METHODS_PNG))
"""Files of the report directory itself (the index and its charts, ``microsim bench
--methods``'s study): no scene may be named like one (its folder would take the place)."""


def _check_scene_names(paths, scenes, out: Path) -> None:
    """Refuse a scene named like one of ``RESERVED_NAMES`` (letter case aside: some file
    systems ignore it)."""
    reserved = {n.lower() for n in RESERVED_NAMES}
    for path, scene in zip(paths, scenes):
        if scene.name.lower() in reserved:
            raise UsageError(
                f"{path}: name: {scene.name!r} clashes with the report's own file "
                f"{out / scene.name.lower()}; give the scene another name (reserved: "
                f"{', '.join(sorted(RESERVED_NAMES))})"
            )


def _scene_digest(path: Path, scene) -> str:
    """SHA-256 of what a scene's result depends on in files: the scene file and, for a
    ``kind = "file"`` surface, its heightfield file."""
    h = hashlib.sha256(path.read_bytes())
    if scene.surface.kind == "file":
        with open(path.parent / scene.surface.params["path"], "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


def _regimes(out: Path, quick: bool) -> RegimeMaps:
    """Regime maps, their chart ``out/REGIME_CHART`` and what the index prints of them."""
    from ...analysis.regimes import regime_chart

    rm = RegimeMaps.from_json(regime_maps(quick))
    fig = regime_chart(rm.maps)
    with atomic.atomic_open(str(out / REGIME_CHART), "wb") as fh:
        fig.savefig(fh, format="png", dpi=100)
    return dataclasses.replace(rm, chart=REGIME_CHART)


def _check_catalogue_out(catalogue: Path, out: Path) -> None:
    norm = Path(os.path.normpath(out))
    cwd, cat = Path.cwd().resolve(), catalogue.resolve()
    if (
        norm.name in ("", ".", "..")
        or norm.resolve() in (cwd, *cwd.parents)
        or norm.resolve() == cat
        or norm.resolve() in cat.parents
    ):
        raise UsageError(
            f"--out {out}: must be a directory of its own, not the current "
            f"directory, a parent of it or the catalogue's"
        )
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: exists and is not a directory")


def _finished_verdicts(scene_out: Path, log: Callable[[str], None]) -> dict | None:
    """The verdicts of a scene the interrupted report finished, or None when its verdicts.json
    is missing or damaged (``atomic.read_json``; said in one line): the scene is run again."""
    try:
        return atomic.read_json(scene_out / VERDICTS_FILE)
    except UsageError as e:
        log(f"microsim: {e}; running {scene_out.name} again")
        return None


def _load_catalogue(catalogue: Path, out: Path) -> tuple[list[Path], list]:
    """The scene files of ``catalogue`` and their scenes, every one validated: unique names,
    none named like a file of the report, the catalogue not inside ``out``."""
    if not catalogue.is_dir():
        raise UsageError(f"--catalogue {catalogue}: not a directory")
    paths = sorted(catalogue.glob("*.toml"))
    if not paths:
        raise UsageError(f"--catalogue {catalogue}: no *.toml scene files")
    scenes = [load_scene(p) for p in paths]
    names = [s.name for s in scenes]
    if len(set(names)) != len(names):
        raise UsageError(f"--catalogue {catalogue}: scene names must be unique, got {names}")
    _check_scene_names(paths, scenes, out)
    _check_catalogue_out(catalogue, out)
    return paths, scenes


def _resumed_state(out: Path, quick: bool, catalogue: Path) -> ReportState:
    """The interrupted report's state in ``out``, refused when there is none or it ran with
    other options."""
    state = read_report_state(out)
    if state is None:
        raise UsageError(
            f"--resume: no interrupted report in {out} ({REPORT_STATE} "
            f"missing); run `microsim report` without --resume"
        )
    if state.quick != bool(quick) or state.catalogue != str(catalogue):
        raise UsageError(
            f"--resume: the interrupted report in {out} ran with quick = "
            f"{state.quick}, catalogue {state.catalogue}; "
            f"resume with the same options"
        )
    return state


def _plan_scenes(paths, scenes, out: Path, done: set, reusable: set, log, scheduler, **options):
    """(plans, finished verdicts): per scene, its folder in ``out`` when it is in ``done`` and
    its verdicts read back (``finished``), else its ``planning.plan_run`` (``options``), which
    continues from the scene's saved tallies when it is in ``reusable``; ``rays = "auto"``
    scenes trace locally, the rest on ``scheduler``."""
    plans, finished = [], {}
    for p, s in zip(paths, scenes):
        scene_out, partial = out / s.name, out / f".{s.name}.partial"
        if s.name in done:
            finished[s.name] = _finished_verdicts(scene_out, log)
        if finished.get(s.name) is not None:
            plans.append(scene_out)
            continue
        saved = s.name in reusable and (partial / "meta.json").is_file()
        plans.append(
            planning.plan_run(
                p,
                out=scene_out,
                force=True,
                tallies=partial if saved else None,
                partial_dir=partial,
                scheduler=None if s.simulation.rays == "auto" else scheduler,
                **options,
            )
        )
    return plans, finished


def _run_scenes(plans, finished: dict, state: ReportState, out: Path, progress, log):
    """(status, verdict documents): run the plans in turn (a finished scene's folder keeps its
    ``finished`` verdicts), recording each finished scene in ``state``; the first scene that
    does not finish ends the run with its status."""
    docs = []
    for k, plan in enumerate(plans, 1):
        checkpoint("report-scene")
        if isinstance(plan, Path):
            log(f"[{k}/{len(plans)}] {plan.name}: finished earlier, kept")
            docs.append(finished[plan.name])
            continue
        log(f"[{k}/{len(plans)}] {plan.scene.name}")
        outcome = execute(plan, progress=progress, log=log)
        if outcome.status != 0:
            return outcome.status, docs
        shutil.rmtree(plan.partial_dir, ignore_errors=True)
        docs.append(outcome.document)
        state = state.finished(plan.scene.name)
        write_report_state(out, state)
    return 0, docs


def _write_index(out: Path, docs: list, scenes: list, quick, threads, regimes) -> None:
    """``out/index.md`` over the scenes' verdict documents, with the Fig. 6 chart when a scene
    asks for it and the regime maps when ``regimes`` (None: when some scene has ``[wave]``)."""
    fig6 = None
    curves = fig6_curves(scenes, planning.effort_for(quick), threads)
    if curves:
        fig6 = FIG6_CHART
        ch.mikkelsen_fig6(curves, out / fig6, "V-grooves, vMF NDF")
    regime = None
    if regimes or (regimes is None and any(s.wave is not None for s in scenes)):
        regime = _regimes(out, quick)
    atomic.write_text(
        out / INDEX_FILE,
        report.index_report(
            docs,
            fig6,
            quick,
            regimes=regime,
            methods=out / METHODS_JSON,
            fullwave=out / FULLWAVE_JSON,
        ),
    )


def run_report(
    catalogue=None,
    out="reports",
    quick=False,
    threads=2,
    progress=True,
    log: Callable[[str], None] | None = None,
    resume=False,
    regimes: bool | None = None,
    scheduler: str | None = None,
) -> int:
    """Run every ``*.toml`` of ``catalogue`` (None: the packaged catalogue,
    ``scene.catalogue_dir``) into ``out/<scene>/`` (each folder replaced in one
    rename) and write ``out/index.md``. All scene files are validated before anything runs.

    Ctrl-C (status 130): finished scenes stay; the interrupted scene's previous report stays
    in place and its tallies are kept in ``out/.<scene>.partial/``; ``resume=True``
    (``report --resume``, same options) skips the scenes finished since the interrupted report
    started (``out/.report-state.json``), continues the interrupted one from its tallies and
    runs the rest; a scene whose scene file (or heightfield file) changed since is run anew,
    its old report and tallies unused. Holds ``atomic.output_lock(out)`` throughout.
    ``regimes``: compute the regime maps for the index (None: when some scene has
    ``[wave]``; reduced in quick mode). A scene named like a file of the report itself
    (``RESERVED_NAMES``) is refused before anything runs. ``scheduler``: a Dask scheduler
    address whose workers trace each scene's main simulation (``plan_run``; the scenes run
    one after another, each bitwise as locally; ``rays = "auto"`` scenes trace locally)."""
    log = log or (lambda s: print(s, file=sys.stderr))
    given = "" if catalogue is None else f" --catalogue {catalogue}"
    catalogue, out = catalogue_dir() if catalogue is None else Path(catalogue), Path(out)
    paths, scenes = _load_catalogue(catalogue, out)
    digests = {s.name: _scene_digest(p, s) for p, s in zip(paths, scenes)}
    hint = f"`microsim report --resume{' --quick' if quick else ''}{given} --out {out}`"
    if scheduler is not None:  # an unusable address fails here, before anything is written
        with connect(check_address(scheduler)):
            pass
    with atomic.output_lock(out):
        state = _resumed_state(out, quick, catalogue) if resume else None
        recorded = state.digests if state else {}
        unchanged = {name for name, digest in recorded.items() if digests.get(name) == digest}
        done = set(state.done) & unchanged if state else set()
        plans, finished = _plan_scenes(
            paths,
            scenes,
            out,
            done,
            unchanged if resume else set(),
            log,
            threads=threads,
            quick=quick,
            resume_hint=hint,
            scheduler=scheduler,
        )
        state = ReportState(bool(quick), str(catalogue), tuple(sorted(done)), digests)
        write_report_state(out, state)
        try:
            status, docs = _run_scenes(plans, finished, state, out, progress, log)
            if status != 0:
                return status
            checkpoint("report-index")
            _write_index(out, docs, scenes, quick, threads, regimes)
        except KeyboardInterrupt:
            log(
                f"microsim: interrupted; finished scene reports kept in {out}; continue with {hint}"
            )
            return 130
        (out / REPORT_STATE).unlink(missing_ok=True)
    log(f"microsim: wrote {out}/index.md ({len(docs)} scenes)")
    return 0
