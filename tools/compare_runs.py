"""Compare two folders of runs bitwise: for every run folder in A, each brdf.npz array (NaN
equal to NaN), verdicts.json and report.md byte for byte, and index.md. Used to check that a
refactoring changes no result. Usage: .venv/bin/python tools/compare_runs.py A B"""

import sys
from pathlib import Path

import numpy as np


def differences(a: Path, b: Path) -> list[str]:
    out = []
    for da in sorted(p for p in a.iterdir() if p.is_dir()):
        db = b / da.name
        if not db.is_dir():
            out.append(f"missing {da.name}")
            continue
        if (da / "brdf.npz").exists():
            with np.load(da / "brdf.npz") as za, np.load(db / "brdf.npz") as zb:
                if sorted(za.files) != sorted(zb.files):
                    out.append(f"arrays {da.name}: {sorted(set(za.files) ^ set(zb.files))}")
                out += [
                    f"array {da.name} {k}"
                    for k in za.files
                    if k in zb.files and not np.array_equal(za[k], zb[k], equal_nan=True)
                ]
        for f in ("verdicts.json", "report.md"):
            if (da / f).exists() and (da / f).read_bytes() != (db / f).read_bytes():
                out.append(f"file {da.name}/{f}")
    if (a / "index.md").exists() and (a / "index.md").read_bytes() != (b / "index.md").read_bytes():
        out.append("file index.md")
    return out


if __name__ == "__main__":
    diffs = differences(Path(sys.argv[1]), Path(sys.argv[2]))
    print("\n".join(diffs + [f"{len(diffs)} differences" if diffs else "bitwise equal"]))
    sys.exit(1 if diffs else 0)
