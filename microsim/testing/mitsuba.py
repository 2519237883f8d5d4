"""Mitsuba 3 BSDFs in microsim's conventions, for ``microsim.testing``'s checks.

``mitsuba_brdf(bsdf)`` is the BSDF as microsim's f(wi, wo), ``mitsuba_sampler(bsdf, wi)`` its
importance sampler for ``assert_sampler_matches``, ``mitsuba_model(bsdf)`` microsim's closed
form of what a ``roughconductor`` implements, for ``assert_brdf_matches_model``. ``bsdf`` is
a loaded ``mi.BSDF`` or the dict ``mi.load_dict`` takes, e.g. ``{"type": "roughconductor",
"distribution": "ggx", "alpha": 0.3}``. Mitsuba is loaded as the bench's peer loads it
(``microsim.app.bench_peer.load_mitsuba``: an LLVM variant, ``PeerUnavailable`` without one).

Conventions (docs/testing.md, "Renderers' conventions"): Mitsuba's BSDFs work in the local
shading frame (z the normal); ``si.wi`` points to the viewer (microsim's wo) and the
``wo`` argument of ``eval``/``pdf`` and the sampled ``bs.wo`` to the light (microsim's wi);
``eval`` returns f·cos θ of that light direction. The adapters call Mitsuba once per batch
(float32 Dr.Jit arrays) and return float64. Mitsuba's ``llvm_ad_rgb`` variant returns RGB;
the adapters take one ``channel`` (``DEFAULT_CHANNEL``: 1, green). A conductor's η, k are
the plugin's values in that channel: ``material`` "none" (Mitsuba's default) is η = 0,
k = 1, where its Fresnel term is exactly 1 (a perfect mirror, microsim's material None); a
preset such as "Al" is a different (η, k) per channel in an RGB variant.
"""

from __future__ import annotations

import functools
import os
import re
import subprocess
import sys
from dataclasses import dataclass

import numpy as np

from microsim import checks as _checks
from microsim.analytic.brdf import TorranceSparrow
from microsim.analytic.dielectric import WalterDielectric
from microsim.analytic.masking import Smith
from microsim.analytic.ndf import GGX, WALTER_2007, Beckmann
from microsim.app.bench_peer import PeerUnavailable, load_mitsuba
from microsim.errors import UsageError

__all__ = [
    "mitsuba_brdf",
    "mitsuba_sampler",
    "mitsuba_model",
    "MitsubaBRDF",
    "MODES",
    "DEFAULT_CHANNEL",
    "ALPHA_MIN",
]

DEFAULT_CHANNEL = 1
"""The RGB channel the adapters return (0 red, 1 green, 2 blue)."""
ALPHA_MIN = 1e-4
"""Mitsuba's microfacet distributions raise α to at least this (float32 1e-4)."""
_U_MAX = np.float32(1.0 - 2.0**-24)
"""The largest float32 below 1: uniform numbers are clipped to it (Mitsuba's samples < 1)."""

_PROBE = """
import numpy as np
from microsim.app.bench_peer import load_mitsuba
mi, dr, _ = load_mitsuba()
b = mi.load_dict({"type": "roughconductor"})
si = dr.zeros(mi.SurfaceInteraction3f, 4)
si.wi = mi.Vector3f(0.0, 0.6, 0.8)
np.asarray(b.eval(mi.BSDFContext(), si, mi.Vector3f(0.0, -0.6, 0.8)))
"""


@functools.cache
def _microfacet_kernels_compile() -> None:
    """PeerUnavailable unless Dr.Jit compiles a microfacet BSDF here, tried in a child
    process: with an LLVM library that lacks an intrinsic Mitsuba's kernels use (Debian 12's
    LLVM 15 cannot select ``llvm.maximum``) LLVM aborts the whole process."""
    out = subprocess.run(
        [sys.executable, "-c", _PROBE], capture_output=True, text=True, env=os.environ.copy()
    )
    if out.returncode != 0:
        last = (out.stderr.strip().splitlines() or ["no message"])[0][:200]
        raise PeerUnavailable(
            f"Mitsuba's LLVM backend cannot compile a microfacet BSDF here (a test process "
            f"exited with status {out.returncode}: {last}); point DRJIT_LIBLLVM_PATH at a newer "
            f"libLLVM (LLVM 19 works, Debian's libllvm19)"
        )


def _load(bsdf):
    """(mi, dr, the mi.BSDF) of a loaded BSDF or of a dict for ``mi.load_dict``."""
    mi, dr, _ = load_mitsuba()
    _microfacet_kernels_compile()
    if isinstance(bsdf, dict):
        try:
            return mi, dr, mi.load_dict(bsdf)
        except Exception as exc:  # noqa: BLE001 - Mitsuba reports bad plugin input so
            raise UsageError(f"bsdf: Mitsuba refused the dict: {exc}") from None
    if not isinstance(bsdf, mi.BSDF):
        raise UsageError(
            f"bsdf must be a Mitsuba BSDF (mi.BSDF) or a dict for mi.load_dict, got "
            f"{type(bsdf).__name__}"
        )
    return mi, dr, bsdf


def _channel(channel) -> int:
    if isinstance(channel, bool) or channel not in (0, 1, 2):
        raise UsageError(f"channel must be 0, 1 or 2 (red, green, blue), got {channel!r}")
    return int(channel)


def _vectors(mi, w: np.ndarray):
    """(N, 3) float64 → a Mitsuba Vector3f (float32) and the float32 z as float64."""
    w32 = np.ascontiguousarray(w, dtype=np.float32)
    return mi.Vector3f(w32[:, 0], w32[:, 1], w32[:, 2]), w32[:, 2].astype(np.float64)


def _viewers(mi, dr, wi32, n: int):
    """A SurfaceInteraction3f of ``n`` lanes with ``si.wi`` = the given Vector3f."""
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = wi32
    return si


def _one(value, channel: int) -> np.ndarray:
    """One channel of a Mitsuba Spectrum (or a Float) as float64 (N,)."""
    a = np.asarray(value, dtype=np.float64)
    return a[channel] if a.ndim == 2 else a


MODES = ("radiance", "importance")
"""Mitsuba's ``TransportMode`` by microsim's names (``testing.bsdf.CONVENTIONS``)."""


@dataclass(frozen=True)
class MitsubaBRDF:
    """A Mitsuba BSDF as microsim's f(wi, wo): (N, 3) unit vectors away from the surface
    (wi towards the light, wo towards the viewer, z the normal, the medium of a dielectric
    below) → N values in sr⁻¹ without the cosine, channel ``channel``; 0 where either
    direction is on the horizon (and, as Mitsuba's eval is, below it for a one-sided BSDF such
    as ``roughconductor``). One ``eval`` per call in Mitsuba's ``TransportMode`` ``mode``
    ("radiance" or "importance"): si.wi = wo, Mitsuba's wo = wi, f = eval / |cos θi| (θi of
    the float32 direction Mitsuba saw). A ``roughdielectric`` in "radiance" mode is then
    microsim's radiance-convention BSDF, in "importance" mode its adjoint f(wo, wi)
    (``testing.bsdf``, ``convention="importance"``)."""

    bsdf: object
    channel: int = DEFAULT_CHANNEL
    mode: str = "radiance"

    def __call__(self, wi, wo):
        mi, dr, _ = load_mitsuba()
        wi = _checks.directions("wi", wi)
        wo = _checks.directions("wo", wo)
        if wi.ndim != 2 or wi.shape != wo.shape:
            raise UsageError(f"wi, wo must have one shape (N, 3), got {wi.shape} and {wo.shape}")
        light, cos_light = _vectors(mi, wi)
        viewer, cos_viewer = _vectors(mi, wo)
        si = _viewers(mi, dr, viewer, len(wi))
        mode = mi.TransportMode.Radiance if self.mode == "radiance" else mi.TransportMode.Importance
        value = _one(self.bsdf.eval(mi.BSDFContext(mode), si, light), self.channel)
        ok = (cos_light != 0.0) & (cos_viewer != 0.0)
        return np.where(ok, value / np.where(ok, np.abs(cos_light), 1.0), 0.0)


def mitsuba_brdf(bsdf, channel: int = DEFAULT_CHANNEL, mode: str = "radiance") -> MitsubaBRDF:
    """The Mitsuba BSDF ``bsdf`` (an ``mi.BSDF`` or a dict for ``mi.load_dict``) as microsim's
    vectorised f(wi, wo) (``MitsubaBRDF``), one RGB ``channel``, evaluated in Mitsuba's
    transport ``mode`` ("radiance", its default, or "importance")."""
    _, _, loaded = _load(bsdf)
    if mode not in MODES:
        raise UsageError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    return MitsubaBRDF(loaded, _channel(channel), mode)


def mitsuba_sampler(bsdf, wi, channel: int = DEFAULT_CHANNEL):
    """(sample, pdf) of ``bsdf``'s importance sampler for the fixed direction ``wi`` (a unit
    3-vector away from the surface, z the normal; Mitsuba's ``si.wi``, the viewer: Mitsuba
    samples the direction towards the light), for ``assert_sampler_matches``:

    * ``sample(u1, u2)`` → (directions (n, 3), pdf (n,), weights (n,)): Mitsuba's ``bs.wo``,
      ``bs.pdf`` and weight f·cos θ/pdf (channel ``channel``) from one ``bsdf.sample`` call
      with sample2 = (u1, u2) in float32 (clipped below 1); Mitsuba's rejected samples
      (e.g. reflected below the horizon) keep their direction and have weight 0;
    * ``pdf(w)`` → (M,) sr⁻¹: ``bsdf.pdf``, 0 below the horizon.

    The BRDF the weights imply, for the check's ``brdf=``: ``lambda w:
    mitsuba_brdf(bsdf)(np.broadcast_to(wi, w.shape), w)`` (f is reciprocal).
    """
    mi, dr, loaded = _load(bsdf)
    channel = _channel(channel)
    fixed = _checks.directions("wi", wi, upper=True)
    if fixed.shape != (3,):
        raise UsageError(f"wi must be one direction, shape (3,), got {fixed.shape}")

    def at(n: int):
        viewer, _ = _vectors(mi, np.broadcast_to(fixed, (n, 3)))
        return _viewers(mi, dr, viewer, n)

    def sample(u1, u2):
        u1 = np.minimum(np.asarray(u1, dtype=np.float32), _U_MAX)
        u2 = np.minimum(np.asarray(u2, dtype=np.float32), _U_MAX)
        bs, weight = loaded.sample(mi.BSDFContext(), at(len(u1)), mi.Float(u1), mi.Point2f(u1, u2))
        directions = np.asarray(bs.wo, dtype=np.float64).T
        return directions, np.asarray(bs.pdf, dtype=np.float64), _one(weight, channel)

    def pdf(w):
        w = np.asarray(w, dtype=np.float64).reshape(-1, 3)
        light, _ = _vectors(mi, w)
        return np.asarray(loaded.pdf(mi.BSDFContext(), at(len(w)), light), dtype=np.float64)

    return sample, pdf


def _parameters(mi, loaded) -> dict:
    """{name: float32 values as float64 array} of the BSDF's uniform parameters (a texture's
    ``.value``, or a plain float such as roughdielectric's ``eta``)."""
    out = {}
    for key, value in mi.traverse(loaded).items():
        name, dot, kind = key.partition(".")
        if dot and kind != "value":
            raise UsageError(
                f"bsdf: mitsuba_model needs constant parameters; {name!r} is a texture ({key})"
            )
        out[name] = np.atleast_1d(np.asarray(value, dtype=np.float64)).ravel()
    return out


def _setting(text: str, name: str) -> str:
    """A plugin setting from the BSDF's description (Mitsuba exposes no other accessor)."""
    found = re.search(rf"\b{name} = (\w+)", text)
    if found is None:
        raise UsageError(f"bsdf: cannot read {name!r} from Mitsuba's description {text[:80]!r}")
    return found.group(1)


def _distribution(loaded, alpha: float):
    """(ndf, Smith G) of the plugin's ``distribution``: Mitsuba's separable Smith G, with the
    rational G1 of Walter et al. 2007 (eq. 27) for Beckmann."""
    if _setting(str(loaded), "distribution") == "ggx":
        return GGX(alpha), Smith(correlated=False)
    return Beckmann(alpha), Smith(correlated=False, lambda_method=WALTER_2007)


def _isotropic_alpha(params) -> float:
    if "alpha" not in params:
        raise UsageError(
            f"bsdf: mitsuba_model needs isotropic roughness (alpha), got alpha_u = "
            f"{params['alpha_u'][0]:g}, alpha_v = {params['alpha_v'][0]:g}"
        )
    return max(float(params["alpha"][0]), float(np.float32(ALPHA_MIN)))


def _unit_factors(params, names) -> None:
    for key in names:
        factor = params.get(key, np.ones(1))
        if np.any(factor != 1.0):
            raise UsageError(f"bsdf: mitsuba_model has no {key} factor (got {factor.tolist()})")


def mitsuba_model(bsdf, channel: int = DEFAULT_CHANNEL):
    """microsim's closed form of the ``roughconductor`` or ``roughdielectric`` ``bsdf`` (its
    ``channel``), with Mitsuba's separable Smith G, G1(wi)G1(wo), and

    * ``distribution`` "ggx": ``GGX(α)`` and the exact Smith Λ (Mitsuba's G1 is exact);
    * "beckmann": ``Beckmann(α)`` (Mitsuba's α is the RMS slope, microsim's m) and the Λ of
      Walter et al. 2007's rational G1, eq. 27 (``lambda_method="walter2007"``), which is
      what Mitsuba evaluates;
    * α the plugin's float32 value, at least ``ALPHA_MIN``.

    ``roughconductor``: ``TorranceSparrow(ndf, Smith(correlated=False, ...), material)``, the
    material the plugin's (η, k) in that channel: η + ik, or None (a mirror, F = 1) for η = 0
    (material "none"). ``roughdielectric``: ``WalterDielectric(ndf, Smith(correlated=False,
    ...), eta)`` with η = int_ior/ext_ior, the plugin's float32 relative index (Mitsuba's
    interior is microsim's medium below; the default ext_ior is air's 1.000277, so η =
    1.5046/1.000277 unless both are given), in the radiance convention of Mitsuba's default
    ``TransportMode.Radiance``.

    Isotropic roughness only (alpha_u ≠ alpha_v: UsageError), no ``specular_reflectance`` or
    ``specular_transmittance`` factor other than 1, constant parameters only; other plugins:
    UsageError.
    """
    mi, _, loaded = _load(bsdf)
    channel = _channel(channel)
    kind = loaded.class_name()
    if kind not in ("RoughConductor", "RoughDielectric"):
        raise UsageError(
            f"bsdf: mitsuba_model knows Mitsuba's roughconductor and roughdielectric only, got "
            f"{kind}"
        )
    params = _parameters(mi, loaded)
    ndf, masking = _distribution(loaded, _isotropic_alpha(params))
    if kind == "RoughDielectric":
        _unit_factors(params, ("specular_reflectance", "specular_transmittance"))
        return WalterDielectric(ndf, masking, float(params["eta"][0]))
    _unit_factors(params, ("specular_reflectance",))

    def pick(values):
        return float(values[channel] if values.size == 3 else values[0])

    eta, k = pick(params["eta"]), pick(params["k"])
    if eta < 0.0 or k < 0.0:
        raise UsageError(f"bsdf: eta and k must be >= 0 for microsim's Fresnel, got {eta}, {k}")
    material = None if eta == 0.0 else complex(eta, k)
    return TorranceSparrow(ndf, masking, material)
