"""Scene files: a surface, a material and simulation settings in TOML (the catalogue shipped
in the package, ``microsim/scenes/*.toml``; the reference page for users is docs/scenes.md).

A scene is named by a path or by a catalogue name (``resolve_scene``, the one resolver of every
command and API): a path that exists is taken as is; otherwise a bare name ``NAME`` or
``NAME.toml`` is looked up in the packaged catalogue.

Schema (every key optional unless marked required; unknown keys are errors)::

    name = "vgroove-beckmann-0.3"      # default: the file stem; a safe single path component
                                       # (it names the output folder): 1-100 characters from
                                       # letters, digits, ".", "_", "-", not starting with "."
    description = "..."
    [surface]
    kind = "vgrooves"                  # required: vgrooves | gaussian | abc | file | flat |
                                       # student-t-transform | student-t-mixture
    # vgrooves: n_grooves = 4000 (at most 1 000 000), ndf (required) = beckmann | ggx |
    #           blinn-phong | vmf | abc with its parameter m | alpha (in [1e-6, 10]) |
    #           e | kappa (in [1e-6, 1e12]) | B and C (in [1e-6, 1e6]) (required),
    #           sampling = "stratified" | "random", tile = 1.0
    # gaussian: n = 512 (8 … 4096), dx = 1.0, sigma, corr_len (required; corr_len >= dx and
    #           rms slope 2 sigma / corr_len <= 10), exact_amplitude = true
    # abc:      n = 512 (8 … 4096), dx = 1.0, sigma, B, C (required), band_limit = 4,
    #           exact_amplitude = true; anisotropic: B_y (B along the y' axis), rotation = 0
    #           (degrees, the x' axis from x)
    # student-t-transform: n, dx, alpha, gamma (in [2, 1e6]), corr_len (>= dx; required),
    #           exact_amplitude = true; anisotropic: alpha_y, rotation = 0
    # student-t-mixture: n, dx, alpha, gamma, corr_len, exact_amplitude, patches = 16
    #           (realisations must be a multiple of patches)
    # file:     path (required; relative to the scene file; .npy, .npz or text, a real 2D
    #           array of at least 8 x 8 and at most 4096 x 4096 finite heights, not all
    #           equal, checked when the scene is loaded; or a measured scan, .x3p or a
    #           SurfaceTopography format, used in micrometres), dx (required for an array,
    #           not given for a scan), periodic = false, form = "none" | "plane" | "poly2"
    #           … "poly4" (default "plane" for a scan, "none" for an array)
    # flat:     size = 1.0
    # every length (dx, sigma, corr_len, B, tile, size) is a number in [1e-6, 1e6]
    [material]
    ior = "mirror"                     # aluminium | methanol | mirror, a number n, or [n, k]
                                       # (n in [0.001, 1000], k in [0, 1000]; not n = 1 with
                                       # k = 0, which reflects nothing)
    wavelength_nm = 550                # optional: ior then names a real material of
                                       # analytic.materials (gold, silver, copper, aluminium,
                                       # chromium, bk7, fused-silica, methanol) at this
                                       # wavelength in nm, within its dataset's range
    transmission = false               # true: the material is a dielectric medium below the
                                       # surface (a real index n); light is reflected and
                                       # refracted (microsim.sim.dielectric), traced at every
                                       # θi from the air and from inside the medium
    [simulation]
    theta_i = [0, 30, 60, 80]          # degrees, distinct, each in [0, 89.99]; at most 180
    rays = 1_000_000                   # per incidence, an integer in [1, 2**48] or "auto"
    theta_bins = 45                    # over θo ∈ [0°, 90°]; an integer in [1, 900]
    phi_bins = 72                      # over Δφ = φo − φi folded to [0°, 180°] (half bins at
                                       # 0° and 180°; microsim.sim.Bins); an integer in [2, 1440]
    realisations = 1                   # independent random surfaces (seeds seed, seed+1, …),
                                       # an integer in [1, 1000], or "auto" (random kinds
                                       # gaussian, abc, vgrooves): a pilot of 8 realisations,
                                       # then as many as bring the tile scatter of the
                                       # energy-weighted BRDF below realisation_target
                                       # (microsim.analysis.budget; at most 32)
    realisation_target = 0.01          # relative; only with realisations = "auto", in
                                       # [0.001, 0.5]
    bounces = 1                        # scattering orders traced: an integer in [1, 256] or
                                       # "all" (microsim.sim.bounces); the verdicts judge
                                       # order 1, the report adds the orders >= 2
    seed = 0
    [wave]                             # optional: also run the wave-optics (Kirchhoff) solver
    wavelength = 0.5                   # required in [wave]; in the unit of dx (the convention:
                                       # micrometres), a number in [1e-6, 1e6]; surface kind
                                       # gaussian or abc only (a heightfield with a nominal PSD)
    surface_model = "smooth"           # "smooth" (band-limited interpolant of the heights,
                                       # fast) | "mesh" (the ray tracer's triangles, exact)
    upsample = 1                       # Fourier upsampling of the heights, an integer in
                                       # [1, 16] (1 with "mesh")
    fresnel_angle = "half"             # R at the half-vector angle ("half") or at θi
                                       # ("incident")

``[wave]`` checks at load time (``WaveSpec``): the tile n·dx must hold at least
``MIN_TILE_WAVELENGTHS`` (10) wavelengths (fewer put the diffraction orders ≥ 0.1 apart in
sin θo, coarser than any useful bin, and the tile holds too few correlation lengths); with
``surface_model = "smooth"`` the grid must sample the orders' phase at the largest incidence,
dx/upsample < λ/(2(1 + sin θi,max)). The height part of the phase-sampling condition depends
on the realised heights and is checked when a run is planned (``runner.wave_run``), before
anything is written. Scenes without ``[wave]`` are geometric only.

The file itself must be a regular file of at most 1 MiB of UTF-8 TOML (a leading byte-order
mark is allowed; ``read_toml``, which reads sweep files too). Every problem raises
``SceneError`` (a ``UsageError``) with a one-line message naming the file, the key and the
allowed values.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from microsim import analytic as an
from microsim.analytic import materials
from microsim.checks import file_path
from microsim.errors import UsageError
from microsim.sim.arguments import MAX_RAYS
from microsim.surfaces.surface import anisotropy_of

from .scene_checks import (
    ANGLE,
    BOOL,
    REQUIRED,
    STR,
    SceneError,
    check_keys,
    check_value,
    fail,
    fill,
    int_in,
    is_int,
    is_num,
)
from .scene_surface import (
    MAX_GRID,
    RANDOM_KINDS,
    SURFACE_KINDS,
    FileSurface,
    SurfaceSpec,
    check_heightfield,
    make_ndf,
    scaled_grid,
    surface_spec,
)
from .toml_file import MAX_SCENE_BYTES, read_toml

__all__ = [
    "SceneError",
    "Scene",
    "SurfaceSpec",
    "SimSettings",
    "load_scene",
    "resolve_scene",
    "catalogue_dir",
    "catalogue_names",
    "CATALOGUE",
    "make_ndf",
    "describe_surface",
    "read_toml",
    "surface_spec",
    "material_ior",
    "check_heightfield",
    "SURFACE_KINDS",
    "WaveSpec",
    "WAVE_KINDS",
    "MIN_TILE_WAVELENGTHS",
    "MAX_THETA_I",
    "RANDOM_KINDS",
    "MAX_GRID",
    "MAX_SCENE_BYTES",
    "scaled_grid",
    "incidence_pairs",
]

CATALOGUE = Path(__file__).resolve().parents[1] / "scenes"
"""The scene catalogue shipped in the package: ``microsim/scenes/NAME.toml`` (and the files
they read, such as ``heightfields/``)."""

MIN_IOR, MAX_IOR = 1e-3, 1e3
"""Bounds of a scene's index of refraction n (and of k, from 0)."""
NAME_PATTERN = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9._-]{0,99}")
NAME_RULE = (
    "1-100 characters from letters, digits, '.', '_', '-', not starting with '.' "
    "(it names the output folder)"
)

MAX_THETA_I = 89.99
"""Largest incidence angle (degrees) of a scene or ``--theta-i``: closer to grazing the tracer
loses rays to rounding."""
_THETA_I = (
    lambda v: (
        isinstance(v, list)
        and 0 < len(v) <= 180
        and all(is_num(t) and 0 <= t <= MAX_THETA_I for t in v)
    ),
    f"a non-empty list of at most 180 angles in degrees, each in [0, {MAX_THETA_I:g}]",
)
MAX_PHI_I = 12
"""Most incidence azimuths of one scene: each multiplies the run's incidences."""
_PHI_I = (
    lambda v: (
        ANGLE[0](v)
        or (isinstance(v, list) and 0 < len(v) <= MAX_PHI_I and all(ANGLE[0](p) for p in v))
    ),
    f"degrees in [-360, 360], or a non-empty list of at most {MAX_PHI_I} such angles",
)
_RAYS = (
    lambda v: v == "auto" or (is_int(v) and 1 <= v <= MAX_RAYS),
    f'an integer in [1, {MAX_RAYS:,}] or "auto"',
)
_SIM_KEYS = {
    "theta_i": ([0.0, 30.0, 60.0, 80.0], _THETA_I),
    "rays": (1_000_000, _RAYS),
    "theta_bins": (45, int_in(1, 900)),
    "phi_bins": (72, int_in(2, 1440)),
    "realisations": (
        1,
        (
            lambda v: v == "auto" or (is_int(v) and 1 <= v <= 1000),
            'an integer in [1, 1000] or "auto"',
        ),
    ),
    "realisation_target": (
        None,
        (lambda v: is_num(v) and 1e-3 <= v <= 0.5, "a number in [0.001, 0.5]"),
    ),
    "bounces": (
        1,
        (lambda v: v == "all" or (is_int(v) and 1 <= v <= 256), 'an integer in [1, 256] or "all"'),
    ),
    "seed": (0, (lambda v: is_int(v) and v >= 0, "an integer >= 0")),
    "phi_i": (0.0, _PHI_I),
    "full_azimuth": (None, BOOL),
}
_TOP_KEYS = ("name", "description", "surface", "material", "simulation", "wave")
WAVE_KINDS = ("gaussian", "abc")
"""Surface kinds the wave solver accepts: heightfields with a nominal PSD (the wave closed
forms need it)."""
MIN_TILE_WAVELENGTHS = 10.0
"""Smallest tile side, in wavelengths, of a ``[wave]`` scene (module docstring)."""
_SURFACE_MODELS = ("smooth", "mesh")
_FRESNEL_ANGLES = ("half", "incident")
_WAVE_KEYS = {
    "wavelength": (
        REQUIRED,
        (
            lambda v: is_num(v) and 1e-6 <= v <= 1e6,
            "a number > 0 in [1e-6, 1e6], in the unit of dx (micrometres by convention)",
        ),
    ),
    "surface_model": (
        "smooth",
        (lambda v: v in _SURFACE_MODELS, " or ".join(f'"{m}"' for m in _SURFACE_MODELS)),
    ),
    "upsample": (1, int_in(1, 16)),
    "fresnel_angle": (
        "half",
        (lambda v: v in _FRESNEL_ANGLES, " or ".join(f'"{m}"' for m in _FRESNEL_ANGLES)),
    ),
}


def incidence_pairs(theta_i, phi_i) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(θi, φi) per incidence of a run (degrees): every θi at the first φi, then every θi at
    the next; with one φi the incidences are the θi in order, as before azimuths were a list."""
    pairs = [(float(t), float(p)) for p in phi_i for t in theta_i]
    return tuple(t for t, _ in pairs), tuple(p for _, p in pairs)


# --- the scene ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class SimSettings:
    """Simulation settings: incidence angles (degrees), rays per incidence (or "auto"),
    outgoing bins (θ over [0°, 90°], φ over [0°, 360°)), realisations (a count or "auto",
    then ``realisation_target``, default ``budget.AUTO_TARGET``), base seed; ``phi_i`` the
    incidence azimuths in degrees (the surface frame: 0° is incidence in the xz plane, across
    oriented grooves or the x correlation axis; a run traces every θi at every φi, see
    ``incidence_pairs``) and ``full_azimuth``: Δφ bins over the whole
    circle instead of folded onto [0°, 180°] (None: full for anisotropic surfaces — oriented
    V-grooves, Gaussian fields with ``corr_len_y``, ABC fields with ``B_y`` — and folded
    otherwise)."""

    theta_i: tuple[float, ...] = (0.0, 30.0, 60.0, 80.0)
    rays: int | str = 1_000_000
    theta_bins: int = 45
    phi_bins: int = 72
    realisations: int | str = 1
    realisation_target: float | None = None
    bounces: int | str = 1
    seed: int = 0
    phi_i: tuple[float, ...] = (0.0,)
    full_azimuth: bool | None = None

    @property
    def phi_i_record(self) -> float | list[float]:
        """``phi_i`` as a run records it: one azimuth as a number, several as a list."""
        return self.phi_i[0] if len(self.phi_i) == 1 else list(self.phi_i)


@dataclass(frozen=True)
class WaveSpec:
    """The ``[wave]`` table: ``wavelength`` (unit of dx, micrometres by convention),
    ``surface_model`` ("smooth" | "mesh"), ``upsample`` (Fourier upsampling of the heights),
    ``fresnel_angle`` ("half" | "incident"), as ``wave.kirchhoff_brdf`` takes them."""

    wavelength: float
    surface_model: str = "smooth"
    upsample: int = 1
    fresnel_angle: str = "half"


@dataclass(frozen=True)
class Scene:
    """A loaded scene file. ``ior``: None (mirror), float (dielectric) or complex n + ik.
    ``wave``: the ``[wave]`` settings, None for a geometric-only scene. ``material_name``: the
    material's name when the file gave one ("aluminium"), which results then record (None with
    ``[material] wavelength_nm``: the run records the dataset's index at that wavelength).
    ``transmission``: a dielectric medium traced with refraction, from the air and from inside
    (``[material] transmission``)."""

    name: str
    path: Path | None
    description: str
    surface: SurfaceSpec
    ior: float | complex | None
    simulation: SimSettings
    wave: WaveSpec | None = None
    material_name: str | None = None
    transmission: bool = False

    @property
    def anisotropic(self) -> bool:
        """Oriented V-grooves, a Gaussian field with two correlation lengths or an ABC field
        with two B (``surfaces.surface.anisotropy_of``)."""
        return anisotropy_of(self.surface.kind, self.surface.params) is not None

    @property
    def full_azimuth(self) -> bool:
        """Whether the Δφ bins cover the whole circle (``SimSettings.full_azimuth``)."""
        f = self.simulation.full_azimuth
        return self.anisotropic if f is None else bool(f)

    @property
    def material(self):
        """What ``simulate`` takes as the material: the name if the file gave one, else ior."""
        return self.material_name if self.material_name is not None else self.ior

    def build_surface(self, seed: int | None = None, scale: float = 1.0):
        """Generate the surface (``microsim.surfaces``); ``seed`` defaults to the scene's.

        ``scale`` shrinks (or grows) the size for quick builds: the grid size n (keeping dx,
        so statistics stay, only the tile shrinks; at least 8) or the number of grooves.
        Realisation r of a random surface uses seed ``simulation.seed + r``.
        """
        try:
            return self._build(seed, scale)
        except UsageError as e:  # a value the generator refuses: name the scene file
            raise SceneError(f"{self.path}: surface: {' '.join(str(e).split())}") from None

    def _build(self, seed, scale):
        seed = self.simulation.seed if seed is None else seed
        base = self.path.parent if self.path is not None else Path.cwd()
        return self.surface.build(seed, scale, base)

    def ndf(self):
        """The ensemble NDF of the scene's surface at its full size — the ``ensemble_ndf`` that
        ``build_surface()`` attaches (``microsim.surfaces.Surface``), computed from the
        parameters without building the surface — or None (file, flat)."""
        return self.surface.ensemble_ndf()


def material_ior(where, table):
    """The index of refraction of a ``[material]`` table (None: no table or a mirror, else a
    float or complex n + ik); a bad value raises ``SceneError`` naming ``where`` and
    ``material.ior``."""
    if table is None:
        return None
    check_keys(where, "material", table, ["ior", "wavelength_nm", "transmission"])
    if "wavelength_nm" in table:
        return _material_at_wavelength(where, table)
    v = table.get("ior", "mirror")
    allowed = (
        f"a name ({', '.join(an.MATERIALS)}), a number n, or [n, k], with n in "
        f"[{MIN_IOR:g}, {MAX_IOR:g}] and k in [0, {MAX_IOR:g}]"
    )
    if not isinstance(v, str):
        pair = v if isinstance(v, list) else [v, 0]
        n, k = pair if len(pair) == 2 else (None, None)
        if not (is_num(n) and is_num(k) and MIN_IOR <= n <= MAX_IOR and 0 <= k <= MAX_IOR):
            fail(where, "material.ior", f"must be {allowed}, got {v!r}")
        if n == 1 and k == 0:
            fail(
                where,
                "material.ior",
                f"n = 1 with k = 0 matches the medium above and reflects nothing; must be "
                f"{allowed}, got {v!r}",
            )
        v = complex(n, k) if isinstance(v, list) else v
    try:
        return an.resolve_material(v)
    except UsageError:
        if materials.table_name(v) is not None:
            fail(
                where,
                "material.ior",
                f"{v!r} needs material.wavelength_nm (nm); without it must be {allowed}",
            )
        fail(where, "material.ior", f"must be {allowed}, got {table.get('ior')!r}")


def _material_at_wavelength(where, table):
    """The index of ``[material] ior`` (a name of ``analytic.materials.TABLE``) at
    ``wavelength_nm``; a bad name or wavelength raises ``SceneError`` naming its key."""
    name = table.get("ior")
    if materials.table_name(name) is None:
        allowed = ", ".join(sorted(materials.TABLE) + sorted(materials.ALIASES))
        fail(where, "material.ior", f"with wavelength_nm must be one of {allowed}, got {name!r}")
    nm = check_value(
        where,
        "material.wavelength_nm",
        table["wavelength_nm"],
        (lambda v: is_num(v) and v > 0, "a wavelength in nm (a number > 0)"),
    )
    try:
        return an.resolve_material((name, nm))
    except UsageError as e:
        fail(where, "material.wavelength_nm", str(e))


def _simulation(where, table) -> SimSettings:
    table = {} if table is None else table
    check_keys(where, "simulation", table, list(_SIM_KEYS))
    sim = SimSettings(**fill(where, "simulation", table, _SIM_KEYS))
    phis = sim.phi_i if isinstance(sim.phi_i, list) else [sim.phi_i]
    sim = replace(
        sim, theta_i=tuple(float(t) for t in sim.theta_i), phi_i=tuple(float(p) for p in phis)
    )
    twice = sorted({t for t in sim.theta_i if sim.theta_i.count(t) > 1})
    if twice:
        fail(where, "simulation.theta_i", f"lists {twice[0]:g}° twice; give each angle once")
    turns = [q % 360.0 for q in sim.phi_i]
    same = sorted({p for p in sim.phi_i if turns.count(p % 360.0) > 1})
    if same:
        fail(
            where,
            "simulation.phi_i",
            f"lists {same[0]:g}° twice (modulo 360°); give each azimuth once",
        )
    if sim.realisation_target is not None and sim.realisations != "auto":
        fail(where, "simulation.realisation_target", 'needs realisations = "auto"')
    return sim


def _wave(where, table, surface: SurfaceSpec, simulation: SimSettings) -> WaveSpec | None:
    """The ``[wave]`` table checked against the surface and incidences (module docstring)."""
    if table is None:
        return None
    check_keys(where, "wave", table, list(_WAVE_KEYS))
    w = WaveSpec(**fill(where, "wave", table, _WAVE_KEYS))
    w = replace(w, wavelength=float(w.wavelength))
    lam = w.wavelength
    if surface.kind not in WAVE_KINDS:
        fail(
            where,
            "wave",
            f"needs surface.kind {' or '.join(WAVE_KINDS)} (a heightfield with a nominal PSD), "
            f"got {surface.kind!r}",
        )
    if w.surface_model == "mesh" and w.upsample != 1:
        fail(where, "wave.upsample", f'must be 1 with surface_model = "mesh", got {w.upsample}')
    n, dx = surface.n, surface.dx
    if n * dx < MIN_TILE_WAVELENGTHS * lam:
        fail(
            where,
            "wave.wavelength",
            f"the tile n·dx = {n * dx:g} holds only {n * dx / lam:.3g} wavelengths; the wave "
            f"solver needs >= {MIN_TILE_WAVELENGTHS:g} (wavelength <= "
            f"{n * dx / MIN_TILE_WAVELENGTHS:g} or a larger n·dx)",
        )
    if w.surface_model == "smooth":
        s_max = float(np.sin(np.radians(max(simulation.theta_i))))
        need = lam / (2.0 * (1.0 + s_max))
        if dx / w.upsample >= need:
            fail(
                where,
                "surface.dx",
                f"grid too coarse for wavelength {lam:g}: dx/upsample = "
                f"{dx / w.upsample:g} must be < λ/(2(1 + sin θi)) = {need:.4g} at θi = "
                f"{max(simulation.theta_i):g}° (the diffraction orders' phase step); need dx < "
                f"{need * w.upsample:.4g} or upsample >= {int(np.floor(dx / need)) + 1}",
            )
    return w


def catalogue_dir() -> Path:
    """The packaged catalogue's folder: relative to the working directory when inside it (a
    source checkout: outputs that print a scene's path then read ``microsim/scenes/...`` on
    every machine), else absolute."""
    try:
        return CATALOGUE.relative_to(Path.cwd().resolve())
    except (ValueError, OSError):  # elsewhere, or the working directory is gone
        return CATALOGUE


def catalogue_names() -> list[str]:
    """The names of the catalogue's scenes (their file stems), sorted."""
    return sorted(p.stem for p in CATALOGUE.glob("*.toml"))


def resolve_scene(name, parameter: str = "scene") -> Path:
    """The scene file ``name`` stands for: a path that exists, as is; else a bare catalogue
    name ``NAME`` or ``NAME.toml`` (no folder part), the file in ``catalogue_dir()``. A
    ``UsageError`` naming ``parameter`` and listing the catalogue's names otherwise."""
    path = file_path("the scene file", name)
    try:
        os.lstat(path)
        return path
    except (FileNotFoundError, NotADirectoryError):
        pass
    except OSError:  # a name too long, a permission: the reader names the failure
        return path
    names = catalogue_names()
    stem = path.name.removesuffix(".toml")
    if len(path.parts) == 1 and stem in names:
        return catalogue_dir() / f"{stem}.toml"
    raise UsageError(
        f"{parameter}: no such scene file {str(name)!r}, nor a catalogue scene of that name; "
        f"give a scene file's path or one of the catalogue's scenes: {', '.join(names)}"
    )


def load_scene(path) -> Scene:
    """Read and validate a scene file, given as a path or a catalogue name (``resolve_scene``;
    module docstring for the schema)."""
    path = resolve_scene(path)
    where = str(path)
    data = read_toml(path)
    check_keys(where, "scene", data, list(_TOP_KEYS))
    if "surface" not in data:
        fail(where, "surface", f"required table with kind = one of {', '.join(SURFACE_KINDS)}")
    name = check_value(where, "name", data.get("name", path.stem), STR)
    if not NAME_PATTERN.fullmatch(name):
        fail(
            where,
            "name",
            f"must be {NAME_RULE}, got {name!r}"
            + (" (the default is the file name)" if "name" not in data else ""),
        )
    description = check_value(where, "description", data.get("description", ""), STR)
    surface = surface_spec(where, data["surface"])
    if isinstance(surface, FileSurface):
        check_heightfield(where, path.parent / surface.path, surface)
    simulation = _simulation(where, data.get("simulation"))
    if simulation.realisations == "auto" and not surface.random:
        fail(
            where,
            "simulation.realisations",
            f'"auto" needs a random surface (kind {", ".join(RANDOM_KINDS)}), '
            f"got kind {surface.kind!r}",
        )
    surface.check_simulation(where, simulation)
    wave = _wave(where, data.get("wave"), surface, simulation)
    ior = material_ior(where, data.get("material"))
    scene = Scene(
        name=name,
        path=path,
        description=description,
        surface=surface,
        ior=ior,
        simulation=simulation,
        wave=wave,
        material_name=_material_name(data.get("material")),
        transmission=_transmission(where, data.get("material"), ior),
    )
    if scene.transmission and wave is not None:
        fail(where, "wave", "the wave solver traces reflection only: not with transmission")
    if scene.transmission and simulation.rays == "auto":
        fail(where, "simulation.rays", 'must be an integer with transmission, got "auto"')
    if wave is not None and len(simulation.phi_i) > 1:
        fail(
            where,
            "simulation.phi_i",
            f"must be one azimuth in a scene with [wave] (the wave solver traces one φi), "
            f"got {list(simulation.phi_i)}",
        )
    if scene.full_azimuth and scene.simulation.phi_bins % 2:
        fail(
            where,
            "simulation.phi_bins",
            f"must be even with full-azimuth bins (one bin centred on Δφ = 180°), got "
            f"{scene.simulation.phi_bins}",
        )
    return scene


def _transmission(where, table, ior) -> bool:
    """``[material] transmission`` (default false); true needs a real index n: a dielectric
    medium whose bulk the refracted light crosses."""
    v = check_value(where, "material.transmission", (table or {}).get("transmission", False), BOOL)
    if v and (ior is None or complex(ior).imag != 0):
        fail(
            where,
            "material.transmission",
            f"true needs a real index n (a clear dielectric medium), got ior {ior!r}",
        )
    return bool(v)


def _material_name(table) -> str | None:
    """The material's name as ``fresnel.MATERIALS`` spells it, if ``[material] ior`` is one
    and no ``wavelength_nm`` is given (the name then stands for its fixed index)."""
    if table is None or "wavelength_nm" in table:
        return None
    return an.material_name(table.get("ior", "mirror"))


# --- description -------------------------------------------------------------------------------
def _fmt(v) -> str:
    if v is None:
        return "-"
    if hasattr(v, "error"):  # a fitted value with its standard error
        return f"{v.value:.4g} ± {v.error:.2g}"
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def _abc_fit(surf):
    """The surface report's ABC fit of a heightfield ``surf`` (``analysis.surface_report``),
    None where it has none."""
    from microsim.analysis.surface_report import surface_report

    heights = getattr(surf, "heights", None)
    return None if heights is None else surface_report(heights, surf.dx).abc


def describe_surface(scene_or_surface) -> str:
    """Plain-text table of a surface's measured statistics next to predicted and nominal values.

    Accepts a ``Scene`` (its surface is built with the scene's seed) or a ``Surface``.
    Slope variances are per axis; the prediction is mesh-exact (Gaussian 2σ²(1 − e^{−u})/dx²,
    ABC discrete spectrum × finite-difference response); "nominal" is the generator's target.
    """
    head = []
    if isinstance(scene_or_surface, Scene):
        sc = scene_or_surface
        head.append(
            f"scene {sc.name} ({sc.path})" + (f": {sc.description}" if sc.description else "")
        )
        head.append(f"material ior: {_fmt(sc.ior) if sc.ior is not None else 'mirror (R = 1)'}")
        surf = sc.build_surface()
    else:
        surf = scene_or_surface
    st = surf.stats()
    nom = st["nominal"]
    lx, ly = st["tile_size"]
    head.append(
        f"surface {surf.kind}: tile {lx:g} x {ly:g}, {st['triangles']} triangles, "
        f"{'periodic' if surf.periodic else 'not periodic'}"
        + (f", grid {st['grid'][1]} x {st['grid'][0]}, dx {st['dx']:g}" if "grid" in st else "")
    )
    head.append("nominal: " + ", ".join(f"{k} = {_fmt(v)}" for k, v in nom.items()))
    rows = [("quantity", "measured", "predicted", "nominal")]
    if "rms_height" in st:
        rows.append(
            ("rms height", st["rms_height"], st.get("predicted_rms_height"), nom.get("sigma"))
        )
    pred = st.get("predicted_slope_var")
    cont = st.get("continuum_slope_var")
    rows += [
        ("slope variance x", st["slope_var_x"], pred, cont),
        ("slope variance y", st["slope_var_y"], pred, cont),
        ("slope correlation", st["slope_corr"], None, 0.0),
        ("m = sqrt(var_x + var_y)", st["m_realised"], st.get("predicted_m"), nom.get("m")),
        ("z min", st["z_range"][0], None, None),
        ("z max", st["z_range"][1], None, None),
    ]
    if "n_grooves" in st:  # the V-groove generator's tilt statistics
        rows += [
            ("grooves", st["n_grooves"], None, nom.get("n_grooves")),
            ("rms tilt (deg)", st["tilt_rms_deg"], None, None),
            ("max tilt (deg)", st["tilt_max_deg"], None, None),
        ]
        if "cdf_max_dev" in st:
            rows.append(("tilt CDF distance to NDF", st["cdf_max_dev"], st["cdf_bound"], None))
    if "slope_ks" in st:  # a heightfield with a stated slope law (surfaces.student_t)
        crit = st["slope_ks_critical"]
        rows += [
            ("|slope| KS distance to its law", st["slope_ks"], crit, None),
            ("slope azimuth KS distance", st["azimuth_ks"], crit, None),
            ("independent cells", st["independent_cells"], None, None),
            ("law's mass beyond max |slope|", st["tail_mass_truncated"], None, None),
            ("height-|slope| rank correlation", st["height_slope_rank_corr"], None, 0.0),
        ]
    fit_notes = []
    if surf.kind == "abc":  # the spectrum's parameters as a measured surface's report fits them
        fit = _abc_fit(surf)
        if fit is not None:
            a_nom = nom.get("A")
            rows += [
                ("PSD fit A", fit.A, None, a_nom),
                ("PSD fit B", fit.B, None, nom.get("B")),
                ("PSD fit C", fit.C, None, nom.get("C")),
            ]
            lo, hi = fit.f_range
            fit_notes.append(
                f"(PSD fit: Löw et al. 2012's ABC PSD fitted to the tile's radial periodogram "
                f"over f in [{lo:.3g}, {hi:.3g}] as microsim surface FILE fits a scan, "
                f"± its standard error, reduced chi² {fit.reduced_chi2:.2f})"
            )
    cells = [[r[0]] + [_fmt(v) for v in r[1:]] for r in rows]
    widths = [max(len(c[i]) for c in cells) for i in range(4)]
    lines = ["  ".join(c[i].ljust(widths[i]) for i in range(4)).rstrip() for c in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    notes = [
        "(slope variances per axis; predicted = mesh-exact; nominal slope variance = "
        "continuum value)"
    ]
    if "slope_ks" in st:
        notes.append(
            "(KS distances: predicted = critical value at level 0.01 for the independent cells, "
            "tile area / corr_len²)"
        )
    notes += fit_notes + [f"warning: {w}" for w in surf.warnings]
    return "\n".join(head + lines + notes)
