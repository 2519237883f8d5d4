"""Which closed forms a simulation is compared with, their bin-averaged predictions, and a
direct ray-traced measurement of Smith's masking function G1.

Default models (``default_models``; names are short and stable, used as ``Result.models`` keys
and in reports). All are Torrance–Sparrow, f = F G D / (4 cos θi cos θo) (Mikkelsen 2009,
eq. 13/18) with exact Fresnel for the run's material; they differ in D and G. The choice asks
the surface what its generator knows (``Surface.ensemble_ndf``, ``Surface.exact_shadowing``):

Surfaces with an exact shadowing and an ensemble NDF (V-grooves: D = the NDF the groove tilts
were drawn from, G = V-groove, Mikkelsen 2009, eq. 25, exact for the V-cavity surface):
  ``ts-vgroove``        D analytic, V-groove G
  ``ts-smith``          D analytic, separable Smith G1(wi)G1(wo)
  ``ts-smith-corr``     D analytic, height-correlated Smith 1/(1 + Λi + Λo)
  ``ts-facets``         D = the surface's own facets (azimuth-averaged when the surface asks
                        for it), the exact G: what the explicit surface represents exactly (no
                        tail beyond its last groove)
Oriented V-grooves (no ensemble NDF: every facet normal lies in the xz plane):
  ``ts-facets``         the tile's facets with V-groove G, exact for the tile
  ``ts-vgroove-oriented``  the same with ``ORIENTED_CONTINUUM`` stratified tilts of the tilt
                        NDF (``Surface.tilt_ndf``): the continuum of grooves the tile quantises
                        (its tail beyond the tile's last quantile included), the ensemble form;
                        the pair measures the tile's departure from it
Surfaces with an exact shadowing and no NDF (the flat mirror, exact shadowing "none"):
  ``mirror-fresnel``    the exact answer: all reflected light in the mirror bin, weight F(θi)
Surfaces without an exact shadowing (heightfields: ``gaussian``, ``abc``, ``file``;
m_nom = the ensemble NDF's Beckmann m — Gaussian 2σ/ℓ, ABC the predicted mesh m —,
m_real = ``surface.stats()["m_realised"]``):
  ``ts-beckmann-nominal-{vgroove,smith,smith-corr}``    the ensemble NDF (none for ``file``);
                        ``ts-ggx-nominal-*``, ``ts-student-t-nominal-*`` for Student-t
                        heightfields (``ensemble_family``)
  ``ts-beckmann-realised-{vgroove,smith,smith-corr}``   Beckmann(m_real) (Beckmann ensembles
                        and ``file`` only: the slope variance of GGX is infinite)
  ``ts-facets``         D = the surface's own facets (Empirical), height-correlated Smith G with
                        the facets' own Λ
  For random scenes run over several realisations, ``ts-facets`` and m_real pool all of them
  (pass the realisations as a sequence); these realisation-specific models are judged against
  ray noise only (``attach_models`` lists them in ``meta["realisation_models"]``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np

from microsim import vectors
from microsim.analytic.anisotropic import AnisotropicBeckmann, AnisotropicNDF
from microsim.analytic.fresnel import resolve_material
from microsim.analytic.masking import Smith
from microsim.analytic.models import TorranceSparrow
from microsim.analytic.ndf import Beckmann
from microsim.errors import UsageError

from .predict import Facets, Predictor, predict_incidences, predictions
from .result import Result
from .tracer import ESCAPED, Tracer

__all__ = [
    "default_models",
    "departure_models",
    "attach_models",
    "measure_g1",
    "G1Measurement",
    "SHADOWING_SUFFIX",
    "VGROOVE_AZIMUTHS",
    "VGROOVE_PAIRS",
    "surface_fingerprint",
]

SHADOWING_SUFFIX = {"vgroove": "vgroove", "smith": "smith", "smith-correlated": "smith-corr"}
# least copies per groove tilt in V-groove ts-facets (predict.bin_average_facets); the sum over
# ``VGROOVE_PAIRS`` pairs takes ~0.2 s per θi on one core (4000 grooves: 4431 distinct tilts ×
# 452 copies, 45 × 37 bins)
VGROOVE_AZIMUTHS = 256
# (distinct tilt, azimuth) pairs V-groove ts-facets uses by default (``azimuths=None``): the
# model's azimuthal noise variance per bin falls as 1/pairs, and is not in the verdict's σ.
# With 500 grooves, 256 copies (1.3e5 pairs) gave χ²/dof 1.3–2.0 against exact 4e5-ray runs
# at θi 30–80° (seeds 0–2, Bins(30, 19)); 2e6 pairs gave 0.9–1.15. Its variance relative to
# the ray variance grows ∝ rays/pairs: pass a larger ``azimuths`` for runs of ≫ 1e6 rays.
VGROOVE_PAIRS = 2_000_000


def _surfaces_and_ndf(scene_or_surfaces, ndf):
    """(surfaces, analytic NDF or None): a Scene builds its surface; a Surface or a sequence of
    Surfaces (the realisations of one random scene) is used as is. The NDF defaults to the
    surface's ``ensemble_ndf``."""
    if hasattr(scene_or_surfaces, "build_surface"):
        surface = scene_or_surfaces.build_surface()
        return [surface], ndf if ndf is not None else surface.ensemble_ndf
    surfaces = (
        list(scene_or_surfaces)
        if isinstance(scene_or_surfaces, (list, tuple))
        else [scene_or_surfaces]
    )
    if not surfaces or not all(
        hasattr(s, "kind") and hasattr(s, "facet_normals") for s in surfaces
    ):
        raise UsageError(
            f"scene_or_surface must be a Scene, a Surface or a non-empty sequence "
            f"of Surfaces, got {scene_or_surfaces!r}"
        )
    if len({s.kind for s in surfaces}) != 1:
        raise UsageError("scene_or_surface: realisations must all be of one surface kind")
    return surfaces, ndf if ndf is not None else surfaces[0].ensemble_ndf


def _pooled_facets(surfaces):
    """Facet normals and projected-area weights of all realisations together, and the NDF the
    pool realises (``_realised_ndf``).

    ``simulate`` gives every realisation the same number of rays over tiles of equal area, so
    its BRDF is the average of the realisations' BRDFs; Torrance–Sparrow with the pooled facets
    is the same average (exactly for V-groove G; for Smith G the pooled Λ stands in for each
    realisation's own, a difference far below the tile-to-tile scatter). Surfaces with an exact
    shadowing (V-grooves, flat) need no realised NDF: None."""
    normals = np.concatenate([s.facet_normals() for s in surfaces])
    weights = np.concatenate([s.projected_areas() / s.projected_areas().sum() for s in surfaces])
    if surfaces[0].exact_shadowing is not None:
        return normals, weights, None
    return normals, weights, _realised_ndf(surfaces)


ORIENTED_CONTINUUM = 2**16
"""Grooves of ``ts-vgroove-oriented``: stratified tilts whose CDF is within 1/2¹⁷ of the tilt
NDF's, 32 × the catalogue tile's 2000 (its bin averages cost ~0.1 s per incidence)."""

ORIENTED_MODEL = "ts-vgroove-oriented"


def _oriented_continuum(surface, material) -> Predictor | None:
    """``ts-vgroove-oriented`` of an oriented V-groove tile (module docstring), or None without
    a ``tilt_ndf``."""
    from microsim.surfaces.vgrooves import vgrooves

    if surface.tilt_ndf is None:
        return None
    dense = vgrooves(ORIENTED_CONTINUUM, surface.tilt_ndf, oriented=True)
    normals, weights, _ = _pooled_facets([dense])
    return Predictor.facets(ORIENTED_MODEL, normals, weights, "vgroove", material, continuum=True)


GEOMEAN_MODEL = "ts-beckmann-nominal-smith-corr-geomean"
"""The anisotropic ensemble NDF with the height-correlated Smith G of the isotropic
α = √(αx αy): the stand-in MaterialX uses for the anisotropic Smith G."""


def _realised_ndf(surfaces):
    """Beckmann at the realised m (``realised_m``); for anisotropic fields (``alpha_x_realised``
    in the stats) the anisotropic Beckmann at the realised αx, αy (means over realisations)
    and the ensemble's rotation. The facet statistics are computed once."""
    stats = [s.stats() for s in surfaces]
    ens = surfaces[0].ensemble_ndf
    if not isinstance(ens, AnisotropicNDF):
        return Beckmann(_m_of(stats))
    ax = float(np.sqrt(np.mean([st["alpha_x_realised"] ** 2 for st in stats])))
    ay = float(np.sqrt(np.mean([st["alpha_y_realised"] ** 2 for st in stats])))
    return AnisotropicBeckmann(ax, ay, ens.rotation)


def realised_m(surfaces) -> float:
    """Beckmann m of the realised slopes of ``surfaces`` (a sequence of realisations):
    √(mean over realisations of var_x + var_y), the projected-area weighted facet slope
    variances of ``Surface.stats`` — the m of the ``ts-beckmann-realised-*`` models."""
    return _m_of([s.stats() for s in surfaces])


def _m_of(stats) -> float:
    return float(np.sqrt(np.mean([st["slope_var_x"] + st["slope_var_y"] for st in stats])))


def ensemble_family(ndf) -> str:
    """The distribution family naming a heightfield's ensemble models (``ts-<family>-nominal-*``):
    the ``name`` of the NDF, of its isotropic member for an anisotropic one ("beckmann", "ggx",
    "student-t")."""
    return (ndf.isotropic_at(1.0) if isinstance(ndf, AnisotropicNDF) else ndf).name


def default_models(
    scene_or_surface, material, ndf=None, *, azimuths: int | None = None
) -> list[Predictor]:
    """The standard model set for a Scene, a Surface, or the realisations of one random scene
    (a sequence of Surfaces: ``ts-facets`` and the realised m then pool all of them, see
    ``_pooled_facets``) — module docstring for the names.

    ``material``: name, n, n + ik or None (see ``resolve_material``). ``ndf``: the analytic
    NDF (default: the surface's ``ensemble_ndf`` — the V-groove surface's source NDF,
    Beckmann(nominal m) for Gaussian, Beckmann(predicted mesh m) for ABC heightfields, as
    ``Scene.ndf``). ``azimuths``: azimuth copies of ``ts-facets`` on surfaces whose
    ``azimuth_average`` is set (V-grooves); default ⌈``VGROOVE_PAIRS`` / distinct tilts⌉, at
    least ``VGROOVE_AZIMUTHS`` and at most 2¹⁶.

    ``ts-facets`` records the fingerprints of the surfaces it was built from
    (``rule.fingerprints``); ``attach_models`` refuses a result traced over other
    realisations (a model of one tile compared with the mean of several is not exact).
    """
    surfaces, ndf = _surfaces_and_ndf(scene_or_surface, ndf)
    resolve_material(material)  # validate now, not at predict time
    kinds = tuple(SHADOWING_SUFFIX)
    normals, weights, realised = _pooled_facets(surfaces)
    exact = surfaces[0].exact_shadowing
    if exact == "none":  # nothing shadows (flat): all light in the mirror bin, weight F(θi)
        return [Predictor.facets("mirror-fresnel", normals, weights, "none", material)]
    if exact is not None and ndf is None and not surfaces[0].azimuth_average:
        # oriented V-grooves: no ensemble NDF; TS with the tile's facets and G is exact, the
        # same with the continuum of tilts is the ensemble form
        facets = Predictor.facets("ts-facets", normals, weights, exact, material)
        continuum = _oriented_continuum(surfaces[0], material)
        if continuum is None:
            return [facets]
        return [continuum, _tagged(facets, surfaces, ensemble=ORIENTED_MODEL)]
    if exact is not None:
        if ndf is None:
            raise UsageError(
                f"ndf must be given for a {surfaces[0].kind} surface without an ensemble_ndf"
            )
        copies = None
        if surfaces[0].azimuth_average:
            copies = int(azimuths) if azimuths is not None else _auto_azimuths(normals)
        specs = [
            Predictor(f"ts-{SHADOWING_SUFFIX[k]}", TorranceSparrow(ndf, k, material)) for k in kinds
        ]
        facets = Predictor.facets("ts-facets", normals, weights, exact, material, copies)
        # the same closed form with the ensemble NDF: the pair measures the tile's departure
        return specs + [_tagged(facets, surfaces, ensemble=f"ts-{SHADOWING_SUFFIX[exact]}")]
    family = "beckmann" if ndf is None else ensemble_family(ndf)
    ndfs = [(family, "nominal", ndf)] if ndf is not None else []
    if family == "beckmann":  # a Beckmann m fitted to the slope variance (infinite for GGX)
        ndfs.append(("beckmann", "realised", realised))
    specs = [
        Predictor(f"ts-{fam}-{label}-{SHADOWING_SUFFIX[k]}", TorranceSparrow(d, k, material))
        for fam, label, d in ndfs
        for k in kinds
    ]
    if isinstance(ndf, AnisotropicNDF):  # anisotropic ensemble
        stand_in = Smith(ndf.isotropic_equivalent(), correlated=True)
        model = TorranceSparrow(ndf, stand_in, material)
        specs.append(Predictor(GEOMEAN_MODEL, model))
    facets = Predictor.facets("ts-facets", normals, weights, "smith-correlated", material)
    return specs + [_tagged(facets, surfaces)]


def departure_models(scene_or_surface, material, ndf=None) -> list[Predictor]:
    """The two models of ``default_models`` whose ratio is one tile's departure from its
    ensemble (``analysis.verdicts.tile_departure``): [the ensemble closed form with the
    surface's exact shadowing, ``ts-facets``] for one surface whose exact shadowing depends on
    its facets alone (V-grooves); [] where that departure is not computable without rays
    (several realisations, heightfields, a flat mirror) or there is no ensemble form (a
    surface without ``tilt_ndf``); for oriented grooves the ensemble form is
    ``ts-vgroove-oriented``."""
    surfaces, _ = _surfaces_and_ndf(scene_or_surface, None)
    if len(surfaces) != 1 or surfaces[0].exact_shadowing in (None, "none"):
        return []
    if surfaces[0].ensemble_ndf is None and surfaces[0].tilt_ndf is None:
        return []
    standard = default_models(scene_or_surface, material, ndf)
    facets = standard[-1]
    ensemble = facets.rule.ensemble
    if ensemble is None:
        return []
    return [s for s in standard if s.name == ensemble] + [facets]


def _auto_azimuths(normals) -> int:
    """Azimuth copies giving ``VGROOVE_PAIRS`` (distinct tilt, azimuth) pairs (tilts rounded
    to 1e-12 rad as ``bin_average_facets`` merges them), clipped to [256, 2¹⁶]."""
    tilts = np.round(np.arctan2(np.hypot(normals[:, 0], normals[:, 1]), normals[:, 2]), 12)
    n = np.unique(tilts).size
    return int(np.clip(-(-VGROOVE_PAIRS // n), VGROOVE_AZIMUTHS, 2**16))


def surface_fingerprint(surface) -> str:
    """The traced surface's identity as ``simulate`` records it (``meta["surface"]`` or
    ``meta["realisations"][r]``, key "fingerprint"): ``Surface.fingerprint``."""
    return surface.fingerprint()


def _tagged(spec: Predictor, surfaces, ensemble: str | None = None) -> Predictor:
    """``spec`` with the sorted fingerprints of the surfaces its facets come from and, for a
    surface whose exact shadowing depends on its facets alone (V-grooves), the name of the
    ensemble model with the same shadowing (``rule.ensemble``; ``attach_models``)."""
    fps = tuple(sorted(surface_fingerprint(s) for s in surfaces))
    return replace(spec, rule=replace(spec.rule, fingerprints=fps, ensemble=ensemble))


def _result_fingerprints(result: Result) -> tuple[str, ...] | None:
    """Sorted fingerprints of the surfaces ``result`` was traced over (None if not recorded)."""
    metas = result.meta.get("realisations") or [result.meta.get("surface")]
    fps = [m.get("fingerprint") for m in metas if isinstance(m, dict)]
    if not fps or None in fps or len(fps) != len(metas):
        return None
    return tuple(sorted(fps))


def attach_models(result: Result, specs, rtol: float = 1e-3) -> Result:
    """A new Result: ``result`` with the bin-averaged predictions of ``specs`` (name → (T, Θ, Φ)
    sr⁻¹, on the result's bins, θi and φi; one ``predict`` call per distinct φi) added to its
    ``models`` and their facet models added to ``meta["realisation_models"]`` (and, when a
    facet model names its ensemble counterpart, that pair as ``meta["tile_departure"]``: the
    verdicts measure the tile's departure from its ensemble with it). ``result``
    itself is left untouched (Results are immutable); predictions travel inside the Result
    because they are saved with it (``model_*`` arrays) and every report reads them there.
    Facet models tagged with surface fingerprints (``default_models``) must match the result's
    realisations, else UsageError. ``specs``: ``Predictor``s, or a mapping name → model object
    (``analytic.models``, any ``BRDFModel``), (model, rule) pair or ``Predictor``."""
    specs = predictions(specs)
    traced = _result_fingerprints(result)
    for s in specs:
        built = s.rule.fingerprints if isinstance(s.rule, Facets) else None
        if built is not None and traced is not None and tuple(built) != traced:
            raise UsageError(
                f"specs: model {s.name!r} was built from {len(built)} surface(s) other than the "
                f"{len(traced)} realisation(s) the result was traced over; pass the same "
                f"surfaces (the list of realisations) to default_models"
            )
    out = predict_incidences(specs, result.theta_i, result.phi_i, result.bins, rtol)
    own = set(result.meta.get("realisation_models", ())) | {
        s.name for s in specs if isinstance(s.rule, Facets) and not s.rule.continuum
    }
    meta = {**result.meta, "realisation_models": sorted(own)}
    models = {**result.models, **out}
    pairs = [
        {"tile": s.name, "ensemble": s.rule.ensemble}
        for s in specs
        if isinstance(s.rule, Facets) and s.rule.ensemble in models
    ]
    if pairs:
        meta["tile_departure"] = pairs[0]
    return replace(result, models=models, meta=meta)


class G1Measurement(NamedTuple):
    """``measure_g1`` result: ``g1`` and its standard error ``stderr``, (K,) over θo."""

    g1: np.ndarray
    stderr: np.ndarray


def measure_g1(
    surface, theta_o_deg, rays: int = 100_000, seed: int = 0, phi_o_deg: float = 0.0
) -> G1Measurement:
    """Ray-traced masking G1(wo) of ``surface`` for polar angles ``theta_o_deg`` (deg, < 90).

    Projected-area identity: the microsurface seen from wo has projected area cos θo per unit
    macro area, so with dA the microsurface area element and V the visibility of a point
    along wo (Smith's G1(wo) is this ratio for his random surface):

        G1(wo) = ∫ V (wo·n)⁺ dA / ∫ (wo·n)⁺ dA.

    Estimator: ``rays`` points drawn uniformly over the true area (facet ∝ area, uniform in
    the triangle), x_k = (wo·n_k)⁺, V_k from a traced masking ray (``Tracer.escapes``, the
    same offsets as the estimator); G1 = Σ V x / Σ x, stderr by the ratio-estimator delta
    method. Seeded per angle with ``default_rng([seed, k])``. For V-grooves (azimuth-averaged
    surfaces) wo is in the groove frame at azimuth ``phi_o_deg``: pass several to average.
    """
    th = np.atleast_1d(np.asarray(theta_o_deg, dtype=np.float64))
    if th.ndim != 1 or th.size == 0 or not np.all((th >= 0) & (th < 90)):
        raise UsageError(f"theta_o_deg must be degrees in [0, 90), got {theta_o_deg!r}")
    if isinstance(rays, bool) or int(rays) != rays or rays < 2:
        raise UsageError(f"rays must be an integer >= 2, got {rays!r}")
    tracer = Tracer(surface)
    vert, faces = np.asarray(surface.vertices, np.float64), np.asarray(surface.faces)
    v0, e1, e2 = (
        vert[faces[:, 0]],
        vert[faces[:, 1]] - vert[faces[:, 0]],
        vert[faces[:, 2]] - vert[faces[:, 0]],
    )
    normals = surface.facet_normals()
    cdf = np.cumsum(surface.facet_areas())
    g1, se = np.empty(th.size), np.empty(th.size)
    for k, t in enumerate(th):
        rng = np.random.default_rng([int(seed), k])
        face = np.minimum(
            np.searchsorted(cdf, rng.random(int(rays)) * cdf[-1], side="right"), len(cdf) - 1
        )
        u, v = rng.random(int(rays)), rng.random(int(rays))
        flip = u + v > 1.0
        u, v = np.where(flip, 1.0 - u, u), np.where(flip, 1.0 - v, v)
        points = v0[face] + u[:, None] * e1[face] + v[:, None] * e2[face]
        wo = vectors.spherical_deg(t, phi_o_deg)
        nrm = normals[face]
        x = np.maximum(nrm @ wo, 0.0)
        lit = np.flatnonzero(x > 0)
        vis = np.zeros(int(rays))
        status = tracer.escapes(points[lit], nrm[lit], np.broadcast_to(wo, (lit.size, 3)))
        vis[lit] = status == ESCAPED
        y = vis * x
        g1[k] = y.sum() / x.sum()
        resid = y - g1[k] * x
        se[k] = np.sqrt(np.sum(resid**2) / (rays * (rays - 1))) / x.mean()
    return G1Measurement(g1, se)
