"""The full-wave rung: rigorous coupled-wave (RCW) efficiencies of 1D gratings, converged.

microsim does not solve Maxwell's equations itself: it drives NIST SCATMECH's rigorous
coupled-wave solver (``RCW_Model``, through the ``pySCATMECH`` package, the optional extra
``fullwave``: ``pip install 'microsim[fullwave]'``, built from source, ~3–5 min on one core).
RCW (Moharam & Gaylord's rigorous coupled-wave analysis) expands the fields in ``order``
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
"""

from __future__ import annotations

import os
import time
from contextlib import contextmanager

import numpy as np

from microsim.checks import integer, positive
from microsim.errors import EnvironmentFailure

from .gratings import Efficiencies, Grating, incident, order_directions

__all__ = ["available", "rcw_efficiencies", "converged_efficiencies", "SCATMECH_GRATINGS"]

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


def _model(grating: Grating, wavelength: float, theta_i_deg: float, order, levels, side):
    try:
        from pySCATMECH.rcw import RCW_Model
    except ImportError as e:
        raise EnvironmentFailure(
            f"the full-wave solver needs the `fullwave` extra: pip install 'microsim[fullwave]' "
            f"({e})"
        ) from None
    n = grating.index
    medium = f"({n.real!r},{n.imag!r})"
    params = {
        "lambda": wavelength,
        "grating.period": grating.period,
        "grating.amplitude": grating.amplitude,
        "grating.nlevels": levels,
        "grating.medium_t": medium,
        "grating.material": medium,
    }
    if grating.profile == "triangular":
        params["grating.aspect"] = 0.5
    return RCW_Model(
        grating=SCATMECH_GRATINGS[grating.profile],
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
    side, ``levels`` slices. ``side`` "reflection", or "transmission" (every order of the
    expansion, evanescent ones at 0; ``wo`` then holds only the tangential component x —
    the substrate's directions are not needed for the energy balance they serve)."""
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
    model = _model(grating, wavelength, theta_i_deg, order, levels, side)
    t0 = time.perf_counter()
    with _quiet():
        mueller = [np.asarray(model.DiffractionEfficiency(int(k)), dtype=np.float64) for k in m]
    seconds = time.perf_counter() - t0
    M = np.array(mueller).reshape(len(m), 4, 4)
    info = {"order": order, "levels": levels, "seconds": seconds, "side": side}
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
) -> Efficiencies:
    """RCW efficiencies raised until converged: from ``start`` = (order, levels), each step
    raises order by ×1.5 and levels by ×1.5 in turn; converged when, under both the last order
    raise and the last levels raise, no order's s or p efficiency changed by more than
    ``tol``. ``info["study"]``: every step's (order, levels, largest change, seconds);
    ``info["converged"]``: whether ``tol`` was met before ``limit``."""
    incident(theta_i_deg)
    tol = positive("tol", tol)
    order, levels = start
    study, prev = [], rcw_efficiencies(grating, wavelength, theta_i_deg, order, levels, side)
    study.append((order, levels, None, prev.info["seconds"]))
    quiet_steps, raise_order = 0, True
    while quiet_steps < 2:
        if raise_order:
            order = int(np.ceil(order * 1.5))
        else:
            levels = int(np.ceil(levels * 1.5))
        if order > limit[0] or levels > limit[1]:
            break
        cur = rcw_efficiencies(grating, wavelength, theta_i_deg, order, levels, side)
        change = _largest_change(prev, cur)
        study.append((order, levels, change, cur.info["seconds"]))
        quiet_steps = quiet_steps + 1 if change <= tol else 0
        prev, raise_order = cur, not raise_order
    info = {**prev.info, "study": study, "converged": quiet_steps >= 2, "tol": tol}
    return Efficiencies(prev.orders, prev.wo, prev.unpolarised, "rcw", prev.s, prev.p, info)


def _largest_change(a: Efficiencies, b: Efficiencies) -> float:
    """Largest |Δη| over the orders both hold, s and p."""
    common, ia, ib = np.intersect1d(a.orders, b.orders, return_indices=True)
    if not common.size:
        return float("inf")
    return float(max(np.max(np.abs(a.s[ia] - b.s[ib])), np.max(np.abs(a.p[ia] - b.p[ib]))))
