"""`microsim bench --methods` (microsim.app.bench_methods): the quick study, its chart and JSON, and
the index subsection "What each method costs" rendered from that JSON (report.methods_section).

One quick study (~10 s on 2 busy cores) is shared by every test of the module."""

import json
import math
from argparse import Namespace

import pytest

from microsim.analysis import report
from microsim.app import bench_methods as bm
from microsim.errors import UsageError


@pytest.fixture(scope="module")
def study():
    return bm.methods_study(quick=True)


@pytest.fixture(scope="module")
def written(study, tmp_path_factory):
    out = tmp_path_factory.mktemp("methods")
    bm.write_methods(study, out)
    return out


def _panel(study, key):
    return next(p for p in study["panels"] if p["key"] == key)


def _curve(panel, key):
    return sorted((p for p in panel["points"] if p["key"] == key), key=lambda p: p["size"])


def test_quick_study_has_every_method_with_a_time_and_an_error(study):
    geo, wave = _panel(study, "geometric"), _panel(study, "wave")
    geo_keys = {"ts-smith", "ts-vgroove", "ray-traced", "ray-analytic"}
    assert {p["key"] for p in geo["points"]} == geo_keys
    assert {p["key"] for p in wave["points"]} == {
        "rayleigh-rice",
        "low-smooth",
        "kirchhoff-first-order",
        "ts-smith",
        "kirchhoff",
        "ray-traced",
    }
    for panel in (geo, wave):
        for p in panel["points"]:
            assert p["seconds"] > 0 and math.isfinite(p["seconds"]), p
            assert p["error"] is not None and p["error"] >= 0, p
            assert p["kind"] in ("closed-form", "curve")
    m = study["machine"]
    assert m["cpus"] >= 1 and m["threads"] == 2 and len(m["load_average_start"]) == 3


def test_ray_trace_error_falls_16x_rays_unless_at_the_model_floor(study):
    """rel_rms² ≈ b² + s_N² (b the model error, s_N the ray-noise floor ∝ 1/√N). Where the
    noise floor at N exceeds twice the error at 16 N, the noise dominates at N and the error
    must fall (expected error(16 N) ≈ √(b² + s_N²/16) < s_N/2 < error(N)); otherwise both are
    near the floor and the error may not rise beyond 3 standard errors of the pair."""
    geo = _panel(study, "geometric")
    checked = 0
    for key in ("ray-traced", "ray-analytic"):
        pts = _curve(geo, key)
        for a in pts:
            for b in pts:
                if b["size"] != 16 * a["size"]:
                    continue
                if a["noise_floor"] > 2.0 * b["error"]:
                    assert b["error"] < a["error"], (key, a, b)
                    checked += 1
                else:
                    se = math.hypot(a["error_se"] or 0.0, b["error_se"] or 0.0)
                    assert b["error"] <= a["error"] + 3.0 * se, (key, a, b)
    assert checked >= 1  # the quick ray counts start well above the floor (1e4 rays: ~17 %)


def test_rayleigh_rice_fails_in_the_transition_regime(study):
    """At σ = λ/4, θi = 30°, g = (4πσ cos θi/λ)² = 7.4: first-order RR puts ≈ F g into the
    diffuse lobe where Kirchhoff puts F (1 − e^−g) (Davies 1954), an excess g/(1 − e^−g) − 1
    = 6.4; over the energy set it must at least be half that, far outside the 5 % criterion."""
    wave = _panel(study, "wave")
    rr = next(p for p in wave["points"] if p["key"] == "rayleigh-rice")
    g = (4 * math.pi * 0.25 * math.cos(math.radians(30))) ** 2
    assert -rr["deviation"] > 0.5 * (g / (1 - math.exp(-g)) - 1)  # ref − model < 0: RR too bright


def test_chart_and_json_are_written_and_the_json_validates(study, written):
    png = (written / bm.METHODS_PNG).read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    d = report.load_methods(written / bm.METHODS_JSON)
    assert [p["key"] for p in d["panels"]] == [p["key"] for p in study["panels"]]
    assert not list(written.glob(".*tmp"))  # atomic writes leave no temporaries


def test_report_section_renders_from_the_json(study, written):
    lines = report.regime_section([], None, written / bm.METHODS_JSON)
    text = "\n".join(lines)
    assert "## Where each method holds" in text and "### What each method costs" in text
    assert "![What each method costs](methods.png)" in text
    m = study["machine"]
    assert f"on {m['cpus']} cores at load {m['load_average_start'][0]:.2f}, commit" in text
    for panel in study["panels"]:
        for p in panel["points"]:
            assert p["method"] in text
    assert report.methods_section(study) == lines[2:]  # the dict renders like its file


def test_report_section_says_which_command_makes_a_missing_json(tmp_path):
    text = "\n".join(report.methods_section(tmp_path / "methods.json"))
    assert "`microsim bench --methods`" in text and "![" not in text
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"panels": [{"title": "x"}], "machine": {}}))
    text = "\n".join(report.methods_section(bad))
    assert "unreadable" in text and "microsim bench --methods" in text


def test_cli_refuses_options_of_the_throughput_bench(tmp_path):
    args = Namespace(methods=str(tmp_path), quick=True, json=False, rays=1000, skip_accuracy=False)
    with pytest.raises(UsageError, match="--rays"):
        bm.run_methods_command(args)
    assert not list(tmp_path.iterdir())
