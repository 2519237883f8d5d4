"""The full-wave rung: rigorous coupled-wave (RCW) efficiencies of 1D gratings, converged.

microsim does not solve Maxwell's equations itself: it drives NIST SCATMECH's rigorous
coupled-wave solver (``RCW_Model``, through the ``pySCATMECH`` package, the optional extra
``fullwave``: ``pip install 'microsim[fullwave]'``, built from source, ~3–5 min on one core).
RCW (rigorous coupled-wave analysis, Moharam & Gaylord 1981) expands the fields in ``order``
diffraction orders each side of the specular one and slices the profile into ``levels``
lamellar layers; both are truncations, so every result here comes with its convergence
study (``converged_efficiencies``): order and levels are raised until no order's efficiency
changes by more than ``tol`` (default 10⁻³) under either raise.

SCATMECH's conventions, mapped to microsim's (``wave.gratings``): its order k leaves along
(sin θi − kλ/Λ, 0, cos θk) with the light coming from −x, i.e. microsim's order m = k with
x mirrored; ``DiffractionEfficiency(k)`` is a Mueller matrix M whose M00 is the unpolarised
efficiency and M00 + M01, M00 − M01 the s (TE) and p (TM) ones (identified against first-order
perturbation theory, whose s and p factors differ: tests/test_fullwave.py); ``type`` 0 gives
the reflected orders, 1 the transmitted ones. Materials as "(n,k)" strings; the incident
medium is vacuum. The solver prints progress on its standard streams, which are silenced.

A ``SampledGrating`` (the piecewise-linear profile through N samples) is SCATMECH's
``Generic_Grating``, read from a description file written to a temporary directory: its
vertices (x_j, h_j) with x mirrored as above (SCATMECH's vertex at x holds microsim's height at
−x), and one boundary per linear piece with vacuum (``medium_i``) above and the material
(``medium_t``) below. SCATMECH slices each band between two consecutive distinct heights into
lamellae in proportion to the horizontal distance the profile crosses there, at least one per
band, about ``levels`` in all: a profile of N distinct heights has at least N − 1 slices
(``info["slices"]`` states the number used). Order mapping and mirroring are checked on a
non-symmetric random profile against Kirchhoff order by order (tests/test_fullwave.py).
"""

from __future__ import annotations

import os
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from microsim.checks import integer, positive
from microsim.errors import EnvironmentFailure

from .gratings import Efficiencies, Grating, SampledGrating, incident, order_directions

__all__ = [
    "available",
    "rcw_efficiencies",
    "converged_efficiencies",
    "generic_grating_description",
    "SCATMECH_GRATINGS",
]

SCATMECH_GRATINGS = {"sinusoidal": "Sinusoidal_Relief_Grating", "triangular": "Triangular_Grating"}


def available() -> str | None:
    """None if pySCATMECH imports, else why not (for a test's skip reason)."""
    try:
        import pySCATMECH.rcw  # noqa: F401
    except ImportError as e:
        return f"needs the `fullwave` extra (pySCATMECH): {e}"
    return None


@contextmanager
def _quiet():
    """Silence file descriptors 1 and 2 (SCATMECH's progress output) while inside."""
    saved = [os.dup(1), os.dup(2)]
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (null, *saved):
            os.close(fd)


def generic_grating_description(grating: SampledGrating) -> str:
    """SCATMECH's ``Generic_Grating`` description of the profile, x mirrored (module
    docstring): vertex j at x = jΛ/N holds h_{(N−j) mod N}, j = 0 … N."""
    h = grating.h
    n = h.size
    x = np.arange(n + 1) * grating.period / n
    z = h[(n - np.arange(n + 1)) % n]
    vertices = [f"v{j} ({float(xj)!r},{float(zj)!r})" for j, (xj, zj) in enumerate(zip(x, z))]
    bounds = [f"v{j} v{j + 1} medium_i medium_t" for j in range(n)]
    lines = ["PARAMETERS", "unused", "END", "MATERIALS", "END", "VERTICES", *vertices, "END"]
    return "\n".join([*lines, "BOUNDARIES", *bounds, "END", ""])


@contextmanager
def _model(grating, wavelength: float, theta_i_deg: float, order, levels, side):
    """The configured ``RCW_Model`` (a ``Generic_Grating`` file lives while inside)."""
    try:
        from pySCATMECH.rcw import RCW_Model
    except ImportError as e:
        raise EnvironmentFailure(
            f"the full-wave solver needs the `fullwave` extra: pip install 'microsim[fullwave]' "
            f"({e})"
        ) from None
    n = grating.index
    medium = f"({n.real!r},{n.imag!r})"
    params = {"lambda": wavelength, "grating.period": grating.period, "grating.medium_t": medium}
    with tempfile.TemporaryDirectory(prefix="microsim-rcw-") as tmp:
        if isinstance(grating, SampledGrating):
            path = Path(tmp) / "profile.txt"
            path.write_text(generic_grating_description(grating), encoding="utf-8")
            name = "Generic_Grating"
            params.update({"grating.filename": str(path), "grating.pstring": "0",
                           "grating.nlayers": levels})  # fmt: skip
        else:
            name = SCATMECH_GRATINGS[grating.profile]
            params.update({"grating.amplitude": grating.amplitude, "grating.nlevels": levels,
                           "grating.material": medium})  # fmt: skip
            if grating.profile == "triangular":
                params["grating.aspect"] = 0.5
        yield RCW_Model(
            grating=name,
            order=order,
            type=0 if side == "reflection" else 1,
            thetai=float(theta_i_deg),
            **params,
        )


def rcw_efficiencies(
    grating: Grating,
    wavelength: float,
    theta_i_deg: float,
    order: int = 25,
    levels: int = 20,
    side: str = "reflection",
) -> Efficiencies:
    """RCW efficiencies of the propagating orders at one truncation: ``order`` orders each
    side, ``levels`` slices (about ``levels`` for a ``SampledGrating``: module docstring;
    ``info["slices"]`` the number used). ``side`` "reflection", or "transmission" (every
    order of the expansion, evanescent ones at 0; ``wo`` then holds only the tangential
    component x — the substrate's directions are not needed for the energy balance they
    serve)."""
    wavelength = positive("wavelength", wavelength)
    order = integer("order", order, 1, 400)
    levels = integer("levels", levels, 1, 2000)
    if side not in ("reflection", "transmission"):
        raise ValueError(f"side must be 'reflection' or 'transmission', got {side!r}")
    if side == "reflection":
        m, wo = order_directions(grating, wavelength, theta_i_deg)
        keep = np.abs(m) <= order
        m, wo = m[keep], wo[keep]
    else:  # every order the expansion holds: more propagate in a denser substrate
        m = np.arange(-order, order + 1)
        x = -incident(theta_i_deg)[0] + m * wavelength / grating.period
        wo = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    t0 = time.perf_counter()
    with _model(grating, wavelength, theta_i_deg, order, levels, side) as model, _quiet():
        mueller = [np.asarray(model.DiffractionEfficiency(int(k)), dtype=np.float64) for k in m]
        slices = len(model.getGratingDefinition()["thickness"])
    seconds = time.perf_counter() - t0
    M = np.array(mueller).reshape(len(m), 4, 4)
    info = {"order": order, "levels": levels, "slices": slices, "seconds": seconds, "side": side}
    return Efficiencies(
        m, wo, M[:, 0, 0], "rcw", M[:, 0, 0] + M[:, 0, 1], M[:, 0, 0] - M[:, 0, 1], info
    )


def converged_efficiencies(
    grating: Grating,
    wavelength: float,
    theta_i_deg: float,
    tol: float = 1e-3,
    start: tuple[int, int] = (15, 20),
    limit: tuple[int, int] = (160, 320),
    side: str = "reflection",
    polarisations: tuple = ("s", "p"),
) -> Efficiencies:
    """RCW efficiencies raised until converged: from ``start`` = (order, levels), each step
    raises order by ×1.5 and levels by ×1.5 in turn; converged when, under both the last order
    raise and the last levels raise, no order's s or p efficiency changed by more than
    ``tol`` (a ``SampledGrating`` starts at ≥ 2N levels, where every raise adds slices).
    ``info["study"]``: every step's (order, levels, slices, largest change, seconds);
    ``info["converged"]``: whether ``tol`` was met before ``limit``."""
    incident(theta_i_deg)
    tol = positive("tol", tol)
    order, levels = start
    if isinstance(grating, SampledGrating):  # below 2N a levels raise may not change a slice
        levels = max(levels, 2 * grating.h.size)
    study, prev = [], rcw_efficiencies(grating, wavelength, theta_i_deg, order, levels, side)
    study.append((order, levels, prev.info["slices"], None, prev.info["seconds"]))
    quiet_steps, raise_order = 0, True
    while quiet_steps < 2:
        if raise_order:
            order = int(np.ceil(order * 1.5))
        else:
            levels = int(np.ceil(levels * 1.5))
        if order > limit[0] or levels > limit[1]:
            break
        cur = rcw_efficiencies(grating, wavelength, theta_i_deg, order, levels, side)
        change = _largest_change(prev, cur, polarisations)
        study.append((order, levels, cur.info["slices"], change, cur.info["seconds"]))
        quiet_steps = quiet_steps + 1 if change <= tol else 0
        prev, raise_order = cur, not raise_order
    info = {**prev.info, "study": study, "converged": quiet_steps >= 2, "tol": tol,
            "polarisations": tuple(polarisations)}  # fmt: skip
    return Efficiencies(prev.orders, prev.wo, prev.unpolarised, "rcw", prev.s, prev.p, info)


def _largest_change(a: Efficiencies, b: Efficiencies, polarisations=("s", "p")) -> float:
    """Largest |Δη| over the orders both hold, in ``polarisations``."""
    common, ia, ib = np.intersect1d(a.orders, b.orders, return_indices=True)
    if not common.size:
        return float("inf")
    return float(max(np.max(np.abs(getattr(a, p)[ia] - getattr(b, p)[ib])) for p in polarisations))
