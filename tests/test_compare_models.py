"""``attach_models`` takes the model objects of ``analytic.models`` (as a mapping name → model)
and predicts with them exactly as with the equivalent ``Predictor``s."""

import numpy as np
import pytest

from microsim import analytic as an
from microsim.errors import UsageError
from microsim.sim import Bins, simulate
from microsim.sim.compare import attach_models
from microsim.sim.predict import FunctionBRDF, Predictor
from microsim.surfaces import vgrooves


@pytest.fixture(scope="module")
def result():
    return simulate(
        vgrooves(100, an.Beckmann(0.3)), "aluminium", [30.0], rays=20_000, bins=Bins(6, 4)
    )


def test_model_objects_predict_like_their_specs(result):
    ndf = an.Beckmann(0.3)
    smooth = an.LowSmooth(10.0, 100.0, 1.5, 0.01, "aluminium")
    objects = attach_models(
        result, {"ts": an.TorranceSparrow(ndf, an.VGroove(), "aluminium"), "smooth": smooth}
    )
    specs = attach_models(
        result,
        [
            Predictor("ts", an.TorranceSparrow(ndf, "vgroove", "aluminium")),
            Predictor("smooth", FunctionBRDF(smooth.f, symmetric=smooth.symmetric)),
        ],
    )
    assert set(objects.models) == {"ts", "smooth"} and not result.models
    for name in ("ts", "smooth"):
        np.testing.assert_array_equal(objects.models[name], specs.models[name])


def test_a_list_must_hold_specs(result):
    with pytest.raises(UsageError, match="mapping name"):
        attach_models(result, [an.LowSmooth(10.0, 100.0, 1.5)])
