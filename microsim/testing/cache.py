"""Reference simulations for agreement checks, traced once and cached on disk.

A *reference* is the ``Result`` of ``simulate`` (or ``simulate_auto`` for ``rays="auto"``) on
an explicit surface. It is identified by a key of everything that determines it: the run's
identity (``microsim.sim.identity.RunDescription``: the surface fingerprint(s) —
``Surface.fingerprint``, the mesh, one per realisation — and whether the estimator averages
the groove azimuth, the material, the incidences, the bins, the seed, the ray target (an
integer count per incidence, or "auto" with its target relative error and ray cap), the
rays' design), the microsim version (``microsim.__version__``) and the standard error's rule
(``sim.tallies.STDERR_RULE``).

The key is the SHA-256 of that description as canonical JSON; the entry is the directory
``CACHE/<first 24 hex digits>/`` holding ``brdf.npz`` and ``meta.json`` (``Result.save``) and
``key.json`` (the description, compared on load). An entry that cannot be used — unreadable,
truncated, edited, made for another description, or holding arrays that do not fit its
description — is reported in one warning line naming the file, discarded and traced again.

Location, first that is set: the ``cache`` argument, pytest's ``--microsim-cache DIR`` (the
plugin calls ``set_default_dir``), the environment variable ``MICROSIM_CACHE``, else
``$XDG_CACHE_HOME/microsim/references`` (default ``~/.cache/microsim/references``).

Derived entries (``derived``): what the surfaces, material, incidences and bins alone
determine — a V-groove tile's departure from its ensemble, a catalogue or physics model's
bin averages — is kept in ``CACHE/derived/<key>.npz`` (the key and the array in one archive,
written by one atomic rename), keyed by the reference's description without rays and seed,
microsim's source (``source_digest``) and what the quantity is. Two processes missing one
compute it both and write the same bytes; no lock is needed.

Concurrency (several pytest-xdist workers asking for one reference): a reader that finds the
entry loads it without locking (entries appear only by an atomic rename, ``atomic.publish_dir``);
one that does not waits for the entry's lock (``atomic.output_lock`` on ``CACHE/.<key>.lock``,
polled every 0.1 s), looks again, and only then traces into a staging directory and publishes
it in one rename. So each reference is traced once, and nobody ever reads half an entry. A
damaged entry is discarded only by the lock's holder, after looking at it again.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import shutil
import time
import warnings
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Callable

import numpy as np

import microsim
from microsim import atomic
from microsim.analysis.budget import MIN_AUTO
from microsim.analytic.fresnel import resolve_material
from microsim.app.scene import Scene, incidence_pairs, load_scene, resolve_scene
from microsim.errors import UsageError
from microsim.sim import Bins, Result, simulate
from microsim.sim.auto import simulate_auto
from microsim.sim.dielectric import check_transmission
from microsim.sim.identity import RunDescription, canonical_json
from microsim.sim.result import META, NPZ
from microsim.sim.tallies import STDERR_RULE

__all__ = [
    "ENV_VAR",
    "AUTO_TARGET",
    "AUTO_MAX_RAYS",
    "AUTO_FIRST",
    "LOCK_TIMEOUT",
    "DEFAULT_REALISATIONS",
    "Reference",
    "cache_dir",
    "set_default_dir",
    "resolve_reference",
    "reference",
    "find_scene",
    "derived",
]

ENV_VAR = "MICROSIM_CACHE"
AUTO_TARGET = 0.02
"""Default target of ``rays="auto"``: energy-weighted relative standard error of the reference
(``microsim.sim.auto.relative_standard_error``) ≤ 2 % per incidence."""
AUTO_MAX_RAYS = 4_000_000
"""Cap of ``rays="auto"`` per incidence (a reference is never traced without bound)."""
AUTO_FIRST = 2**18
"""Rays of the first batch of ``rays="auto"``."""
DEFAULT_REALISATIONS = MIN_AUTO
"""Realisations of a scene whose file says ``realisations = "auto"``."""
LOCK_TIMEOUT = 3600.0
"""Seconds a process waits for another one tracing the same reference before giving up."""

KEY_FILE = "key.json"
DERIVED_DIR = "derived"

_default_dir: Path | None = None


def set_default_dir(path) -> None:
    """Set (or with None clear) the cache directory used when no ``cache`` argument is given;
    the pytest plugin calls it with ``--microsim-cache``."""
    global _default_dir
    _default_dir = None if path is None else Path(path)


def cache_dir(cache=None) -> Path:
    """The cache directory: ``cache``, else ``set_default_dir``'s, else ``$MICROSIM_CACHE``,
    else ``$XDG_CACHE_HOME/microsim/references`` (``~/.cache/microsim/references``)."""
    if cache is not None:
        if not isinstance(cache, (str, os.PathLike)) or not str(cache):
            raise UsageError(f"cache must be a directory path, got {cache!r}")
        return Path(cache)
    if _default_dir is not None:
        return _default_dir
    env = os.environ.get(ENV_VAR)
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "microsim" / "references"


def find_scene(name) -> Path:
    """Path of a scene given as a file path or a catalogue name (``NAME`` or ``NAME.toml``,
    the packaged catalogue: ``microsim.app.scene.resolve_scene``). UsageError naming
    ``surface_or_scene`` and listing the catalogue's scenes if neither exists."""
    return resolve_scene(name, "surface_or_scene")


@dataclass(frozen=True)
class Reference:
    """What to trace: the surfaces (one, or the realisations of a random scene) by their
    ``fingerprints`` and ``azimuth_average`` flags, built on demand by ``build`` (property
    ``surfaces``: only a cache miss or a facet model needs the meshes), the material η
    (None = mirror), incidences ``theta_i`` with their azimuths ``phi_i`` (degrees, one per
    incidence), ``bins``, ``seed``, ``rays`` (int or "auto") with
    the auto ``target``/``max_rays``, a ``label`` for messages (scene file or surface) and the
    surfaces' ``ensemble_ndf`` (the analytic NDF their generator samples, or None: file, flat,
    oriented V-grooves; ``Surface.ensemble_ndf``, ``Scene.ndf``) and ``exact_shadowing`` (the
    shadowing kind exact on them: "vgroove", "none", or None for heightfields);
    ``transmission``: traced through a dielectric interface (``simulate(...,
    transmission=True)``, single scattering), θi in (90, 180] lit from inside the medium."""

    fingerprints: tuple[str, ...]
    azimuth_average: tuple[bool, ...]
    build: Callable[[], tuple]
    material: complex | float | None
    theta_i: tuple[float, ...]
    phi_i: tuple[float, ...]
    bins: Bins
    seed: int
    rays: int | str
    target: float
    max_rays: int
    label: str
    ensemble_ndf: object = None
    exact_shadowing: str | None = None
    transmission: bool = False

    @cached_property
    def surfaces(self) -> tuple:
        """The Surfaces (built once per Reference), checked against ``fingerprints``."""
        built = tuple(self.build())
        if tuple(s.fingerprint() for s in built) != self.fingerprints:  # pragma: no cover
            raise UsageError("surface_or_scene: the scene's surfaces changed while in use")
        return built

    def run(self) -> RunDescription:
        """The run the reference traces (``microsim.sim.identity``): its surfaces by their
        fingerprints and azimuth-average flags; ``rays`` a count or the "auto" rule."""
        rays = (
            {"auto": {"target": self.target, "max_rays": self.max_rays, "first": AUTO_FIRST}}
            if self.rays == "auto"
            else int(self.rays)
        )
        return RunDescription(
            material=self.material,
            theta_i=self.theta_i,
            phi_i=self.phi_i,
            bins=self.bins,
            rays=rays,
            seed=self.seed,
            surfaces={
                "fingerprints": list(self.fingerprints),
                "azimuth_average": list(self.azimuth_average),
            },
            realisations=len(self.fingerprints),
            transmission=self.transmission,
        )

    def description(self) -> dict:
        """The cache key's content (module docstring), JSON values only: the run's identity,
        the microsim version and the standard error's rule."""
        return {
            **self.run().identity(),
            "microsim": microsim.__version__,
            "stderr_rule": STDERR_RULE,
        }

    def key(self) -> str:
        text = canonical_json(self.description())
        return hashlib.sha256(text.encode()).hexdigest()[:24]


def _bins(bins, default: Bins) -> Bins:
    if bins is None:
        return default
    if isinstance(bins, Bins):
        return bins
    if (
        isinstance(bins, (tuple, list))
        and len(bins) == 2
        and all(isinstance(b, (int, np.integer)) and not isinstance(b, bool) for b in bins)
    ):
        return Bins(int(bins[0]), int(bins[1]))
    raise UsageError(f"bins must be a microsim.sim.Bins or (n_theta, n_phi), got {bins!r}")


def _theta(theta_i, transmission: bool = False) -> tuple[float, ...]:
    """The incidences: in [0, 90), or with ``transmission`` also (90, 180] (from inside)."""
    try:
        th = np.atleast_1d(np.asarray(theta_i, dtype=np.float64))
    except (TypeError, ValueError):
        th = np.array([np.nan])
    top = 180.0 if transmission else 90.0
    if th.ndim != 1 or th.size == 0 or not np.all((th >= 0) & (th <= top) & (th != 90)):
        raise UsageError(
            "theta_i must be one or more incidence angles in degrees, each in [0, 90)"
            + (" or (90, 180] (from inside the medium)" if transmission else "")
            + f", got {theta_i!r}"
        )
    return tuple(float(t) for t in th)


def _phi(phi_i, n: int) -> tuple[float, ...]:
    """``phi_i`` (degrees; a scalar, or one per θi) as one azimuth per incidence."""
    try:
        ph = np.atleast_1d(np.asarray(phi_i, dtype=np.float64))
    except (TypeError, ValueError):
        ph = np.array([np.nan])
    if ph.ndim != 1 or ph.size not in (1, n) or not np.all(np.abs(ph) <= 360.0):
        raise UsageError(
            f"phi_i must be an incidence azimuth in degrees in [-360, 360], or one per θi "
            f"({n}), got {phi_i!r}"
        )
    return tuple(float(p) for p in np.broadcast_to(ph, (n,)))


def _is_surface(s) -> bool:
    return hasattr(s, "facet_normals") and hasattr(s, "fingerprint")


def resolve_reference(
    surface_or_scene,
    material="scene",
    theta_i=None,
    *,
    phi_i=None,
    rays="auto",
    bins=None,
    seed: int = 0,
    target: float = AUTO_TARGET,
    max_rays: int = AUTO_MAX_RAYS,
    realisations: int | None = None,
    transmission: bool = False,
) -> Reference:
    """Validate the arguments of ``reference``/``assert_brdf_agrees`` into a ``Reference``.

    ``surface_or_scene``: a ``Scene``, a scene file or catalogue name (``find_scene``), a
    ``Surface`` or a sequence of Surfaces (realisations). A scene supplies the defaults:
    ``material="scene"`` takes its ior, ``theta_i=None`` and ``phi_i=None`` its incidences
    (every θi at each of its φi, as ``microsim run`` traces them), ``bins=None`` its
    (theta_bins, phi_bins) — over the whole circle where the scene has ``full_azimuth``; its
    realisations r = 0 … R−1 are built with seed
    ``simulation.seed + r`` at full size. ``realisations`` (an integer in [1, 1000]) overrides
    the scene's count; a scene with ``realisations = "auto"`` gets ``DEFAULT_REALISATIONS``
    (= ``microsim.analysis.budget.MIN_AUTO``, 8) — the runner's pilot rule, which may choose
    more, is not run here. For a Surface, ``material`` (name, n, n + ik, None =
    mirror) and ``theta_i`` are required, ``phi_i`` defaults to 0 and ``bins`` to ``Bins()``.
    ``phi_i`` given: a scalar or one azimuth per θi (degrees, the surface frame).
    ``transmission=True`` (``assert_bsdf_agrees``): through the dielectric interface of a real
    index ``material``, θi also in (90, 180], a fixed ray count."""
    if realisations is not None and (
        isinstance(realisations, bool)
        or not isinstance(realisations, (int, np.integer))
        or not 1 <= realisations <= 1000
    ):
        raise UsageError(f"realisations must be an integer in [1, 1000], got {realisations!r}")
    if isinstance(surface_or_scene, (str, os.PathLike, Scene)):
        scene = surface_or_scene
        if not isinstance(scene, Scene):
            scene = load_scene(find_scene(surface_or_scene))
        source = _scene_source(scene, realisations, material, theta_i, phi_i)
    else:
        source = _surfaces_source(surface_or_scene, realisations, material, theta_i, phi_i)
    eta = resolve_material(source.material)
    _check_budget(seed, rays, target, max_rays)
    if transmission:
        check_transmission(True, eta)
        if rays == "auto":
            raise UsageError("rays must be an integer >= 1000 with transmission, got 'auto'")
    theta = _theta(source.theta_i, transmission)
    return Reference(
        fingerprints=source.fingerprints,
        azimuth_average=source.azimuth_average,
        build=source.build,
        material=eta,
        theta_i=theta,
        phi_i=_phi(0.0 if source.phi_i is None else source.phi_i, len(theta)),
        bins=_bins(bins, source.bins),
        seed=int(seed),
        rays=rays if isinstance(rays, str) else int(rays),
        target=float(target),
        max_rays=int(max_rays),
        label=source.label,
        ensemble_ndf=source.ensemble_ndf,
        exact_shadowing=source.exact_shadowing,
        transmission=bool(transmission),
    )


@dataclass(frozen=True)
class _Source:
    """What a scene or explicit surfaces give a reference: the surfaces (fingerprints,
    azimuth-average flags, builder), the material, incidences and default bins, a label and
    the surfaces' ensemble NDF (or None) and exact shadowing kind (or None)."""

    fingerprints: tuple
    azimuth_average: tuple
    build: Callable[[], tuple]
    material: object
    theta_i: object
    phi_i: object
    bins: Bins
    label: str
    ensemble_ndf: object
    exact_shadowing: str | None


def _scene_source(scene: Scene, realisations, material, theta_i, phi_i) -> _Source:
    """A scene's realisations (its seeds, ``realisations`` or its count, "auto":
    ``DEFAULT_REALISATIONS``) and its defaults for the other arguments."""
    R, s0 = scene.simulation.realisations, int(scene.simulation.seed)
    if realisations is not None:
        R = int(realisations)
    elif not isinstance(R, (int, np.integer)):  # "auto"
        R = DEFAULT_REALISATIONS
    build = _scene_builder(scene, s0, int(R))
    fingerprints, azimuth = _scene_identity(scene, s0, int(R), build)
    if isinstance(material, str) and material == "scene":
        material = scene.ior
    if theta_i is None:
        theta_i = scene.simulation.theta_i
    if phi_i is None:
        theta_i, phi_i = incidence_pairs(_theta(theta_i), scene.simulation.phi_i)
    bins = Bins(
        scene.simulation.theta_bins, scene.simulation.phi_bins, folded=not scene.full_azimuth
    )
    label = f"{scene.path or scene.name}"
    return _Source(
        fingerprints,
        azimuth,
        build,
        material,
        theta_i,
        phi_i,
        bins,
        label,
        scene.ndf(),
        scene.surface.exact_shadowing,
    )


def _surfaces_source(surface_or_surfaces, realisations, material, theta_i, phi_i) -> _Source:
    """A Surface or a sequence of them (realisations); ``material`` and ``theta_i`` must be
    given."""
    if realisations is not None:
        raise UsageError(
            "realisations applies to a scene; for Surfaces pass the list of realisations"
        )
    if _is_surface(surface_or_surfaces):
        surfaces = (surface_or_surfaces,)
    elif (
        isinstance(surface_or_surfaces, (list, tuple))
        and surface_or_surfaces
        and all(_is_surface(s) for s in surface_or_surfaces)
    ):
        surfaces = tuple(surface_or_surfaces)
    else:
        raise UsageError(
            "surface_or_scene must be a Scene, a scene file or catalogue name, a Surface "
            f"or a sequence of Surfaces (realisations), got {surface_or_surfaces!r}"
        )
    label = repr(surfaces[0]) + (f" (+{len(surfaces) - 1} realisations)" * (len(surfaces) > 1))
    if isinstance(material, str) and material == "scene":
        raise UsageError(
            "material must be given for a Surface (a name such as 'aluminium', n, n + ik, "
            "or None for a mirror); 'scene' takes it from a scene"
        )
    if theta_i is None:
        raise UsageError("theta_i must be given for a Surface (degrees, each in [0, 90))")
    return _Source(
        tuple(s.fingerprint() for s in surfaces),
        tuple(bool(s.azimuth_average) for s in surfaces),
        lambda: surfaces,
        material,
        theta_i,
        phi_i,
        Bins(),
        label,
        surfaces[0].ensemble_ndf,
        surfaces[0].exact_shadowing,
    )


def _check_budget(seed, rays, target, max_rays) -> None:
    """UsageError naming the first bad one of ``seed``, ``rays``, ``target``, ``max_rays``."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise UsageError(f"seed must be an integer >= 0, got {seed!r}")
    if isinstance(rays, str):
        if rays != "auto":
            raise UsageError(f"rays must be an integer >= 1000 or 'auto', got {rays!r}")
    elif isinstance(rays, bool) or not isinstance(rays, (int, np.integer)) or rays < 1000:
        raise UsageError(f"rays must be an integer >= 1000 or 'auto', got {rays!r}")
    if not (isinstance(target, (int, float)) and not isinstance(target, bool) and 0 < target < 1):
        raise UsageError(f"target must be a relative error in (0, 1), got {target!r}")
    if isinstance(max_rays, bool) or not isinstance(max_rays, (int, np.integer)) or max_rays < 1000:
        raise UsageError(f"max_rays must be an integer >= 1000, got {max_rays!r}")


_IDENTITIES: dict = {}  # scene identity key → (fingerprints, azimuth flags), this process


def _scene_builder(scene: Scene, seed: int, n: int) -> Callable[[], tuple]:
    """The scene's n realisations from seed ``seed``, built on the first call and kept: the
    look-up of their fingerprints and a trace of the reference share one build."""

    @functools.cache
    def build() -> tuple:
        return tuple(scene.build_surface(seed=seed + r) for r in range(n))

    return build


def _mtime(path) -> tuple:
    try:
        st = os.stat(path)
        return (str(Path(path).resolve()), st.st_mtime_ns, st.st_size)
    except OSError:
        return (str(path), None, None)


def _scene_identity(scene: Scene, seed: int, n: int, build) -> tuple[tuple, tuple]:
    """(fingerprints, azimuth flags) of the scene's n realisations from seed ``seed``,
    memoised in this process by what the surfaces are built from (kind, parameters, seeds,
    and a heightfield file's path, size and modification time), so that a test suite builds
    a random scene's meshes once per process to look its reference up, not once per check."""
    params = tuple(sorted((k, repr(v)) for k, v in scene.surface.params.items()))
    extra = ()
    if scene.surface.kind == "file":
        base = scene.path.parent if scene.path is not None else Path.cwd()
        extra = _mtime(base / scene.surface.params["path"])
    key = (scene.surface.kind, params, seed, n, extra)
    if key not in _IDENTITIES:
        surfaces = build()
        _IDENTITIES[key] = (
            tuple(s.fingerprint() for s in surfaces),
            tuple(bool(s.azimuth_average) for s in surfaces),
        )
    return _IDENTITIES[key]


def _auto_rays(ref: Reference, threads) -> int:
    """Rays per incidence of a several-realisation ``rays="auto"`` reference: ``simulate_auto``
    on realisation 0 (a pilot, seed ``seed``) to ``target``, its largest ray count over the
    incidences, times the number of realisations — each realisation as precise as one
    surface traced to ``target``, the mean √R times more (its tile-to-tile scatter is what the
    t tests then weigh)."""
    return int(np.max(_auto_first_surface(ref, threads).rays)) * len(ref.surfaces)


def _auto_first_surface(ref: Reference, threads) -> Result:
    """``simulate_auto`` on the reference's first surface to its ``target``."""
    return simulate_auto(
        ref.surfaces[0],
        ref.material,
        list(ref.theta_i),
        phi_i=list(ref.phi_i),
        target=ref.target,
        bins=ref.bins,
        seed=ref.seed,
        threads=threads,
        first=AUTO_FIRST,
        max_rays=ref.max_rays,
    )


def _trace(ref: Reference, threads) -> Result:
    if ref.rays == "auto" and len(ref.surfaces) == 1:
        return _auto_first_surface(ref, threads)
    if len(ref.surfaces) == 1:
        return simulate(
            ref.surfaces[0],
            ref.material,
            list(ref.theta_i),
            phi_i=list(ref.phi_i),
            rays=ref.rays,
            bins=ref.bins,
            seed=ref.seed,
            threads=threads,
            transmission=ref.transmission,
        )
    rays = _auto_rays(ref, threads) if ref.rays == "auto" else ref.rays
    return simulate(
        None,
        ref.material,
        list(ref.theta_i),
        phi_i=list(ref.phi_i),
        rays=rays,
        bins=ref.bins,
        seed=ref.seed,
        threads=threads,
        realisations=list(ref.surfaces),
        transmission=ref.transmission,
    )


class _DamagedEntry(Exception):
    """A cache entry that exists but cannot be used; the message names the file and why."""


def _fault(error: Exception) -> str:
    """One line of at most 160 characters saying why an entry cannot be read (a
    ``UsageError`` names the file itself; an ``OSError`` its path)."""
    text = str(error) if isinstance(error, UsageError) else f"{type(error).__name__}: {error}"
    text = " ".join(text.split())
    return text if len(text) <= 160 else text[:159] + "…"


def _load(entry: Path, description: dict) -> Result | None:
    """The cached Result of ``entry``, or None if there is no entry. Raises ``_DamagedEntry``
    naming the file if the entry cannot be read (``atomic.read_json``, ``Result.load``:
    missing, truncated, edited; or an ``OSError``), was made for another description
    (``key.json``), or holds a result that is not the one described (bins, incidences, array
    shapes, negative or non-finite values)."""
    if not os.path.lexists(entry):
        return None
    key, meta, npz = entry / KEY_FILE, entry / META, entry / NPZ
    try:
        stored = atomic.read_json(key)
        if stored != json.loads(json.dumps(description)):
            raise _DamagedEntry(f"{key}: made for another reference than its name says")
        res = Result.load(entry)
    except (UsageError, OSError) as e:
        raise _DamagedEntry(_fault(e)) from None
    bins = res.bins.to_dict()
    if bins != description["bins"]:
        raise _DamagedEntry(f"{meta}: bins {bins} instead of {description['bins']}")
    shape = (len(description["theta_i"]), res.bins.n_theta, res.bins.n_phi)
    arrays = {"brdf": res.brdf, "stderr": res.stderr, "counts": res.counts}
    for name, a in arrays.items():
        if a is None or a.shape != shape or not np.all(np.isfinite(a) & (a >= 0)):
            raise _DamagedEntry(f"{npz}: {name} is not {shape} finite values >= 0")
    same = np.array_equal(res.theta_i, description["theta_i"]) and np.array_equal(
        res.phi_i, np.broadcast_to(np.asarray(description["phi_i"], float), res.phi_i.shape)
    )
    if not same or res.is_partial:
        raise _DamagedEntry(
            f"{npz}: not the complete result at θi = {description['theta_i']}, "
            f"φi = {description['phi_i']}"
        )
    return res


def _discard(entry: Path) -> None:
    """Remove a damaged entry (under its lock); what cannot be removed is replaced by the
    next ``atomic.publish_dir``."""
    try:
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry)
        else:
            entry.unlink()
    except OSError:
        pass


def _acquire(path: Path, timeout: float):
    """Enter ``atomic.output_lock(path)`` (a context manager), retrying while it is held."""
    start = time.monotonic()
    while True:
        cm = atomic.output_lock(path)
        try:
            cm.__enter__()
            return cm
        except UsageError:
            if time.monotonic() - start > timeout:
                raise UsageError(
                    f"cache: waited {timeout:g} s for another process tracing {path}"
                ) from None
            time.sleep(0.1)


def reference(
    surface_or_scene,
    material="scene",
    theta_i=None,
    *,
    phi_i=None,
    rays="auto",
    bins=None,
    seed: int = 0,
    target: float = AUTO_TARGET,
    max_rays: int = AUTO_MAX_RAYS,
    realisations: int | None = None,
    cache=None,
    threads: int | None = None,
) -> Result:
    """The reference ``Result`` (sr⁻¹ bin averages, standard errors, realisations) for these
    arguments (``resolve_reference``), from the cache or traced once and cached (module
    docstring). ``cache=False`` traces without reading or writing the cache.

    ``rays``: primary rays per incidence, or ``"auto"``: ``simulate_auto`` traces batches
    (the first ``AUTO_FIRST`` rays, then as many as predicted from rse ∝ N^(−1/2), at most 4×
    per step) until the energy-weighted relative standard error over the bins carrying 90 %
    of the reflected energy is ≤ ``target`` (default 2 %) or ``max_rays`` (default 4·10⁶)
    rays per incidence were traced — never more. With several realisations, ``"auto"``
    traces realisation 0 that way first (a pilot) and then every realisation with the pilot's
    largest ray count (``_auto_rays``), at most R × ``max_rays`` per incidence."""
    ref = resolve_reference(
        surface_or_scene,
        material,
        theta_i,
        phi_i=phi_i,
        rays=rays,
        bins=bins,
        seed=seed,
        target=target,
        max_rays=max_rays,
        realisations=realisations,
    )
    return cached(ref, cache=cache, threads=threads)


def cached(ref: Reference, *, cache=None, threads: int | None = None) -> Result:
    """``ref``'s Result from the cache, or traced, published atomically and returned."""
    if cache is False:
        return _trace(ref, threads)
    root = cache_dir(cache)
    desc = ref.description()
    entry = root / ref.key()
    try:
        res = _load(entry, desc)
    except _DamagedEntry:
        res = None  # looked at again under the lock: another process may be replacing it
    if res is not None:
        return res
    root.mkdir(parents=True, exist_ok=True)
    lock = _acquire(entry, LOCK_TIMEOUT)
    try:
        try:
            res = _load(entry, desc)  # another process may have published it meanwhile
        except _DamagedEntry as damaged:
            _discard(entry)  # first: under ``-W error`` the warning raises
            warnings.warn(
                f"microsim reference cache: {damaged}; discarded the entry, tracing the "
                f"reference again",
                stacklevel=2,
            )
        if res is not None:
            return res
        atomic.clean_stale(entry)
        res = _trace(ref, threads)
        stage = atomic.make_staging(entry)
        try:
            res.save(stage)
            atomic.write_json(stage / KEY_FILE, desc)
            atomic.publish_dir(stage, entry)
        except BaseException:
            shutil.rmtree(stage, ignore_errors=True)
            raise
        return res
    finally:
        lock.__exit__(None, None, None)


_DERIVED: dict = {}  # this process: derived description (canonical JSON) → array or None


@functools.cache
def source_digest() -> str:
    """SHA-256 (24 hex digits) of microsim's own source (every ``.py`` file of the package,
    by relative path): derived entries are keyed by it, so that code computing them
    differently is never answered from an older computation."""
    root = Path(microsim.__file__).resolve().parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()[:24]


def derived(ref: Reference, what: dict, shape: tuple, compute, *, cache=None):
    """What the reference's surfaces, material, incidences and bins alone determine, not its
    rays or seed (a catalogue model's bin averages, the tile's departure from its ensemble):
    ``compute()``, a float array of ``shape`` or None, computed once per process and, unless
    ``cache=False``, once per cache directory: kept in ``CACHE/derived/<key>.npz`` under the
    key of ``ref.description()`` without rays and seed, microsim's ``source_digest`` and
    ``what`` (JSON values naming the quantity). Returns a copy. An entry that cannot be used
    is reported in one warning naming the file, discarded and computed again; one that cannot
    be written is not kept."""
    desc = {k: v for k, v in ref.description().items() if k not in ("seed", "rays")}
    text = canonical_json({**desc, "source": source_digest(), "derived": what})
    if text not in _DERIVED:
        _DERIVED[text] = _derived_value(text, tuple(shape), compute, cache)
    value = _DERIVED[text]
    return None if value is None else value.copy()


def _derived_value(text: str, shape: tuple, compute, cache):
    """``derived``'s value: read from the cache entry of ``text``, else computed and stored."""
    if cache is False:
        return compute()
    path = cache_dir(cache) / DERIVED_DIR / f"{hashlib.sha256(text.encode()).hexdigest()[:24]}.npz"
    try:
        stored = _load_derived(path, text, shape)
    except _DamagedEntry as damaged:
        stored = None
        _discard(path)  # first: under ``-W error`` the warning raises
        warnings.warn(
            f"microsim reference cache: {damaged}; discarded the entry, computing it again",
            stacklevel=3,
        )
    if stored is not None:
        return stored[0]
    value = compute()
    arrays = {"key": np.array(text)}
    if value is not None:
        arrays["values"] = np.asarray(value, dtype=np.float64)
    try:
        with atomic.atomic_open(path, "wb") as fh:
            np.savez(fh, **arrays)
    except OSError:
        pass  # a read-only cache: the value is computed again by the next process
    return value


def _load_derived(path: Path, text: str, shape: tuple) -> tuple | None:
    """(value,) of the derived entry ``path`` (value None where None was stored), or None if
    there is no entry. Raises ``_DamagedEntry`` naming the file if it cannot be read, was
    made for another description or holds no float array of ``shape``."""
    if not os.path.lexists(path):
        return None
    try:
        arrays = atomic.read_npz(path)
    except (UsageError, OSError) as e:
        raise _DamagedEntry(_fault(e)) from None
    key = arrays.get("key")
    if key is None or key.shape != () or str(key) != text:
        raise _DamagedEntry(f"{path}: made for another quantity than its name says")
    value = arrays.get("values")
    if value is not None and (value.dtype != np.float64 or value.shape != shape):
        raise _DamagedEntry(f"{path}: values are not {shape} floats")
    return (value,)
