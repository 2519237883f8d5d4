"""A run's identity: ``RunDescription``, everything that determines a run's numbers, and
``saved_identity``, the one reader of the identity of a saved run, whatever microsim wrote it.

``RunDescription.identity()`` is a canonical, versioned, JSON-able dict (``IDENTITY_VERSION``);
``key()`` its SHA-256. Every consumer uses it: ``estimate(resume=...)`` and ``microsim run
--resume`` compare the description of the run asked for with the saved run's
(``mismatches``), the testing cache names its entries by ``key()``, and a sweep task's id
is the key of its run with the models that judge it.

Fields: ``surfaces`` (how the surfaces are made: their fingerprints, or a scene's surface
recipe; None when each realisation is checked by its fingerprint as it is built), the
material (n, k) or None (a mirror), the incidences (θi, φi in degrees, one pair each), the
outgoing bins, the scattering orders traced (``bounces``), the realisations, the rays per
incidence, the random stream (``seed``), the masking test, the origins' sampling and the
per-block azimuth rotation (``isotropic``), and whether light is transmitted through a
dielectric interface (``transmission``, recorded only when it is); the identity adds the
block size and the rays' design (``streams.BLOCK``, ``streams.DESIGN``).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

import numpy as np

from microsim.bins import Bins

from .streams import BLOCK, DESIGN

__all__ = ["IDENTITY_VERSION", "RunDescription", "saved_identity", "canonical_json"]

IDENTITY_VERSION = 1
"""Version of ``RunDescription.identity``'s layout; a change of layout changes every key."""

COMPARED = (
    "surfaces",
    "material",
    "theta_i",
    "phi_i",
    "bins",
    "bounces",
    "realisations",
    "rays",
    "seed",
    "masking",
    "origins",
    "isotropic",
    "block",
    "design",
    "transmission",
)
"""The identity's fields in the order a mismatch is reported."""


def canonical_json(value) -> str:
    """``value`` as canonical JSON (sorted keys, no spaces): equal identities, equal text."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def _material(ior) -> list | None:
    """A complex index (or None, a mirror) as [n, k]."""
    if ior is None:
        return None
    c = complex(ior)
    return [float(c.real), float(c.imag)]


@dataclass(frozen=True)
class RunDescription:
    """What determines a run's numbers (module docstring). ``material`` a complex index or
    None; ``theta_i``/``phi_i`` one pair per incidence (degrees); ``rays`` an integer, or a
    JSON-able dict for a run traced to a precision (its target and cap); ``surfaces`` JSON
    values or None."""

    material: object
    theta_i: tuple
    phi_i: tuple
    bins: Bins
    rays: object
    seed: int
    surfaces: object = None
    bounces: int | str = 1
    realisations: int = 1
    masking: str = "traced"
    origins: str = "stratified"
    isotropic: bool = False
    transmission: bool = False

    @classmethod
    def of(cls, experiment, estimator, realisations: int, surfaces=None) -> RunDescription:
        """The description of ``estimate(experiment, estimator)`` over ``realisations``."""
        return cls(
            material=experiment.ior,
            theta_i=experiment.theta_i,
            phi_i=experiment.phi_i,
            bins=experiment.bins,
            rays=estimator.rays,
            seed=estimator.seed,
            surfaces=surfaces,
            bounces=experiment.bounces,
            realisations=realisations,
            masking=estimator.masking,
            origins=estimator.origins,
            isotropic=estimator.isotropic,
            transmission=experiment.transmission,
        )

    def identity(self) -> dict:
        """The canonical, versioned, JSON-able identity (module docstring); ``transmission``
        only when True (the identities of runs without it are unchanged)."""
        return {
            "identity": IDENTITY_VERSION,
            "surfaces": _json(self.surfaces),
            "material": _material(self.material),
            "theta_i": [float(t) for t in self.theta_i],
            "phi_i": [float(p) for p in np.broadcast_to(self.phi_i, (len(self.theta_i),))],
            "bins": self.bins.to_dict(),
            "bounces": self.bounces,
            "realisations": int(self.realisations),
            "rays": _json(self.rays),
            "seed": int(self.seed),
            "masking": self.masking,
            "origins": self.origins,
            "isotropic": bool(self.isotropic),
            "block": BLOCK,
            "design": DESIGN,
        } | ({"transmission": True} if self.transmission else {})

    def key(self, extra: dict | None = None) -> str:
        """SHA-256 (hex) of the identity (with ``extra``, JSON values, added)."""
        text = canonical_json({**self.identity(), **(extra or {})})
        return hashlib.sha256(text.encode()).hexdigest()

    def mismatches(self, saved: dict) -> list[tuple[str, object, object]]:
        """(field, saved value, this run's value) for every field of ``saved`` (an identity,
        e.g. ``saved_identity``) this run cannot continue; ``surfaces`` is compared only when
        this description has them. A saved run of the first k realisations of this run, each
        with this run's rays, is continued, not refused."""
        now = self.identity()
        fields = [k for k in COMPARED if (k != "surfaces" or now[k] is not None)]
        diff = [k for k in fields if saved.get(k) != now.get(k)]
        if set(diff) <= {"rays", "realisations"} and _is_prefix(saved, now):
            return []
        return [(k, saved.get(k), now.get(k)) for k in diff]


def _json(value):
    return json.loads(json.dumps(value)) if value is not None else None


def _is_prefix(old: dict, new: dict) -> bool:
    """Whether identity ``old`` (k realisations) is the first k realisations of ``new``:
    fewer realisations, every one with exactly the same rays (no remainder)."""
    (k, n), (a, b) = (old["realisations"], new["realisations"]), (old["rays"], new["rays"])
    if not all(isinstance(x, int) and x > 0 for x in (k, n, a, b)):
        return False
    return k < n and a % k == 0 and b % n == 0 and a // k == b // n


def saved_identity(result) -> dict:
    """The identity of a saved ``Result``, read from what every microsim version wrote: a
    key an older version did not write takes the value that version used (origins
    "stratified", isotropic False, one bounce, design 1); the realisations are the rows of
    the raw tallies; ``surfaces`` the scene's surface recipe of a ``microsim run`` result
    (``meta["run"]``: scene, surface, quick) or None. A key no default stands for (an
    unrecorded seed, rays, block) reads as None and so matches nothing."""
    meta = result.meta
    blocks = (result.tallies or {}).get("blocks")
    run = meta.get("run")
    return {
        "identity": IDENTITY_VERSION,
        "surfaces": scene_recipe_of_record(run) if isinstance(run, dict) else None,
        "material": (meta.get("material") or {}).get("ior"),
        "theta_i": [float(t) for t in result.theta_i],
        "phi_i": [float(p) for p in result.phi_i],
        "bins": result.bins.to_dict(),
        "bounces": meta.get("bounces", 1),
        "realisations": None if blocks is None else int(np.shape(blocks)[0]),
        "rays": meta.get("rays"),
        "seed": meta.get("seed"),
        "masking": meta.get("masking"),
        "origins": meta.get("origins", "stratified"),
        "isotropic": bool(meta.get("isotropic", False)),
        "block": meta.get("block"),
        "design": meta.get("design", 1),
    } | ({"transmission": True} if meta.get("transmission") else {})


SCENE_RECIPE = ("scene", "surface", "quick")
"""What a ``microsim run`` result's surfaces are made from (``meta["run"]``): the scene's
name, its [surface] settings (a heightfield file by its SHA-256) and the effort."""


def scene_recipe_of_record(run: dict) -> dict:
    """The surface recipe of a ``meta["run"]`` record (a key it lacks reads None)."""
    return {k: run.get(k) for k in SCENE_RECIPE}
