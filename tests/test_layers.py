"""The package's layers: no module imports upwards, no private module is reached across
layers, and the module import graph has no cycle (function-local imports included).

Layers, bottom to top (docs/layout.md): core (errors, checkpoints, atomic, checks, vectors,
stats, display, kernel_cache, jit, trig, bin_kernels, bins) → analytic → surfaces → sim → wave
→ analysis → app (``microsim.app``: scene, runner, sweep, bench, bench_methods, bench_peer,
wave_bench, view, cli; and ``microsim.testing``).
"""

import ast
import re
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "microsim"
LAYERS = [
    (
        "core",
        (
            "microsim.errors",
            "microsim.checkpoints",
            "microsim.atomic",
            "microsim.checks",
            "microsim.vectors",
            "microsim.stats",
            "microsim.display",
            "microsim.kernel_cache",
            "microsim.jit",
            "microsim.trig",
            "microsim.bin_kernels",
            "microsim.bins",
        ),
    ),
    ("analytic", ("microsim.analytic",)),
    ("surfaces", ("microsim.surfaces",)),
    ("sim", ("microsim.sim",)),
    ("wave", ("microsim.wave",)),
    ("measured", ("microsim.measured",)),
    ("analysis", ("microsim.analysis",)),
    ("app", ("microsim.app", "microsim.testing", "microsim.__main__")),
]


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in PACKAGE.rglob("*.py")}


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """Every microsim module ``name`` imports, anywhere in the file (absolute or relative)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            # "from pkg import sub" imports the submodule when there is one
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in known else mod for a in node.names]
        else:
            continue
        out.update(t for t in targets if t == "microsim" or t.startswith("microsim."))
    return out


def _layer(module: str) -> int:
    for rank, (_, prefixes) in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return rank
    raise AssertionError(f"{module} belongs to no layer: add it to LAYERS in {__file__}")


MODULES = _modules()
GRAPH = {name: _imports(name, path, set(MODULES)) - {name} for name, path in MODULES.items()}


def test_every_module_has_a_layer():
    for name in MODULES:
        if name != "microsim":
            _layer(name)


@pytest.mark.parametrize("name", sorted(n for n in MODULES if n != "microsim"))
def test_no_module_imports_upwards(name):
    up = sorted(t for t in GRAPH[name] if t != "microsim" and _layer(t) > _layer(name))
    assert not up, f"{name} ({LAYERS[_layer(name)][0]}) imports the higher layer(s): {up}"


def test_no_private_module_is_reached_from_another_package():
    bad = []
    for name, targets in GRAPH.items():
        for t in targets:
            private = [p for p in t.split(".") if p.startswith("_") and p != "__init__"]
            if private and t.rpartition(".")[0] != name.rpartition(".")[0]:
                bad.append(f"{name} -> {t}")
    assert not bad, bad


def test_the_module_graph_has_no_cycle():
    """Depth-first search over module → imported module (the package's own ``__init__``
    re-exports are left out: importing ``microsim`` itself is the user's entry point)."""
    graph = {
        n: {t for t in ts if t != "microsim" and t in GRAPH}
        for n, ts in GRAPH.items()
        if n != "microsim"
    }
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n):
        state[n] = 1
        stack.append(n)
        for t in sorted(graph[n]):
            if state.get(t) == 1:
                raise AssertionError("import cycle: " + " -> ".join(stack[stack.index(t) :] + [t]))
            if t not in state:
                visit(t)
        stack.pop()
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n)


SIM_LAYERS = [
    ("compiled support", ("engine.codes",)),
    (
        "results, infrastructure",
        (
            "ledger",
            "result",
            "progress",
            "scratch",
            "schedule",
            "compilation",
        ),
    ),
    (
        "ray engine",
        ("engine", "engine.facets", "engine.horizon", "engine.beam", "engine.primary")
        + ("engine.segments",)
        + ("tracer", "periodic_walk", "embree_backends", "horizon_bounds", "vgroove_profile")
        + ("heightfield_caster", "embree_packets"),
    ),
    (
        "estimator",
        ("pcg64", "streams", "origin_kernels", "fresnel_kernels", "vgroove_kernels")
        + ("tracer_cache",)
        + ("ray_bins", "masking_rays", "facet_tables", "ray_columns", "events", "paths")
        + ("bounce_kernels", "bounces", "dielectric_kernels", "interface_grid", "dielectric")
        + ("drawn_primary", "tally_kernels")
        + ("tallies", "spectral", "arguments", "cluster")
        + ("experiment", "identity", "estimator", "auto"),
    ),
    ("model predictions on the bins", ("facet_sum_kernels", "predict", "compare")),
]
"""Sub-layers of ``microsim.sim``, bottom to top: results below the ray engine
(periodic walk, Embree backends, grid walk), the engine below the estimator (streams, paths,
the bounce chain, tallies, the drivers), the model predictions on top. The package's
``__init__`` (its public names) may import any of them."""


def _sim_layer(module: str) -> int:
    short = module.removeprefix("microsim.sim.")
    for rank, (_, names) in enumerate(SIM_LAYERS):
        if short in names:
            return rank
    raise AssertionError(f"{module} belongs to no sub-layer: add it to SIM_LAYERS in {__file__}")


@pytest.mark.parametrize(
    "name", sorted(n for n in MODULES if n.startswith("microsim.sim.") and not n.endswith("sim"))
)
def test_no_sim_module_imports_a_higher_sim_sub_layer(name):
    up = sorted(
        t for t in GRAPH[name] if t.startswith("microsim.sim.") and _sim_layer(t) > _sim_layer(name)
    )
    level = SIM_LAYERS[_sim_layer(name)][0]
    assert not up, f"{name} ({level}) imports from above its sub-layer: {up}"


def _outside_parentheses(text: str) -> str:
    """``text`` without its parenthesised parts (nested ones included)."""
    out, depth = [], 0
    for ch in text:
        depth += ch == "("
        if depth == 0:
            out.append(ch)
        depth -= ch == ")" and depth > 0
    return "".join(out)


def _package_of(path: str) -> str:
    """A package as the table writes it (``microsim/app/``, ``app/runner``, ``testing``) → its
    dotted name."""
    parts = path.strip("/").split("/")
    return ".".join(parts if parts[0] == "microsim" else ["microsim", *parts])


def _layout_table() -> tuple[set[str], set[str]]:
    """(packages, modules) docs/layout.md's package layout table names, dotted. A row's second
    column lists its packages; its third the modules of the first one and, after a prefix
    such as "`runner/`:", those of the row's package ending in that name. Names mentioned only
    inside parentheses (a module's description) are not counted."""
    layout = (PACKAGE.parent / "docs" / "layout.md").read_text(encoding="utf-8")
    table = layout[layout.index("### Package layout") :]
    table = table[: table.index("\n## ")]
    packages, modules = set(), set()
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3 or cells[0] == "layer" or not cells[0].strip("-"):
            continue
        row = [_package_of(p) for p in re.findall(r"`([\w/]+)`", cells[1])]
        packages.update(row)
        current = row[0]
        for name, colon in re.findall(r"`([\w/]+)`(:?)", _outside_parentheses(cells[2])):
            if name.endswith("/") and colon:
                current = next(p for p in row if p.endswith("." + name.strip("/")))
            else:
                modules.add(f"{current}.{name}")
    return packages, modules


def test_the_layout_table_names_every_module_of_every_package():
    """Each module is named under its own package (``testing/measured`` is not named by the
    ``measured`` package, nor ``sim/cluster`` by ``app/cluster``), and every name exists."""
    packages, modules = _layout_table()
    paths = list(PACKAGE.rglob("*.py"))
    real_packages = {_module_name(p) for p in paths if p.name == "__init__.py"}
    real_modules = {_module_name(p) for p in paths if p.name not in ("__init__.py", "__main__.py")}
    assert packages == real_packages, (
        f"docs/layout.md's package column lacks {sorted(real_packages - packages)}, "
        f"names no such package {sorted(packages - real_packages)}"
    )
    assert modules == real_modules, (
        f"docs/layout.md's package layout table lacks {sorted(real_modules - modules)}, "
        f"names no such module {sorted(modules - real_modules)}"
    )
