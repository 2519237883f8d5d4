"""The physics' own error on the reference scenes at the testing API's default settings: for
each scene of ``microsim.testing.PHYSICS_REFERENCES`` (and ``gaussian-m0.5``), microsim's
``ts-smith-corr`` judged by ``physics_error`` (rays "auto", the scene's realisations, bins and
material) — the energy deviation ± its standard error, the relative RMS error and the verdict
per θi, as docs/testing.md tabulates them. Traces each reference once into the testing cache.

    .venv/bin/python tools/physics_errors.py
"""

from microsim.testing import PHYSICS_REFERENCES, physics_error

EXTRA = ("gaussian-m0.5",)


def main() -> None:
    scenes = [s for names in PHYSICS_REFERENCES.values() for s in names] + list(EXTRA)
    print("| scene | R | θi 0° | θi 30° | θi 60° | θi 80° |")
    print("|---|---|---|---|---|---|")
    for scene in scenes:
        records = physics_error(scene)
        cells = []
        for r in records:
            se = "" if r.energy_se is None else f" ± {100 * r.energy_se:.2f}"
            cells.append(f"{r.result}: {100 * r.energy_dev:+.2f}{se} % (rel {r.rel_rms:.1%})")
        realisations = records[0].verdict["realisations"]
        print(f"| `{scene}` | {realisations} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
