"""``microsim.testing.assert_brdf_matches_measured``: a BRDF against a measured one (a MERL
file, a microsim table). Facts checked: a closed form written to MERL matches itself read back
within the format's interpolation error (far below the 5 % tolerance); the same model with a
10 % rougher NDF fails and the message names the incidences; a ``microsim measure``-style table
of a V-groove tile is matched by its exact closed form; bad arguments name the parameter."""

from __future__ import annotations

import numpy as np
import pytest

from microsim.analytic import GGX, Beckmann, Smith, TorranceSparrow, VGroove
from microsim.errors import UsageError
from microsim.measured import BRDFTable, write_merl
from microsim.sim import Bins, simulate
from microsim.surfaces import vgrooves
from microsim.testing import BRDFMismatch, assert_brdf_matches_measured

GGX_AL = TorranceSparrow(GGX(0.3), Smith(correlated=True), "aluminium")


@pytest.fixture(scope="module")
def merl_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("merl") / "ggx.binary"
    write_merl(path, GGX_AL.f)
    return path


def test_a_merl_file_matches_its_own_closed_form_and_not_a_rougher_one(merl_file):
    out = assert_brdf_matches_measured(GGX_AL.f, merl_file, rtol=0.05)
    assert max(out["rel_rms"]) < 0.01 and np.allclose(out["energy_ratio"], 1.0, atol=0.01)
    rough = TorranceSparrow(GGX(0.33), Smith(correlated=True), "aluminium")
    with pytest.raises(BRDFMismatch, match="θi = 0°"):
        assert_brdf_matches_measured(rough.f, merl_file, rtol=0.05, name="rough")


def test_a_measured_table_of_vgrooves_is_matched_by_the_exact_form():
    bins = Bins(18, 19)
    theta = [0.0, 30.0, 60.0]
    res = simulate(vgrooves(4000, Beckmann(0.3)), "aluminium", theta, rays=2_000_000, bins=bins)
    table = BRDFTable(np.array(theta), bins, res.brdf, res.stderr, "vgrooves")
    exact = TorranceSparrow(Beckmann(0.3), VGroove(), "aluminium")
    out = assert_brdf_matches_measured(exact.f, table, theta, bins=bins, rtol=0.03)
    assert max(out["rel_rms"]) < 0.03
    smith = TorranceSparrow(Beckmann(0.3), Smith(correlated=True), "aluminium")
    with pytest.raises(BRDFMismatch):  # Smith G is 4–20 % off on V-grooves
        assert_brdf_matches_measured(smith.f, table, theta, bins=bins, rtol=0.03)


def test_bad_arguments_name_the_parameter(merl_file):
    with pytest.raises(UsageError, match="rtol"):
        assert_brdf_matches_measured(GGX_AL.f, merl_file, rtol=2)
    with pytest.raises(UsageError, match="reference"):
        assert_brdf_matches_measured(GGX_AL.f, merl_file.with_suffix(".txt"))
    with pytest.raises(UsageError, match="folded"):
        assert_brdf_matches_measured(GGX_AL.f, merl_file, bins=Bins(18, 36, folded=False))
