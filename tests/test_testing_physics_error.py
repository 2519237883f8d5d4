"""``assert_brdf_agrees`` tells the physics' own error apart from the BRDF's: on a failure it
judges microsim's Smith model (``ts-smith-corr``) against the same reference and says, per
failing incidence, whether Smith itself deviates there; ``physics_error`` asks for the same
records without a BRDF.

The reference: Beckmann(0.3) V-grooves (a mirror, so the BRDF below needs no Fresnel).
Smith's masking is not the V-groove surface's (Mikkelsen 2009, eq. 25 is), and at θi = 0°
the two differ below this reference's precision (the Smith verdict does not deviate), at 80°
by ~6 % of the energy (it deviates) — measured, not assumed: test (c) checks both."""

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.special import erf

from microsim.analytic import Beckmann
from microsim.errors import UsageError
from microsim.surfaces import vgrooves
from microsim.surfaces.surface import flat
from microsim.testing import (
    PHYSICS_REFERENCES,
    PhysicsError,
    assert_brdf_agrees,
    find_scene,
    physics_error,
)

M = 0.3
THETA = [0, 80]
KW = dict(rays=200_000, bins=(18, 12))


def beckmann_smith(scale: float = 1.0):
    """Torrance–Sparrow on a mirror from its formulas: Beckmann D, height-correlated Smith
    G2 = 1/(1 + Λ(wi) + Λ(wo)), Λ = (erf(a) − 1)/2 + e^(−a²)/(2a√π), a = 1/(m tan θ);
    f = D G2/(4 cos θi cos θo), times ``scale``."""

    def lam(cos):
        a = cos / (M * np.sqrt(np.maximum(1.0 - cos**2, 1e-300)))
        return 0.5 * (erf(a) - 1.0) + np.exp(-(a**2)) / (2.0 * a * np.sqrt(np.pi))

    def f(wi, wo):
        h = wi + wo
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        c = h[:, 2]
        d = np.exp(-(1.0 - c**2) / (c**2 * M**2)) / (np.pi * M**2 * c**4)
        ci, co = wi[:, 2], wo[:, 2]
        return scale * d / (4.0 * ci * co * (1.0 + lam(ci) + lam(co)))

    return f


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """(surface, keyword arguments with one cache shared by the module's checks)."""
    cache = tmp_path_factory.mktemp("references")
    return vgrooves(400, Beckmann(M)), dict(KW, cache=cache, chart_dir=cache / "charts")


def _failure(reference, brdf, **kw):
    surface, args = reference
    with pytest.raises(AssertionError) as e:
        assert_brdf_agrees(brdf, surface, None, THETA, **{**args, **kw})
    return str(e.value), e.value.agreement


def _physics_line(msg: str, theta: int) -> tuple[str, str]:
    """The two lines on Smith's own error at θi = ``theta``."""
    lines = msg.splitlines()
    k = next(i for i, s in enumerate(lines) if s.startswith(f"at θi = {theta}°: Smith's own"))
    return lines[k], lines[k + 1]


def test_a_correct_smith_brdf_failing_where_smith_deviates_is_told_the_physics_is_the_cause(
    reference,
):
    msg, agreement = _failure(reference, beckmann_smith(), name="my_beckmann")
    assert agreement["failing"] == [80.0], msg
    head, conclusion = _physics_line(msg, 80)
    assert re.search(r"ts-smith-corr deviates from the reference by \+\d+\.\d+% ± ", head), msg
    assert head.endswith("its verdict deviates"), msg
    assert "brdf/ts-smith-corr energy ratio 1.000×" in conclusion, msg  # the brdf is Smith's
    assert "a correct Beckmann(m=0.3) with Smith's G cannot pass here" in conclusion
    assert "the deviation is the physics' (Smith's masking / single scattering)" in conclusion
    assert "θi = 0°: Smith's own" not in msg  # only failing incidences get a line
    (record,) = agreement["physics"]
    assert isinstance(record, PhysicsError) and not record.holds and record.theta_i == 80.0


def test_a_wrong_brdf_where_smith_holds_is_told_the_deviation_is_its_own(reference):
    msg, agreement = _failure(reference, beckmann_smith(1.05))
    assert 0.0 in agreement["failing"], msg
    head, conclusion = _physics_line(msg, 0)
    assert not head.endswith("its verdict deviates"), msg
    assert "brdf/ts-smith-corr energy ratio 1.050×" in conclusion, msg
    assert conclusion.endswith("Smith holds here, so the deviation is the brdf's"), msg
    assert "cannot pass here" not in conclusion


def test_physics_error_returns_the_records_the_message_prints(reference):
    surface, args = reference
    args = {k: v for k, v in args.items() if k != "chart_dir"}
    records = physics_error(surface, None, THETA, **args)
    assert [(type(r), r.theta_i) for r in records] == [(PhysicsError, 0.0), (PhysicsError, 80.0)]
    assert [r.holds for r in records] == [True, False]
    assert all(r.model == "ts-smith-corr" and r.brdf_energy_ratio is None for r in records)
    assert records[1].verdict["model"] == "ts-smith-corr"
    msg, agreement = _failure(reference, beckmann_smith(1.05))
    for r, shown in zip(records, agreement["physics"]):
        head, _ = _physics_line(msg, int(r.theta_i))
        assert f"by {100 * r.energy_dev:+.2f}% ± {100 * r.energy_se:.2f}%" in head, head
        assert shown.energy_dev == r.energy_dev and shown.holds == r.holds
    with pytest.raises(dataclasses.FrozenInstanceError):
        records[0].holds = False
    with pytest.raises(TypeError):
        records[0]["holds"] = False


def test_tolerance_mode_judges_the_physics_by_the_same_tolerance(reference):
    msg, agreement = _failure(reference, beckmann_smith(), rtol=0.03)
    (record,) = agreement["physics"]
    assert not record.holds and record.theta_i == 80.0 and not record.tolerance["passed"]
    assert _physics_line(msg, 80)[0].endswith("its verdict beyond rtol = 0.03"), msg


def test_a_surface_without_an_ensemble_ndf_gets_no_physics_line(tmp_path):
    with pytest.raises(AssertionError) as e:
        assert_brdf_agrees(
            lambda wi, wo: np.full(len(wi), 1.0), flat(), None, [30], cache=tmp_path, **KW
        )
    assert e.value.agreement["physics"] is None and "Smith's own" not in str(e.value)
    with pytest.raises(UsageError, match="surface_or_scene: .* has no ensemble NDF"):
        physics_error(flat(), None, [30], cache=tmp_path, **KW)


def test_the_named_physics_references_are_catalogue_scenes_and_documented():
    for scenes in PHYSICS_REFERENCES.values():
        assert all(find_scene(s).is_file() for s in scenes)
    with pytest.raises(TypeError):
        PHYSICS_REFERENCES["ggx"] = ("vgroove-ggx-0.3",)
    docs = (Path(__file__).resolve().parents[1] / "docs" / "testing.md").read_text()
    for name, scenes in PHYSICS_REFERENCES.items():
        row = f"| {name} | {', '.join(f'`{s}`' for s in scenes)} |"
        assert row in docs, row
