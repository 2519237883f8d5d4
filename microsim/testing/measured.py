"""Judging a BRDF against a measured one: a MERL ``.binary`` or RGL ``.bsdf`` file, a
microsim table (``microsim measure``'s ``table.npz``, a ``BRDFTable``) or any tabulated BRDF.

``assert_brdf_matches_measured(brdf, reference, theta_i, bins=..., rtol=0.05)`` bin-averages
the callable on the bins (``sim.predict``, both ±Δφ halves unless ``symmetric=True``) and takes
the reference's own bin averages — a ``BRDFTable`` on the same bins and incidences as they are,
a MERL file through ``MERLBRDF.table`` (its quadrature of the log-linear interpolant), any other
table evaluated and averaged likewise. Measured references carry no noise model a statistical
test could use (MERL files have none; a microsim table's standard errors are per bin but its
surface's departure from an ensemble is unknown), so the test is a tolerance: at every
incidence the energy-weighted relative RMS of (reference − brdf)/reference over the bins
carrying 90 % of the reference's energy (``stats.energy_set``) must be ≤ ``rtol``. Bins where
the reference holds no data (0: bins touching MERL's invalid samples, empty table bins) are
left out, and the number of bins compared at each incidence is returned and printed. An
incidence at which the reference holds no data at all is refused (a ``UsageError``, never a
pass on nothing compared), as is a MERL file without a single valid sample (``read_merl``).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from microsim.bins import Bins
from microsim.errors import UsageError
from microsim.measured import MERLBRDF, BRDFTable, read_merl, read_rgl
from microsim.sim.predict import FunctionBRDF, Predictor, predict
from microsim.stats import energy_set

from .agreement import BRDFMismatch, readable_name, symmetric_keyword, wrap_brdf

__all__ = ["assert_brdf_matches_measured", "measured_reference"]

QUAD_RTOL = 1e-3


def measured_reference(reference, theta_i, bins: Bins) -> BRDFTable:
    """The reference's bin averages (``BRDFTable``) at ``theta_i`` on ``bins``: a path
    (.binary: MERL; .bsdf: RGL; .npz: ``BRDFTable.load``), a ``MERLBRDF``, a ``BRDFTable``
    (its own values when its bins and incidences are these, else its evaluation averaged) or a
    callable f(wi, wo)."""
    theta = np.atleast_1d(np.asarray(theta_i, dtype=np.float64))
    if isinstance(reference, (str, os.PathLike)):
        path = Path(reference)
        if path.suffix == ".binary":
            reference = read_merl(path)
        elif path.suffix == ".npz":
            reference = BRDFTable.load(path)
        elif path.suffix == ".bsdf":
            reference = read_rgl(path).f
        else:
            raise UsageError(
                f"reference must be a MERL .binary file, an RGL .bsdf file or a microsim table "
                f".npz, got {path}"
            )
    if isinstance(reference, MERLBRDF):
        return reference.table(theta, bins)
    if isinstance(reference, BRDFTable):
        same = reference.bins == bins and np.array_equal(reference.theta_i, theta)
        if same:
            return reference
        fn, name = reference.f, reference.name
    elif callable(reference):
        fn, name = reference, readable_name(reference)
    else:
        raise UsageError(
            f"reference must be a file, a BRDFTable, a MERLBRDF or a callable, got {reference!r}"
        )
    spec = Predictor("reference", FunctionBRDF(wrap_brdf(fn), symmetric=True))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        values = predict([spec], theta, bins, rtol=QUAD_RTOL)["reference"]
    return BRDFTable(theta, bins, values, np.zeros_like(values), name)


def assert_brdf_matches_measured(
    brdf,
    reference,
    theta_i=(0, 20, 40, 60, 80),
    *,
    bins=(18, 37),
    rtol: float = 0.05,
    symmetric: bool = False,
    name: str | None = None,
    isotropic: bool | None = None,
) -> dict:
    """Assert that ``brdf(wi, wo)`` ((N, 3) unit vectors away from the surface, wi in the x–z
    plane; N values in sr⁻¹) matches the measured ``reference`` within ``rtol`` at every
    incidence (module docstring). ``bins``: (n_theta, n_phi) or folded ``Bins``. Returns
    {"rel_rms": [per θi], "energy_ratio": [brdf/reference per θi], "bins_compared": [the
    number of bins in the relative RMS per θi]}; raises ``BRDFMismatch`` naming the failing
    incidences, a ``UsageError`` naming the incidences where the reference holds no data."""
    __tracebackhide__ = True
    if not callable(brdf):
        raise UsageError(f"brdf must be a callable f(wi, wo) -> sr⁻¹, got {brdf!r}")
    symmetric = symmetric_keyword(symmetric, isotropic)
    if isinstance(rtol, bool) or not isinstance(rtol, (int, float)) or not 0 < rtol < 1:
        raise UsageError(f"rtol must be a relative error in (0, 1), got {rtol!r}")
    b = bins if isinstance(bins, Bins) else Bins(*bins)
    if not b.folded:
        raise UsageError("bins must be folded: measured tables are of isotropic BRDFs")
    theta = np.atleast_1d(np.asarray(theta_i, dtype=np.float64))
    if theta.ndim != 1 or not np.all((theta >= 0) & (theta < 90)) or np.any(np.diff(theta) <= 0):
        raise UsageError(f"theta_i must be increasing incidences in [0°, 90°), got {theta_i!r}")
    ref = measured_reference(reference, theta, b)
    empty = [t for t in range(len(theta)) if not np.any(ref.brdf[t] > 0)]
    if empty:
        raise UsageError(
            f"reference {ref.name!r} holds no measured data at θi = "
            + ", ".join(f"{theta[t]:g}°" for t in empty)
            + " (every bin 0: no valid samples there), so there is nothing to compare; "
            "leave those incidences out of theta_i"
        )
    name = name or readable_name(brdf)
    spec = Predictor("brdf", FunctionBRDF(wrap_brdf(brdf), symmetric=symmetric))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mine = predict([spec], theta, b, rtol=QUAD_RTOL)["brdf"]
    omega = b.projected_solid_angle()
    rel_rms, ratio, compared = [], [], []
    for t in range(len(theta)):
        r = ref.brdf[t]
        has = r > 0
        w = np.where(has, r * omega, 0.0)
        E = energy_set(w).reshape(r.shape)
        rel = (r[E] - mine[t][E]) / r[E]
        rel_rms.append(float(np.sqrt(np.sum(w[E] * rel**2) / np.sum(w[E]))))
        ratio.append(float(np.sum(mine[t][has] * omega[has]) / np.sum(w)))
        compared.append(int(np.count_nonzero(E)))
    out = {"rel_rms": rel_rms, "energy_ratio": ratio, "bins_compared": compared}
    failing = [t for t in range(len(theta)) if rel_rms[t] > rtol]
    if not failing:
        return out
    lines = [
        f"brdf {name!r} does not match the measured reference {ref.name!r} within rtol = "
        f"{rtol:g} at θi = " + ", ".join(f"{theta[t]:g}°" for t in failing),
        f"  (bin averages {b.n_theta} × {b.n_phi}; energy-weighted relative RMS of "
        "(reference − brdf)/reference over the reference's 90 % energy bins)",
        "  θi     rel RMS   energy ratio brdf/reference   bins compared",
    ]
    lines += [
        f"  {theta[t]:>4g}°  {100 * rel_rms[t]:6.2f} %   {ratio[t]:<28.4f} {compared[t]}"
        for t in range(len(theta))
    ]
    raise BRDFMismatch("\n".join(lines), out)
