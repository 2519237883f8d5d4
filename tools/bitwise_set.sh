#!/usr/bin/env bash
# usage: tools/bitwise_set.sh OUTDIR   (run from the repository root; uses .venv)
# Runs a fixed set of quick scenes and API calls whose outputs must stay bitwise equal;
# compare two OUTDIRs with: .venv/bin/python tools/compare_runs.py A B
set -euo pipefail
out=$1; rm -rf "$out"; mkdir -p "$out"
for s in vgroove-beckmann-0.3 gaussian-m0.3 file-gaussian-64 abc-smooth-wave flat-aluminium; do
  .venv/bin/microsim run "$s" --quick --threads 2 --no-progress --out "$out/$s" >/dev/null
done
.venv/bin/python - "$out" <<'PY'
import sys
from pathlib import Path
from microsim.analytic import Beckmann, GGX
from microsim.sim import Bins, simulate
from microsim.surfaces import vgrooves
out = Path(sys.argv[1])
vg = vgrooves(300, Beckmann(0.4), seed=2)
for masking in ("traced", "exact", "analytic"):
    for bounces in ((1,) if masking == "exact" else (1, "all")):
        r = simulate(vg, "aluminium", [20.0, 70.0], rays=200_000, bins=Bins(12, 8),
                     masking=masking, bounces=bounces, seed=5)
        r.save(out / f"api-vgroove-{masking}-{bounces}")
r = simulate(vgrooves(200, GGX(0.3), sampling="random", seed=3), 1.5, 45.0, rays=100_000,
             bins=Bins(9, 10), origins="independent", seed=1)
r.save(out / "api-vgroove-independent")
PY
