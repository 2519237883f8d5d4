"""False alarms and power of the examples (a)–(c) over independent reference traces.

    .venv/bin/python examples/calibrate_examples.py N FIRST_SEED [CACHE_DIR] [--min-events M]

runs the checks of ``test_check_your_brdf.py`` at its settings with ``seed`` = FIRST_SEED …
FIRST_SEED + N − 1 (each seed is a new reference trace, ~5 s on 2 cores) and prints, per seed
and in total, the false alarms of the correct GGX (a), the detections of the 3 % rougher GGX
(b) and the incidences at which Schlick's Fresnel (c) fails. ``--min-events M`` passes
``min_events=M`` to ``assert_brdf_agrees`` (default: its own). docs/testing.md quotes its output.
"""

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import test_check_your_brdf as ex  # noqa: E402

from microsim.testing import BRDFMismatch, assert_brdf_agrees  # noqa: E402


def main(n: int, start: int, cache=None, min_events=None) -> None:
    false_alarms = detected = 0
    schlick = {float(t): 0 for t in ex.THETA_I}
    for seed in range(start, start + n):
        kw = dict(theta_i=ex.THETA_I, rays=ex.RAYS, bins=ex.BINS, symmetric=True, seed=seed)
        kw["cache"] = cache
        if min_events is not None:
            kw["min_events"] = min_events
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
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("n", type=int, help="number of seeds")
    parser.add_argument("first_seed", type=int)
    parser.add_argument("cache_dir", nargs="?", default=None)
    parser.add_argument("--min-events", type=int, default=None)
    args = parser.parse_args()
    main(args.n, args.first_seed, args.cache_dir, args.min_events)
