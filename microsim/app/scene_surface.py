"""The ``[surface]`` table of a scene (or sweep) file: one frozen description per surface
kind (``SURFACE_TYPES``), whose fields are the table's keys — each with its check and
default — and which builds the surface and tells its ensemble NDF (the scene-file schema:
``microsim.app.scene``)."""

from __future__ import annotations

from dataclasses import MISSING, dataclass, field, fields
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar, Mapping

from microsim import analytic as an
from microsim import surfaces
from microsim.errors import UsageError
from microsim.surfaces import scan
from microsim.surfaces.heightfields import (
    MAX_RMS_SLOPE,
    abc_ensemble_ndf,
    gaussian_ensemble_ndf,
)
from microsim.surfaces.loader import check_heightfield_file
from microsim.surfaces.student_t import (
    student_t_ensemble,
    student_t_mixture,
    student_t_transform,
)

from .scene_checks import (
    ANGLE,
    BOOL,
    LENGTH,
    PATH,
    REQUIRED,
    STR,
    Check,
    SceneError,
    check_keys,
    fail,
    fill,
    int_in,
    is_num,
    num_in,
)

__all__ = [
    "SurfaceSpec",
    "VGrooveSurface",
    "GaussianSurface",
    "ABCSurface",
    "StudentTTransformSurface",
    "StudentTMixtureSurface",
    "FileSurface",
    "FlatSurface",
    "SURFACE_TYPES",
    "SURFACE_KINDS",
    "RANDOM_KINDS",
    "MAX_GRID",
    "surface_spec",
    "make_ndf",
    "scaled_grid",
    "check_heightfield",
]

MAX_GRID = 4096
"""Largest heightfield grid side a scene may ask for (grid points per side)."""
_GRID = int_in(8, MAX_GRID)
_C_ABC: Check = (lambda v: is_num(v) and v > 1, "a number > 1 (C <= 1: infinite height variance)")
_BAND: Check = (lambda v: is_num(v) and v >= 1, "a number >= 1")
_SAMPLING: Check = (lambda v: v in ("stratified", "random"), '"stratified" or "random"')
_FORM: Check = (lambda v: v in scan.FORMS, " | ".join(f'"{f}"' for f in scan.FORMS))


def _key(check: Check, default: Any = REQUIRED, *, real: bool = False):
    """A field that is a scene key: its ``check``, its ``default`` (``REQUIRED``: none) and
    whether the value is stored as a float (``real``)."""
    meta = {"check": check, "real": real}
    if default is REQUIRED:
        return field(metadata=meta)
    return field(default=default, metadata=meta)


def make_ndf(name: str, params: Mapping[str, float]):
    """Analytic NDF from a scene name (``analytic.scene_distributions()``) and its parameters
    (the class's ``scene_params`` are taken from ``params``)."""
    cls = an.scene_distribution(name)
    return cls(**{k: params[k] for k in cls.scene_params})


def scaled_grid(n: int, scale: float) -> int:
    """Grid points per side of a heightfield of ``n`` built at surface scale ``scale``."""
    return max(8, round(n * scale))


@dataclass(frozen=True, kw_only=True)
class SurfaceSpec:
    """A validated ``[surface]`` table (defaults filled in): ``kind`` and, per kind, one
    attribute per key. ``build(seed, scale, base_dir)`` makes the ``Surface`` (``scale``
    shrinks the grid or the groove count, see ``Scene.build_surface``); ``ensemble_ndf()`` is
    the ``Surface.ensemble_ndf`` of the full-size surface, without building it."""

    kind: ClassVar[str] = ""
    random: ClassVar[bool] = False
    exact_shadowing: ClassVar[str | None] = None
    """The surface's exact shadowing kind (``Surface.exact_shadowing``) known without building
    it: "vgroove" for V-grooves, "none" for the flat mirror, None for heightfields."""
    """Whether realisations (seeds seed, seed + 1, …) are independent draws of one ensemble."""

    @classmethod
    def schema(cls) -> dict[str, tuple[Any, Check]]:
        """Key → (default or ``REQUIRED``, check) of the kind's table, in the table's order."""
        return {
            f.name: (REQUIRED if f.default is MISSING else f.default, f.metadata["check"])
            for f in fields(cls)
            if "check" in f.metadata
        }

    @classmethod
    def from_table(cls, where: str, table: dict) -> SurfaceSpec:
        """The checked description of ``table`` (its ``kind`` is this class's)."""
        table, schema = cls._table_schema(where, table)
        check_keys(where, "surface", table, ["kind", *schema])
        values = fill(where, "surface", {k: v for k, v in table.items() if k != "kind"}, schema)
        reals = cls._real_keys(values)
        spec = cls._from_values(
            {k: float(v) if k in reals and v is not None else v for k, v in values.items()}
        )
        spec.check(where)
        return spec

    @classmethod
    def _table_schema(cls, where, table) -> tuple[dict, dict]:
        return table, cls.schema()

    @classmethod
    def _real_keys(cls, values) -> set[str]:
        return {f.name for f in fields(cls) if f.metadata.get("real")}

    @classmethod
    def _from_values(cls, values) -> SurfaceSpec:
        return cls(**values)

    def check(self, where: str) -> None:
        """Checks across keys (after each key's own), a ``SceneError`` naming ``where``."""

    def check_simulation(self, where: str, simulation) -> None:
        """Checks of the scene's ``SimSettings`` that this surface needs (none by default)."""

    @property
    def params(self) -> Mapping[str, Any]:
        """The table's keys and values (without ``kind``; read-only), as runs record them."""
        return MappingProxyType({f.name: getattr(self, f.name) for f in fields(self)})

    def build(self, seed: int, scale: float, base: Path):
        raise NotImplementedError

    def ensemble_ndf(self):
        """The full-size surface's ensemble NDF; None where the kind has none."""
        return None


def _scene_ndf(where, name):
    """The distribution class a V-groove scene names, else a SceneError naming the allowed
    names."""
    try:
        return an.scene_distribution(name)
    except UsageError as e:
        message = str(e).removeprefix("ndf ")
    fail(where, "surface.ndf", message)


def _check_resolved(where, key, corr_len, dx) -> None:
    """A correlation length the grid resolves (>= dx), else a SceneError naming ``key``."""
    if corr_len < dx:
        fail(
            where,
            key,
            f"must be >= dx = {dx:g} (a shorter correlation length is not resolved by the "
            f"grid), got {corr_len:g}",
        )


@dataclass(frozen=True, kw_only=True)
class VGrooveSurface(SurfaceSpec):
    """``surfaces.vgrooves``: ``n_grooves`` grooves whose facet tilts follow the distribution
    ``ndf`` (a scene name) with ``ndf_params`` (its ``scene_params``, keys of the table too)."""

    kind: ClassVar[str] = "vgrooves"
    random: ClassVar[bool] = True
    exact_shadowing: ClassVar[str | None] = "vgroove"
    n_grooves: int = _key(int_in(1, 1_000_000), 4000)
    ndf: str = _key(STR)
    sampling: str = _key(_SAMPLING, "stratified")
    tile: float = _key(LENGTH, 1.0, real=True)
    oriented: bool = _key(BOOL, False)
    ndf_params: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))

    @classmethod
    def _table_schema(cls, where, table):
        ndf = _scene_ndf(where, table.get("ndf"))
        # beyond these bounds the closed forms over- or underflow
        bounds = {k: (REQUIRED, num_in(*b)) for k, b in ndf.scene_params.items()}
        return {**table, "ndf": ndf.name}, {**cls.schema(), **bounds}

    @classmethod
    def _real_keys(cls, values):
        return super()._real_keys(values) | (set(values) - set(cls.schema()))

    @classmethod
    def _from_values(cls, values):
        own = set(cls.schema())
        ndf_params = MappingProxyType({k: v for k, v in values.items() if k not in own})
        return cls(**{k: v for k, v in values.items() if k in own}, ndf_params=ndf_params)

    def check(self, where):
        try:
            self.distribution()
        except UsageError as e:
            raise SceneError(f"{where}: surface: {e}") from None

    @property
    def params(self):
        own = {k: getattr(self, k) for k in self.schema()}
        return MappingProxyType({**own, **self.ndf_params})

    def distribution(self):
        """The facet-tilt distribution (an ``analytic`` NDF)."""
        return make_ndf(self.ndf, self.ndf_params)

    def build(self, seed, scale, base):
        return surfaces.vgrooves(
            max(1, round(self.n_grooves * scale)),
            self.distribution(),
            seed,
            self.sampling,
            self.tile,
            oriented=self.oriented,
        )

    def ensemble_ndf(self):
        return None if self.oriented else self.distribution()


@dataclass(frozen=True, kw_only=True)
class _Heightfield(SurfaceSpec):
    """A random heightfield of ``n`` × ``n`` points ``dx`` apart; its generator takes the
    table's keys as keywords."""

    random: ClassVar[bool] = True
    generator: ClassVar[Any] = None
    n: int = _key(_GRID, 512)
    dx: float = _key(LENGTH, 1.0, real=True)

    def build(self, seed, scale, base):
        return type(self).generator(seed=seed, **{**self.params, "n": scaled_grid(self.n, scale)})


@dataclass(frozen=True, kw_only=True)
class GaussianSurface(_Heightfield):
    """``surfaces.gaussian``: rms height ``sigma``, correlation length ``corr_len`` (and
    ``corr_len_y`` across, the axes turned by ``rotation`` degrees)."""

    kind: ClassVar[str] = "gaussian"
    generator: ClassVar[Any] = staticmethod(surfaces.gaussian)
    sigma: float = _key(LENGTH, real=True)
    corr_len: float = _key(LENGTH, real=True)
    exact_amplitude: bool = _key(BOOL, True)
    corr_len_y: float | None = _key(LENGTH, None)
    rotation: float = _key(ANGLE, 0.0)

    def check(self, where):
        _check_resolved(where, "surface.corr_len", self.corr_len, self.dx)
        if 2.0 * self.sigma / self.corr_len > MAX_RMS_SLOPE:
            fail(
                where,
                "surface.sigma",
                f"rms slope 2 sigma / corr_len must be <= {MAX_RMS_SLOPE:g}, got "
                f"{2.0 * self.sigma / self.corr_len:.3g} (sigma = "
                f"{self.sigma:g}, corr_len = {self.corr_len:g})",
            )

    def ensemble_ndf(self):
        return gaussian_ensemble_ndf(self.sigma, self.corr_len, self.corr_len_y, self.rotation)


@dataclass(frozen=True, kw_only=True)
class ABCSurface(_Heightfield):
    """``surfaces.abc``: the ABC (K-correlation) spectrum of rms height ``sigma``, ``B``
    (``B_y`` across, the axes turned by ``rotation`` degrees), ``C``, cut at ``band_limit``."""

    kind: ClassVar[str] = "abc"
    generator: ClassVar[Any] = staticmethod(surfaces.abc)
    sigma: float = _key(LENGTH, real=True)
    B: float = _key(LENGTH, real=True)
    C: float = _key(_C_ABC, real=True)
    band_limit: float = _key(_BAND, 4.0, real=True)
    exact_amplitude: bool = _key(BOOL, True)
    B_y: float | None = _key(LENGTH, None)
    rotation: float = _key(ANGLE, 0.0)

    def ensemble_ndf(self):
        return abc_ensemble_ndf(
            self.n, self.dx, self.sigma, self.B, self.C, self.band_limit, self.B_y, self.rotation
        )


_ALPHA: Check = num_in(*an.StudentT.scene_params["alpha"])
_GAMMA: Check = num_in(*an.StudentT.scene_params["gamma"])


@dataclass(frozen=True, kw_only=True)
class StudentTTransformSurface(_Heightfield):
    """``surfaces.student_t_transform``: a Gaussian field of correlation length ``corr_len``
    mapped so that its facet slopes follow the Student-t distribution (``alpha``, ``gamma``;
    ``alpha_y`` across, the axes turned by ``rotation`` degrees)."""

    kind: ClassVar[str] = "student-t-transform"
    generator: ClassVar[Any] = staticmethod(student_t_transform)
    alpha: float = _key(_ALPHA, real=True)
    gamma: float = _key(_GAMMA, real=True)
    corr_len: float = _key(LENGTH, real=True)
    exact_amplitude: bool = _key(BOOL, True)
    alpha_y: float | None = _key(_ALPHA, None)
    rotation: float = _key(ANGLE, 0.0)

    def check(self, where):
        _check_resolved(where, "surface.corr_len", self.corr_len, self.dx)
        if self.alpha_y is not None:
            across = self.corr_len * self.alpha / self.alpha_y
            if across < self.dx:
                fail(
                    where,
                    "surface.alpha_y",
                    f"the correlation length across, corr_len·alpha/alpha_y = {across:g}, "
                    f"must be >= dx = {self.dx:g} (resolved by the grid); got alpha_y = "
                    f"{self.alpha_y:g}",
                )

    def ensemble_ndf(self):
        return student_t_ensemble(self.alpha, self.gamma, self.alpha_y, self.rotation)


@dataclass(frozen=True, kw_only=True)
class StudentTMixtureSurface(_Heightfield):
    """``surfaces.student_t_mixture``: realisation seed s is patch s mod ``patches`` of the
    Student-t (``alpha``, ``gamma``) as a Gamma mixture of Gaussian heightfields of correlation
    length ``corr_len``; the realisations must be a multiple of ``patches``."""

    kind: ClassVar[str] = "student-t-mixture"
    generator: ClassVar[Any] = staticmethod(student_t_mixture)
    alpha: float = _key(_ALPHA, real=True)
    gamma: float = _key(_GAMMA, real=True)
    corr_len: float = _key(LENGTH, real=True)
    patches: int = _key(int_in(1, 1000), 64)
    exact_amplitude: bool = _key(BOOL, True)

    def check(self, where):
        _check_resolved(where, "surface.corr_len", self.corr_len, self.dx)

    def check_simulation(self, where, simulation):
        n = simulation.realisations
        if n == "auto" or n % self.patches:
            fail(
                where,
                "simulation.realisations",
                f"must be a multiple of surface.patches = {self.patches} (each run of "
                f"{self.patches} consecutive seeds covers every stratum of the mixture once), "
                f"got {n!r}",
            )

    def ensemble_ndf(self):
        return student_t_ensemble(self.alpha, self.gamma)


@dataclass(frozen=True, kw_only=True)
class FileSurface(SurfaceSpec):
    """``surfaces.from_file``: the heightfield file ``path`` (relative to the scene file),
    points ``dx`` apart (an array file; a scan gives its own spacing, in micrometres), tiled
    ``periodic``-ally or not, its ``form`` removed (default: "plane" for a scan, "none" for
    an array, ``scan.default_form``)."""

    kind: ClassVar[str] = "file"
    path: str = _key(PATH)
    dx: float | None = _key(LENGTH, None, real=True)
    periodic: bool = _key(BOOL, False)
    form: str | None = _key(_FORM, None)

    @classmethod
    def _from_values(cls, values):
        if values["form"] is None:
            values = {**values, "form": scan.default_form(values["path"])}
        return cls(**values)

    def check(self, where):
        if scan.is_scan(self.path) and self.dx is not None:
            fail(
                where,
                "surface.dx",
                f"a scan file gives its own spacing (used in micrometres); leave dx out, "
                f"got {self.dx:g}",
            )
        if not scan.is_scan(self.path) and self.dx is None:
            fail(
                where,
                "surface.dx",
                f"required for a .npy, .npz or text heightfield (it gives no spacing); must be "
                f"{LENGTH[1]}",
            )

    def build(self, seed, scale, base):
        return surfaces.from_file(base / self.path, self.dx, self.periodic, self.form)


@dataclass(frozen=True, kw_only=True)
class FlatSurface(SurfaceSpec):
    """``surfaces.flat``: a plane tile of side ``size``."""

    kind: ClassVar[str] = "flat"
    exact_shadowing: ClassVar[str | None] = "none"
    size: float = _key(LENGTH, 1.0, real=True)

    def build(self, seed, scale, base):
        return surfaces.flat(self.size)


SURFACE_TYPES: Mapping[str, type[SurfaceSpec]] = MappingProxyType(
    {
        c.kind: c
        for c in (
            VGrooveSurface,
            GaussianSurface,
            ABCSurface,
            StudentTTransformSurface,
            StudentTMixtureSurface,
            FileSurface,
            FlatSurface,
        )
    }
)
SURFACE_KINDS = tuple(SURFACE_TYPES)
RANDOM_KINDS = tuple(k for k, c in SURFACE_TYPES.items() if c.random)
"""Kinds whose realisations (seeds seed, seed + 1, …) are independent draws of one ensemble."""


def surface_spec(where, table) -> SurfaceSpec:
    """The validated ``SurfaceSpec`` of a ``[surface]`` table (defaults filled in); a bad
    value raises ``SceneError`` naming ``where`` (the file) and the key. Used by scene and
    sweep files alike."""
    if not isinstance(table, dict):
        fail(where, "surface", f"must be a table, got {table!r}")
    kind = table.get("kind", REQUIRED)
    if kind is REQUIRED:
        fail(where, "surface.kind", f"required; one of {', '.join(SURFACE_KINDS)}")
    if kind not in SURFACE_TYPES:
        fail(where, "surface.kind", f"must be one of {', '.join(SURFACE_KINDS)}, got {kind!r}")
    return SURFACE_TYPES[kind].from_table(where, table)


def check_heightfield(where: str, path: Path, spec: FileSurface) -> None:
    """The heightfield file ``path`` of ``spec`` usable by ``surfaces.from_file``, checked
    before anything runs (``surfaces.loader.check_heightfield_file``: a regular file holding a
    real 2D array of finite heights, or a scan, that fits in memory, at most ``MAX_GRID`` per
    side); the one-line error names the scene file, the key and the heightfield file."""
    try:
        check_heightfield_file(path, spec.dx, spec.periodic, max_side=MAX_GRID, form=spec.form)
    except UsageError as e:
        fail(where, "surface.path", " ".join(str(e).split()))
