"""`microsim run` with `bounces = "all"`: the verdicts keep judging order 1, the
report gains "Scattering orders" with the fraction of light single scattering misses and the
order-resolved comparison, and verdicts.json its "orders" section."""

import json

import numpy as np
import pytest

from microsim.app.cli import main

# slow (15 s end to end): the default run covers the bounce chain (test_bounces) and the
# orders section and chart (test_multiple_analysis)
pytestmark = [pytest.mark.integration, pytest.mark.slow]

SCENE = """\
name = "orders-vg"
[surface]
kind = "vgrooves"
n_grooves = 800
ndf = "beckmann"
m = 0.6
[material]
ior = "aluminium"
[simulation]
theta_i = [30, 70]
rays = 40000
theta_bins = 9
phi_bins = 10
bounces = "all"
seed = 2
"""


def test_run_with_bounces_reports_the_scattering_orders(tmp_path):
    scene = tmp_path / "orders.toml"
    scene.write_text(SCENE)
    out = tmp_path / "run"
    assert main(["run", str(scene), "--quick", "--out", str(out), "--no-progress"]) == 0
    doc = json.loads((out / "verdicts.json").read_text())
    orders = doc["orders"]
    assert orders["bounces"] == "all" and len(orders["needs"]) == 2
    for n in orders["needs"]:  # m = 0.6 grooves at 30° and 70° scatter several % twice
        assert n["needs"] and n["multiple_fraction"] > 0.01 and n["cut"] == 0.0
    cmp = orders["comparison"]
    assert cmp is not None and {"random-walk", "kulla-conty", "mikkelsen-eq28"} <= set(
        cmp["incidences"][0]["models"]
    )
    for inc in cmp["incidences"]:  # energy closes: orders + absorbed + cut = 1
        sim = inc["sim"]
        total = sum(sim["orders"]) + sim["absorbed"] + sim["cut"] + sim.get("lost", 0.0)
        assert total == pytest.approx(1.0, abs=1e-9)
    report = (out / "report.md").read_text()
    assert (
        "## Scattering orders" in report and "## How much light single scattering misses" in report
    )
    assert (out / "multiple.png").is_file()
    # order 1 is what the verdicts judge: Result.brdf is the order-1 slot
    with np.load(out / "brdf.npz") as z:
        assert np.array_equal(z["brdf"], z["brdf_orders"][0], equal_nan=True)
