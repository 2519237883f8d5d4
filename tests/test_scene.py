"""Scene files: the catalogue loads and builds; malformed files fail with one-line errors."""

import warnings
from pathlib import Path

import numpy as np
import pytest

from microsim import analytic as an
from microsim.app.scene import CATALOGUE as SCENES
from microsim.app.scene import SceneError, SimSettings, describe_surface, load_scene

CATALOGUE = sorted(SCENES.glob("*.toml"))


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # C <= 3 / height-retention notices
        yield


@pytest.mark.parametrize("path", CATALOGUE, ids=[p.stem for p in CATALOGUE])
def test_catalogue_scene_loads_builds_and_describes(path):
    sc = load_scene(path)
    assert sc.name == path.stem
    surf = sc.build_surface(scale=0.25)
    assert surf.kind == sc.surface.kind and np.all(surf.facet_normals()[:, 2] > 0)
    if sc.surface.kind == "vgrooves":
        assert len(surf.faces) == 4 * round(sc.surface.params["n_grooves"] * 0.25)
    if sc.surface.kind in ("gaussian", "abc"):
        assert surf.heights.shape == (128, 128)
        if sc.wave is None:  # wave scenes: 4 fixed tiles (the Kirchhoff solve per tile)
            assert sc.simulation.realisations == "auto"  # enough tiles for verdicts
    if sc.anisotropic:  # oriented grooves have none; anisotropic fields an anisotropic one
        assert sc.ndf() is None if sc.surface.kind == "vgrooves" else sc.ndf().alpha_x > 0
        assert sc.full_azimuth and not surf.azimuth_average
    elif sc.surface.kind in ("vgrooves", "gaussian", "abc"):
        assert isinstance(sc.ndf(), an.NDF)
    text = describe_surface(surf)
    assert "slope variance x" in text and surf.kind in text


def test_catalogue_covers_the_issue():
    scenes = [load_scene(p) for p in CATALOGUE]
    vg = {
        (
            s.surface.params["ndf"],
            tuple(
                sorted(
                    (k, s.surface.params[k])
                    for k in ("m", "alpha", "e", "kappa", "B", "C")
                    if k in s.surface.params
                )
            ),
        )
        for s in scenes
        if s.surface.kind == "vgrooves"
    }
    assert {n for n, _ in vg} == {"beckmann", "ggx", "blinn-phong", "vmf", "abc"}
    assert ("vmf", (("kappa", 17.0),)) in vg and ("vmf", (("kappa", 1024.0),)) in vg
    gauss = [s for s in scenes if s.surface.kind == "gaussian" and not s.anisotropic]
    opaque = [s for s in gauss if not s.transmission]
    assert sorted(round(s.ndf().m, 6) for s in opaque) == [0.1, 0.3, 0.5]
    glass = {(s.surface.kind, s.ior) for s in scenes if s.transmission}  # rough glass, water
    assert glass == {("gaussian", 1.5), ("student-t-mixture", 1.5), ("gaussian", 1.33)}
    aniso = [s.ndf() for s in scenes if s.surface.kind == "gaussian" and s.anisotropic]
    assert any(4 <= max(n.alpha_x / n.alpha_y, n.alpha_y / n.alpha_x) <= 8 for n in aniso)
    assert any(s.anisotropic and s.surface.kind == "vgrooves" for s in scenes)
    assert all(s.surface.params["corr_len"] >= 7 * s.surface.params["dx"] for s in gauss)
    cs = sorted(s.surface.params["C"] for s in scenes if s.surface.kind == "abc" and s.wave is None)
    assert len(cs) == 2 and 1 < cs[0] <= 3 < cs[1]


def test_full_size_describe_gaussian():
    sc = load_scene(next(p for p in CATALOGUE if p.stem == "gaussian-m0.3"))
    text = describe_surface(sc)
    st = sc.build_surface().stats()
    assert "rms height" in text and f"{st['rms_height']:.6g}" in text and sc.name in text


def write(tmp_path, text, name="scene.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_defaults(tmp_path):
    sc = load_scene(write(tmp_path, '[surface]\nkind = "flat"\n', "my-flat.toml"))
    assert sc.name == "my-flat" and sc.ior is None and sc.simulation == SimSettings()
    assert sc.build_surface().kind == "flat" and sc.ndf() is None


@pytest.mark.parametrize(
    "ior, expect",
    [('"methanol"', 1.329), ("1.5", 1.5), ("[0.769, 6.08]", 0.769 + 6.08j), ('"mirror"', None)],
)
def test_material(tmp_path, ior, expect):
    sc = load_scene(write(tmp_path, f'[surface]\nkind = "flat"\n[material]\nior = {ior}\n'))
    assert sc.ior == expect


def test_rays_auto_and_seed(tmp_path):
    text = (
        '[surface]\nkind = "gaussian"\nn = 32\nsigma = 1.0\ncorr_len = 8.0\n'
        '[simulation]\nrays = "auto"\nseed = 3\ntheta_i = [0, 89.5]\n'
    )
    sc = load_scene(write(tmp_path, text))
    assert sc.simulation.rays == "auto" and sc.simulation.theta_i == (0.0, 89.5)
    a, b, c = sc.build_surface(), sc.build_surface(seed=3), sc.build_surface(seed=4)
    assert np.array_equal(a.heights, b.heights) and not np.allclose(a.heights, c.heights)
    assert sc.ndf().m == pytest.approx(0.25)


def test_file_scene_relative_path(tmp_path):
    np.save(tmp_path / "h.npy", np.random.default_rng(0).normal(size=(16, 16)))
    sc = load_scene(
        write(tmp_path, '[surface]\nkind = "file"\npath = "h.npy"\ndx = 0.5\nperiodic = true\n')
    )
    assert sc.build_surface().heights.shape == (16, 16)


VG = '[surface]\nkind = "vgrooves"\nndf = "beckmann"\nm = 0.3\n'


@pytest.mark.parametrize(
    "text, key",
    [
        ("foo = 1\n" + VG, "foo"),
        (VG + 'colour = "red"\n', "surface.colour"),
        (VG + 'n_grooves = "many"\n', "surface.n_grooves"),
        (VG + "n_grooves = 2.5\n", "surface.n_grooves"),
        (VG + "n_grooves = true\n", "surface.n_grooves"),
        (VG.replace("m = 0.3", "m = -1"), "surface.m"),
        (VG.replace("m = 0.3", 'm = "rough"'), "surface.m"),
        (VG.replace("m = 0.3", "alpha = 0.3"), "surface.alpha"),
        (VG.replace("m = 0.3\n", ""), "surface.m"),
        (VG.replace('"beckmann"', '"cauchy"'), "surface.ndf"),
        (VG + 'sampling = "sobol"\n', "surface.sampling"),
        ('[surface]\nkind = "sphere"\n', "surface.kind"),
        ("[surface]\nn = 8\n", "surface.kind"),
        ('name = "x"\n', "surface"),
        ('[surface]\nkind = "gaussian"\nsigma = 1.0\n', "surface.corr_len"),
        ('[surface]\nkind = "gaussian"\nsigma = 1.0\ncorr_len = 8.0\nn = 4\n', "surface.n"),
        ('[surface]\nkind = "abc"\nsigma = 1.0\nB = 8.0\nC = 1.0\n', "surface.C"),
        (VG + '[material]\nior = "gold"\n', "material.ior"),
        (VG + "[material]\nior = [1.0]\n", "material.ior"),
        (VG + "[material]\nior = -2.0\n", "material.ior"),
        (VG + "[material]\nn = 1.5\n", "material.n"),
        (VG + "[simulation]\ntheta_i = [0, 95]\n", "simulation.theta_i"),
        (VG + "[simulation]\ntheta_i = 30\n", "simulation.theta_i"),
        (VG + '[simulation]\nrays = "lots"\n', "simulation.rays"),
        (VG + "[simulation]\nrays = 0\n", "simulation.rays"),
        (VG + "[simulation]\ntheta_bins = 4.5\n", "simulation.theta_bins"),
        (VG + "[simulation]\nseed = -1\n", "simulation.seed"),
        (VG + "[simulation]\nlambda = 500\n", "simulation.lambda"),
        ("name = 3\n" + VG, "name"),
        ("[surface\nkind = 1", "TOML"),
    ],
)
def test_malformed_scene(tmp_path, text, key):
    p = write(tmp_path, text, "bad-scene.toml")
    with pytest.raises(SceneError) as exc:
        load_scene(p)
    msg = str(exc.value)
    assert isinstance(exc.value, ValueError)
    assert "bad-scene.toml" in msg and key in msg and "\n" not in msg


def test_missing_scene_file(tmp_path):
    with pytest.raises(ValueError, match="no such scene file"):
        load_scene(tmp_path / "nope.toml")


# --- hardening: names, sizes, encodings, heightfield files ------------------------
@pytest.mark.parametrize(
    "name", ["", ".", "..", "../../escape", "a/b", ".hidden", "x" * 101, "a b", "ü"]
)
def test_unsafe_scene_name_refused(tmp_path, name):
    """A scene name becomes a folder name: only a safe single path component passes."""
    p = write(tmp_path, f'name = "{name}"\n' + VG, "bad-scene.toml")
    with pytest.raises(SceneError) as exc:
        load_scene(p)
    msg = str(exc.value)
    assert "bad-scene.toml" in msg and "name" in msg and "letters, digits" in msg


def test_default_name_from_an_unsafe_file_stem_refused(tmp_path):
    p = write(tmp_path, VG, ".toml")  # stem "" → would name runs/ itself
    with pytest.raises(SceneError, match="name"):
        load_scene(p)


@pytest.mark.parametrize(
    "text, key",
    [
        (VG + "[simulation]\ntheta_bins = 1e6\n", "simulation.theta_bins"),
        (VG + "[simulation]\ntheta_bins = 1000000\n", "simulation.theta_bins"),
        (VG + "[simulation]\nphi_bins = 1\n", "simulation.phi_bins"),
        (VG + "[simulation]\nphi_bins = 100000\n", "simulation.phi_bins"),
        (VG + "[simulation]\nrealisations = 100000\n", "simulation.realisations"),
        (VG + '[simulation]\nrealisations = "many"\n', "simulation.realisations"),
        (VG + "[simulation]\nbounces = 0\n", "simulation.bounces"),
        (VG + "[simulation]\nbounces = 300\n", "simulation.bounces"),
        (VG + '[simulation]\nbounces = "some"\n', "simulation.bounces"),
        (VG + "[simulation]\nrealisation_target = 0.01\n", "simulation.realisation_target"),
        (
            VG + '[simulation]\nrealisations = "auto"\nrealisation_target = 0\n',
            "simulation.realisation_target",
        ),
        (
            '[surface]\nkind = "flat"\n[simulation]\nrealisations = "auto"\n',
            "simulation.realisations",
        ),
        (VG + "n_grooves = 1e8\n", "surface.n_grooves"),
        (VG + "n_grooves = 100000000\n", "surface.n_grooves"),
        ('[surface]\nkind = "gaussian"\nsigma = 1e200\ncorr_len = 8.0\n', "surface.sigma"),
        ('[surface]\nkind = "gaussian"\nsigma = 1e5\ncorr_len = 8.0\n', "surface.sigma"),
        ('[surface]\nkind = "gaussian"\nsigma = 1.0\ncorr_len = 1e-9\n', "surface.corr_len"),
        ('[surface]\nkind = "gaussian"\nsigma = 1.0\ncorr_len = 8.0\nn = 100000\n', "surface.n"),
        ('[surface]\nkind = "abc"\nsigma = 1e200\nB = 8.0\nC = 3.0\n', "surface.sigma"),
        ('[surface]\nkind = "flat"\nsize = 1e300\n', "surface.size"),
    ],
)
def test_values_that_cannot_be_built_are_refused_up_front(tmp_path, text, key):
    p = write(tmp_path, text, "bad-scene.toml")
    with pytest.raises(SceneError) as exc:
        load_scene(p)
    assert "bad-scene.toml" in str(exc.value) and key in str(exc.value)


def test_scene_file_not_regular_too_large_or_not_utf8(tmp_path):
    for path, what in [(Path("/dev/zero"), "regular"), (tmp_path, "directory")]:
        with pytest.raises(SceneError) as exc:
            load_scene(path)
        assert str(path) in str(exc.value) and what in str(exc.value)
    big = write(tmp_path, VG + "#" + "x" * (1 << 20) + "\n", "big.toml")
    with pytest.raises(SceneError, match="big.toml.*MiB"):
        load_scene(big)
    latin = tmp_path / "latin.toml"
    latin.write_bytes(('description = "caf\u00e9"\n' + VG).encode("latin-1"))
    with pytest.raises(SceneError, match="latin.toml.*UTF-8"):
        load_scene(latin)


def _truncated_npy(p):
    np.save(p, np.zeros((16, 16)))
    p.write_bytes(p.read_bytes()[:200])  # header intact, data cut short


FILE_SCENE = '[surface]\nkind = "file"\npath = "{}"\ndx = 1.0\n'


@pytest.mark.parametrize(
    "make, what",
    [
        (None, "no such heightfield"),
        (lambda p: p.write_bytes(b"not numpy at all"), "not a readable"),
        (lambda p: np.save(p, np.zeros((4, 4, 4))), "2D"),
        (lambda p: np.save(p, np.zeros((4, 4))), "8"),
        (lambda p: np.save(p, np.full((16, 16), np.nan)), "NaN"),
        (lambda p: np.save(p, np.zeros((16, 16), dtype=complex)), "real"),
        (lambda p: _truncated_npy(p), "npy"),
        (lambda p: p.mkdir(), "regular file"),
    ],
)
def test_bad_heightfield_file_refused_at_load(tmp_path, make, what):
    """Heightfield problems are found when the scene is loaded, naming the scene, key and file."""
    h = tmp_path / "h.npy"
    if make is not None:
        make(h)
    p = write(tmp_path, FILE_SCENE.format("h.npy"), "bad-scene.toml")
    with pytest.raises(SceneError) as exc:
        load_scene(p)
    msg = str(exc.value)
    assert "bad-scene.toml" in msg and "surface.path" in msg and "h.npy" in msg and what in msg
    assert "\n" not in msg
