"""Publishing a run: the output files and their JSON documents, staging directories moved to
their place in one rename (``microsim.atomic``), saved tallies for ``--resume`` and the
progress file of ``microsim report --resume``.

Wall times go to ``timings.json`` only, so ``report.md``, ``verdicts.json`` and ``index.md``
are reproducible byte for byte.
"""

from __future__ import annotations

import math
import os
import shutil
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from ... import atomic
from ...errors import UsageError
from ...sim.schedule import DeferredInterrupt
from .glass import INSIDE_DIR
from .planning import RESULT_FILES, RunPlan
from .tracing import auto_summary
from .wave_run import WAVE_DIR

__all__ = [
    "VERDICTS_FILE",
    "REPORT_FILE",
    "TIMINGS_FILE",
    "REPORT_STATE",
    "SCHEMA_VERSION",
    "OUTSIDE_DOMAIN",
    "CHARTS",
    "OUTPUT_NAMES",
    "staging",
    "publish_dir",
    "holds_finished_result",
    "save_tallies",
    "fit_record",
    "verdict_document",
    "timings_document",
    "read_report_state",
    "write_report_state",
]

VERDICTS_FILE, REPORT_FILE, TIMINGS_FILE = "verdicts.json", "report.md", "timings.json"
REPORT_STATE = ".report-state.json"
"""``microsim report``'s progress file in OUT (finished scenes), for ``report --resume``."""
SCHEMA_VERSION = 1
OUTSIDE_DOMAIN = {
    "low-smooth": (
        "wave-optics model (Löw et al. 2012, §2.2: surfaces smoother than the wavelength) "
        "against the geometric ray trace; fit-only"
    ),
}
"""Models whose verdicts against the ray tracer are outside the model's domain: the report
and the index show them as such (the fit numbers are kept), not as a test of the model."""


CHARTS = {
    "inplane": "inplane.png",
    "hemisphere": "hemisphere.png",
    "appearance": "appearance.png",
    "energy": "energy.png",
    "stability": "stability.png",
    "speed": "speed.png",
    "multiple": "multiple.png",
    "glass": "glass.png",
}
"""The charts a run may write (key → file name in the run's directory)."""
OUTPUT_NAMES = frozenset((*RESULT_FILES, TIMINGS_FILE, WAVE_DIR, INSIDE_DIR, *CHARTS.values()))
"""Everything a run writes into its directory; anything else there is the user's."""


def staging(out: Path) -> Path:
    """A new empty staging directory beside ``out`` (``atomic.make_staging``)."""
    return atomic.make_staging(out)


def publish_dir(stage: Path, out: Path) -> None:
    """Move the finished ``stage`` directory to ``out`` (``atomic.publish_dir``: the old
    result is removed only once the new one is in place). Entries of the old ``out`` that
    microsim does not write (not in ``OUTPUT_NAMES``: the user's notes, scripts, folders)
    are carried into the new one."""
    atomic.publish_dir(stage, out, keep=lambda name: name not in OUTPUT_NAMES)


def holds_finished_result(out: Path) -> bool:
    """Whether ``out`` holds more than partial tallies — a result, or complete tallies —
    which an interrupted run must not replace (True when unsure: an unreadable meta.json)."""
    try:
        names = set(os.listdir(out))
    except FileNotFoundError:
        return False
    if not names & set(RESULT_FILES):
        return False  # empty, or only the user's files (publish_dir carries them over)
    try:
        meta = atomic.read_json(out / "meta.json")
    except (OSError, UsageError):
        return True
    return meta.get("partial") is not True


def save_tallies(result, dest: Path) -> None:
    """Publish the tallies of ``result`` (brdf.npz + meta.json, no models) to ``dest``. A
    further Ctrl-C while they are written is held back until they are in place."""
    result = result.with_models({})
    with DeferredInterrupt():
        stage = staging(dest)
        try:
            result.save(stage)
            publish_dir(stage, dest)
        finally:
            if stage.exists():
                shutil.rmtree(stage, ignore_errors=True)


def fit_record(fit) -> dict:
    """JSON form of a ``FitResult`` (Löw E1/E2 with their square roots, as Löw et al. 2012,
    Table II; ``at_bounds``: its ``bounds_reached``)."""
    e1, e2 = fit.e1, fit.e2
    root = lambda e: math.sqrt(e) if e is not None and np.isfinite(e) and e >= 0 else None  # noqa: E731
    return {
        "model": fit.name,
        "params": dict(fit.params),
        "cost": fit.cost,
        "e1": e1,
        "e2": e2,
        "sqrt_e1": root(e1),
        "sqrt_e2": root(e2),
        "success": bool(fit.success),
        "at_bounds": [asdict(b) for b in fit.bounds_reached],
        "converged": bool(fit.converged),
        "n_starts": int(fit.n_starts),
    }


def surface_record(scene) -> dict:
    """The ``surface`` of verdicts.json: the ``[surface]`` kind and keys, and the ensemble NDF
    the nominal models use (its ``name`` and ``params()``; None for file and flat surfaces)."""
    ndf = scene.ndf()
    return {
        "kind": scene.surface.kind,
        "params": dict(scene.surface.params),
        "ensemble_ndf": None if ndf is None else {"name": ndf.name, **ndf.params()},
    }


def verdict_document(
    plan: RunPlan,
    result,
    ranking,
    verdicts,
    fits,
    speed,
    speed_theta,
    speed_ref,
    sweep,
    stability,
    warnings,
    wave=None,
) -> dict:
    """``verdicts.json``: the run's settings, model ranking, verdicts, fits, speed runs (errors
    only) and the stability sweep (docs/verdicts.md: schema); ``outside_domain`` (model →
    reason: models whose verdicts against the ray tracer are no test of them,
    ``OUTSIDE_DOMAIN``) and, for a scene with ``[wave]``, ``wave`` (``wave_run.run_wave``: the
    verdicts against Kirchhoff)."""
    sc = plan.scene
    doc = {
        "schema_version": SCHEMA_VERSION,
        "scene": sc.name,
        "scene_file": str(sc.path),
        "description": sc.description,
        "surface": surface_record(sc),
        "quick": plan.quick,
        "rays": int(result.rays.max()) if plan.auto else plan.rays,
        "theta_i": list(plan.theta_i),
        "phi_i": list(plan.phi_i),
        "seed": plan.seed,
        "ranking": ranking,
        "verdicts": verdicts,
        "fits": [fit_record(f) for f in fits.values()],
        "speed": {
            "theta_i": speed_theta,
            "phi_i": plan.phi_i[0],
            "reference": speed_ref,
            "runs": {
                k: {"rays": list(plan.effort.speed_rays), "rel_rms": e}
                for k, (t, e) in speed.items()
            },
        },
        "stability": {
            "theta_i": sweep.theta_i,
            "phi_i": plan.phi_i[0],
            "rays": plan.effort.sweep_rays,
            "rel_rms": stability,
            "warnings": warnings,
        },
    }
    present = {v["model"] for v in verdicts}
    judged = {v["model"].replace("-", "_") for v in (wave or {}).get("verdicts", [])}
    suffix = "; judged against Kirchhoff under Wave optics"
    doc["outside_domain"] = {
        m: OUTSIDE_DOMAIN[m] + (suffix if m in judged else "")
        for m in OUTSIDE_DOMAIN
        if m in present
    }
    if wave is not None:
        doc["wave"] = wave
    if plan.auto:
        doc["rays_auto"] = auto_summary(result)
    return atomic.json_safe(doc)


def timings_document(plan: RunPlan, result, speed, speed_theta) -> dict:
    """``timings.json``: the wall times (simulation, analysis, speed runs; the pilot of
    ``realisations = "auto"`` separately)."""
    info = result.info
    auto = (info.run or {}).get("realisations_auto") or {}
    return {
        "simulation_seconds": info.seconds,
        "pilot_seconds": auto.get("pilot_seconds"),
        "rays_per_second": info.rays_per_second,
        "analysis_seconds": info.seconds_analysis,
        "speed": {
            "theta_i": speed_theta,
            "runs": {
                k: {"rays": list(plan.effort.speed_rays), "seconds": t}
                for k, (t, e) in speed.items()
            },
        },
    }


@dataclass(frozen=True)
class ReportState:
    """``microsim report``'s progress (``REPORT_STATE``): the options it ran with, the scenes
    finished so far and the digest of every scene file (``catalogue._scene_digest``)."""

    quick: bool | None
    catalogue: str | None
    done: tuple = ()
    digests: dict = field(default_factory=dict)

    def finished(self, name: str) -> ReportState:
        """This state with scene ``name`` finished too."""
        return replace(self, done=tuple(sorted({*self.done, name})))

    def to_json(self) -> dict:
        return {**asdict(self), "done": list(self.done)}


def read_report_state(out: Path) -> ReportState | None:
    """The interrupted report's state in ``out`` (None if there is none); digests that are not
    a table count as none recorded."""
    path = out / REPORT_STATE
    if not os.path.lexists(path):
        return None
    rerun = "run `microsim report` without --resume"
    try:
        state = atomic.read_json(path)
    except UsageError as e:
        raise UsageError(f"--resume: {e}; {rerun}") from None
    done = state.get("done")
    if not isinstance(done, list) or not all(isinstance(name, str) for name in done):
        raise UsageError(
            f"--resume: {path}: done must be a list of scene names, got {done!r:.80}; {rerun}"
        )
    digests = state.get("digests")
    return ReportState(
        quick=state.get("quick"),
        catalogue=state.get("catalogue"),
        done=tuple(done),
        digests=digests if isinstance(digests, dict) else {},
    )


def write_report_state(out: Path, state: ReportState) -> None:
    atomic.write_json(out / REPORT_STATE, state.to_json())
