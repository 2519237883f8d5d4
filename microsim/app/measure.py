"""`microsim measure`: a virtual gonioreflectometer — the whole single-bounce BRDF of a scene's
surface tabulated over a dense grid of incidences, each traced until its error target, with
standard errors, resumable, written as a ``measured.BRDFTable``. It is the single-bounce BRDF
(what the verdicts judge; the scene's ``bounces`` is not used). A scene with ``[material]
transmission`` gets its BRDF lit from the air — the reflected part of its BSDF (the
expectation of the reflected first order): neither export format holds transmission (an RGL
.bsdf file is read by Mitsuba's ``measured`` plugin as glossy front-side reflection only, and
MERL's binary tabulates the upper hemisphere), and the command says so.

Acquisition: θi = 0, Δ, 2Δ, … ≤ ``theta_max`` (``--theta-step`` Δ, default 5°; at most
89.99°) on the scene's bins (folded: isotropic surfaces only — an anisotropic surface's
table would need φi as a dimension, which this table has not), one surface realisation (the
scene's seed, at the ``--quick`` scale if given), each incidence traced by ``simulate_auto``
until the energy-weighted relative standard error over the bins carrying 90 % of the energy is
≤ ``--target`` (default 2 %) or ``--max-rays`` rays. Reciprocity is not used to save work:
the table is measured at every θi it holds, so reciprocity stays a check of the result
(``measured.BRDFTable`` does not impose it).

Output directory: ``measure.json`` (the settings, written first; per incidence its rays,
seconds, achieved error and convergence once traced, and the totals — the acquisition's
cost), ``incidences/theta-XX.XX/`` (each incidence's ``Result``, written atomically when it
is done), and at the end ``table.npz`` (``BRDFTable.save``) and the exports (``--export``,
default all of ``EXPORTS``): ``table.binary`` (MERL, ``measured.write_merl``) and
``table.bsdf`` (RGL, ``measured.write_rgl``, RGB flavour, warped by the scene's ensemble NDF
with a ``RGL_FLOOR`` Lambertian share —
an RGL file stores the NDF that parameterises it; a scene without one, a heightfield file, gets
no RGL file by default and an error when ``--export rgl`` asks for it). Each export is read
back and its bin averages compared with the table's: the ``exports`` of ``measure.json``
records per format the file, the seconds and that difference (energy-weighted relative RMS
over each incidence's 90 % energy bins, its largest over the incidences) beside the table's
own relative standard error over the same bins: a format that stores a reciprocal average
and interpolates smooths the table's noise, so a difference near the noise is no format
error. Memory does not grow with the ray count (``simulate_auto``).

Every option is checked and the scheduler reached before anything is written. A new measure
(or ``--force``) is made in a staging directory that replaces the output in one rename once
complete (``atomic.publish_dir``; the user's files in it carried over), so no file of an
older measure survives it. Ctrl-C (``MeasureInterrupted``, exit 130) keeps the finished
incidences in the output for ``--resume`` unless it holds a finished measure, which stays as
it was. ``--resume`` continues after checking that the settings are the same; an incidence
whose files or record are damaged is traced again (the same result: each incidence has its
own seed), a damaged ``measure.json`` is a ``UsageError`` naming it.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import time
from contextlib import ExitStack
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from zipfile import BadZipFile

import numpy as np

from .. import atomic
from ..analysis.markdown import percent
from ..checks import integer
from ..errors import EXIT_INTERRUPTED, EXIT_OK, UsageError
from ..measured import BRDFTable, read_merl, read_rgl, write_merl, write_rgl
from ..sim import Bins, Estimator, Execution, Experiment, Result
from ..sim.arguments import MAX_RAYS, MAX_THREADS
from ..sim.auto import AutoRecord, Precision, estimate_to_precision
from ..sim.schedule import DeferredInterrupt
from ..stats import energy_set
from .cluster import check_address, connect
from .options import SCENE_HELP
from .runner.planning import check_output_path, effort_for, tally_settings
from .scene import MAX_THETA_I, load_scene

__all__ = [
    "Acquisition",
    "MeasureInterrupted",
    "plan_measure",
    "measure",
    "configure_measure",
    "SETTINGS_FILE",
]

SETTINGS_FILE = "measure.json"
EXPORTS = {"merl": "table.binary", "rgl": "table.bsdf"}
"""Export formats → file name in the output directory."""
RGL_FLOOR = 0.01
"""Lambertian share of the NDF an RGL export warps by (``measured.write_rgl``'s ``floor``): a
table holds small values beyond the lobe (bin averages, their interpolation) where the
scene's exact NDF vanishes, which the file could not otherwise carry."""
TABLE_FILE = "table.npz"
INCIDENCES = "incidences"
OUTPUT_NAMES = frozenset((SETTINGS_FILE, TABLE_FILE, INCIDENCES, *EXPORTS.values()))
"""Everything ``measure`` writes into its directory; anything else there is the user's."""
MAX_INCIDENCES = 900


@dataclass(frozen=True)
class IncidenceRecord:
    """``measure.json``'s record of one traced incidence: its rays, tracing seconds, achieved
    relative standard error and whether it reached the target."""

    rays: int
    seconds: float
    rse: float | None
    converged: bool

    @classmethod
    def read(cls, entry) -> IncidenceRecord | None:
        """The record of a saved entry, None when it is not a whole one."""
        number = lambda x: isinstance(x, (int, float)) and not isinstance(x, bool)  # noqa: E731
        if not (
            isinstance(entry, dict)
            and number(entry.get("rays"))
            and number(entry.get("seconds"))
            and (entry.get("rse") is None or number(entry.get("rse")))
            and isinstance(entry.get("converged"), bool)
        ):
            return None
        return cls(**{f.name: entry.get(f.name) for f in fields(cls)})


@dataclass(frozen=True)
class Totals:
    """The acquisition's cost over its incidences: rays, tracing seconds, all converged."""

    incidences: int
    rays: int
    seconds: float
    converged: bool


@dataclass(frozen=True)
class ExportRecord:
    """One export (``_export``): its file name, size, the seconds to write and read it back,
    the interpolation error per incidence and at worst, and the table's own relative standard
    error per incidence over the same bins."""

    file: str
    bytes: int
    seconds: float
    interpolation_rel_rms: list
    interpolation_rel_rms_max: float
    table_rel_se: list


@dataclass
class MeasureRecord:
    """``measure.json`` as the acquisition fills it: the ``settings`` a ``--resume`` must
    match, the finished incidences by θi ("30" for 30°: an ``IncidenceRecord``, or a saved
    entry that is not a whole one, kept as read until its incidence is traced again), then
    the totals and the exports."""

    settings: dict
    incidences: dict = field(default_factory=dict)
    totals: Totals | None = None
    exports: dict | None = None

    @classmethod
    def from_json(cls, doc: dict) -> MeasureRecord:
        """The record of a saved ``measure.json`` (an object with settings and incidences)."""
        totals, exports = doc.get("totals"), doc.get("exports")
        return cls(
            settings=doc.get("settings"),
            incidences={
                key: IncidenceRecord.read(entry) or entry
                for key, entry in doc.get("incidences").items()
            },
            totals=None if totals is None else Totals(**totals),
            exports=None if exports is None else {e: ExportRecord(**r) for e, r in exports.items()},
        )

    def to_json(self) -> dict:
        doc = {
            "settings": self.settings,
            "incidences": {
                key: asdict(r) if isinstance(r, IncidenceRecord) else r
                for key, r in self.incidences.items()
            },
        }
        if self.totals is not None:
            doc = {**doc, "totals": asdict(self.totals)}
        if self.exports is not None:
            doc = {**doc, "exports": {e: asdict(r) for e, r in self.exports.items()}}
        return doc

    def write(self, root: Path) -> None:
        atomic.write_json(root / SETTINGS_FILE, self.to_json())


class MeasureInterrupted(KeyboardInterrupt):
    """Ctrl-C during ``measure``: the one-line message says what was kept and how to go on."""


@dataclass(frozen=True)
class Acquisition:
    """A validated ``measure``: the scene, output directory, incidence grid (degrees), error
    ``target``, ``max_rays`` per incidence, ``seed``, ``threads``, ``quick`` (surface scale);
    ``resume`` (continue the measure in ``out``) or ``force`` (replace ``out``)."""

    scene: object
    out: Path
    theta_i: tuple[float, ...]
    target: float
    max_rays: int
    seed: int
    threads: int
    quick: bool
    exports: tuple[str, ...] = tuple(EXPORTS)
    scheduler: str | None = None  # Dask scheduler whose workers trace (``sim.cluster``)
    resume: bool = False
    force: bool = False

    @property
    def bins(self) -> Bins:
        sim = self.scene.simulation
        return Bins(sim.theta_bins, sim.phi_bins)

    def settings(self) -> dict:
        """What a ``--resume`` must match (JSON values)."""
        return atomic.json_safe(
            {
                "scene": self.scene.name,
                **tally_settings(self.scene),
                "theta_i": list(self.theta_i),
                "target": self.target,
                "max_rays": self.max_rays,
                "seed": self.seed,
                "quick": self.quick,
                "bins": self.bins.to_dict(),
            }
        )


def _incidences(theta_step, theta_max) -> tuple[float, ...]:
    """θi = 0, ``theta_step``, … up to ``theta_max`` degrees (refused beyond ``MAX_THETA_I``
    or ``MAX_INCIDENCES``)."""
    step, top = float(theta_step), float(theta_max)
    if not (math.isfinite(step) and step > 0):
        raise UsageError(f"--theta-step must be a positive angle in degrees, got {theta_step!r}")
    if not (math.isfinite(top) and 0 <= top <= MAX_THETA_I):
        raise UsageError(f"--theta-max must be in [0, {MAX_THETA_I:g}] degrees, got {theta_max!r}")
    thetas = tuple(float(t) for t in np.round(np.arange(0.0, top + 1e-9, step), 6))
    if len(thetas) > MAX_INCIDENCES:
        raise UsageError(
            f"--theta-step {step:g} gives {len(thetas)} incidences; at most {MAX_INCIDENCES}"
        )
    return thetas


def _exports(scene, exports) -> tuple[str, ...]:
    """The asked export formats (None: every one of ``EXPORTS`` the scene allows), each once;
    RGL needs the scene's ensemble NDF (asked for without one: refused)."""
    asked = exports is not None
    exports = tuple(dict.fromkeys(EXPORTS if exports is None else exports))
    if not all(e in EXPORTS for e in exports):
        raise UsageError(f"--export must be among {', '.join(EXPORTS)}, got {', '.join(exports)}")
    if "rgl" in exports and scene.ndf() is None:
        if asked:
            raise UsageError(
                f"--export rgl: scene {scene.name} has no ensemble NDF (a heightfield file), "
                f"which an RGL file needs for its parameterisation; use --export merl"
            )
        exports = tuple(e for e in exports if e != "rgl")
    return exports


def _check_resumable(acq: Acquisition) -> None:
    """Refuse a ``--resume`` whose settings differ from the saved measure's, naming the first
    setting that differs."""
    out = acq.out
    saved = _saved_document(out).settings
    if saved != acq.settings():
        key = next(
            k for k in sorted({*saved, *acq.settings()}) if saved.get(k) != acq.settings().get(k)
        )
        raise UsageError(
            f"--resume {out}: {key} is {saved.get(key)!r} there but "
            f"{acq.settings().get(key)!r} now; resume with the same settings or use --force"
        )


def plan_measure(
    scene_path,
    *,
    out=None,
    theta_step: float = 5.0,
    theta_max: float = 85.0,
    target: float = 0.02,
    max_rays: int = 10**8,
    seed=None,
    threads: int = 2,
    quick: bool = False,
    resume: bool = False,
    force: bool = False,
    exports=None,
    scheduler: str | None = None,
) -> Acquisition:
    """Validate a ``measure`` without touching the disk (every problem a one-line UsageError
    naming the option). ``exports``: formats among ``EXPORTS`` (None: every one the scene
    allows); ``scheduler``: a Dask scheduler address whose workers trace (the table is the
    local one bit for bit)."""
    scene = load_scene(scene_path)
    if scene.anisotropic:
        raise UsageError(
            f"scene {scene.name}: measure tabulates isotropic surfaces (a table over θi and "
            f"folded bins); this surface is anisotropic"
        )
    thetas = _incidences(theta_step, theta_max)
    if not (isinstance(target, (int, float)) and 1e-4 <= target <= 0.5):
        raise UsageError(f"--target must be a relative error in [0.0001, 0.5], got {target!r}")
    max_rays = integer("--max-rays", max_rays, 2**16, MAX_RAYS, " (rays per incidence)")
    threads = integer("--threads", threads, 1, MAX_THREADS)
    if seed is not None:
        seed = integer("--seed", seed, 0, None, " (the random stream)")
    if scheduler is not None:
        check_address(scheduler)
    exports = _exports(scene, exports)
    out = Path(out) if out is not None else Path("runs") / f"{scene.name}-measured"
    check_output_path(out, "--out", scene.path)
    acq = Acquisition(
        scene,
        out,
        thetas,
        float(target),
        max_rays,
        scene.simulation.seed if seed is None else seed,
        threads,
        bool(quick),
        exports,
        scheduler,
        bool(resume),
        bool(force),
    )
    if not resume:
        _check_replaceable(acq)
    else:
        _check_resumable(acq)
    return acq


def _read_json(path: Path) -> dict:
    with open(path, encoding="utf-8") as fh:
        return json.load(fh)


def _saved_document(out: Path) -> MeasureRecord:
    """``measure.json`` of the measure ``--resume`` continues; a one-line ``UsageError``
    naming the file if it is missing, unreadable or not a measure's record."""
    path = out / SETTINGS_FILE
    try:
        doc = _read_json(path)
    except FileNotFoundError:
        raise UsageError(
            f"--resume {out}: no {SETTINGS_FILE} there; not a microsim measure directory"
        ) from None
    except ValueError as e:
        raise UsageError(
            f"--resume {out}: {path} is unreadable ({' '.join(str(e).split())}); "
            f"rerun with --force to measure anew"
        ) from None
    if not (
        isinstance(doc, dict)
        and isinstance(doc.get("settings"), dict)
        and isinstance(doc.get("incidences"), dict)
    ):
        raise UsageError(
            f"--resume {out}: {path} is not a measure's record (an object with settings and "
            f"incidences); rerun with --force to measure anew"
        )
    return MeasureRecord.from_json(doc)


def _check_replaceable(acq: Acquisition) -> None:
    """A new measure's ``out`` must not exist, or (``--force``) be an empty directory or a
    microsim measure directory (one with ``measure.json``)."""
    if not acq.out.exists():
        return
    if not acq.force:
        raise UsageError(
            f"{acq.out} already exists; pass --resume to continue it or --force to replace it"
        )
    try:
        names = os.listdir(acq.out)
    except OSError as e:
        raise UsageError(f"--out {acq.out}: cannot list it ({e.strerror})") from None
    if names and SETTINGS_FILE not in names:
        raise UsageError(
            f"--force {acq.out}: not a microsim measure directory (no {SETTINGS_FILE}); "
            f"refusing to replace it"
        )


def measure(acq: Acquisition, log=print) -> BRDFTable:
    """Trace every incidence of ``acq`` not already finished, then write and return the table
    (module docstring). ``log``: one line per incidence (None: silent). The scheduler is
    reached before anything is written. ``--resume`` continues in ``acq.out``; otherwise the
    acquisition is made in a staging directory that replaces ``acq.out`` once complete (the
    user's own files in it carried over). Ctrl-C raises ``MeasureInterrupted``, whose message
    says what was kept."""
    with ExitStack() as stack:
        client = None if acq.scheduler is None else stack.enter_context(connect(acq.scheduler))
        stack.enter_context(atomic.output_lock(acq.out, holder="measure"))
        atomic.clean_stale(acq.out)
        if acq.resume:
            doc = MeasureRecord(acq.settings(), _saved_document(acq.out).incidences)
            try:
                return _acquire(acq, acq.out, doc, client, log)
            except KeyboardInterrupt:
                raise MeasureInterrupted(_kept(acq, doc)) from None
        _check_replaceable(acq)
        stage = atomic.make_staging(acq.out)
        try:
            doc = MeasureRecord(acq.settings())
            try:
                table = _acquire(acq, stage, doc, client, log)
            except BaseException as e:
                note = _keep_unfinished(acq, stage, doc)
                if isinstance(e, KeyboardInterrupt):
                    raise MeasureInterrupted(note) from None
                raise
            stopped = _publish(stage, acq.out)
        finally:
            shutil.rmtree(stage, ignore_errors=True)
    if stopped:
        raise MeasureInterrupted(f"{acq.out} was written completely before it stopped")
    return table


def _publish(stage: Path, out: Path) -> bool:
    """Move ``stage`` to ``out`` in one rename (the user's files in ``out`` carried over); a
    Ctrl-C meanwhile waits until it is in place. Returns whether one came."""
    with DeferredInterrupt() as stop:
        atomic.publish_dir(stage, out, keep=lambda name: name not in OUTPUT_NAMES)
    return stop.is_set()


def _acquire(acq: Acquisition, root: Path, doc: MeasureRecord, client, log) -> BRDFTable:
    """Trace into ``root`` the incidences ``doc`` (``measure.json``'s content; a resumed one
    holds the saved entries as read) does not hold finished there, then write the table, its
    exports and the totals."""
    doc.write(root)
    scale = effort_for(acq.quick).scale_for(acq.scene.surface.kind)
    surface = None
    results = []
    for k, theta in enumerate(acq.theta_i):
        where = root / INCIDENCES / f"theta-{theta:05.2f}"
        key = f"{theta:g}"
        saved = _finished_incidence(acq, theta, where, doc.incidences.pop(key, None), log)
        if saved is not None:
            doc.incidences[key] = saved[1]
            results.append(saved[0])
            continue
        if surface is None:
            surface = acq.scene.build_surface(seed=acq.seed, scale=scale)
        t0 = time.perf_counter()
        res = estimate_to_precision(  # simulate_auto's, with its defaults
            Experiment(surface, acq.scene.material, theta, 0.0, acq.bins),
            Estimator(acq.max_rays, acq.seed + k),
            Execution(acq.threads, cluster=client),
            Precision(acq.target),
        )
        res.save(where)
        auto = AutoRecord.of(res.info.auto).incidences[0]
        doc.incidences[key] = IncidenceRecord(
            rays=int(auto.rays),
            seconds=time.perf_counter() - t0,
            rse=auto.rse,
            converged=bool(auto.converged),
        )
        doc.write(root)
        results.append(res)
        if log:
            log(
                f"microsim measure: θi = {theta:g}° ({k + 1}/{len(acq.theta_i)}): "
                f"{auto.rays:,} rays, relative error {percent(auto.rse, unit=' %')}"
                f"{'' if auto.converged else ' (max-rays reached)'}"
            )
    table = BRDFTable(
        np.array(acq.theta_i),
        acq.bins,
        np.stack([r.brdf[0] for r in results]),
        np.stack([r.stderr[0] for r in results]),
        f"{acq.scene.name} (simulated)",
    )
    per = [doc.incidences[f"{theta:g}"] for theta in acq.theta_i]
    doc.totals = Totals(
        incidences=len(acq.theta_i),
        rays=int(sum(d.rays for d in per)),
        seconds=float(sum(d.seconds for d in per)),
        converged=all(d.converged for d in per),
    )
    table.save(root / TABLE_FILE)
    doc.exports = {e: _export(e, table, root / EXPORTS[e], acq.scene) for e in acq.exports}
    doc.write(root)
    return table


def _finished_incidence(acq: Acquisition, theta: float, where: Path, entry, log):
    """(Result, ``IncidenceRecord``) of the incidence ``theta`` finished in ``where``, or
    None to trace it: not finished, or damaged — an incomplete entry, or files that do not
    load as this incidence on the measure's bins (``log`` names the damage; tracing it again
    gives the same result, as each incidence has its own seed)."""
    if entry is None:
        return None
    try:
        record = entry if isinstance(entry, IncidenceRecord) else IncidenceRecord.read(entry)
        if record is None:
            raise UsageError(f"{SETTINGS_FILE}: its record of this incidence is incomplete")
        res = Result.load(where)
        if res.bins != acq.bins or res.theta_i.tolist() != [theta]:
            raise UsageError(f"{where}: not θi = {theta:g}° on the measure's bins")
    except (
        FileNotFoundError, ValueError, KeyError, TypeError, IndexError, EOFError, BadZipFile
    ) as e:  # fmt: skip
        if log:
            log(
                f"microsim measure: θi = {theta:g}°: the saved incidence is damaged "
                f"({type(e).__name__}: {' '.join(str(e).split())}); tracing it again"
            )
        return None
    return res, record


def _kept(acq: Acquisition, doc: MeasureRecord) -> str:
    """What an interrupted measure kept in ``acq.out`` and how to continue it."""
    return (
        f"{len(doc.incidences)} of {len(acq.theta_i)} incidences kept in {acq.out}; "
        f"continue with microsim measure {acq.scene.path} --out {acq.out} --resume "
        f"(same options)"
    )


def _keep_unfinished(acq: Acquisition, stage: Path, doc: MeasureRecord) -> str:
    """After an acquisition in ``stage`` was interrupted or failed: its finished incidences
    replace ``acq.out`` (for ``--resume``) unless there are none or ``acq.out`` holds a
    finished measure, which is kept as it was. Returns the line saying which."""
    done = len(doc.incidences)
    if done and not _holds_finished_measure(acq.out):
        _publish(stage, acq.out)
        return _kept(acq, doc)
    if done:
        return (
            f"{acq.out} keeps its finished table (this run's {done} incidences are dropped; "
            f"rerun with --force to replace it)"
        )
    state = "is unchanged" if acq.out.exists() else "was not written"
    return f"no incidence was finished; {acq.out} {state}"


def _holds_finished_measure(out: Path) -> bool:
    """Whether ``out`` holds a finished measure (its ``measure.json`` has the totals; True
    when unsure: an unreadable one)."""
    try:
        doc = _read_json(out / SETTINGS_FILE)
    except FileNotFoundError:
        return False
    except (OSError, ValueError):
        return True
    return not isinstance(doc, dict) or "totals" in doc


def _export(fmt: str, table: BRDFTable, path: Path, scene) -> ExportRecord:
    """Write ``table`` as ``fmt`` to ``path``, read it back and measure the format's
    interpolation error against the table (module docstring)."""
    t0 = time.perf_counter()
    if fmt == "merl":
        write_merl(path, table)
        back = read_merl(path).table(table.theta_i, table.bins)
    else:
        write_rgl(path, table.evaluate, scene.ndf(), description=table.name, floor=RGL_FLOOR)
        back = read_rgl(path).table(table.theta_i, table.bins)
    seconds = time.perf_counter() - t0
    omega = table.bins.projected_solid_angle()
    errors, noise = [], []
    for f, g, se in zip(table.brdf, back.brdf, table.stderr):
        w = f * omega
        E = energy_set(w).reshape(f.shape) & (f > 0)
        errors.append(float(np.sqrt(np.sum(w[E] * ((g[E] - f[E]) / f[E]) ** 2) / np.sum(w[E]))))
        noise.append(float(np.sqrt(np.sum(w[E] * (se[E] / f[E]) ** 2) / np.sum(w[E]))))
    return ExportRecord(
        file=path.name,
        bytes=path.stat().st_size,
        seconds=seconds,
        interpolation_rel_rms=errors,
        interpolation_rel_rms_max=max(errors),
        table_rel_se=noise,
    )


def _cmd_measure(args) -> int:
    acq = plan_measure(
        args.scene,
        out=args.out,
        theta_step=args.theta_step,
        theta_max=args.theta_max,
        target=args.target,
        max_rays=args.max_rays,
        seed=args.seed,
        threads=args.threads,
        quick=args.quick,
        resume=args.resume,
        force=args.force,
        exports=tuple(args.export) if args.export else None,
        scheduler=args.scheduler,
    )
    log = None if args.no_progress else (lambda s: print(s, flush=True))
    try:
        measure(acq, log)
    except MeasureInterrupted as e:
        print(f"microsim measure: interrupted; {e}", flush=True)
        return EXIT_INTERRUPTED
    doc = MeasureRecord.from_json(_read_json(acq.out / SETTINGS_FILE))
    tot = doc.totals
    print(
        f"microsim measure: wrote {acq.out / TABLE_FILE} ({tot.incidences} incidences, "
        f"{tot.rays:,} rays, {tot.seconds:.1f} s of tracing"
        f"{'' if tot.converged else '; some incidences stopped at --max-rays'})"
    )
    if acq.scene.transmission:
        print(
            f"microsim measure: {acq.scene.name} transmits light: the table and its exports "
            f"hold the BRDF lit from the air, the reflected part of its BSDF (RGL's .bsdf and "
            f"MERL's binary store reflection only)"
        )
    for fmt, e in (doc.exports or {}).items():
        print(
            f"microsim measure: wrote {acq.out / e.file} ({fmt}, {e.bytes:,} bytes; "
            f"read back against the table: {percent(e.interpolation_rel_rms_max, unit=' %')} "
            f"energy-weighted relative RMS at worst; the table's own noise there: "
            f"{percent(max(e.table_rel_se), unit=' %')} at worst)"
        )
    return EXIT_OK


def configure_measure(m) -> None:
    """The arguments of ``microsim measure`` on its parser ``m`` (``cli.COMMANDS``)."""
    m.add_argument("scene", help=f"{SCENE_HELP}; an isotropic surface")
    m.add_argument("--out", help="output directory (default runs/<scene>-measured)")
    m.add_argument("--theta-step", type=float, default=5.0, help="θi step, degrees (default 5)")
    m.add_argument("--theta-max", type=float, default=85.0, help="largest θi (default 85)")
    m.add_argument(
        "--target",
        type=float,
        default=0.02,
        help="energy-weighted relative standard error per incidence (default 0.02)",
    )
    m.add_argument(
        "--max-rays", type=int, default=10**8, help="rays per incidence at most (default 1e8)"
    )
    m.add_argument("--seed", type=int, help="random seed (default: the scene's)")
    m.add_argument("--threads", type=int, default=2, help="tracing threads (default 2)")
    m.add_argument("--quick", action="store_true", help="the --quick surface scale")
    m.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="trace on the workers of this Dask scheduler (the table is the local one)",
    )
    m.add_argument(
        "--export",
        action="append",
        choices=tuple(EXPORTS),
        help=f"formats to write (repeatable; default all the scene allows: {', '.join(EXPORTS)})",
    )
    g = m.add_mutually_exclusive_group()
    g.add_argument("--resume", action="store_true", help="continue an interrupted measure")
    g.add_argument("--force", action="store_true", help="replace an existing output directory")
    m.add_argument("--no-progress", action="store_true", help="no progress lines")
    m.set_defaults(func=_cmd_measure)
