"""How long ``microsim.testing`` checks take once warm, each in a new Python process (as a
pytest run is): the numba kernels compiled and cached on disk, the references in the testing
cache. Every case is run once to warm the caches, then ``--repeats`` times, each time in a
fresh subprocess; the table gives the median with min–max, the machine's load average before
and after, and a digest of each check's numbers (the Agreement's model values, verdicts,
physics records and message; ``assert_brdf_matches_model``'s returned dict) so that two
versions of the code can be compared for bitwise equal results.

    .venv/bin/python tools/testing_times.py [--repeats 3] [--cache DIR] [--only CASE ...]
                                            [--against OLD_TREE]

``--cache`` (default: ``$MICROSIM_CACHE`` or the default testing cache) is the reference cache
the checks use; the first, warming, run traces what is missing into it. ``--against`` times
another source tree (``git archive <commit> | tar -x -C DIR``) alternately with this one, so
that both see the same machine load, and prints its table after this one's.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# What one subprocess runs: argv[1] the case name. Prints one JSON line of seconds and digests.
CHILD = r'''
import hashlib, json, sys, time
from pathlib import Path
t0 = time.perf_counter()
import numpy as np
import microsim
from microsim.testing import BRDFMismatch, assert_brdf_agrees, assert_brdf_matches_model
t_import = time.perf_counter() - t0

ETA = 0.769 + 6.08j  # aluminium, the scenes' n + ik


def fresnel(c):
    s2 = 1.0 - c * c
    et = np.sqrt(ETA * ETA - s2 + 0j)
    rs = (c - et) / (c + et)
    rp = (ETA * ETA * c - et) / (ETA * ETA * c + et)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def numpy_brdf(ndf, alpha, masking):
    """A renderer's Torrance-Sparrow in NumPy: GGX or Beckmann D; V-groove G, or
    height-correlated Smith G = 1/(1 + Λi + Λo) (Heitz 2014), exact Fresnel."""

    def lam(c):
        a = c / (alpha * np.sqrt(1.0 - c * c))
        if ndf == "ggx":
            return 0.5 * (np.sqrt(1.0 + 1.0 / (a * a)) - 1.0)
        return np.where(a < 1.6, (1 - 1.259 * a + 0.396 * a * a) / (3.535 * a + 2.181 * a * a), 0)

    def f(wi, wo):
        ci, co = wi[:, 2], wo[:, 2]
        h = wi + wo
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        ch, cd = h[:, 2], np.sum(wi * h, 1)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            if ndf == "ggx":
                d = alpha**2 / (np.pi * (ch * ch * (alpha**2 - 1) + 1) ** 2)
            else:
                t2 = (1 - ch * ch) / (ch * ch)
                d = np.exp(-t2 / alpha**2) / (np.pi * alpha**2 * ch**4)
            if masking == "vgroove":
                g = np.minimum(1.0, 2.0 * ch * np.minimum(ci, co) / cd)
            else:
                g = 1.0 / (1.0 + lam(ci) + lam(co))
            out = fresnel(np.clip(cd, 0, 1)) * d * g / (4 * ci * co)
        return np.where((ci > 0) & (co > 0) & (ch > 0), np.nan_to_num(out), 0.0)

    return f


ROOT = str(Path(microsim.__file__).resolve().parents[1])


def digest(*parts):
    """Of the numbers and words, not of where this microsim is (the scene's path)."""
    return hashlib.sha256(repr(parts).replace(ROOT, "<microsim>").encode()).hexdigest()[:16]


def agrees(brdf, scene):
    try:
        out = assert_brdf_agrees(brdf, scene)
    except BRDFMismatch as e:
        out = e.agreement
    a = np.ascontiguousarray(out["model"]).tobytes()
    return ("passed" if out["passed"] else "failed"), digest(
        a, repr(out["verdicts"]), repr(out["physics"]), out["message"]
    )


def matches():
    from microsim.analytic import GGX
    from microsim.analytic.masking import Smith
    from microsim.analytic.models import TorranceSparrow

    model = TorranceSparrow(GGX(0.3), Smith(correlated=True), ETA)
    out = assert_brdf_matches_model(numpy_brdf("ggx", 0.3, "smith"), model, [0, 30, 60, 80])
    return "passed", digest(repr(out))


CASES = {
    "vgroove-callable": lambda: agrees(numpy_brdf("ggx", 0.3, "vgroove"), "vgroove-ggx-0.3"),
    "vgroove-callable-smith": lambda: agrees(numpy_brdf("ggx", 0.3, "smith"), "vgroove-ggx-0.3"),
    "vgroove-model": lambda: agrees("ts-smith-corr", "vgroove-ggx-0.3"),
    "gaussian-model": lambda: agrees("ts-beckmann-nominal-smith-corr", "gaussian-m0.3"),
    "gaussian-callable": lambda: agrees(numpy_brdf("beckmann", 0.3, "smith"), "gaussian-m0.3"),
    "matches-model": matches,
}
case = sys.argv[1]
t1 = time.perf_counter()
outcome, d1 = CASES[case]()
t2 = time.perf_counter()
outcome2, d2 = CASES[case]()
t3 = time.perf_counter()
assert d1 == d2, "the second check gave other numbers than the first"
print(json.dumps({"import": t_import, "first": t2 - t1, "second": t3 - t2,
                  "outcome": outcome, "digest": d1}))
'''

CASES = {
    "vgroove-callable": "assert_brdf_agrees(numpy GGX, V-groove G; 'vgroove-ggx-0.3')",
    "vgroove-callable-smith": "assert_brdf_agrees(numpy GGX, Smith G; 'vgroove-ggx-0.3')",
    "vgroove-model": "assert_brdf_agrees('ts-smith-corr', 'vgroove-ggx-0.3')",
    "gaussian-model": "assert_brdf_agrees('ts-beckmann-nominal-smith-corr', 'gaussian-m0.3')",
    "gaussian-callable": "assert_brdf_agrees(numpy Beckmann, Smith G; 'gaussian-m0.3')",
    "matches-model": "assert_brdf_matches_model(numpy GGX, TS(GGX(0.3), Smith corr.), 4 θi)",
}


def run_once(case: str, env: dict) -> dict:
    """One fresh process running ``case`` twice, in the source tree it times (``python -c``
    puts the working directory first on the path); its JSON line."""
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, case],
        env=env,
        cwd=env["PYTHONPATH"],
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0:
        raise SystemExit(f"{case}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def spread(xs) -> str:
    return f"{statistics.median(xs):.2f} ({min(xs):.2f}–{max(xs):.2f})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--cache", help="reference cache directory (default: the testing default)")
    ap.add_argument("--only", nargs="+", choices=list(CASES), help="cases to run")
    ap.add_argument(
        "--against",
        metavar="DIR",
        help="another microsim source tree (e.g. a checkout of the version before a change), "
        "timed alternately with this one under the same load",
    )
    args = ap.parse_args()
    roots = [str(ROOT)] + ([str(Path(args.against).resolve())] if args.against else [])
    envs = {root: {**os.environ, "PYTHONPATH": root} for root in roots}
    for env in envs.values():
        if args.cache:
            env["MICROSIM_CACHE"] = args.cache
    cases = args.only or list(CASES)
    load_before = os.getloadavg()
    for case in cases:
        for env in envs.values():
            run_once(case, env)  # warm: traces missing references, compiles, caches on disk
    rows = {(root, case): [] for root in roots for case in cases}
    for _ in range(args.repeats):
        for case in cases:
            for root, env in envs.items():
                rows[root, case].append(run_once(case, env))
    load_after = os.getloadavg()
    print(
        f"{os.cpu_count()} cores; load average (1, 5, 15 min) before "
        f"{', '.join(f'{x:.2f}' for x in load_before)}, after "
        f"{', '.join(f'{x:.2f}' for x in load_after)}; seconds, median (min–max) of "
        f"{args.repeats} fresh processes"
    )
    for root in roots:
        print(f"\n{root}\n")
        print("| check | import | first check | second check | outcome | digest |")
        print("|---|---|---|---|---|---|")
        for case in cases:
            runs = rows[root, case]
            digests = {r["digest"] for r in runs}
            print(
                f"| `{CASES[case]}` | {spread([r['import'] for r in runs])} | "
                f"{spread([r['first'] for r in runs])} | {spread([r['second'] for r in runs])} | "
                f"{runs[0]['outcome']} | {', '.join(sorted(digests))} |"
            )


if __name__ == "__main__":
    main()
