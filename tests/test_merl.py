"""The MERL BRDF format (microsim.measured.merl): layout, round trips, lookups, damaged files,
bin-averaged tables as fit references.

Interpolation errors are checked against their leading-order Taylor predictions, computed from
the closed form's own derivatives in the MERL index coordinates u = (90 √(θh/90°), θd/1°,
φd/1°) (module docstring of merl): with direction pairs drawn with density ∝ cos θi cos θo
(θ ≤ 80°: MERL cells below the horizon stay out of reach), the energy-weighted relative RMS
ε = √(Σ (f̂ − f)² / Σ f²) is predicted as
    reader      ε² Σf² = Σ_pairs Σ_u (∂f/∂u)²/12                (uniform offset in a cell)
    linear      ε² Σf² = Σ_pairs E[(Σ_u a_u t_u(1 − t_u))²],    a_u = ½ ∂²f/∂u²
    log-linear  the same with a_u = ½ f ∂²ln f/∂u²
with E[t²(1 − t)²] = 1/30 and E[t(1 − t)]² = 1/36 for independent uniform t. Terms of the
next order (relative size ~ cell width / lobe width) are not in the prediction: the measured
ε must lie within 25% of it.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from microsim import vectors
from microsim.analysis import fits
from microsim.analytic import GGX, Beckmann
from microsim.analytic.masking import Smith
from microsim.analytic.models import CookTorrance, TorranceSparrow
from microsim.errors import UsageError
from microsim.measured.merl import (
    EXACT_COUNT,
    LOW2012_THETA_I,
    LUMINANCE,
    MERL_FILE_BYTES,
    MERL_SAMPLES,
    MERL_SCALE,
    MERLBRDF,
    from_rusinkiewicz_rad,
    low2012_result,
    read_merl,
    result_of_table,
    rusinkiewicz_rad,
    sample_angles_rad,
    write_merl,
)
from microsim.measured.rgl import read_rgl, write_rgl
from microsim.measured.table import BRDFTable
from microsim.sim import Bins
from microsim.sim.predict import Predictor, predict

GGX_AL = TorranceSparrow(GGX(0.3), Smith(correlated=True), "aluminium")
BECKMANN_GLASS = TorranceSparrow(Beckmann(0.2), Smith(correlated=True), 1.5)
TOLERANCE = 0.25  # measured / predicted interpolation RMS within 1 ± this (module docstring)


def _grid():
    """wi, wo (90, 90, 180, 3) at the sample centres and the above-horizon mask."""
    th, td, pd = sample_angles_rad()
    wi, wo = from_rusinkiewicz_rad(th[:, None, None], td[None, :, None], pd[None, None, :])
    return wi, wo, (wi[..., 2] > 1e-9) & (wo[..., 2] > 1e-9)


def _cosine_pairs(n: int, seed: int, theta_max: float = 80.0):
    """n pairs (wi, wo), each drawn with density ∝ cos θ on θ ≤ theta_max."""
    rng = np.random.default_rng(seed)

    def draw():
        s = np.sqrt(rng.random(n) * np.sin(np.radians(theta_max)) ** 2)
        phi = 2 * np.pi * rng.random(n)
        return np.stack([s * np.cos(phi), s * np.sin(phi), np.sqrt(1 - s * s)], axis=-1)

    return draw(), draw()


def _index_coords(wi, wo):
    th, td, pd = rusinkiewicz_rad(wi, wo)
    return np.stack(
        [90 * np.sqrt(th / (np.pi / 2)), td / (np.pi / 2) * 90, np.mod(pd, np.pi) / np.pi * 180],
        axis=-1,
    )


def _at_index(f, u):
    th = (u[..., 0] / 90) ** 2 * (np.pi / 2)
    return f(*from_rusinkiewicz_rad(th, u[..., 1] / 90 * (np.pi / 2), u[..., 2] / 180 * np.pi))


def _predicted(f, wi, wo, h: float = 0.25) -> dict:
    """Leading-order ε of each lookup (module docstring) from central differences, step h."""
    u = _index_coords(wi, wo)
    fc = _at_index(f, u)
    grad, d2, l2 = (np.empty(u.shape) for _ in range(3))
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        fp, fm = _at_index(f, u + e), _at_index(f, u - e)
        grad[:, j] = (fp - fm) / (2 * h)
        d2[:, j] = (fp - 2 * fc + fm) / h**2
        l2[:, j] = (np.log(fp) - 2 * np.log(fc) + np.log(fm)) / h**2

    def second(a):
        return np.sum(a**2, 1) / 30 + (np.sum(a, 1) ** 2 - np.sum(a**2, 1)) / 36

    den = np.sum(fc**2)
    return {
        "reader": np.sqrt(np.sum(grad**2) / 12 / den),
        "linear": np.sqrt(np.sum(second(0.5 * d2)) / den),
        "log-linear": np.sqrt(np.sum(fc**2 * second(0.5 * l2)) / den),
    }


def _rms(a, b) -> float:
    return float(np.sqrt(np.sum((a - b) ** 2) / np.sum(b**2)))


@pytest.fixture(scope="module")
def ggx_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("merl") / "ggx.binary"
    write_merl(path, GGX_AL.f)
    return path


# --- layout --------------------------------------------------------------------------------------
def test_file_size_header_scales_and_horizon(tmp_path):
    path = tmp_path / "grey.binary"
    write_merl(path, lambda wi, wo: np.full(wi.shape[:-1], 0.5 / np.pi))
    raw = path.read_bytes()
    assert len(raw) == MERL_FILE_BYTES == 12 + 3 * 8 * 90 * 90 * 180
    assert tuple(np.frombuffer(raw[:12], "<i4")) == (90, 90, 180)
    values = np.frombuffer(raw[12:], "<f8").reshape(3, MERL_SAMPLES)
    _, _, up = _grid()
    for c, scale in enumerate(MERL_SCALE):  # stored = BRDF / scale (read: raw × scale)
        np.testing.assert_allclose(values[c, up.ravel()], 0.5 / np.pi / scale, rtol=1e-15)
        assert np.all(values[c, ~up.ravel()] == -1.0)
    assert MERL_SCALE == (1 / 1500, 1.15 / 1500, 1.66 / 1500)


def test_coordinates_identities_and_reader_layout(tmp_path):
    wi, wo = _cosine_pairs(1000, seed=3)
    th, td, pd = rusinkiewicz_rad(wi, wo)
    h = vectors.half_vector(wi, wo)
    np.testing.assert_allclose(np.cos(2 * td), np.sum(wi * wo, -1), atol=1e-12)
    np.testing.assert_allclose(np.cos(th), h[:, 2], atol=1e-12)
    # the inverse map, up to the φh the isotropic coordinates drop
    a, b = from_rusinkiewicz_rad(th, td, pd)
    for x, y in zip(rusinkiewicz_rad(a, b), (th, td, pd)):
        np.testing.assert_allclose(x, y, atol=1e-10)
    # mirror pair: θh = 0, θd = θi
    th0, td0, _ = rusinkiewicz_rad(vectors.spherical_deg(30, 20), vectors.spherical_deg(30, 200))
    assert abs(th0) < 1e-12 and abs(np.degrees(td0) - 30) < 1e-12

    # a file whose raw value is its own index (BRDFRead.cpp: ind = k + 180 j + 180·90 i,
    # green at ind + 90·90·180, blue at ind + 2·90·90·180), read at cell centres
    raw = np.arange(3 * MERL_SAMPLES, dtype="<f8")
    path = tmp_path / "index.binary"
    path.write_bytes(np.array([90, 90, 180], "<i4").tobytes() + raw.tobytes())
    brdf = read_merl(path)
    i, j, k = np.array([0, 7, 40, 89]), np.array([3, 30, 60, 1]), np.array([0, 90, 179, 45])
    ths, tds, pds = sample_angles_rad()
    a, b = from_rusinkiewicz_rad(ths[i], tds[j], pds[k])
    ok = (a[:, 2] > 0) & (b[:, 2] > 0)
    ind = k + 180 * j + 180 * 90 * i
    expect = np.stack([(ind + c * MERL_SAMPLES) * MERL_SCALE[c] for c in range(3)], -1)
    np.testing.assert_allclose(brdf.rgb(a, b)[ok], expect[ok], rtol=1e-15)
    # reciprocity: swapping wi and wo moves φd by π, which the reader folds onto the same cell
    assert np.array_equal(brdf.evaluate(wi, wo), brdf.evaluate(wo, wi))


# --- closed forms: grid points and interpolation -------------------------------------------------
@pytest.mark.parametrize("model", [GGX_AL, BECKMANN_GLASS], ids=["ggx-0.3-al", "beckmann-0.2"])
def test_closed_form_round_trip(model, tmp_path):
    path = tmp_path / "model.binary"
    write_merl(path, model.f)
    brdf = read_merl(path)
    wi, wo, up = _grid()
    f = model.f(wi[up], wo[up])
    for c in range(3):  # ½[f(wi, wo) + f(wo, wi)], × 1/scale, × scale: a few roundings
        np.testing.assert_allclose(brdf.values[c][up], f, rtol=1e-13)
    assert np.array_equal(brdf.valid, up)
    assert np.array_equal(brdf.evaluate(wi[up], wo[up]), brdf.samples()[up])
    # off the grid: each lookup's error as its leading-order prediction says
    a, b = _cosine_pairs(20000, seed=1)
    exact = model.f(a, b)
    predicted = _predicted(model.f, a, b)
    for lookup, pred in predicted.items():
        measured = _rms(brdf.with_options(lookup=lookup).evaluate(a, b), exact)
        print(f"\nMERL {lookup} lookup: {100 * measured:.3g} % (predicted {100 * pred:.3g} %)")
        assert abs(measured / pred - 1) < TOLERANCE, (lookup, measured, pred)


def test_colour_channels_and_luminance(ggx_file, tmp_path):
    rgb = np.array([0.9, 0.5, 0.2])
    path = tmp_path / "colour.binary"
    write_merl(path, GGX_AL.f, rgb=rgb)
    grey, colour = read_merl(ggx_file), read_merl(path)
    assert np.array_equal(colour.valid, grey.valid)
    for c in range(3):
        v = grey.values[0][grey.valid]
        np.testing.assert_allclose(colour.values[c][colour.valid], rgb[c] * v, rtol=1e-14)
    wi, wo = _cosine_pairs(2000, seed=5)
    f = grey.evaluate(wi, wo)
    np.testing.assert_allclose(colour.with_options(channel="green")(wi, wo), 0.5 * f, rtol=1e-14)
    np.testing.assert_allclose(colour.evaluate(wi, wo), np.dot(LUMINANCE, rgb) * f, rtol=1e-14)
    np.testing.assert_allclose(colour.rgb(wi, wo), f[:, None] * rgb, rtol=1e-14)
    # an RGB callable (a MERL BRDF's own channels at its sample centres) writes the same file
    again = tmp_path / "again.binary"
    write_merl(again, colour.rgb)
    np.testing.assert_allclose(read_merl(again).values, colour.values, rtol=1e-15)


# --- damaged and foreign files, failed writes -----------------------------------------------------
@pytest.mark.parametrize(
    "damage, words",
    [
        (lambda b: b[:-8], "truncated"),
        (lambda b: b[:12], "truncated"),
        (lambda b: b[:7], "12-byte header"),
        (lambda b: b + b"\0" * 8, "trailing data"),
        (lambda b: np.array([90, 90, 90], "<i4").tobytes() + b[12:], "(90, 90, 90)"),
        (lambda b: np.array([90, 90, 180], ">i4").tobytes() + b[12:], "big-endian"),
        (lambda b: b[:100] + np.array([np.nan]).tobytes() + b[108:], "NaN"),
    ],
    ids=["short", "header-only", "no-header", "trailing", "dims", "big-endian", "nan"],
)
def test_damaged_file_names_the_file(ggx_file, tmp_path, damage, words):
    bad = tmp_path / "bad.binary"
    bad.write_bytes(damage(ggx_file.read_bytes()))
    with pytest.raises(UsageError, match=str(bad)) as err:
        read_merl(bad)
    assert words in str(err.value)
    with pytest.raises(UsageError, match="no such MERL file"):
        read_merl(tmp_path / "missing.binary")


def test_failed_write_leaves_nothing(ggx_file, tmp_path):
    before = ggx_file.read_bytes()

    def broken(wi, wo):
        f = GGX_AL.f(wi, wo)
        f[0] = np.nan
        return f

    with pytest.raises(UsageError, match="finite"):
        write_merl(ggx_file, broken)
    with pytest.raises(UsageError, match="shape"):
        write_merl(tmp_path / "new.binary", lambda wi, wo: np.zeros(3))
    with pytest.raises(UsageError, match="rgb"):
        write_merl(tmp_path / "new.binary", GGX_AL.f, rgb=(1, -1, 1))
    assert ggx_file.read_bytes() == before
    assert os.listdir(tmp_path) == []
    assert [p for p in os.listdir(ggx_file.parent) if p.endswith(".tmp")] == []


def test_invalid_samples_read_as_no_data(ggx_file):
    brdf = read_merl(ggx_file)
    values = np.array(brdf.values)
    values[:, 20:30, 10:20, :] = -1.0  # a hole in the lobe (θh 4.5°–10.1°, θd 10°–20°)
    holed = MERLBRDF(values)
    ths, tds, pds = sample_angles_rad()
    wi, wo = from_rusinkiewicz_rad(ths[25], tds[15], pds[40])
    assert holed.evaluate(wi, wo) == 0.0 and brdf.evaluate(wi, wo) > 0
    bins = Bins(18, 19)
    full, table = brdf.table([15.0], bins), holed.table([15.0], bins)
    hole = table.brdf == 0
    assert hole.any() and not (full.brdf == 0)[:, :16].any()
    # elsewhere the same bin averages, each within the quadrature's rtol = 1e-3
    np.testing.assert_allclose(table.brdf[~hole], full.brdf[~hole], rtol=2e-3)
    result = result_of_table(table, theta_max=80.0)
    used = fits.FitData.from_result(result).used
    keep = bins.theta_edges[1:] <= 80.0
    assert np.array_equal(used, (table.brdf > 0) & keep[None, :, None])
    assert np.all(result.counts[used] == EXACT_COUNT) and np.all(result.counts[~used] == 0)


# --- fits and tables ------------------------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["merl", "rgl"])
def test_fit_recovers_cook_torrance(tmp_path, fmt):
    """Löw's E2 fit of ``cook-torrance`` to a MERL (or RGL) file of that closed form recovers
    its parameters (the RGL file warped by its Beckmann NDF with a 5 % Lambertian floor, which
    its diffuse term needs) within the shift the data's deviation δg (from the fit model's own
    bin averages at the true parameters) can cause to first order: δp = (JᵀWJ)⁻¹JᵀW δg, bounded by
    |δp_k| ≤ √([(JᵀWJ)⁻¹]_kk · Σ W δg²) (Cauchy–Schwarz), J = ∂g/∂p, W Löw's weights (eq. 33).
    """
    true = {"ks": 0.8, "m": 0.25, "kd": 0.05}
    model = CookTorrance(Beckmann(true["m"]), "aluminium", ks=true["ks"], kd=true["kd"])
    if fmt == "merl":
        write_merl(tmp_path / "ct.binary", model.f)
        reader = read_merl(tmp_path / "ct.binary")
    else:
        write_rgl(tmp_path / "ct.bsdf", model.f, Beckmann(true["m"]), floor=0.05)
        reader = read_rgl(tmp_path / "ct.bsdf")
    bins = Bins(18, 37)
    result = low2012_result(reader, bins=bins)
    fit = fits.fit_all(result, "aluminium", names=("cook-torrance",), quick=True)["cook-torrance"]
    assert fit.converged

    data = fits.FitData.from_result(result)
    used = data.used
    ti, to, dti, dto, dpo = np.broadcast_arrays(*data.geometry(), data.sim)[:5]
    weight = np.radians(dti) * np.radians(dto) * np.radians(dpo) * np.sin(np.radians(to))
    cos_i = np.cos(np.radians(ti))
    fit_model = fits.FIT_MODELS["cook-torrance"]

    def g(params):  # the fit's own bin averages (3 × 3 rule), as ln(1 + cos θi f̄)
        fn = fit_model.make(params, "aluminium")
        rows = []
        for t in LOW2012_THETA_I:
            wi = vectors.spherical_deg(t, 0.0)
            rows.append(fits.bin_rule(bins, wi, 3, 0.0).average(fn, wi))
        return np.log1p(cos_i * np.stack(rows))[used]

    names = fit_model.names
    J = []
    for k in names:
        step = 1e-4 * true[k]
        J.append((g({**true, k: true[k] + step}) - g({**true, k: true[k] - step})) / (2 * step))
    J, W = np.stack(J, axis=1), weight[used]
    dg = np.log1p(cos_i * data.sim)[used] - g(true)
    cov = np.linalg.inv(J.T @ (W[:, None] * J))
    shift = cov @ (J.T @ (W * dg))
    bound = np.sqrt(np.diag(cov) * np.sum(W * dg**2))
    for k, name in enumerate(names):
        error = fit.params[name] - true[name]
        assert abs(error) <= bound[k], (name, error, bound[k])
        assert abs(error - shift[k]) <= 0.1 * bound[k], (name, error, shift[k])  # linear regime


def test_table_round_trip(tmp_path):
    """A BRDFTable written to MERL holds, at every sample centre, its reciprocal average
    ½[T(wi, wo) + T(wo, wi)] (the format stores one value for both orders); read back, it
    agrees with that average within the lookups' interpolation errors."""
    bins = Bins(30, 31)
    theta = np.arange(0.0, 90.0, 10.0)
    values = predict([Predictor("ggx", GGX_AL)], theta, bins)["ggx"]
    table = BRDFTable(theta, bins, values, np.zeros_like(values), "ggx")
    path = tmp_path / "table.binary"
    write_merl(path, table)
    brdf = read_merl(path)
    wi, wo, up = _grid()
    a, b = wi[up], wo[up]
    np.testing.assert_allclose(brdf.samples()[up], 0.5 * (table(a, b) + table(b, a)), rtol=1e-13)

    def symmetric(x, y):
        return 0.5 * (table(x, y) + table(y, x))

    a, b = _cosine_pairs(20000, seed=2)
    pred = _predicted(symmetric, a, b)
    reader = _rms(brdf.evaluate(a, b), symmetric(a, b))
    assert abs(reader / pred["reader"] - 1) < TOLERANCE, (reader, pred["reader"])
    # the table is log-linear between bin centres: its kinks make the finite-difference
    # second derivatives larger than the curvature inside a MERL cell, so the second-order
    # prediction is an upper bound here
    smooth = _rms(brdf.with_options(lookup="log-linear").evaluate(a, b), symmetric(a, b))
    assert smooth < (1 + TOLERANCE) * pred["log-linear"], (smooth, pred["log-linear"])


def test_bad_arguments(ggx_file):
    brdf = read_merl(ggx_file)
    with pytest.raises(UsageError, match="channel"):
        brdf.with_options(channel="alpha")
    with pytest.raises(UsageError, match="lookup"):
        read_merl(ggx_file, lookup="cubic")
    with pytest.raises(UsageError, match="bins"):
        brdf.table([0.0], Bins(10, 20, folded=False))
    with pytest.raises(UsageError, match="table"):
        result_of_table(brdf)
    table = brdf.table([0.0], Bins(9, 10))
    with pytest.raises(UsageError, match="theta_max"):
        result_of_table(table, theta_max=5.0)
    with pytest.raises(UsageError, match="brdf"):
        write_merl(ggx_file.parent / "x.binary", "not callable")


def test_a_table_bin_without_events_is_not_averaged_into_its_reciprocal_partner(tmp_path):
    """A constant table (1/π) with the pole bins empty at the largest incidence: pairs whose
    reversed order is interpolated from an empty bin are not ``resolved``, and the MERL file
    holds the measured order there (1/π, not half of it); elsewhere the usual average."""
    bins, theta = Bins(18, 7), np.array([0.0, 30.0, 60.0])
    values = np.full((3, bins.n_theta, bins.n_phi), 1 / np.pi)
    values[2, 0, :] = 0.0  # θi 60°, θo in the first (pole) bin: no events
    table = BRDFTable(theta, bins, values, np.zeros_like(values), "constant")
    wi, wo = vectors.spherical_deg(0.0, 0.0), vectors.spherical_deg(55.0, 0.0)
    assert table.resolved(wi, wo) and not table.resolved(wo, wi)
    assert table.evaluate(wo, wi) < 0.5 / np.pi  # pulled towards 0 by the empty bin
    path = tmp_path / "t.binary"
    write_merl(path, table)
    back = read_merl(path, lookup="reader")
    assert np.isclose(back.evaluate(wi[None], wo[None])[0], 1 / np.pi, rtol=1e-3)
    wi2, wo2 = vectors.spherical_deg(20.0, 0.0), vectors.spherical_deg(30.0, 180.0)
    assert table.resolved(wi2, wo2) and table.resolved(wo2, wi2)
    assert np.isclose(back.evaluate(wi2[None], wo2[None])[0], 1 / np.pi, rtol=1e-3)
