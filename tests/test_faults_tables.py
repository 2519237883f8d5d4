"""Fault corpus of the measured-BRDF tables and files (``microsim.measured``) and of the check
against them (``microsim.testing.assert_brdf_matches_measured``): a file that is not a table
``BRDFTable.save`` wrote, a MERL file without measured samples and an RGL file with negative
values are refused in one line naming the file (and the field); a result of an anisotropic
surface is not made into an isotropic table; the comparison never passes on nothing compared
and says how many bins it judged."""

import dataclasses

import numpy as np
import pytest
from support import refused

from microsim.analytic import GGX, Beckmann, Smith, TorranceSparrow
from microsim.measured import MERLBRDF, BRDFTable, read_merl, read_rgl, write_merl, write_rgl
from microsim.measured.merl import MERL_SAMPLES, MERL_SHAPE
from microsim.measured.rgl import RGLResolution, read_tensor_file, tensor_file_bytes
from microsim.sim import Bins, Result, simulate
from microsim.surfaces import vgrooves
from microsim.testing import assert_brdf_matches_measured

GGX_AL = TorranceSparrow(GGX(0.3), Smith(correlated=True), "aluminium")
BINS = Bins(9, 10)


# --- BRDFTable.load ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def table_file(tmp_path_factory):
    table = BRDFTable.from_function(GGX_AL.f, [0.0, 30.0], BINS, "ggx")
    path = tmp_path_factory.mktemp("table") / "table.npz"
    table.save(path)
    return path


def _with_scalar_bins(good, bad):
    with np.load(good) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["bins"] = np.array(9)
    with open(bad, "wb") as fh:
        np.savez(fh, **arrays)


@pytest.mark.parametrize(
    "name, damage, words",
    [
        ("x.npy", lambda good, bad: np.save(bad, np.ones(3)), ["single array"]),
        ("scalar.npz", _with_scalar_bins, ["bins", "two integers"]),
        ("half.npz", lambda good, bad: bad.write_bytes(good.read_bytes()[:1000]), ["not a"]),
    ],
    ids=["npy", "scalar-bins", "truncated"],
)
def test_a_file_that_is_no_table_is_refused_naming_it(table_file, tmp_path, name, damage, words):
    bad = tmp_path / name
    damage(table_file, bad)
    refused(lambda: BRDFTable.load(bad), str(bad), *words)
    assert BRDFTable.load(table_file).name == "ggx"


# --- BRDFTable.from_result of an anisotropic surface ---------------------------------------------
def test_a_traced_result_of_oriented_grooves_is_no_isotropic_table():
    oriented = simulate(
        vgrooves(200, Beckmann(0.3), oriented=True), "aluminium", [0, 30], rays=20_000, bins=BINS
    )
    assert oriented.bins.folded and not np.any(oriented.phi_i)  # what the folded check passes
    refused(lambda: BRDFTable.from_result(oriented), "anisotropic", "incidence azimuth")
    cavity = simulate(vgrooves(200, Beckmann(0.3)), "aluminium", [0, 30], rays=20_000, bins=BINS)
    assert BRDFTable.from_result(cavity).brdf.shape == (2,) + BINS.shape


@pytest.mark.parametrize(
    "surface",
    [
        {"kind": "gaussian", "nominal": {"sigma": 0.01, "corr_len": 0.1, "corr_len_y": 0.2}},
        {"kind": "abc", "nominal": {"sigma": 0.01, "B": 10.0, "B_y": 20.0, "C": 2.0}},
        {"kind": "grating", "nominal": {"amplitude": 0.1, "period": 1.0}},
        {"kind": "gaussian", "sigma": 0.01, "corr_len": 0.1, "corr_len_y": 0.2},  # a wave run
    ],
    ids=["gaussian", "abc", "grating", "wave-run"],
)
def test_a_result_recording_an_anisotropic_surface_is_refused(surface):
    table = BRDFTable.from_function(GGX_AL.f, [0.0, 30.0], BINS)
    result = Result(
        theta_i=np.array(table.theta_i),
        phi_i=np.zeros(2),
        bins=BINS,
        brdf=np.array(table.brdf),
        stderr=np.array(table.stderr),
        meta={"surface": surface},
    )
    refused(lambda: BRDFTable.from_result(result), "anisotropic", surface["kind"])
    isotropic = dataclasses.replace(result, meta={"surface": {"kind": "gaussian", "nominal": {}}})
    assert np.array_equal(BRDFTable.from_result(isotropic).brdf, table.brdf)


# --- MERL files without data, the comparison's usable bins ------------------------------------
@pytest.fixture(scope="module")
def merl_files(tmp_path_factory):
    """(a GGX file, the same with a hole of invalid samples in its lobe, a file of −1 only)."""
    d = tmp_path_factory.mktemp("merl")
    good = d / "ggx.binary"
    write_merl(good, GGX_AL.f)
    data = good.read_bytes()
    raw = np.frombuffer(data, dtype="<f8", offset=12).reshape((3,) + MERL_SHAPE).copy()
    raw[:, 20:30, 10:20, :] = -1.0  # θh 4.5°–10.1°, θd 10°–20°
    holed = d / "holed.binary"
    holed.write_bytes(data[:12] + raw.astype("<f8").tobytes())
    empty = d / "empty.binary"
    empty.write_bytes(data[:12] + np.full(3 * MERL_SAMPLES, -1.0, "<f8").tobytes())
    return good, holed, empty


def test_a_merl_file_of_no_data_markers_is_refused(merl_files):
    _, _, empty = merl_files
    refused(lambda: read_merl(empty), str(empty), "no measured samples")
    refused(lambda: assert_brdf_matches_measured(GGX_AL.f, empty), "no measured samples")


def test_a_reference_without_data_at_an_incidence_is_refused_not_passed():
    nothing = MERLBRDF(np.full((3,) + MERL_SHAPE, -1.0))
    refused(
        lambda: assert_brdf_matches_measured(GGX_AL.f, nothing, [0, 30], bins=BINS),
        "no measured data", "0°, 30°",
    )  # fmt: skip
    table = BRDFTable.from_function(GGX_AL.f, [0.0, 30.0], BINS)
    brdf = np.array(table.brdf)
    brdf[1] = 0.0
    half = BRDFTable(table.theta_i, BINS, brdf, table.stderr)
    refused(
        lambda: assert_brdf_matches_measured(GGX_AL.f, half, [0, 30], bins=BINS),
        "no measured data", "30°",
    )  # fmt: skip


def test_invalid_merl_samples_are_left_out_and_the_bins_compared_counted(merl_files):
    good, holed, _ = merl_files
    kw = dict(theta_i=[15.0], bins=Bins(18, 19), rtol=0.05)
    full = assert_brdf_matches_measured(GGX_AL.f, good, **kw)
    part = assert_brdf_matches_measured(GGX_AL.f, holed, **kw)
    assert 0 < part["bins_compared"][0] < full["bins_compared"][0]
    assert max(part["rel_rms"]) < 0.05


# --- RGL files with negative values -------------------------------------------------------------
@pytest.fixture(scope="module")
def rgl_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("rgl") / "ggx.bsdf"
    res = RGLResolution(theta_i=8, vndf=(16, 16), samples=16, ndf=64)
    write_rgl(path, GGX_AL.f, GGX(0.3), resolution=res)
    return path


@pytest.mark.parametrize(
    "field, value, words",
    [
        ("rgb", -1.0, ["negative", ">= 0"]),
        ("luminance", -1.0, ["negative", ">= 0"]),
        ("ndf", -1.0, ["negative", ">= 0"]),
        ("sigma", -1.0, ["negative", ">= 0"]),
        ("vndf", -1.0, ["negative", ">= 0"]),
        ("rgb", np.inf, ["infinite"]),
        ("rgb", np.nan, ["NaN"]),
    ],
    ids=["rgb", "luminance", "ndf", "sigma", "vndf", "rgb-inf", "rgb-nan"],
)
def test_rgl_values_that_are_no_brdf_are_refused_naming_file_and_field(
    rgl_file, tmp_path, field, value, words
):
    fields = read_tensor_file(rgl_file)
    a = fields[field].copy()
    a[a > 0] *= np.float32(value)
    fields[field] = a
    bad = tmp_path / "bad.bsdf"
    bad.write_bytes(tensor_file_bytes(fields))
    refused(lambda: read_rgl(bad), str(bad), repr(field), *words)
    assert read_rgl(rgl_file).evaluate([0.0, 0.0, 1.0], [0.0, 0.0, 1.0]) > 0
