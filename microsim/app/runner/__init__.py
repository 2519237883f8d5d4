"""`microsim run` and `microsim report`: simulate scenes, compare, fit, judge and write reports.

Modules, in the order a run uses them:

- ``planning``: ``Effort`` (``FULL``, ``QUICK`` = exactly what ``--quick`` changes),
  ``plan_run``: every option and path validated before anything is written;
- ``tracing``: the scene's simulations (realisation r built with seed ``seed + r``);
- ``side_studies``: the model set, stability sweep, speed runs, albedo tables, Fig. 6 curves;
- ``publishing``: staging, publishing in one rename, verdicts.json / timings.json, saved
  tallies;
- ``run``: ``execute`` (one plan) and ``catalogue``: ``run_report`` (every scene + index.md);
- ``progress``: the stderr progress bars.

Ctrl-C during the simulation keeps the tallies so far: they are saved with
``meta["partial"] = True`` (exit status 130) and ``--resume DIR`` continues them to the requested
ray count, giving the same tallies as an uninterrupted run. Ctrl-C after the simulation (side
studies, fits, charts) saves the complete tallies the same way (130), never over a finished
result; while the finished directory is moved in it waits until that is done (130); a side
study cut short is never used for a report. ``microsim report`` keeps the tallies of an interrupted
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
"""

from __future__ import annotations

from .catalogue import run_report
from .planning import AUTO_MAX_RAYS, AUTO_TARGET, FULL, QUICK, Effort, RunPlan, plan_run
from .publishing import REPORT_FILE, REPORT_STATE, TIMINGS_FILE, VERDICTS_FILE, publish_dir
from .run import RunOutcome, execute

__all__ = [
    "Effort",
    "FULL",
    "QUICK",
    "AUTO_TARGET",
    "AUTO_MAX_RAYS",
    "RunPlan",
    "RunOutcome",
    "plan_run",
    "execute",
    "run_report",
    "publish_dir",
    "VERDICTS_FILE",
    "REPORT_FILE",
    "TIMINGS_FILE",
    "REPORT_STATE",
]
