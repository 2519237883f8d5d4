"""``assert_brdf_agrees`` tells the physics' own error apart from the BRDF's: on a failure it
judges microsim's Smith model (``ts-smith-corr``) against the same reference and says, per
failing incidence, whether Smith itself deviates there; ``physics_error`` asks for the same
records without a BRDF.

The reference: 8 realisations of a 256² GGX heightfield (``student_t_transform``, α = 0.3; a
mirror, so the BRDF below needs no Fresnel). Its heights and slopes are correlated, which
Smith's masking assumes they are not: at θi = 0° Smith's error is within 1 % (the tolerance
``rtol = 0.01`` the checks use; statistically it is resolved, ~0.7 % with grazing bins off),
at 60° it is ~12 % of the energy — measured, not assumed: test (c) checks both. On V-grooves
(and the flat mirror) the surface's own G is exact, so no Smith line is added there."""

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from microsim.analytic import Beckmann
from microsim.errors import UsageError
from microsim.surfaces import student_t_transform, vgrooves
from microsim.surfaces.surface import flat
from microsim.testing import (
    PHYSICS_REFERENCES,
    PhysicsError,
    assert_brdf_agrees,
    find_scene,
    physics_error,
)

ALPHA = 0.3
THETA = [0, 60]
KW = dict(rays=400_000, bins=(18, 12), rtol=0.01)


def ggx_smith(scale: float = 1.0):
    """Torrance–Sparrow on a mirror from its formulas: GGX D, height-correlated Smith
    G2 = 1/(1 + Λ(wi) + Λ(wo)), Λ = (√(1 + α² tan²θ) − 1)/2; f = D G2/(4 cos θi cos θo),
    times ``scale``."""

    def lam(cos):
        return 0.5 * (np.sqrt(1.0 + ALPHA**2 * (1.0 - cos**2) / cos**2) - 1.0)

    def f(wi, wo):
        h = wi + wo
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        c2 = h[:, 2] ** 2
        d = ALPHA**2 / (np.pi * (ALPHA**2 * c2 + 1.0 - c2) ** 2)
        ci, co = wi[:, 2], wo[:, 2]
        return scale * d / (4.0 * ci * co * (1.0 + lam(ci) + lam(co)))

    return f


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """(surfaces, keyword arguments with one cache shared by the module's checks)."""
    cache = tmp_path_factory.mktemp("references")
    tiles = [student_t_transform(256, 1.0, ALPHA, 2.0, 8.0, seed=s) for s in range(8)]
    return tiles, dict(KW, cache=cache, chart_dir=cache / "charts")


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
    msg, agreement = _failure(reference, ggx_smith(), name="my_ggx")
    assert agreement["failing"] == [60.0], msg
    head, conclusion = _physics_line(msg, 60)
    assert re.search(r"ts-smith-corr deviates from the reference by \+\d+\.\d+% ± ", head), msg
    assert head.endswith("its verdict beyond rtol = 0.01"), msg
    assert "brdf/ts-smith-corr energy ratio 1.000×" in conclusion, msg  # the brdf is Smith's
    assert "a correct GGX(alpha=0.3) with Smith's G cannot pass here" in conclusion
    assert "the deviation is the physics' (Smith's masking / single scattering)" in conclusion
    assert "θi = 0°: Smith's own" not in msg  # only failing incidences get a line
    (record,) = agreement["physics"]
    assert isinstance(record, PhysicsError) and not record.holds and record.theta_i == 60.0


def test_a_wrong_brdf_where_smith_holds_is_told_the_deviation_is_its_own(reference):
    msg, agreement = _failure(reference, ggx_smith(1.05))
    assert 0.0 in agreement["failing"], msg
    head, conclusion = _physics_line(msg, 0)
    assert head.endswith("its verdict within rtol = 0.01"), msg
    assert "brdf/ts-smith-corr energy ratio 1.050×" in conclusion, msg
    assert conclusion.endswith("Smith holds here, so the deviation is the brdf's"), msg
    assert "cannot pass here" not in conclusion


def test_physics_error_returns_the_records_the_message_prints(reference):
    surface, args = reference
    args = {k: v for k, v in args.items() if k != "chart_dir"}
    records = physics_error(surface, None, THETA, **args)
    assert [(type(r), r.theta_i) for r in records] == [(PhysicsError, 0.0), (PhysicsError, 60.0)]
    assert [r.holds for r in records] == [True, False]
    assert all(r.model == "ts-smith-corr" and r.brdf_energy_ratio is None for r in records)
    assert records[1].verdict["model"] == "ts-smith-corr"
    msg, agreement = _failure(reference, ggx_smith(1.05))
    for r, shown in zip(records, agreement["physics"]):
        head, _ = _physics_line(msg, int(r.theta_i))
        assert f"by {100 * r.energy_dev:+.2f}% ± {100 * r.energy_se:.2f}%" in head, head
        assert shown.energy_dev == r.energy_dev and shown.holds == r.holds
    with pytest.raises(dataclasses.FrozenInstanceError):
        records[0].holds = False
    with pytest.raises(TypeError):
        records[0]["holds"] = False


def test_tolerance_mode_judges_the_physics_by_the_same_tolerance(reference):
    msg, agreement = _failure(reference, ggx_smith(), rtol=0.03)
    (record,) = agreement["physics"]
    assert not record.holds and record.theta_i == 60.0 and not record.tolerance["passed"]
    assert _physics_line(msg, 60)[0].endswith("its verdict beyond rtol = 0.03"), msg


@pytest.mark.parametrize("surface", [flat(), vgrooves(400, Beckmann(0.3))], ids=["flat", "vgroove"])
def test_a_surface_with_its_own_exact_masking_gets_no_physics_line(tmp_path, surface):
    """The flat mirror has no NDF and V-grooves have the V-groove G: Smith is not their
    physics, so a failure there says nothing about Smith's error."""
    with pytest.raises(AssertionError) as e:
        assert_brdf_agrees(
            lambda wi, wo: np.full(len(wi), 1.0), surface, None, [30], cache=tmp_path, **KW
        )
    assert e.value.agreement["physics"] is None and "Smith's own" not in str(e.value)
    with pytest.raises(UsageError, match="surface_or_scene: .* no Smith model of it to judge"):
        physics_error(surface, None, [30], cache=tmp_path, **KW)


def test_the_named_physics_references_are_catalogue_scenes_and_documented():
    for scenes in PHYSICS_REFERENCES.values():
        assert all(find_scene(s).is_file() for s in scenes)
    with pytest.raises(TypeError):
        PHYSICS_REFERENCES["ggx"] = ("vgroove-ggx-0.3",)
    docs = (Path(__file__).resolve().parents[1] / "docs" / "testing.md").read_text()
    for name, scenes in PHYSICS_REFERENCES.items():
        row = f"| {name} | {', '.join(f'`{s}`' for s in scenes)} |"
        assert row in docs, row
