"""Spectral runs: every path's geometry traced once, the Fresnel factor of each of W materials
(a material of ``materials.TABLE`` at W wavelengths, or any W materials) applied to it.

The weight of a path is a product of Fresnel factors Π_b F(c_b) over its bounces, and
nothing else a path does depends on the material: where it starts, which facets it meets,
their cosines c_b and where it escapes are geometry. So a spectral run traces the geometry
once — the same rays, one cast per ray and bounce, as a run of one material — and weights it
W times:

- ``bounces`` = 1: the single-bounce paths (``paths.choose_path``: traced, facet table,
  rotated, analytic V-groove) are followed with the material ``fresnel_kernels.COSINE``, whose
  weight is the hit's cosine c; each material's weight is then F(c) (``fresnel_weights``),
  the value a run of that material computes from the same c;
- ``bounces`` = K or "all": the Embree bounce chain (``bounces.trace_bounces``) is traced
  with F = 1 and records each step's cosines; after every step ``bounce_kernels.
  spectral_step`` multiplies each material's carried weight by its F(c_b) in the order a run
  of that material does. With "all", each material's path is cut where its own weight falls
  below ``bounces.WEIGHT_FLOOR``; the geometry goes on while any material still carries the
  path (the maximum weight over the materials is above the floor). So every material's
  paths end exactly where its own run ends them.

Each material's per-block tallies are then those of its own run (``tallies``), so the Result
of material j is bitwise the Result of ``simulate`` with that material and the same seed
(tests/test_spectral.py); only the wall time is shared. Cost: the geometry once, plus per
material one Fresnel pass and the tallies. Memory per thread task: ~35 bytes per ray and
material for the bounce chains' per-material ledger (``bounce_kernels.SpectralLedger``).

Not traced spectrally (a UsageError naming the argument): ``transmission=True`` (a
dielectric's paths branch on Russian roulette over its Fresnel factor, so their geometry
depends on the material), ``masking="analytic"`` with ``bounces`` > 1 (its closed-form chain
weights inside the kernel), a cluster, and ``resume``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from microsim.analytic import materials as material_table
from microsim.analytic.fresnel import resolve_material
from microsim.checks import check_memory
from microsim.errors import UsageError

from .bounce_kernels import SpectralMaterials
from .bounces import choose_bounce_path, order_slots
from .fresnel_kernels import COSINE, fresnel_mode, fresnel_weights
from .paths import Incidence, choose_path
from .result import Result
from .schedule import IN_FLIGHT
from .tallies import ChunkTallies, Tally, split_order_tallies, split_tallies

__all__ = [
    "Spectrum",
    "SpectralResult",
    "SpectralTally",
    "spectral_task",
    "check_spectral_run",
    "check_task_memory",
    "MAX_MATERIALS",
    "TASK_BYTES",
]

MAX_MATERIALS = 1024
"""Most materials (wavelengths) of one spectral run."""
TASK_BYTES = 80
"""Bytes per ray and material a spectral thread task holds beyond a one-material run's: the
bounce chain's per-material ledger (35, ``bounce_kernels.SpectralLedger``) and each
material's per-block tallies until they are added (at most ~40)."""


@dataclass(frozen=True, eq=False)
class Spectrum:
    """The W materials of a spectral run: ``materials`` as ``resolve_material`` takes them
    (pairs (name, wavelength_nm) for a table material), ``wavelengths_nm`` (W floats) or None
    when the materials were given as a list, and ``iors`` their resolved indices."""

    materials: tuple
    wavelengths_nm: tuple | None
    iors: tuple

    @classmethod
    def of(cls, material, wavelengths_nm=None) -> "Spectrum":
        """``material`` at each of ``wavelengths_nm`` (a name of ``materials.TABLE``, e.g.
        "gold", and a sequence of wavelengths in nm inside its dataset's range), or, without
        ``wavelengths_nm``, ``material`` a list of materials (each one ``resolve_material``
        takes: a name, an index n / n+ik, a (name, wavelength_nm) pair, None). A UsageError
        names what is wrong: an empty list, a wavelength out of range, a name without a
        table."""
        if wavelengths_nm is None:
            if not isinstance(material, list):
                raise UsageError(
                    "a spectral run needs wavelengths_nm (a list of wavelengths in nm, with a "
                    "material of the table such as 'gold') or material as a list of materials, "
                    f"got material {material!r} and no wavelengths_nm"
                )
            _check_count("material", material)
            mats = tuple(material)
            return cls(mats, None, tuple(resolve_material(m) for m in mats))
        if not isinstance(material, str) or material_table.table_name(material) is None:
            allowed = ", ".join(sorted(material_table.TABLE))
            raise UsageError(
                f"material with wavelengths_nm must be one of {allowed}, got {material!r}"
            )
        nm = _wavelengths(wavelengths_nm)
        mats = tuple((material, w) for w in nm)
        try:
            iors = tuple(resolve_material(m) for m in mats)
        except UsageError as e:
            raise UsageError(str(e).replace("wavelength_nm", "wavelengths_nm", 1)) from None
        return cls(mats, nm, iors)

    def kernel_materials(self) -> SpectralMaterials:
        """The materials as the bounce chain's kernels take them."""
        modes = [fresnel_mode(ior) for ior in self.iors]
        return SpectralMaterials(
            np.array([m[1] for m in modes]),
            np.array([m[2] for m in modes]),
            np.array([m[0] for m in modes], dtype=np.int64),
        )

    def material_meta(self, j: int, record: dict) -> dict:
        """Material ``j``'s record in its Result's meta: ``record`` (as ``simulate`` writes
        it) named after the table material and with its ``wavelength_nm``."""
        if self.wavelengths_nm is None:
            return record
        name = self.materials[j][0]
        return {**record, "name": name, "wavelength_nm": self.wavelengths_nm[j]}


def check_spectral_run(transmission: bool, masking: str, bounces, cluster) -> None:
    """A UsageError, before any work, for what a spectral run does not trace (module
    docstring), naming the argument."""
    if transmission:
        raise UsageError(
            "a spectral run traces reflection only: pass transmission=False (a dielectric's "
            "paths branch on its Fresnel factor, so they are traced per material with simulate)"
        )
    if masking == "analytic" and bounces != 1:
        raise UsageError(
            f"a spectral run with bounces {bounces!r} follows the Embree chain: pass "
            "masking='traced' (masking='analytic' serves bounces=1 only)"
        )
    if cluster is not None:
        raise UsageError("a spectral run traces on local threads only: pass cluster=None")


def check_task_memory(materials: int, chunk: int, threads: int) -> None:
    """A UsageError naming ``chunk`` when the thread tasks in flight (``IN_FLIGHT`` per
    thread) of ``chunk`` rays would hold more than the memory limit for ``materials``
    materials (``TASK_BYTES``; ``microsim.checks.check_memory``)."""
    tasks = IN_FLIGHT * threads
    check_memory(
        "chunk",
        tasks * chunk * materials * TASK_BYTES,
        f"{tasks} thread tasks of {chunk:,} rays × {materials} materials (pass a smaller chunk)",
    )


def _check_count(name: str, values) -> None:
    """UsageError unless ``values`` holds 1 to ``MAX_MATERIALS`` entries."""
    if not 1 <= len(values) <= MAX_MATERIALS:
        raise UsageError(
            f"{name} must hold 1 to {MAX_MATERIALS} entries for a spectral run, got {len(values)}"
        )


def _wavelengths(wavelengths_nm) -> tuple:
    """``wavelengths_nm`` as a tuple of finite floats (1 to ``MAX_MATERIALS``), or a
    UsageError naming it."""
    what = "a list of wavelengths in nm (numbers)"
    if isinstance(wavelengths_nm, (str, bytes)) or np.ndim(wavelengths_nm) != 1:
        raise UsageError(f"wavelengths_nm must be {what}, got {wavelengths_nm!r}")
    try:
        nm = np.asarray(wavelengths_nm, dtype=np.float64)
    except (TypeError, ValueError):
        raise UsageError(f"wavelengths_nm must be {what}, got {wavelengths_nm!r}") from None
    _check_count("wavelengths_nm", nm)
    if not np.all(np.isfinite(nm)):
        raise UsageError(f"wavelengths_nm must be finite numbers, got {wavelengths_nm!r}")
    return tuple(float(w) for w in nm)


@dataclass(frozen=True, eq=False)
class SpectralResult:
    """What a spectral run gives: one ordinary ``Result`` per material (``results``, each
    with its own BRDF, standard errors, ledger and tallies, its material — and wavelength — in
    ``meta["material"]``) and the ``wavelengths_nm`` (W,) (None for a list of materials).
    ``result[j]``, ``len(result)`` and iteration go over the Results; ``brdf`` and ``stderr``
    stack them (W, T, Θ, Φ), read-only."""

    results: tuple
    wavelengths_nm: np.ndarray | None

    def __post_init__(self):
        if self.wavelengths_nm is not None:
            nm = np.array(self.wavelengths_nm, dtype=np.float64)
            nm.flags.writeable = False
            object.__setattr__(self, "wavelengths_nm", nm)
        object.__setattr__(self, "results", tuple(self.results))

    def __len__(self) -> int:
        return len(self.results)

    def __getitem__(self, j: int) -> Result:
        return self.results[j]

    def __iter__(self):
        return iter(self.results)

    @property
    def brdf(self) -> np.ndarray:
        """The BRDFs (W, T, Θ, Φ) in sr⁻¹ (order 1 for bounce chains, as ``Result.brdf``)."""
        return _stacked([r.brdf for r in self.results])

    @property
    def stderr(self) -> np.ndarray:
        """Their standard errors (W, T, Θ, Φ) in sr⁻¹."""
        return _stacked([r.stderr for r in self.results])


def _stacked(arrays) -> np.ndarray:
    """``arrays`` stacked into a new read-only array."""
    out = np.stack(arrays)
    out.flags.writeable = False
    return out


class SpectralTally:
    """The running sums of one (realisation, incidence) for each material (``tallies``:
    one ``Tally`` each), added chunk by chunk as ``Tally.add_chunk`` adds one material's."""

    def __init__(self, materials: int, nbin: int, classes: int):
        self.tallies = tuple(Tally.empty(nbin, classes) for _ in range(materials))

    def add_chunk(self, chunk: "SpectralChunk") -> int:
        """Add a chunk's per-block tallies of every material; returns the blocks added."""
        for tally, part in zip(self.tallies, chunk.parts):
            tally.add_chunk(part)
        return chunk.blocks


class SpectralChunk:
    """The per-block tallies of one chunk, one ``ChunkTallies`` per material."""

    def __init__(self, parts: list[ChunkTallies]):
        self.parts = parts
        self.blocks = parts[0].blocks


def spectral_task(
    incidence: Incidence,
    profile,
    azimuth: bool,
    isotropic: bool,
    bounces,
    spectrum: Spectrum,
    pool=None,
    parts: int = 1,
):
    """The thread task of one incidence of a spectral run: ``task(blocks)`` follows the paths
    of those blocks once and returns each material's per-block tallies (``SpectralChunk``).
    As ``bounces.chain_task``, with the geometry traced as the module docstring says."""
    nbin = incidence.bins.shape[0] * incidence.bins.shape[1]
    if bounces == 1:
        path = choose_path(replace(incidence, ior=COSINE), profile, azimuth, isotropic, pool, parts)
        return partial(_single_bounce_tallies, path, nbin, spectrum.kernel_materials())
    path = choose_bounce_path(
        incidence, profile, azimuth, isotropic, bounces, nbin, pool, parts,
        spectrum.kernel_materials(),
    )  # fmt: skip
    return partial(_chain_tallies, path, nbin * order_slots(bounces))


def _single_bounce_tallies(path, nbin: int, materials: SpectralMaterials, blocks):
    """Each material's per-block tallies of ``blocks`` followed once by the single-bounce
    ``path`` (its weights the hits' cosines): F(c) per material, then ``split_tallies``."""
    blocks = list(blocks)
    status, cosine, where = path.follow(blocks)
    weight = np.empty(len(cosine))
    parts = []
    for n2, k2, mode in zip(*materials):
        fresnel_weights(cosine, float(n2), float(k2), int(mode), weight)
        parts.append(split_tallies(status, weight, where, len(blocks), nbin))
    return SpectralChunk(parts)


def _chain_tallies(path, nbin_total: int, blocks):
    """Each material's per-block tallies of ``blocks`` followed once by the spectral bounce
    chain ``path`` (its ``SpectralLedger``): ``split_order_tallies`` per material."""
    blocks = list(blocks)
    ledger = path.follow(blocks)
    parts = []
    for j in range(ledger.term.shape[1]):
        columns = [np.ascontiguousarray(a[:, j]) for a in ledger[:5]]
        parts.append(split_order_tallies(*columns, len(blocks), nbin_total))
    return SpectralChunk(parts)
