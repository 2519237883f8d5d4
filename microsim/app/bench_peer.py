"""The bench's peer: the same single-bounce estimator written with Mitsuba 3's LLVM backend.

microsim's throughput is judged against "a Mitsuba 3 LLVM single-bounce estimator of the
same work on the same machine". This module is that estimator, so that
``microsim bench`` can measure the peer itself instead of quoting a figure. It needs the
optional extra ``pip install 'microsim[peer]'`` (mitsuba ≥ 3.5, drjit); without it every entry
point raises ``PeerUnavailable``.

The estimator (same as ``microsim.sim.simulate`` with traced masking, Mikkelsen 2009, eq. 9):

* N primary rays along −wi start on the plane z = zmax + margin over one tile
  [−Lx/2, Lx/2] × [−Ly/2, Ly/2], stratified like microsim: rays 2k and 2k + 1 share the
  stratum q ∈ [2k/N, (2k + 2)/N) of a row-major sweep of the tile (R = round(√(N·Ly/Lx))
  rows), each uniform inside it (random numbers: Dr.Jit's PCG32, one stream per ray). Uniform
  origins on a horizontal plane sample the surface flux-weighted: the (n·wi) dA factor.
* Closest hit (``Scene.ray_intersect_preliminary``, coherent rays) → facet f with unit
  geometric normal n (float64, cross(v1 − v0, v2 − v0), as ``microsim.sim.Tracer``); weight
  F(n·wi), exact unpolarised Fresnel (``microsim.analytic.fresnel``); mirror direction
  wo = 2(wi·n)n − wi. These depend on the facet alone, so — as microsim's ``facet_table`` —
  they are computed once per incidence in NumPy (float64) for every facet, with the
  (θo, Δφ) bin of wo (``microsim.sim.Bins.locate``), and gathered per ray in Dr.Jit.
* Masking: a shadow ray (``Scene.ray_test``, coherent) from the hit point o + t·d offset by
  ``eps`` along n, along wo, up to the height zmax (nothing above can block it). Escaped rays
  with wo_z > 0 add w to their bin: f̄_B = Σ w / (N Ω_B) (sr⁻¹), Ω_B the bin's projected
  solid angle; the standard error is microsim's paired-strata estimate,
  se_B = √(Σw² − 2 Σ_k w_2k w_2k+1 [same bin]) / (N Ω_B) (``microsim.sim.tallies``),
  unbiased since the two rays of a pair are independent in one stratum.
  Tallies are Dr.Jit scatter-adds in float64 (atomic: the last bits depend on scheduling).

Ledger (as ``microsim.sim.LEDGER``): single, masked, downward (wo_z ≤ 0), unresolved
(back-facing facet n·wi ≤ 0, or a masking ray that would leave the tiled copies — below),
missed (no hit: a leak).

The peer's approximations (where it is *not* the same as microsim):

* No periodic wrap. Mitsuba has none, so the mesh is copied (2m + 1) × (2m + 1) times and
  primary rays start over the centre copy; m (``copies_per_side``) is the smallest number of
  copies per side that a ray at θi or at θo = 88° (``MASKING_CAP_DEG``) cannot cross between
  zmax and zmin: 1 (3 × 3 copies, 4.7 M triangles) for the bench's 512² tile (relief
  zmax − zmin = 10.7), 3 (7 × 7) for a 64² tile of σ = 1.2, ℓ = 8 (relief 6.3). A masking
  ray whose climb to zmax would end outside the copies cannot be decided: it is counted as
  ``unresolved`` and tallied nowhere (a bias towards lower albedo of at most the Fresnel sum
  of those rays, returned in the ledger). With 3 × 3 copies of that 64² tile 0.07 % of the
  rays at θi = 30° were unresolved and the albedo fell 3e-4 (5 σ at 2·10⁵ rays) below
  microsim's — hence the 88° rule. microsim's exact wrap has no such rays.
* Mitsuba builds its Embree scene with ``RTC_SCENE_FLAG_NONE`` (not robust; no option to
  change it) and ``RTC_BUILD_QUALITY_HIGH``: rays through shared edges or vertices can leak
  (counted as ``missed``; the copies' seams are shared edges too). microsim uses Embree's
  robust mode and has no leaks (the peer's bench run: 1–3 leaks in 4.2 M rays). Packets are
  Dr.Jit's LLVM vector width (``rtcIntersect8``/``rtcOccluded8`` on AVX2), flagged coherent
  (``COHERENT``; on the bench, at load 5–7 on 2 cores, the flag changed the peer's rate by
  less than the run-to-run scatter, and a 3 × 3 tiling traced primary rays as fast as a
  single tile).
* Float32 hit points; the shadow ray's offset ``eps`` is 4 float32 ulp of the largest
  coordinate of the tiled scene (microsim: 2 ulp of one tile, projected onto the facet plane
  first in float64).

Dielectric paths (``PeerScene.run_dielectric``, ``mitsuba_dielectric``): the same estimator
as ``simulate(..., transmission=True)`` (``microsim.sim.dielectric``; docs/dielectric.md). Air
(index 1) above the surface, a medium of real index η below; light from above (θi < 90°) or
from inside (θi in (90, 180]: primary rays start under the relief, z = zmin − margin).

* Primary rays: stratified origins and closest hit as above; per facet (one direction per
  incidence, so computed once in NumPy, float64) whether it is met from the light's side, the
  exact unpolarised Fresnel reflectance F of the crossing (``microsim.analytic.fresnel``, 1 at
  total internal reflection), the mirror and the refracted (Snell) directions. A facet met
  from the other side ends the path as ``unresolved``, no hit as ``missed``.
* Russian roulette, as microsim: reflect with probability F, refract otherwise, the weight
  staying 1 (a uniform of the ray's PCG32 stream per interaction).
* Continuation, per ray (its direction is its own) in one Dr.Jit loop (``dr.while_loop``,
  symbolic: one kernel): closest hit from the start, offset ``eps`` off the facet to the new
  ray's side and moved by whole tiles into the centre copy (the surface is periodic, so the
  copies hold every ray that stays between zmin and zmax up to θ = ``MASKING_CAP_DEG``); at a
  hit c = −d·n must say the path's side (else ``unresolved``), F and the new direction from
  Mitsuba's own ``mi.fresnel``, ``mi.reflect``, ``mi.refract`` (float32); after ``bounces``
  interactions a further hit ends the path as ``cut``. A ray without a hit leaves the relief
  up or down: tallied as reflected (the incidence's side) or transmitted if it leaves from the
  side the path is on (else a leak, ``missed``) and its exit from the relief lies over the
  copies (else ``unresolved``: it might have met a copy beyond them).
* Tallies: reflected and transmitted bins (``bins``, θo from the pole of the side the path
  leaves by, Δφ of the direction itself; binned in Dr.Jit, float32), paired-strata standard
  errors as above; R and T the fractions of the paths, with their paired-strata errors.

The ledger (``INTERFACE_LEDGER``): reflected, transmitted, cut, unresolved, missed.

Instruction set: Dr.Jit compiles the peer's kernels for the host CPU at its widest vector
width (16 lanes with AVX-512, 8 with AVX2). ``MICROSIM_PEER_LLVM_CPU`` (an LLVM CPU name, e.g.
``haswell``) pins them to that CPU at 8 lanes, AVX2 and FMA (Dr.Jit's ``jit_llvm_set_target``),
so that with ``NUMBA_CPU_NAME``, ``NUMBA_CPU_FEATURES=""`` (else numba adds the host's
features to the named CPU) and ``NPY_DISABLE_CPU_FEATURES`` both sides' compiled code takes
its AVX2 path on an AVX-512 machine (docs/performance.md); ``llvm_target`` reports the
target in use. Embree's own kernels, inside Mitsuba and inside microsim, still choose theirs
from the host.

Timing (``peer_throughput``; ``microsim bench`` times both estimators itself): marginal
samples/s (a sample = one primary ray and, when lit, its masking ray) excluding the scene
build (mesh upload, BVH) and the JIT compilation (a warm-up run first; Dr.Jit caches the
kernels), best of ``repeat`` runs, the per-incidence facet table included (as microsim's
pipeline figure includes its own).
"""

from __future__ import annotations

import ctypes
import inspect
import os
import time
from dataclasses import dataclass, field

import numpy as np

from microsim.checks import integer
from microsim.errors import EnvironmentFailure, UsageError

__all__ = [
    "PeerUnavailable",
    "load_mitsuba",
    "PeerResult",
    "PeerScene",
    "VARIANTS",
    "PIP_COMMAND",
    "mitsuba_single_bounce",
    "mitsuba_dielectric",
    "PeerInterfaceResult",
    "INTERFACE_LEDGER",
    "peer_throughput",
    "copies_per_side",
    "llvm_target",
    "PEER_CPU_VARIABLE",
]

VARIANTS = ("llvm_ad_rgb", "llvm_rgb")
"""Mitsuba variants tried in turn (LLVM backend; PyPI wheels ship ``llvm_ad_rgb``)."""
PIP_COMMAND = "pip install 'microsim[peer]'  (or: pip install mitsuba)"
BATCH = 2**20
"""Primary rays per Dr.Jit launch (even: the pairs (2k, 2k + 1) never straddle two)."""
COHERENT = True
"""Embree's coherent-ray flag on both queries (``PeerScene.coherent``)."""
MASKING_CAP_DEG = 88.0
"""Masking rays up to this polar angle never leave the tiled copies (``copies_per_side``)."""
MAX_COPIES_PER_SIDE = 16
LEDGER = ("single", "masked", "downward", "unresolved", "missed")
_SINGLE, _MASKED, _DOWNWARD, _UNRESOLVED, _MISSED = range(5)
INTERFACE_LEDGER = ("reflected", "transmitted", "cut", "unresolved", "missed")
"""Where each path through the dielectric interface ends (``PeerScene.run_dielectric``)."""
_REFLECTED, _TRANSMITTED, _CUT = range(3)  # then _UNRESOLVED, _MISSED as in LEDGER
_LIVE = len(INTERFACE_LEDGER)  # a path still being followed


PEER_CPU_VARIABLE = "MICROSIM_PEER_LLVM_CPU"
"""An LLVM CPU name that pins Dr.Jit's kernels to it, 8 lanes (module docstring)."""
_AVX2_FEATURES = b"+avx,+avx2,+fma,+f16c,+bmi,+bmi2,+popcnt,+lzcnt,+movbe"
# Dr.Jit's core library exports jit.h's functions under their C++ (mangled) names
_SET_TARGET, _TARGET_CPU, _VECTOR_WIDTH = (
    "_Z19jit_llvm_set_targetPKcS0_j",
    "_Z19jit_llvm_target_cpuv",
    "_Z21jit_llvm_vector_widthv",
)


class PeerUnavailable(EnvironmentFailure):
    """Mitsuba 3 (or its LLVM backend) cannot be used here; the message says why and how."""


def load_mitsuba():
    """(mi, dr, variant): mitsuba with an LLVM variant set, or PeerUnavailable (the one
    loader of Mitsuba 3: the bench's peer and ``microsim.testing.mitsuba``)."""
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as exc:
        raise PeerUnavailable(
            f"the Mitsuba 3 peer needs mitsuba (not importable: {exc}); install it with "
            f"{PIP_COMMAND}"
        ) from None
    errors = []
    for variant in VARIANTS:
        if variant not in mi.variants():
            errors.append(f"{variant}: not built")
            continue
        try:
            mi.set_variant(variant)
        except Exception as exc:  # noqa: BLE001 - LLVM missing shows as ImportError/RuntimeError
            errors.append(f"{variant}: {exc}")
            continue
        cpu = os.environ.get(PEER_CPU_VARIABLE)
        if cpu:
            getattr(_jit_core(dr), _SET_TARGET)(cpu.encode(), _AVX2_FEATURES, ctypes.c_uint32(8))
        return mi, dr, variant
    raise PeerUnavailable(
        "Mitsuba 3 is installed but no LLVM variant works (Dr.Jit's LLVM backend needs "
        f"libLLVM; set DRJIT_LIBLLVM_PATH): {'; '.join(errors)}"
    )


def _jit_core(dr) -> ctypes.CDLL:
    """Dr.Jit's core library, or PeerUnavailable when its LLVM target calls are missing."""
    lib = ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), "libdrjit-core.so"))
    try:
        getattr(lib, _TARGET_CPU).restype = ctypes.c_char_p
        getattr(lib, _VECTOR_WIDTH).restype = ctypes.c_uint32
        getattr(lib, _SET_TARGET)
    except AttributeError as exc:
        raise PeerUnavailable(
            f"{PEER_CPU_VARIABLE} is set but this Dr.Jit does not export its LLVM target calls "
            f"({exc})"
        ) from None
    return lib


def llvm_target(dr=None) -> dict:
    """The CPU and vector width Dr.Jit (the module ``dr``, else set up by ``load_mitsuba``)
    compiles the peer's kernels for: {"cpu", "lanes"} ("unknown" and None where its library
    does not say)."""
    dr = load_mitsuba()[1] if dr is None else dr
    try:
        lib = _jit_core(dr)
    except PeerUnavailable:
        return {"cpu": "unknown", "lanes": None}
    cpu, lanes = getattr(lib, _TARGET_CPU)(), getattr(lib, _VECTOR_WIDTH)()
    return {"cpu": cpu.decode(), "lanes": int(lanes)}


def copies_per_side(depth: float, tile: tuple, theta_i_deg: float) -> int:
    """m such that the (2m + 1)² copies hold every primary ray at θi and every masking ray up
    to θo = ``MASKING_CAP_DEG`` between zmax and zmin, wherever it starts in the centre copy:
    a ray at polar angle θ moves depth·tan θ sideways, so
    m = max(1, ⌈depth·tan max(θi, θcap) / min(Lx, Ly)⌉). Masking rays still steeper than that
    may leave the copies; they are counted as ``unresolved``."""
    theta = max(float(theta_i_deg), MASKING_CAP_DEG)
    reach = depth * np.tan(np.radians(theta))
    return max(1, int(np.ceil(reach / min(tile))))


@dataclass(frozen=True)
class _KernelScalars:
    """The per-run scalars of the peer's kernel, as Dr.Jit opaque values (one compiled kernel
    serves every batch and incidence): ``N`` rays over ``R`` rows of strata on the ``lx`` ×
    ``ly`` tile, primary rays from height ``z0`` in direction ``d``, masking rays offset by
    ``eps`` along the normal and followed up to ``ztop`` inside ±``half_x`` × ±``half_y``,
    ``nf`` facets per tile copy, the stream ``seed``."""

    N: object
    R: object
    lx: object
    ly: object
    z0: object
    ztop: object
    eps: object
    half_x: object
    half_y: object
    nf: object
    seed: object
    d: object


@dataclass(frozen=True)
class PeerResult:
    """The peer's bin-averaged single-bounce BRDF and its bookkeeping.

    ``brdf``/``stderr`` (n_theta, n_phi) in sr⁻¹ (NaN-free: empty bins are 0 ± 0);
    ``counts`` single-bounce events per bin; ``albedo`` Σ w / N over single events (the
    single-bounce albedo ρ(θi), Mikkelsen 2009, eq. 27) and ``albedo_stderr`` its
    paired-strata standard error; ``ledger`` rays per class of ``LEDGER`` and
    ``ledger_fresnel`` their Fresnel sums / N; ``copies`` (2m + 1) tile copies per side.
    """

    brdf: np.ndarray
    stderr: np.ndarray
    counts: np.ndarray
    albedo: float
    albedo_stderr: float
    ledger: dict
    ledger_fresnel: dict
    rays: int
    copies: int
    seconds: float
    meta: dict = field(default_factory=dict)


@dataclass(frozen=True)
class PeerInterfaceResult:
    """The peer's estimate of the paths through a dielectric interface (all orders summed).

    ``brdf``/``btdf`` (n_theta, n_phi) sr⁻¹: the reflected and the transmitted light,
    f̄_B = Σ w / (N Ω_B), θo from the pole of the side the path leaves by, with their
    paired-strata ``stderr_brdf``/``stderr_btdf``; ``counts`` (2, n_theta, n_phi) paths per
    reflected and transmitted bin; ``reflectance``/``transmittance`` R and T (fractions of
    the paths) with their paired-strata standard errors; ``ledger`` paths per class of
    ``INTERFACE_LEDGER``; ``segments`` the rays traced per path; ``copies`` tile copies per
    side."""

    brdf: np.ndarray
    btdf: np.ndarray
    stderr_brdf: np.ndarray
    stderr_btdf: np.ndarray
    counts: np.ndarray
    reflectance: float
    transmittance: float
    reflectance_stderr: float
    transmittance_stderr: float
    ledger: dict
    segments: float
    rays: int
    copies: int
    seconds: float
    meta: dict = field(default_factory=dict)


@dataclass(frozen=True)
class _InterfaceScalars:
    """The dielectric kernel's scalars beyond ``_KernelScalars`` (opaque): the relief's
    bottom ``zbot``, the index ``eta`` of the medium, the interaction ``cap``, whether the
    light comes from ``below``, the incidence azimuth ``phi_i`` (degrees)."""

    zbot: object
    eta: object
    cap: object
    below: object
    phi_i: object


def _check_surface(surface):
    """(vertices float64, faces int64, Lx, Ly) of an explicit (non-V-groove) surface."""
    missing = object()  # looked up without reading: a heightfield derives its mesh on access
    if any(inspect.getattr_static(surface, a, missing) is missing for a in ("vertices", "faces")):
        raise UsageError(
            f"surface must be a microsim.surfaces.Surface (vertices, faces, tile_size), "
            f"got {type(surface).__name__}"
        )
    if getattr(surface, "azimuth_average", False):
        raise UsageError(
            "surface must not be azimuth-averaged V-grooves for the Mitsuba peer (it traces "
            "the mesh as given, without per-ray groove azimuths); use a heightfield"
        )
    v = np.asarray(surface.vertices, dtype=np.float64)
    f = np.asarray(surface.faces)
    if v.ndim != 2 or v.shape[1] != 3 or not np.all(np.isfinite(v)):
        raise UsageError(f"surface.vertices must be a finite (V, 3) array, got shape {v.shape}")
    if (
        f.ndim != 2
        or f.shape[1] != 3
        or len(f) == 0
        or not np.issubdtype(f.dtype, np.integer)
        or f.min() < 0
        or f.max() >= len(v)
    ):
        raise UsageError(
            f"surface.faces must be a non-empty (F, 3) array of indices in [0, {len(v) - 1}]"
        )
    lx, ly = (float(t) for t in surface.tile_size)
    if not (lx > 0 and ly > 0 and np.isfinite(lx) and np.isfinite(ly)):
        raise UsageError(f"surface.tile_size must be two finite lengths > 0, got {lx, ly}")
    return v, f.astype(np.int64), lx, ly


def _check_threads(threads) -> int:
    return integer("threads", threads, 1, 1024, " (Dr.Jit worker threads incl. the caller)")


class PeerScene:
    """A Mitsuba scene of (2m + 1)² copies of ``surface``'s tile (``copies_per_side`` for
    ``theta_max_deg``, or m = ``copies`` in [1, ``MAX_COPIES_PER_SIDE``]) with the float64
    facet normals; ``run`` traces one incidence up to ``theta_max_deg``.
    Building uploads the mesh buffers (``mi.Mesh`` + ``mi.traverse``) and builds Embree's BVH
    (``mi.load_dict``); ``build_seconds`` records it, ``llvm_target`` what Dr.Jit compiles for."""

    def __init__(self, surface, theta_max_deg: float = 30.0, copies: int | None = None):
        v, f, lx, ly = _check_surface(surface)
        if not (0.0 <= float(theta_max_deg) < 90.0):
            raise UsageError(f"theta_i must lie in [0, 90) degrees, got {theta_max_deg!r}")
        mi, dr, variant = load_mitsuba()
        self.mi, self.dr, self.variant = mi, dr, variant
        t0 = time.perf_counter()
        e1, e2 = v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
        cross = np.cross(e1, e2)
        norm = np.linalg.norm(cross, axis=1)
        if np.any(norm == 0) or np.any(cross[:, 2] <= 0):
            raise UsageError(
                "surface.faces must be non-degenerate and ordered so that every normal "
                "cross(v1 - v0, v2 - v0) points up (z > 0)"
            )
        self.normals = cross / norm[:, None]
        self.n_faces = len(f)
        self.tile = (lx, ly)
        self.zmin, self.zmax = float(v[:, 2].min()), float(v[:, 2].max())
        depth = self.zmax - self.zmin
        reach = depth * np.tan(np.radians(float(theta_max_deg)))  # a primary ray's sideways run
        need = max(1, int(np.ceil(reach / min(lx, ly))))
        if copies is None:
            self.m = max(need, min(copies_per_side(depth, self.tile, 0.0), MAX_COPIES_PER_SIDE))
        else:
            self.m = integer(
                "copies",
                copies,
                need,
                max(need, MAX_COPIES_PER_SIDE),
                f" (tile copies per side; primary rays at {theta_max_deg:g}° cross {need})",
            )
        k = np.arange(-self.m, self.m + 1)
        shifts = np.stack(np.meshgrid(k * lx, k * ly, indexing="ij"), -1).reshape(-1, 2)
        big = max(float(np.abs(v).max()), (self.m + 0.5) * max(lx, ly))
        self.eps = 4.0 * float(np.spacing(np.float32(big)))
        self.top_margin = self.eps
        verts = np.concatenate([v + np.array([sx, sy, 0.0]) for sx, sy in shifts])
        faces = np.concatenate([f + i * len(v) for i in range(len(shifts))])
        mesh = mi.Mesh("microsim-tile", len(verts), len(faces))
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(verts.astype(np.float32).ravel())
        params["faces"] = mi.UInt32(faces.astype(np.uint32).ravel())
        params.update()
        self.scene = mi.load_dict({"type": "scene", "tile": mesh})
        dr.eval()
        self.build_seconds = time.perf_counter() - t0
        self.llvm_target = llvm_target(dr)
        self.theta_max_deg = float(theta_max_deg)
        self.coherent = COHERENT

    def _table(self, wi: np.ndarray, ior, bins, phi_i_deg: float):
        """Per-facet (code, weight, bin, wo) for incidence ``wi`` (microsim's facet table):
        code 0 = lit and reflected upward, 2 = downward, 3 = back-facing (unresolved)."""
        from microsim.analytic.fresnel import fresnel_real_arithmetic

        n = self.normals
        c = n @ wi
        wo = 2.0 * c[:, None] * n - wi
        code = np.where(c <= 0.0, _UNRESOLVED, np.where(wo[:, 2] <= 0.0, _DOWNWARD, _SINGLE))
        weight = np.where(c > 0.0, fresnel_real_arithmetic(np.clip(c, 0.0, 1.0), ior), 0.0)
        where = bins.locate(wo, phi_i_deg)
        return code.astype(np.uint32), weight, np.maximum(where, 0).astype(np.uint32), wo

    def run(
        self,
        material,
        theta_i_deg: float,
        rays: int,
        bins,
        seed: int = 0,
        phi_i_deg=0.0,
        threads: int | None = None,
    ) -> PeerResult:
        """Trace ``rays`` primary rays at (θi, φi) degrees on ``threads`` Dr.Jit threads (None:
        Dr.Jit's current setting; the caller's setting is restored); returns a ``PeerResult``
        whose ``seconds`` is the wall time of this run (facet table + tracing + tallies; the
        first run of a process also compiles the kernels)."""
        if threads is None:
            return self._trace(material, theta_i_deg, rays, bins, seed, phi_i_deg)
        threads = _check_threads(threads)
        before = self.dr.thread_count()
        self.dr.set_thread_count(threads)
        try:
            return self._trace(material, theta_i_deg, rays, bins, seed, phi_i_deg)
        finally:
            self.dr.set_thread_count(before)

    def _trace(self, material, theta_i_deg, rays, bins, seed, phi_i_deg) -> PeerResult:
        from microsim.analytic.fresnel import resolve_material
        from microsim.sim import Bins

        if not isinstance(bins, Bins):
            raise UsageError(f"bins must be a microsim.sim.Bins, got {type(bins).__name__}")
        theta = float(theta_i_deg)
        if not (0.0 <= theta <= self.theta_max_deg):
            raise UsageError(
                f"theta_i must lie in [0, {self.theta_max_deg:g}] degrees for this scene "
                f"(built for theta_max_deg={self.theta_max_deg:g}), got {theta_i_deg!r}"
            )
        rays = integer("rays", rays, 2, 2**31 - 2, " (primary rays)")
        seed = integer("seed", seed, 0, 2**32 - 1, " (the random stream)")
        ior = resolve_material(material)
        mi, dr = self.mi, self.dr
        t0 = time.perf_counter()
        th, ph = np.radians(theta), np.radians(float(phi_i_deg))
        wi = np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])
        code, weight, where, wo = self._table(wi, ior, bins, float(phi_i_deg))
        t_code, t_w, t_bin = mi.UInt32(code), mi.Float64(weight), mi.UInt32(where)
        t_wo = mi.Vector3f(*(mi.Float(wo[:, k].astype(np.float32)) for k in range(3)))
        t_n = mi.Vector3f(*(mi.Float(self.normals[:, k].astype(np.float32)) for k in range(3)))
        nbin = bins.n_theta * bins.n_phi
        acc = [dr.zeros(mi.Float64, nbin) for _ in range(3)]  # Σw, Σw², Σ pairs
        cnt = dr.zeros(mi.UInt32, nbin)
        led_n = np.zeros(len(LEDGER), dtype=np.int64)
        led_f = np.zeros(len(LEDGER))
        lx, ly = self.tile
        rows = max(1, int(round(np.sqrt(rays * ly / lx))))
        op = self._scalars(rays, rows, self.zmax + self.top_margin, seed, wi)
        albedo_var = np.zeros(1)  # Σx² − 2 Σ_k x_2k x_2k+1 over all single events
        for lo in range(0, rays, BATCH):
            n = min(BATCH, rays - lo)
            table = (t_code, t_w, t_bin, t_wo, t_n)
            self._batch(op, lo, n, table, acc, cnt, (led_n, led_f, albedo_var))
        s_w, s_w2, s_pair = (np.asarray(a, dtype=np.float64) for a in acc)
        counts = np.asarray(cnt, dtype=np.int64)
        seconds = time.perf_counter() - t0
        omega = bins.projected_solid_angle().ravel()
        brdf = s_w / (rays * omega)
        var = np.maximum(s_w2 - 2.0 * s_pair, 0.0)
        stderr = np.sqrt(var) / (rays * omega)
        return PeerResult(
            brdf=brdf.reshape(bins.shape),
            stderr=stderr.reshape(bins.shape),
            counts=counts.reshape(bins.shape),
            albedo=float(s_w.sum() / rays),
            albedo_stderr=float(np.sqrt(max(albedo_var[0], 0.0)) / rays),
            ledger={k: int(c) for k, c in zip(LEDGER, led_n)},
            ledger_fresnel={k: float(x) / rays for k, x in zip(LEDGER, led_f)},
            rays=rays,
            copies=2 * self.m + 1,
            seconds=seconds,
            meta={
                "variant": self.variant,
                "mitsuba_version": mi.__version__,
                "eps": self.eps,
                "rows": rows,
                "theta_i": theta,
                "phi_i": float(phi_i_deg),
            },
        )

    def run_dielectric(
        self,
        material,
        theta_i_deg: float,
        rays: int,
        bins,
        seed: int = 0,
        bounces="all",
        threads: int | None = None,
    ) -> PeerInterfaceResult:
        """Follow ``rays`` paths through the dielectric interface of index ``material``
        (real, the medium below the surface) lit at θi degrees (φi = 0; θi in (90, 180]: from
        inside the medium), at most ``bounces`` interactions ("all": ``bounces.MAX_BOUNCES``),
        on ``threads`` Dr.Jit threads (None: Dr.Jit's setting, the caller's restored). The
        estimator is ``simulate(..., transmission=True)``'s (module docstring, "Dielectric
        paths"); ``seconds`` the wall time of this run (first run: compilation included)."""
        if threads is None:
            return self._trace_dielectric(material, theta_i_deg, rays, bins, seed, bounces)
        threads = _check_threads(threads)
        before = self.dr.thread_count()
        self.dr.set_thread_count(threads)
        try:
            return self._trace_dielectric(material, theta_i_deg, rays, bins, seed, bounces)
        finally:
            self.dr.set_thread_count(before)

    def _trace_dielectric(self, material, theta_i_deg, rays, bins, seed, bounces):
        from microsim.analytic.fresnel import resolve_material
        from microsim.sim import Bins
        from microsim.sim.bounces import bounce_limit, check_bounces
        from microsim.sim.dielectric import check_transmission
        from microsim.vectors import spherical_deg

        if not isinstance(bins, Bins):
            raise UsageError(f"bins must be a microsim.sim.Bins, got {type(bins).__name__}")
        theta, top = float(theta_i_deg), self.theta_max_deg
        if not (0.0 <= theta <= top or 180.0 - top <= theta <= 180.0):
            raise UsageError(
                f"theta_i must lie in [0, {top:g}] or [{180 - top:g}, 180] degrees for this "
                f"scene (built for theta_max_deg={top:g}), got {theta_i_deg!r}"
            )
        rays = integer("rays", rays, 2, 2**31 - 2, " (primary rays)")
        seed = integer("seed", seed, 0, 2**32 - 1, " (the random stream)")
        ior = resolve_material(material)
        check_transmission(True, ior)
        if complex(ior).imag != 0:
            raise UsageError(f"material must be a real index for the peer, got {ior!r}")
        eta, cap = complex(ior).real, bounce_limit(check_bounces(bounces))[0]
        mi, dr = self.mi, self.dr
        t0 = time.perf_counter()
        wi = spherical_deg(theta, 0.0)
        below = theta > 90.0
        table = self._interface_table(wi, eta)
        nbin = bins.n_theta * bins.n_phi
        acc = [dr.zeros(mi.Float64, 2 * nbin) for _ in range(3)]  # Σw, Σw², Σ pairs
        cnt = dr.zeros(mi.UInt32, 2 * nbin)
        led = np.zeros(len(INTERFACE_LEDGER), dtype=np.int64)
        side_sums = np.zeros(4)  # paths reflected, transmitted; pairs both R, both T
        lx, ly = self.tile
        rows = max(1, int(round(np.sqrt(rays * ly / lx))))
        start = self.zmin - self.top_margin if below else self.zmax + self.top_margin
        op = self._scalars(rays, rows, start, seed, wi)
        iface = _InterfaceScalars(
            zbot=dr.opaque(mi.Float, self.zmin),
            eta=dr.opaque(mi.Float, eta),
            cap=dr.opaque(mi.UInt32, cap),
            below=dr.opaque(mi.Bool, below),
            phi_i=dr.opaque(mi.Float, 0.0),
        )
        segments = 0
        for lo in range(0, rays, BATCH):
            n = min(BATCH, rays - lo)
            tallies = (acc, cnt, led, side_sums)
            segments += self._interface_batch(op, iface, lo, n, table, bins, tallies)
        s_w, s_w2, s_pair = (np.asarray(a, dtype=np.float64) for a in acc)
        counts = np.asarray(cnt, dtype=np.int64).reshape((2, *bins.shape))
        seconds = time.perf_counter() - t0
        omega = np.tile(bins.projected_solid_angle().ravel(), 2)
        f = (s_w / (rays * omega)).reshape((2, *bins.shape))
        se = (np.sqrt(np.maximum(s_w2 - 2.0 * s_pair, 0.0)) / (rays * omega)).reshape(f.shape)
        n_r, n_t, pairs_r, pairs_t = side_sums
        return PeerInterfaceResult(
            brdf=f[0],
            btdf=f[1],
            stderr_brdf=se[0],
            stderr_btdf=se[1],
            counts=counts,
            reflectance=n_r / rays,
            transmittance=n_t / rays,
            reflectance_stderr=float(np.sqrt(max(n_r - 2.0 * pairs_r, 0.0)) / rays),
            transmittance_stderr=float(np.sqrt(max(n_t - 2.0 * pairs_t, 0.0)) / rays),
            ledger={k: int(c) for k, c in zip(INTERFACE_LEDGER, led)},
            segments=segments / rays,
            rays=rays,
            copies=2 * self.m + 1,
            seconds=seconds,
            meta={
                "variant": self.variant,
                "mitsuba_version": mi.__version__,
                "eps": self.eps,
                "rows": rows,
                "theta_i": theta,
                "eta": eta,
                "bounces": cap,
            },
        )

    def _scalars(self, rays, rows, z0, seed, wi) -> _KernelScalars:
        """The kernel's ``_KernelScalars`` of a run: scalars as opaque values, so that one
        compiled kernel serves every batch and incidence."""
        mi, dr = self.mi, self.dr
        lx, ly = self.tile
        return _KernelScalars(
            N=dr.opaque(mi.Float64, float(rays)),
            R=dr.opaque(mi.Float64, float(rows)),
            lx=dr.opaque(mi.Float64, lx),
            ly=dr.opaque(mi.Float64, ly),
            z0=dr.opaque(mi.Float, z0),
            ztop=dr.opaque(mi.Float, self.zmax),
            eps=dr.opaque(mi.Float, self.eps),
            half_x=dr.opaque(mi.Float, (self.m + 0.5) * lx),
            half_y=dr.opaque(mi.Float, (self.m + 0.5) * ly),
            nf=dr.opaque(mi.UInt32, self.n_faces),
            seed=dr.opaque(mi.UInt64, seed),
            d=mi.Vector3f(*(dr.opaque(mi.Float, -float(x)) for x in wi)),
        )

    def _interface_table(self, wi: np.ndarray, eta: float):
        """Per facet, for the primary rays (direction −wi, one per incidence): whether it is
        met from the side the light comes from, the exact Fresnel reflectance F of the
        crossing (``microsim.analytic.fresnel``, float64; 1 at total internal reflection),
        the reflected and the refracted (Snell) directions, the facet normals — as Dr.Jit
        arrays."""
        from microsim.analytic.fresnel import fresnel_real_arithmetic

        mi = self.mi
        n = self.normals
        c = n @ wi  # = −d·n: > 0 met from above
        valid = (c < 0.0) if wi[2] < 0.0 else (c > 0.0)
        ci = np.abs(c)
        rel2 = eta**2 if wi[2] > 0.0 else 1.0 / eta**2  # (η_t/η_i)²
        tir = (1.0 - ci * ci) >= rel2
        fresnel = np.ones(len(c))
        ok = valid & ~tir
        fresnel[ok] = fresnel_real_arithmetic(ci[ok], np.sqrt(rel2))
        reflected = 2.0 * c[:, None] * n - wi
        r = 1.0 / np.sqrt(rel2)
        ct = np.sqrt(np.maximum(1.0 - r * r * (1.0 - ci * ci), 0.0))
        refracted = -r * wi + ((r * ci - ct) * np.sign(c))[:, None] * n

        def vec(a):
            return mi.Vector3f(*(mi.Float(a[:, k].astype(np.float32)) for k in range(3)))

        fresnel32 = mi.Float(fresnel.astype(np.float32))
        return mi.Bool(valid), fresnel32, vec(reflected), vec(refracted), vec(n)

    def _interface_batch(self, op, iface, lo, n, table, bins, tallies) -> int:
        """Follow paths lo … lo + n − 1 (lo even) through the interface, add them to the
        tallies; returns the rays traced."""
        mi, dr = self.mi, self.dr
        t_valid, t_fresnel, t_refl, t_refr, t_n = table
        acc, cnt, led, side_sums = tallies
        nbin = bins.n_theta * bins.n_phi
        o, rng = self._origins(op, lo, n)
        d = mi.Vector3f(op.d)
        lx, ly = mi.Float(op.lx), mi.Float(op.ly)

        def recentre(p):
            """p moved by whole tiles into the centre copy (the surface is periodic)."""
            return mi.Point3f(p.x - dr.round(p.x / lx) * lx, p.y - dr.round(p.y / ly) * ly, p.z)

        def leave(p, nrm, new_d):
            """The next ray's start: p moved eps off the facet to the new ray's side."""
            side = dr.select(dr.dot(new_d, nrm) > 0.0, op.eps, -op.eps)
            return recentre(p + side * nrm)

        # the primary ray: closest hit, then the facet table's Fresnel and directions
        pi = self.scene.ray_intersect_preliminary(mi.Ray3f(o, d), coherent=self.coherent)
        hit = pi.is_valid()
        facet = pi.prim_index % op.nf
        valid = hit & dr.gather(mi.Bool, t_valid, facet, hit)
        reflect = rng.next_float32() < dr.gather(mi.Float, t_fresnel, facet, hit)
        nrm = dr.gather(mi.Vector3f, t_n, facet, hit)
        new_d = dr.select(
            reflect,
            dr.gather(mi.Vector3f, t_refl, facet, hit),
            dr.gather(mi.Vector3f, t_refr, facet, hit),
        )
        o = dr.select(valid, leave(o + pi.t * d, nrm, new_d), o)
        inside = dr.select(reflect, iface.below, ~iface.below)
        status = dr.select(
            ~hit, _u(mi, _MISSED), dr.select(valid, _u(mi, _LIVE), _u(mi, _UNRESOLVED))
        )
        state = (o, new_d, inside, status, mi.UInt32(1), mi.UInt32(1), mi.UInt32(0), rng)

        def cond(o, d, inside, status, b, traced, where, rng):
            return status == _LIVE

        def body(o, d, inside, status, b, traced, where, rng):
            pi = self.scene.ray_intersect_preliminary(mi.Ray3f(o, d), coherent=self.coherent)
            hit = pi.is_valid()
            traced += 1
            # no hit: the path leaves the relief up or down, if it stays over the copies
            up = d.z > 0.0
            t_out = (dr.select(up, op.ztop, iface.zbot) - o.z) / d.z
            end = o + t_out * d
            held = (d.z != 0.0) & (dr.abs(end.x) <= op.half_x) & (dr.abs(end.y) <= op.half_y)
            leaves = ~hit & held & (up != inside)  # else it left through the wrong side
            transmitted = up == iface.below
            slot = dr.select(transmitted, mi.UInt32(nbin), mi.UInt32(0))
            where = dr.select(leaves, slot + _bin_of(mi, dr, d, bins, iface.phi_i), where)
            left = dr.select(transmitted, _u(mi, _TRANSMITTED), _u(mi, _REFLECTED))
            ended = dr.select(held, dr.select(leaves, left, _u(mi, _MISSED)), _u(mi, _UNRESOLVED))
            status = dr.select(~hit, ended, status)
            # a hit: met from the path's side, then reflected or refracted by roulette
            nrm = dr.gather(mi.Vector3f, t_n, pi.prim_index % op.nf, hit)
            c = -dr.dot(d, nrm)
            wrong = hit & ((c == 0.0) | ((c < 0.0) != inside))
            cut = hit & ~wrong & (b >= iface.cap)
            go = hit & ~wrong & ~cut
            status = dr.select(wrong, _u(mi, _UNRESOLVED), dr.select(cut, _u(mi, _CUT), status))
            fresnel, cos_t, _, eta_ti = mi.fresnel(c, iface.eta)
            reflect = rng.next_float32(go) < fresnel
            new_d = dr.select(
                reflect, mi.reflect(-d, nrm), mi.refract(-d, mi.Normal3f(nrm), cos_t, eta_ti)
            )
            o = dr.select(go, leave(o + pi.t * d, nrm, new_d), o)
            d = dr.select(go, new_d, d)
            inside = dr.select(go & ~reflect, ~inside, inside)
            b = dr.select(go, b + 1, b)
            return o, d, inside, status, b, traced, where, rng

        state = dr.while_loop(state, cond, body, label="peer-interface")
        status, traced, where = state[3], state[5], state[6]
        tallied = (status == _REFLECTED) | (status == _TRANSMITTED)
        xw = dr.select(tallied, mi.Float64(1.0), 0.0)
        dr.scatter_reduce(dr.ReduceOp.Add, acc[0], xw, where, tallied)
        dr.scatter_reduce(dr.ReduceOp.Add, acc[1], xw * xw, where, tallied)
        dr.scatter_reduce(dr.ReduceOp.Add, cnt, mi.UInt32(1), where, tallied)
        dr.eval(status, where, xw, traced)
        w0, w1, (b0, b1) = _pair_sums(mi, dr, acc[2], where, xw, n)
        both = (w0 * w1 > 0.0) & ((b0 < nbin) == (b1 < nbin))  # same side
        pairs_t = both & (b0 >= nbin)
        sums = [
            dr.sum(dr.select(status == _REFLECTED, 1, 0)),
            dr.sum(dr.select(status == _TRANSMITTED, 1, 0)),
            dr.sum(dr.select(both & ~pairs_t, 1, 0)),
            dr.sum(dr.select(pairs_t, 1, 0)),
        ]
        per = [dr.sum(dr.select(status == c, 1, 0)) for c in range(len(INTERFACE_LEDGER))]
        rays_traced = dr.sum(mi.UInt64(traced))
        dr.eval(acc, cnt, sums, per, rays_traced)
        led += np.array([int(p[0]) for p in per], dtype=np.int64)
        side_sums += np.array([float(x[0]) for x in sums])
        return int(rays_traced[0])

    def _origins(self, op, lo, n):
        """(float32 origins on the plane z = ``op.z0``, PCG32 streams) of primary rays lo … lo +
        n − 1: rays 2k and 2k + 1 share a stratum of the tile (module docstring)."""
        mi, dr = self.mi, self.dr
        r = dr.arange(mi.UInt32, n) + dr.opaque(mi.UInt32, lo)
        rng = mi.PCG32(n, initstate=op.seed, initseq=mi.UInt64(r))
        xi, eta = rng.next_float64(), rng.next_float64()
        pair = mi.Float64(r - (r & 1))  # rays 2k, 2k + 1 share a stratum of width 2/N
        width = dr.select(op.N - pair < 2.0, op.N - pair, 2.0)  # (dr.minimum: LLVM 14)
        s = (pair + width * xi) / op.N * op.R  # stratum position in rows
        row = dr.floor(s)
        row = dr.select(row > op.R - 1.0, op.R - 1.0, row)  # (dr.minimum: LLVM 14 fails)
        x = (s - row) * op.lx - 0.5 * op.lx
        y = (row + eta) / op.R * op.ly - 0.5 * op.ly
        return mi.Point3f(mi.Float(x), mi.Float(y), op.z0), rng

    def _batch(self, op, lo, n, table, acc, cnt, sums_out):
        """Trace primary rays lo … lo + n − 1 (lo even) and add them to the tallies."""
        mi, dr = self.mi, self.dr
        t_code, t_w, t_bin, t_wo, t_n = table
        led_n, led_f, albedo_var = sums_out
        o, _ = self._origins(op, lo, n)
        d = op.d
        pi = self.scene.ray_intersect_preliminary(mi.Ray3f(o, d), coherent=self.coherent)
        hit = pi.is_valid()
        facet = pi.prim_index % op.nf
        code = dr.gather(mi.UInt32, t_code, facet, hit)
        w = dr.gather(mi.Float64, t_w, facet, hit)
        wo = dr.gather(mi.Vector3f, t_wo, facet, hit)
        nrm = dr.gather(mi.Vector3f, t_n, facet, hit)
        lit = hit & (code == _SINGLE)
        mo = o + pi.t * d + op.eps * nrm
        tmax = (op.ztop - mo.z) / wo.z
        end = mo + tmax * wo
        inside = (dr.abs(end.x) <= op.half_x) & (dr.abs(end.y) <= op.half_y)
        test = lit & inside
        ray = mi.Ray3f(mo, wo)
        ray.maxt = dr.select(tmax > 0.0, tmax, 0.0)
        blocked = self.scene.ray_test(ray, coherent=self.coherent, active=test)
        single = test & ~blocked
        status = dr.select(
            ~hit,
            _MISSED,
            dr.select(
                lit, dr.select(inside, dr.select(blocked, _MASKED, _SINGLE), _UNRESOLVED), code
            ),
        )
        status = mi.UInt32(status)
        where = dr.select(single, dr.gather(mi.UInt32, t_bin, facet, single), 0)
        xw = dr.select(single, w, 0.0)
        # the tallies' scatters join the tracing kernel: one pass over the rays
        dr.scatter_reduce(dr.ReduceOp.Add, acc[0], xw, where, single)
        dr.scatter_reduce(dr.ReduceOp.Add, acc[1], xw * xw, where, single)
        dr.scatter_reduce(dr.ReduceOp.Add, cnt, mi.UInt32(1), where, single)
        dr.eval(status, where, xw, w)
        w0, w1, _ = _pair_sums(mi, dr, acc[2], where, xw, n)  # any bins: the albedo's
        sums = [dr.sum(xw * xw), dr.sum(w0 * w1)]
        per = [dr.sum(dr.select(status == c, 1, 0)) for c in range(len(LEDGER))]
        fre = [dr.sum(dr.select(status == c, w, 0.0)) for c in range(len(LEDGER))]
        dr.eval(acc, cnt, sums, per, fre)
        led_n += np.array([int(p[0]) for p in per], dtype=np.int64)
        led_f += np.array([float(f[0]) for f in fre])
        albedo_var += float(sums[0][0]) - 2.0 * float(sums[1][0])


def _u(mi, code: int):
    """A ledger code as a Dr.Jit UInt32 (the loop's status keeps one type)."""
    return mi.UInt32(code)


def _bin_of(mi, dr, d, bins, phi_i):
    """Flat (θo, Δφ) bin of the directions ``d`` as ``Bins.locate`` (θo from the pole of the
    side d points to: |d_z|; Δφ = φo − ``phi_i`` degrees, folded or not), in float32 with
    Dr.Jit's arctangent (a direction within rounding of an edge may fall on either side)."""
    to_deg = 180.0 / np.pi
    n_theta, n_phi = bins.n_theta, bins.n_phi
    theta = dr.atan2(dr.sqrt(d.x * d.x + d.y * d.y), dr.abs(d.z)) * to_deg
    it = dr.floor(theta * (n_theta / 90.0))
    it = dr.select(it > n_theta - 1, n_theta - 1, it)  # (dr.minimum: LLVM 14 fails)
    dphi = dr.atan2(d.y, d.x) * to_deg - phi_i
    dphi = dr.select(dphi < 0.0, dphi + 360.0, dphi)
    if bins.folded:
        w = 180.0 / (n_phi - 1)
        dphi = dr.select(dphi > 180.0, 360.0 - dphi, dphi)
    else:
        w = 360.0 / n_phi
        dphi = dr.select(dphi >= 360.0 - 0.5 * w, dphi - 360.0, dphi)
    k = dr.floor(dphi / w + 0.5)
    k = dr.select(k < 0.0, 0.0, dr.select(k > n_phi - 1, n_phi - 1, k))
    return mi.UInt32(it) * n_phi + mi.UInt32(k)


def _pair_sums(mi, dr, acc_pair, where, xw, n):
    """Add w_2k·w_2k+1 of the pairs (2k, 2k + 1) of one batch tallied in the same bin to
    ``acc_pair`` (the paired-strata variance, module docstring); returns the pairs' weights
    (w0, w1) and bins (b0, b1)."""
    k = dr.arange(mi.UInt32, n // 2) * 2
    b0, b1 = dr.gather(mi.UInt32, where, k), dr.gather(mi.UInt32, where, k + 1)
    w0, w1 = dr.gather(mi.Float64, xw, k), dr.gather(mi.Float64, xw, k + 1)
    both = (w0 > 0.0) & (w1 > 0.0) & (b0 == b1)
    dr.scatter_reduce(dr.ReduceOp.Add, acc_pair, w0 * w1, b0, both)
    return w0, w1, (b0, b1)


def mitsuba_single_bounce(
    surface, material, theta_i_deg: float, rays: int, bins=None, seed: int = 0, threads=None
) -> PeerResult:
    """The single-bounce BRDF of ``surface`` at θi (degrees, φi = 0) by the Mitsuba 3 peer:
    ``rays`` stratified primary rays, ``bins`` (default microsim's ``Bins()``), ``seed`` the
    PCG32 streams, ``threads`` Dr.Jit threads (None: leave Dr.Jit's setting). Per-bin
    averages f̄_B = Σ w / (N Ω_B) as ``microsim.sim.simulate`` (module docstring)."""
    from microsim.sim import Bins

    bins = Bins() if bins is None else bins
    threads = None if threads is None else _check_threads(threads)
    scene = PeerScene(surface, theta_i_deg)
    return scene.run(material, theta_i_deg, rays, bins, seed, threads=threads)


def mitsuba_dielectric(
    surface, material, theta_i_deg: float, rays: int, bins=None, seed: int = 0, **options
) -> PeerInterfaceResult:
    """The paths through the dielectric interface of index ``material`` below ``surface``
    lit at θi (degrees, φi = 0; (90, 180]: from inside) by the Mitsuba 3 peer: ``rays``
    stratified paths, ``bins`` (default microsim's ``Bins()``), ``seed`` the PCG32 streams;
    ``options``: ``bounces`` (default "all") and ``threads`` of ``PeerScene.run_dielectric``."""
    from microsim.sim import Bins

    bins = Bins() if bins is None else bins
    theta = float(theta_i_deg)
    scene = PeerScene(surface, 180.0 - theta if theta > 90.0 else theta)
    return scene.run_dielectric(material, theta, rays, bins, seed, **options)


def peer_throughput(
    surface, material, theta_i_deg: float, rays: int, threads: int = 1, repeat: int = 3, bins=None
) -> dict:
    """Marginal samples/s of the peer: scene build and a warm-up run (JIT compilation) first,
    then the best of ``repeat`` runs of ``rays`` primary rays on ``threads`` Dr.Jit threads.
    Returns {"samples_per_s", "seconds" (best run), "build_seconds", "variant",
    "mitsuba_version", "threads", "rays", "ledger" (of the best run), "copies" (per side)}."""
    from microsim.sim import Bins

    bins = Bins(45, 37) if bins is None else bins
    threads = _check_threads(threads)
    repeat = integer("repeat", repeat, 1, 1000, " (timed runs)")
    _check_surface(surface)
    scene = PeerScene(surface, theta_i_deg)
    scene.run(material, theta_i_deg, rays, bins, seed=0, threads=threads)  # compiles the kernels
    best = None
    for k in range(repeat):
        res = scene.run(material, theta_i_deg, rays, bins, seed=1 + k, threads=threads)
        if best is None or res.seconds < best.seconds:
            best = res
    return {
        "samples_per_s": best.rays / best.seconds,
        "seconds": best.seconds,
        "build_seconds": scene.build_seconds,
        "variant": scene.variant,
        "mitsuba_version": scene.mi.__version__,
        "threads": threads,
        "rays": best.rays,
        "ledger": best.ledger,
        "copies": best.copies,
    }
