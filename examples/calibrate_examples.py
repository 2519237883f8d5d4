"""False alarms and power of the examples (a)–(c) over independent reference traces.

    .venv/bin/python examples/calibrate_examples.py N FIRST_SEED [CACHE_DIR]

runs the checks of ``test_check_your_brdf.py`` at its settings with ``seed`` = FIRST_SEED …
FIRST_SEED + N − 1 (each seed is a new reference trace, ~5 s on 2 cores) and prints, per seed
and in total, the false alarms of the correct GGX (a), the detections of the 3 % rougher GGX
(b) and the incidences at which Schlick's Fresnel (c) fails. docs/testing.md quotes its output.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import test_check_your_brdf as ex  # noqa: E402

from microsim.testing import BRDFMismatch, assert_brdf_agrees  # noqa: E402


def main(n: int, start: int, cache=None) -> None:
    false_alarms = detected = 0
    schlick = {float(t): 0 for t in ex.THETA_I}
    for seed in range(start, start + n):
        kw = dict(theta_i=ex.THETA_I, rays=ex.RAYS, bins=ex.BINS, isotropic=True, seed=seed)
        kw["cache"] = cache
        try:
            assert_brdf_agrees(ex.ggx_brdf(0.3), ex.SCENE, **kw)
        except BRDFMismatch as e:
            false_alarms += 1
            print(f"seed {seed}: false alarm of (a) at θi = {e.agreement['failing']}")
        try:
            assert_brdf_agrees(ex.ggx_brdf(0.3 * 1.03), ex.SCENE, **kw)
        except BRDFMismatch:
            detected += 1
        try:
            assert_brdf_agrees(ex.ggx_brdf(0.3, ex.fresnel_schlick), ex.SCENE, **kw)
        except BRDFMismatch as e:
            for t in e.agreement["failing"]:
                schlick[t] += 1
        print(
            f"seed {seed}: (a) false alarms {false_alarms}, (b) detected {detected}, "
            f"(c) failing per θi {schlick}",
            flush=True,
        )
    print(
        f"{n} seeds from {start}: (a) false alarms {false_alarms}/{n}; (b) detected "
        f"{detected}/{n}; (c) failing per θi {schlick}"
    )


if __name__ == "__main__":
    main(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3] if len(sys.argv) > 3 else None)
