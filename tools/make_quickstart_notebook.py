"""Write examples/quickstart.ipynb (unexecuted) from the cells below; tests/test_notebook.py runs
it. Usage: .venv/bin/python tools/make_quickstart_notebook.py"""

from pathlib import Path

import nbformat

CELLS = [
    (
        "md",
        """# microsim quickstart

Build an explicit microsurface, ray-trace its BRDF with error bars, compare it with closed-form
models on the same bins, judge each model, and plot. About half a minute on 2 cores.""",
    ),
    (
        "md",
        """## 1. A surface

4000 V-grooves whose tilts follow Beckmann m = 0.3. On this surface Torrance–Sparrow with
Blinn's V-groove G is exact for single scattering (Mikkelsen 2009, eq. 25), Smith G is not.""",
    ),
    (
        "code",
        """%matplotlib inline
from microsim.analytic import Beckmann
from microsim.surfaces import vgrooves

surface = vgrooves(4000, Beckmann(0.3))
surface""",
    ),
    (
        "md",
        """## 2. Simulate

The run's three frozen descriptions: what is measured, how it is estimated, how it runs.
`masking="analytic"` is the exact float64 V-groove path (no Embree).""",
    ),
    (
        "code",
        """from microsim.sim import Bins, Estimator, Execution, Experiment, estimate

experiment = Experiment(surface, "aluminium", (30, 60, 80), bins=Bins(30, 37))
result = estimate(experiment, Estimator(rays=1_000_000, masking="analytic"), Execution(threads=2))
result""",
    ),
    (
        "md",
        """## 3. Compare with the closed forms

`default_models` gives the standard set for this surface (Torrance–Sparrow with V-groove G,
separable and height-correlated Smith G, and the traced tile's own facets); `attach_models`
returns a new Result holding their bin averages.""",
    ),
    (
        "code",
        """from microsim.sim.compare import attach_models, default_models

judged = attach_models(result, default_models(surface, "aluminium"))
list(judged.models)""",
    ),
    (
        "md",
        """## 4. Judge

One verdict per model and incidence: ✓ agrees within the error bars, ✗ deviates (with its
energy-weighted relative RMS error), ? inconclusive (docs/verdicts.md).""",
    ),
    (
        "code",
        """from microsim.analysis.verdicts import verdict_kind, verdicts_for_result

verdicts = verdicts_for_result(judged)
verdicts""",
    ),
    (
        "code",
        """exact = [v for v in verdicts if v["model"] == "ts-vgroove"]
assert all(verdict_kind(v) == "agrees" for v in exact), "the exact model must agree"
{v["theta_i"]: round(v["rel_rms"], 3) for v in verdicts if v["model"] == "ts-smith"}""",
    ),
    (
        "md",
        """## 5. Plot

In-plane curves with a ratio panel (model / simulation with the ±1σ band).""",
    ),
    (
        "code",
        """from microsim.analysis.charts import inplane_curves

inplane_curves(judged, dict(judged.models), scene_name="V-grooves, Beckmann m = 0.3")""",
    ),
]


def main() -> None:
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    for kind, text in CELLS:
        make = nbformat.v4.new_markdown_cell if kind == "md" else nbformat.v4.new_code_cell
        nb.cells.append(make(text))
    for k, cell in enumerate(nb.cells):
        cell["id"] = f"cell-{k}"
    path = Path(__file__).resolve().parents[1] / "examples" / "quickstart.ipynb"
    nbformat.validate(nb)
    nbformat.write(nb, path)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
