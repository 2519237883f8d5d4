"""Structure measures of the package: the largest modules, each sub-package's share of the
lines, the longest parameter lists and the functions over 80 lines (AST count, docstrings
included). Usage: .venv/bin/python tools/structure_metrics.py [package_dir]"""

import ast
import sys
from pathlib import Path


def main(pkg: Path) -> None:
    files = sorted(pkg.rglob("*.py"))
    lines = {f: len(f.read_text(encoding="utf-8").splitlines()) for f in files}
    total = sum(lines.values())
    print(f"total lines {total}")
    for f, n in sorted(lines.items(), key=lambda x: -x[1])[:5]:
        print(f"  {n:5d} {f}")
    for sub in sorted({f.relative_to(pkg).parts[0] for f in files if f.parent != pkg}):
        share = sum(n for f, n in lines.items() if f.relative_to(pkg).parts[0] == sub)
        print(f"{sub}/ {share} lines = {100 * share / total:.1f} %")
    params, long = [], []
    for f in files:
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = node.args
                n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs)
                n += bool(a.vararg) + bool(a.kwarg)
                where = f"{f}:{node.lineno} {node.name}"
                params.append((n, where))
                if node.end_lineno - node.lineno + 1 > 80:
                    long.append((node.end_lineno - node.lineno + 1, where))
    print("longest parameter lists:")
    for n, where in sorted(params, reverse=True)[:5]:
        print(f"  {n} {where}")
    print(f"functions over 80 lines: {len(long)}")
    for n, where in sorted(long, reverse=True):
        print(f"  {n} {where}")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "microsim"))
