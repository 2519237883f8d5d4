"""Progress when stderr is not a terminal: plain lines (one per 10 % of the rays, one per
analysis stage), never tqdm's carriage returns; the rate is measured from the first chunk."""

import io
import subprocess
import sys

from microsim.app.runner import progress as P
from microsim.sim.progress import RaysDone


def _event(rays, finished=False):
    return RaysDone(
        realisation=0, realisations=1, incidence=0, theta_i=30.0, rays=rays, finished=finished
    )


def test_rays_print_one_line_per_ten_percent(monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    monkeypatch.setattr(P, "RATE_AFTER", 0.0)
    bar = P.RayProgress(1000, "scene")
    for k in range(40):  # 25 rays per chunk
        bar(_event(25, finished=k == 39))
    bar.close()
    out = err.getvalue()
    assert "\r" not in out
    lines = out.splitlines()
    assert [int(line.split(": ")[1].split(" %")[0]) for line in lines] == list(range(10, 101, 10))
    assert all(line.startswith("scene: ") and "of 1,000 rays" in line for line in lines)
    assert "left)" in lines[-2]  # a rate and the time left once two chunks are in


def test_stages_print_one_line_each(monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    st = P.StageProgress("scene", extra=1)
    for name in P.StageProgress.STAGES:
        st.stage(name)
    st.close()
    lines = err.getvalue().splitlines()
    assert lines == [
        f"scene analysis: {n} ({k}/{len(P.StageProgress.STAGES) + 1})"
        for k, n in enumerate(P.StageProgress.STAGES, 1)
    ]


def test_disabled_progress_prints_nothing(monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    bar = P.RayProgress(100, "scene", enabled=False)
    bar(_event(100, True))
    bar.close()
    P.StageProgress("scene", enabled=False).stage("models")
    assert err.getvalue() == ""


def test_a_piped_run_writes_lines_not_carriage_returns(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "microsim.app.cli", "run", "flat-aluminium",
         "--quick", "--rays", "200000", "--out", str(tmp_path / "out"), "--threads", "2"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "\r" not in r.stderr
    assert any(" % of " in line and " rays" in line for line in r.stderr.splitlines())
    assert any(line.startswith("flat-aluminium analysis: charts") for line in r.stderr.splitlines())
