"""Which bug a BRDF's deviation from a closed form looks like.

The BRDF's bin averages are fitted by a few *variants* of the model it should implement, each
the model with one common implementation bug, and the variant that fits best is named with its
size. For a Torrance–Sparrow model f = F(wi·h) D(h) G(wi, wo, h)/(4 cos θi cos θo) (Mikkelsen
2009, eq. 13) the variants are:

- normalisation: c·f, c fitted by least squares (a missing 1/4, 1/π, a factor 2);
- cosine: f·cos θi or f·cos θo (the cosine of the rendering equation left in: Mitsuba 3's
  ``eval`` and Cycles' closures return f·cos θ);
- Fresnel: the conductor's η and k swapped (n + ik read as k + in), Schlick's approximation
  (Schlick 1994) for the exact F;
- masking: G1(wi) or G1(wo) for G2, separable Smith G1(wi)G1(wo) for the height-correlated
  1/(1 + Λ(wi) + Λ(wo)) (Heitz 2014) and the converse, no G at all, and for Beckmann the
  rational G1 of Walter et al. 2007 (eq. 27) for the exact one;
- roughness: α² for α and √α for α (the roughness squared once too often, or not at all), and
  a roughness fitted to the lobe's width (``lobe_width_deg``).

For Walter et al. 2007's rough dielectric BSDF (``WalterDielectric``, both lobes: ``lobes``)
the variants are the normalisation and cosine ones (their cos θi, cos θo the absolute
values, on either side), the roughness ones, and:

- the η² of the BTDF: f_t × η_i²/η_o² (η² missing, or the BSDF in the other convention than
  the one checked: its adjoint f(wo, wi), Walter et al. 2007, eq. 21) and f_t × η_o²/η_i²
  (η² applied twice), η_i the index on the incidence's side, η_o on the other;
- Fresnel from the wrong side: for light from inside F(|wi·h|, η) for F(|wi·h|, 1/η) (the
  index not inverted with the side), and on the transmitted lobe 1 − F(|wo·h|, η_o/η_i) for
  1 − F(|wi·h|, η_o/η_i) (the refracted direction's cosine with the incident side's index);
- masking: the other Smith forms of ``analysis.glass.GLASS_MODELS`` — separable
  G1(wi)G1(wo) ↔ height-correlated 1/(1 + Λ(wi) + Λ(wo)), and across the interface that
  form ↔ Heitz 2014's B(1 + Λ(wi), 1 + Λ(wo)) (``WalterDielectric.crossing``).

Any other model (or a callable) gets the normalisation and cosine variants only. Each variant
is bin-averaged as the BRDF is (``microsim.sim.predict``; a BSDF lobe by lobe,
``bin_averages``' ``lobes``); its misfit is

    e = √( mean over θi of Σ Ω⊥ (f_brdf − f_variant)² / Σ Ω⊥ f_brdf² )

(Ω⊥ the bins' projected solid angles), and the best variant is named when it explains the
deviation: e ≤ ``EXPLAINS`` × the misfit of the model itself.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np

from microsim import vectors
from microsim.analysis.glass import GLASS_MODELS, canonical_incidence, lobe_function
from microsim.analytic.brdf import TorranceSparrow
from microsim.analytic.dielectric import WalterDielectric, dielectric_fresnel
from microsim.analytic.fresnel import f0_from_material, fresnel, resolve_material, schlick
from microsim.analytic.masking import NoMasking, Smith
from microsim.analytic.ndf import WALTER_2007, Beckmann
from microsim.bins import Bins
from microsim.sim.predict import FunctionBRDF, Predictor, predict_incidences

__all__ = ["EXPLAINS", "Cause", "bin_averages", "likely_cause", "misfit", "lobe_width_deg"]

EXPLAINS = 0.3
"""A variant is named when its misfit is at most this share of the model's own misfit (it
removes ≥ 70 % of the deviation)."""
QUAD_RTOL = 1e-4
"""Default relative accuracy of the variants' bin averages (``likely_cause``'s ``rtol``)."""


@dataclass(frozen=True)
class Cause:
    """The variant of the model that fits the BRDF best: ``kind`` (normalisation, cosine,
    fresnel, masking, roughness), ``text`` (what the bug is and its size), ``misfit`` (the
    variant's relative misfit e) and ``model_misfit`` (the model's own)."""

    kind: str
    text: str
    misfit: float
    model_misfit: float

    def sentence(self) -> str:
        """The message's line: the cause, then how well it fits."""
        return (
            f"{self.text} (the brdf differs from that variant of the model by "
            f"{self.misfit:.2%}, from the model itself by {self.model_misfit:.2%}: relative "
            "RMS over the bins)"
        )


def lobe_width_deg(bins: Bins, f) -> float:
    """Energy-weighted RMS angle (deg) of the bins' centre directions about the energy-weighted
    mean direction of ``f`` (Θ × Φ bin averages on ``bins``) over the outgoing hemisphere:
    the lobe's width."""
    from microsim.vectors import spherical_deg

    th, ph = np.meshgrid(bins.theta_centers, bins.phi_centers, indexing="ij")
    w = np.where(np.isfinite(f), f, 0.0) * bins.projected_solid_angle()
    if not np.any(w > 0):
        return float("nan")
    d = spherical_deg(th, ph)
    mean = (w[..., None] * d).sum((0, 1))
    mean /= np.linalg.norm(mean)
    ang = np.degrees(np.arccos(np.clip(d @ mean, -1.0, 1.0)))
    return float(np.sqrt((w * ang**2).sum() / w.sum()))


def misfit(bins: Bins, user, values, used=None) -> float:
    """e = √(mean over incidences of Σ Ω⊥ (user − values)² / Σ Ω⊥ user²) over the ``used``
    bins (default: where both are finite); (T, Θ, Φ) arrays."""
    om = bins.projected_solid_angle()
    ok = np.isfinite(user) & np.isfinite(values)
    if used is not None:
        ok &= used
    num = np.where(ok, (user - values) ** 2, 0.0) * om
    den = np.where(ok, user**2, 0.0) * om
    per = num.sum((1, 2)) / np.maximum(den.sum((1, 2)), 1e-300)
    return float(np.sqrt(per.mean()))


@dataclass(frozen=True)
class _Variant:
    """The model with one bug: ``kind``, ``text`` (with its size) and either its bin averages
    ``values`` or the ``model`` to bin-average."""

    kind: str
    text: str
    values: np.ndarray | None = None
    model: object = None


def _times(model, factor: Callable) -> FunctionBRDF:
    """``model`` times ``factor(wi, wo)`` as a model of its own."""
    return FunctionBRDF(lambda wi, wo: model.f(wi, wo) * factor(wi, wo), model.symmetric)


def _half_cos(wi, wo) -> np.ndarray:
    """wi·h, h the half vector (the angle Fresnel's F is evaluated at)."""
    return np.clip(vectors.dot(wi, vectors.half_vector(wi, wo)), 0.0, 1.0)


def _fresnel_variants(model: TorranceSparrow) -> list[_Variant]:
    eta = resolve_material(model.material)
    if eta is None:
        return []
    out = []
    if isinstance(eta, complex) and eta.imag > 0:
        swapped = complex(eta.imag, eta.real)
        out.append(
            _Variant(
                "fresnel",
                f"Fresnel with η and k swapped (n + ik = {swapped.real:g} + {swapped.imag:g}i "
                f"for {eta.real:g} + {eta.imag:g}i)",
                model=dataclasses.replace(model, material=swapped),
            )
        )
    f0 = f0_from_material(eta)

    def schlick_for_exact(wi, wo):
        c = _half_cos(wi, wo)
        exact = fresnel(c, eta)
        return np.where(exact > 0, schlick(c, f0) / np.where(exact > 0, exact, 1.0), 0.0)

    out.append(
        _Variant(
            "fresnel",
            f"Schlick's Fresnel approximation (F0 = {f0:.4g}) for the exact Fresnel factor",
            model=_times(model, schlick_for_exact),
        )
    )
    return out


def _masking_variants(model: TorranceSparrow) -> list[_Variant]:
    m = model.masking
    bare = dataclasses.replace(model, masking=NoMasking())
    out = [_Variant("masking", "no masking–shadowing G at all (G = 1)", model=bare)]
    if not isinstance(m, Smith):
        return out

    def g1_of(which):
        def factor(wi, wo):
            return m.g1(wi if which == "wi" else wo, vectors.half_vector(wi, wo))

        return factor

    other = "separable G1(wi)·G1(wo)" if m.correlated else "height-correlated"
    this = "height-correlated 1/(1 + Λ(wi) + Λ(wo))" if m.correlated else "separable"
    out += [
        _Variant(
            "masking",
            f"{other} Smith G for the {this} one",
            model=dataclasses.replace(
                model, masking=dataclasses.replace(m, correlated=not m.correlated)
            ),
        ),
        _Variant("masking", "G1(wo) for G2: masking only", model=_times(bare, g1_of("wo"))),
        _Variant("masking", "G1(wi) for G2: shadowing only", model=_times(bare, g1_of("wi"))),
    ]
    if isinstance(m.ndf, Beckmann) and m.lambda_method != WALTER_2007:
        out.append(
            _Variant(
                "masking",
                "Walter et al. 2007's rational approximation of Beckmann's Smith G1 (eq. 27, "
                "within 0.35 %; Mitsuba 3 and Cycles evaluate it) for the exact one: compare "
                f"with Smith(..., lambda_method={WALTER_2007!r})",
                model=dataclasses.replace(
                    model, masking=dataclasses.replace(m, lambda_method=WALTER_2007)
                ),
            )
        )
    return out


def _relative_index(wi, eta: float) -> np.ndarray:
    """η_o/η_i per pair: the index on the side opposite the incidence over the incidence's
    (air above, ``eta`` below)."""
    return np.where(wi[..., 2] > 0.0, eta, 1.0 / eta)


def _transmitted(wi, wo) -> np.ndarray:
    return wi[..., 2] * wo[..., 2] < 0.0


def _eta_squared(eta: float, power: float) -> Callable:
    """The factor (η_i²/η_o²)^power on the transmitted lobe, 1 on the reflected one."""

    def factor(wi, wo):
        rel = _relative_index(wi, eta)
        return np.where(_transmitted(wi, wo), rel ** (-2.0 * power), 1.0)

    return factor


def _facet_cosines(wi, wo, eta: float):
    """(|wi·h|, |wo·h|, relative index, transmitted) per pair: h the half vector of
    reflection or of refraction (Walter et al. 2007, eq. 13, 16)."""
    rel = _relative_index(wi, eta)
    through = _transmitted(wi, wo)
    h = vectors.normalize(np.where(through[..., None], -(wi + rel[..., None] * wo), wi + wo))
    return np.abs(vectors.dot(wi, h)), np.abs(vectors.dot(wo, h)), rel, through


def _fresnel(c, rel):
    """Dielectric F at cosines ``c`` and relative indices ``rel`` (one per side)."""
    out = np.empty_like(c)
    for r in np.unique(rel):
        on = rel == r
        out[on] = dielectric_fresnel(np.clip(c[on], 0.0, 1.0), r)
    return out


def _fresnel_ratio(right, wrong, through):
    """The factor turning F (reflected) and 1 − F (transmitted) at ``right`` into ``wrong``."""
    right, wrong = np.where(through, 1.0 - right, right), np.where(through, 1.0 - wrong, wrong)
    return np.where(right > 0.0, wrong / np.where(right > 0.0, right, 1.0), 1.0)


def _fresnel_index_not_inverted(eta: float) -> Callable:
    """Light from inside: F(|wi·h|, η) for F(|wi·h|, 1/η) — the relative index of the air
    side kept for the medium's (1 from the air)."""

    def factor(wi, wo):
        c, _, rel, through = _facet_cosines(wi, wo, eta)
        return np.where(
            rel < 1.0, _fresnel_ratio(_fresnel(c, rel), _fresnel(c, 1 / rel), through), 1.0
        )

    return factor


def _fresnel_at_the_other_direction(eta: float) -> Callable:
    """Transmitted lobe: 1 − F(|wo·h|, η_o/η_i) for 1 − F(|wi·h|, η_o/η_i) — the cosine of the
    direction on the other side with the index of the incidence's (1 on reflection, where
    |wo·h| = |wi·h|)."""

    def factor(wi, wo):
        ci, co, rel, through = _facet_cosines(wi, wo, eta)
        return np.where(through, _fresnel_ratio(_fresnel(ci, rel), _fresnel(co, rel), through), 1.0)

    return factor


def _dielectric_variants(model: WalterDielectric) -> list[_Variant]:
    """The η², Fresnel-side and Smith-form variants of a ``WalterDielectric`` (module
    docstring)."""
    eta = model.eta
    out = [
        _Variant(
            "eta2",
            "the BTDF's η² missing: f_t × η_i²/η_o² (1/η² lit from the air, η² from inside) — "
            "or the BSDF is in the other convention than convention= says: the adjoint "
            "f(wo, wi), importance for radiance or the converse (Walter et al. 2007, eq. 21)",
            model=_times(model, _eta_squared(eta, 1.0)),
        ),
        _Variant(
            "eta2",
            "the BTDF's η² applied twice: f_t × η_o²/η_i² (η² lit from the air, 1/η² from inside)",
            model=_times(model, _eta_squared(eta, -1.0)),
        ),
        _Variant(
            "fresnel",
            f"Fresnel evaluated from the wrong side for light from inside: F(|wi·h|, η = {eta:g}) "
            f"for F(|wi·h|, 1/η = {1 / eta:.4g}) (the relative index not inverted with the side "
            "of the incidence)",
            model=_times(model, _fresnel_index_not_inverted(eta)),
        ),
        _Variant(
            "fresnel",
            "Fresnel evaluated from the wrong side on the transmitted lobe: 1 − F(|wo·h|, "
            "η_o/η_i) for 1 − F(|wi·h|, η_o/η_i) (the cosine of the refracted direction with "
            "the index of the incident one)",
            model=_times(model, _fresnel_at_the_other_direction(eta)),
        ),
    ]
    this = (model.masking.correlated, model.crossing)
    for name, (correlated, crossing) in GLASS_MODELS.items():
        if (correlated, crossing) == this:
            continue
        masking = dataclasses.replace(model.masking, correlated=correlated)
        out.append(
            _Variant(
                "masking",
                f"{_SMITH_FORMS[(correlated, crossing)]} for the "
                f"{_SMITH_FORMS[this]} ({name} of analysis.glass)",
                model=dataclasses.replace(model, masking=masking, crossing=crossing),
            )
        )
    return out


_SMITH_FORMS = {
    (False, "as-reflection"): "separable Smith G1(wi)·G1(wo)",
    (True, "as-reflection"): "height-correlated Smith 1/(1 + Λ(wi) + Λ(wo)) on both lobes",
    (True, "height-correlated"): "height-correlated Smith with Heitz 2014's "
    "B(1 + Λ(wi), 1 + Λ(wo)) across the interface",
}


_ROUGHNESS = ("alpha", "m")


def _roughness_key(ndf) -> str | None:
    key = next(iter(ndf.params()), None)
    return key if key in _ROUGHNESS else None


def _with_roughness(model, value: float):
    """``model`` (a ``TorranceSparrow`` or ``WalterDielectric``) with its distribution's
    roughness ``value`` (Smith G bound to the new D where it was bound to the model's)."""
    ndf = dataclasses.replace(model.ndf, **{_roughness_key(model.ndf): value})
    m = model.masking
    masking = dataclasses.replace(m, ndf=ndf) if isinstance(m, Smith) and m.ndf == model.ndf else m
    return dataclasses.replace(model, ndf=ndf, masking=masking)


def _roughness_variants(model) -> list[_Variant]:
    key = _roughness_key(model.ndf)
    if key is None:
        return []
    a = float(model.ndf.params()[key])
    out = []
    if a < 1.0:
        out += [
            _Variant(
                "roughness",
                f"{key} = {a * a:.4g} = {a:g}²: the roughness squared where it is already "
                f"{key} (α² for α)",
                model=_with_roughness(model, a * a),
            ),
            _Variant(
                "roughness",
                f"{key} = {np.sqrt(a):.4g} = √{a:g}: the roughness parameter used as {key} "
                "without squaring it (α for α²)",
                model=_with_roughness(model, float(np.sqrt(a))),
            ),
        ]
    return out


def _fitted_roughness(model, user, model_values, bins, low: int, theta, phi, rtol, lobes):
    """A variant with the roughness that fits ``user`` best (bounded search about the lobe
    widths' ratio at incidence ``low``), or None; ``lobes`` as ``bin_averages``'."""
    from scipy.optimize import minimize_scalar

    key = _roughness_key(model.ndf)
    if key is None:
        return None
    a = float(model.ndf.params()[key])
    w_user = lobe_width_deg(bins, user[low])
    w_model = lobe_width_deg(bins, model_values[low])
    if not (np.isfinite(w_user) and np.isfinite(w_model) and w_model > 0):
        return None
    guess = np.log(a * w_user / w_model)

    def values_at(log_a):
        varied = _with_roughness(model, float(np.exp(log_a)))
        return bin_averages([varied], theta, phi, bins, rtol, lobes)[0]

    fit = minimize_scalar(
        lambda x: misfit(bins, user, values_at(x)),
        bounds=(guess - 0.3, guess + 0.3),
        method="bounded",
        options={"xatol": 1e-3},
    )
    best = float(np.exp(fit.x))
    change = best / a - 1.0
    if abs(change) < 0.002:
        return None
    return _Variant(
        "roughness",
        f"a {'rougher' if change > 0 else 'smoother'} distribution: {key} ≈ {best:.3g} for "
        f"{a:g} ({change:+.0%}; lobe RMS width {w_user:.2f}° vs {w_model:.2f}° at "
        f"θi = {theta[low]:g}°)",
        values=values_at(fit.x),
    )


def bin_averages(models, theta, phi, bins, rtol: float = QUAD_RTOL, lobes=None) -> list:
    """The bin averages (T, Θ, Φ) of each model at incidences ``theta``, ``phi`` (degrees).

    ``lobes`` (one of ``analysis.glass.LOBES`` per incidence, or None): each row is that lobe
    of a BSDF, θi in (90°, 180°] lit from inside the medium, on the bins of a dielectric
    ``Result`` (θo from the pole of the side the light leaves by, Δφ of the direction itself;
    ``analysis.glass.lobe_values``)."""
    theta = np.atleast_1d(np.asarray(theta, dtype=np.float64))
    phi = np.broadcast_to(np.asarray(phi, dtype=np.float64), theta.shape)
    if lobes is None:
        return _averages(models, theta, phi, bins, rtol)
    out = [np.empty((len(theta),) + bins.shape) for _ in models]
    rows = [(*canonical_incidence(float(t)), lobe) for t, lobe in zip(theta, lobes)]
    for inside, lobe in sorted({(inside, lobe) for _, inside, lobe in rows}):
        sel = [k for k, (_, i, b) in enumerate(rows) if (i, b) == (inside, lobe)]
        sided = [FunctionBRDF(lobe_function(m, inside, lobe), m.symmetric) for m in models]
        canonical = np.array([rows[k][0] for k in sel])
        for values, part in zip(out, _averages(sided, canonical, phi[sel], bins, rtol)):
            values[sel] = part
    return out


def _averages(models, theta, phi, bins, rtol: float) -> list[np.ndarray]:
    specs = [Predictor(f"v{k}", m) for k, m in enumerate(models)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        out = predict_incidences(specs, theta, phi, bins, rtol=rtol)
    return [out[s.name] for s in specs]


def _best_constant(bins, user, values) -> float:
    om = bins.projected_solid_angle()
    ok = np.isfinite(user) & np.isfinite(values)
    num = (np.where(ok, user * values, 0.0) * om).sum()
    den = (np.where(ok, values**2, 0.0) * om).sum()
    return float(num / den) if den > 0 else 1.0


def likely_cause(
    user, model, model_values, theta_i, phi_i, bins: Bins, rtol: float = QUAD_RTOL, lobes=None
) -> Cause | None:
    """The variant of ``model`` (module docstring) that best explains ``user``, the BRDF's bin
    averages (T, Θ, Φ) at incidences ``theta_i``, ``phi_i`` (degrees) on ``bins``, given the
    model's own bin averages ``model_values`` (None: computed here); None when none explains it
    (or the BRDF already matches the model). ``rtol``: the relative accuracy of the variants'
    bin averages (that of ``user``'s is enough); deviations below 10 × rtol are not fitted.
    ``lobes``: for a BSDF, the lobe of each row (``bin_averages``)."""
    user = np.asarray(user, dtype=np.float64)
    theta = np.asarray(theta_i, dtype=np.float64)
    phi = np.broadcast_to(np.asarray(phi_i, dtype=np.float64), theta.shape)
    if model_values is None:
        model_values = bin_averages([model], theta, phi, bins, rtol, lobes)[0]
    model_values = np.asarray(model_values, dtype=np.float64)
    base = misfit(bins, user, model_values)
    if not np.isfinite(base) or base < 10 * rtol:
        return None
    cos_i = np.abs(np.cos(np.radians(theta)))[:, None, None]
    low = int(np.argmax(cos_i.ravel()))  # the incidence nearest the normal
    c = _best_constant(bins, user, model_values)
    variants = [
        _Variant(
            "normalisation",
            f"a constant factor: brdf ≈ {c:.4g} × the model in every bin (normalisation: a "
            "missing 1/4, 1/π or factor 2?)",
            values=c * model_values,
        ),
        _Variant(
            "cosine",
            "a cosine left in: brdf ≈ model × cos θi (the incident cosine of the rendering "
            "equation belongs to the integrator, not to f)",
            values=model_values * cos_i,
        ),
        _Variant(
            "cosine",
            "a cosine left in: brdf ≈ model × cos θo (Mitsuba's and Cycles' eval return "
            "f·cos θo; microsim wants f alone)",
            model=_times(model, lambda wi, wo: np.abs(wo[..., 2])),
        ),
    ]
    if isinstance(model, TorranceSparrow):
        variants += _fresnel_variants(model) + _masking_variants(model)
    if isinstance(model, WalterDielectric):
        variants += _dielectric_variants(model)
    closed_form = isinstance(model, (TorranceSparrow, WalterDielectric))
    if closed_form:
        variants += _roughness_variants(model)
    to_average = [v.model for v in variants if v.values is None]
    averaged = iter(bin_averages(to_average, theta, phi, bins, rtol, lobes))
    values = [v.values if v.values is not None else next(averaged) for v in variants]
    fits = [(misfit(bins, user, vals), k) for k, vals in enumerate(values)]
    if closed_form and min(fits)[0] > 0.01 * base:
        fitted = _fitted_roughness(model, user, model_values, bins, low, theta, phi, rtol, lobes)
        if fitted is not None:
            fits.append((misfit(bins, user, fitted.values), len(variants)))
            variants.append(fitted)
    best, k = min(fits)
    if best > EXPLAINS * base:
        return None
    return Cause(variants[k].kind, variants[k].text, best, base)


@dataclass(frozen=True)
class Closest:
    """Of several correct models, the one nearest the BRDF: ``name``, ``model``, its bin
    averages ``values`` and the relative ``misfit`` of the BRDF to it."""

    name: str
    model: object
    values: np.ndarray
    misfit: float

    @property
    def is_the_model(self) -> bool:
        """The BRDF is this model, within the quadratures' accuracy (the BRDF's bin averages are
        accurate to 1e-3, ``microsim.sim.predict``'s default)."""
        return self.misfit <= IS_THE_MODEL


IS_THE_MODEL = 3e-3
"""Relative misfit below which a BRDF is taken to be the model itself (its bin averages and the
model's agree to within their quadratures' accuracy)."""


def closest(
    user, models: dict, theta_i, phi_i, bins: Bins, rtol: float = QUAD_RTOL, lobes=None
) -> Closest:
    """The model of ``models`` (name → model) nearest ``user`` (bin averages, T × Θ × Φ), the
    bin averages accurate to ``rtol``; ``lobes`` as ``bin_averages``'."""
    theta = np.asarray(theta_i, dtype=np.float64)
    values = bin_averages(list(models.values()), theta, phi_i, bins, rtol, lobes)
    fits = [misfit(bins, user, v) for v in values]
    k = int(np.argmin(fits))
    return Closest(list(models)[k], list(models.values())[k], values[k], fits[k])
