"""`microsim sweep SWEEP.toml`: a grid of scenes × parameters × incidences, one verdict table.

Sweep file (TOML, UTF-8)::

    name = "vgroove-roughness"          # default: the file stem; names the default output
    description = "..."                 #   directory sweeps/out/<name>
    rays = 200_000                      # primary rays per task (one task = one θi)
    seed = 0
    theta_bins = 45                     # outgoing bins (folded Δφ)
    phi_bins = 37
    models = ["vgroove", "smith"]       # Torrance–Sparrow shadowing variants to judge
                                        #   (oriented V-grooves: "vgroove" alone, required)
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
prediction with the scene's NDF (oriented V-grooves: ``ts-vgroove-oriented`` for
"vgroove", ``task.judged_models``), judged exactly as ``microsim run`` judges it: an ensemble
model on the one traced tile, with the tile's own departure from its ensemble computed where
the surface allows (V-grooves), so the ``verdict`` column reads "agrees", "deviates" or
"inconclusive" (``verdicts.verdict_kind``) as the run's table would — is written as
``OUT/tasks/<id>.json`` as soon as the task finishes, and only
if its simulation is complete (an interrupted simulation writes nothing); writes are atomic
(``microsim.atomic``). The id is a hash of the task's full description. A rerun computes every
task whose JSON is missing, unreadable, or not a complete result of that very task (fewer rays
than requested, marked partial, not one verdict per model it is judged by); ``gather`` ignores
such files too. Finally every task JSON is gathered into ``OUT/summary.csv``, ``OUT/summary.md`` and
``OUT/error_vs_roughness.png``.

Interrupts (Ctrl-C, or SIGTERM to the sweep's process): the finished tasks stay in
``OUT/tasks``, tasks in flight are stopped and leave nothing, no summary is written, and
``run_sweep`` raises ``SweepInterrupted`` (a ``KeyboardInterrupt``); the CLI prints one line
telling to rerun the same command, exit 130 (143 for SIGTERM). A local worker process that
dies (SIGKILL, out of memory) has its unfinished tasks run again in a fresh pool; two pools
in a row breaking before any task finishes is an ``EnvironmentFailure``.

Execution: local worker processes (``concurrent.futures.ProcessPoolExecutor``, ``--workers``,
started by a fork server; a worker ends when its sweep process does),
or, with ``--scheduler ADDRESS``, the same task function on a Dask distributed cluster
(``dask.distributed.Client(ADDRESS)``; the cluster's workers must see ``OUT``). Each task
traces on one thread. One sweep at a time may write to an output directory (a lock file
``OUT/.sweep.lock``).
"""

from .command import configure_sweep
from .execution import LOCK_FILE, SweepInterrupted, SweepOutcome, run_sweep
from .grid import MAX_TASKS, SweepSpec, Task, expand_tasks, load_sweep, material_text, task_label
from .summary import COLUMNS, SummaryFiles, gather, summary_table, write_summary
from .task import run_task

__all__ = [
    "SweepSpec",
    "Task",
    "SweepInterrupted",
    "SweepOutcome",
    "SummaryFiles",
    "load_sweep",
    "expand_tasks",
    "run_task",
    "run_sweep",
    "gather",
    "summary_table",
    "write_summary",
    "task_label",
    "material_text",
    "configure_sweep",
    "COLUMNS",
    "LOCK_FILE",
    "MAX_TASKS",
]
