"""Compare two results trees dataset by dataset: did a change leave every number where it was?

Usage::

    python benchmarks/compare_results.py RESULTS_A RESULTS_B [--tol 1e-9]

Every ``.nc`` file under ``RESULTS_A`` is opened beside the same path under
``RESULTS_B``; every data variable and coordinate must agree to ``tol``
(``|a - b| <= tol * (1 + |b|)``, NaN equal to NaN, inf to inf, strings exactly).  Left
out: wall times and memory peaks (they are measurements of the machine, not
results), all attributes (provenance: commit, code hash, package versions) and the
run ledger's copies of the datasets (``tracking/artifacts/<random run id>/``).
Exits 1 and lists the differences when any value differs or a file or
variable is missing on one side.  Not a test: a tool for refactors.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np
import xarray as xr

#: Variables that measure the run rather than the result (and the Pareto flags, which rank those times).
MEASURED = re.compile(r"wall_time|time_s$|_seconds$|peak_rss|peak_mb|tracemalloc|elapsed|^pareto$")
#: A wall time quoted inside a text (a choice's reason): masked before strings are compared.
QUOTED_TIME = re.compile(r"\d+(\.\d+)?(e[+-]?\d+)? s\b")


def _masked(v: np.ndarray) -> np.ndarray:
    return np.vectorize(lambda s: QUOTED_TIME.sub("<t> s", str(s)), otypes=[object])(v) if v.size else v.astype(str)


def compare_datasets(a: xr.Dataset, b: xr.Dataset, tol: float) -> list[str]:
    """Differences between two datasets (data variables and coordinates), as messages."""
    out = []
    names_a = {n for n in [*a.data_vars, *a.coords] if not MEASURED.search(str(n))}
    names_b = {n for n in [*b.data_vars, *b.coords] if not MEASURED.search(str(n))}
    for n in sorted(names_a ^ names_b, key=str):
        out.append(f"{n}: only in {'A' if n in names_a else 'B'}")
    for n in sorted(names_a & names_b, key=str):
        va, vb = a[n].values, b[n].values
        if va.shape != vb.shape:
            out.append(f"{n}: shape {va.shape} vs {vb.shape}")
            continue
        if va.dtype.kind in "fciub" and vb.dtype.kind in "fciub":
            x, y = va.astype(float), vb.astype(float)
            with np.errstate(invalid="ignore"):  # inf - inf
                same = (np.isnan(x) & np.isnan(y)) | (x == y) | (np.abs(x - y) <= tol * (1.0 + np.abs(y)))
            if not np.all(same):
                k = int(np.argmax(~same.ravel()))
                out.append(
                    f"{n}: {int(np.count_nonzero(~same))} of {same.size} values differ "
                    f"(first: {x.ravel()[k]!r} vs {y.ravel()[k]!r})"
                )
        elif not np.array_equal(_masked(va), _masked(vb)):
            out.append(f"{n}: values differ")
    return out


def _ledger_copy(rel: Path) -> bool:
    """MLflow's copies of the datasets (under a random run id): the originals are compared instead."""
    return rel.parts[:2] == ("tracking", "artifacts")


def compare_trees(root_a: Path, root_b: Path, tol: float) -> dict[str, list[str]]:
    """Per relative path, the differences (empty list: equal)."""
    files_a = {p.relative_to(root_a) for p in root_a.rglob("*.nc") if not _ledger_copy(p.relative_to(root_a))}
    files_b = {p.relative_to(root_b) for p in root_b.rglob("*.nc") if not _ledger_copy(p.relative_to(root_b))}
    report = {str(f): [f"only in {'A' if f in files_a else 'B'}"] for f in sorted(files_a ^ files_b)}
    for f in sorted(files_a & files_b):
        with xr.open_dataset(root_a / f) as a, xr.open_dataset(root_b / f) as b:
            report[str(f)] = compare_datasets(a.load(), b.load(), tol)
    return report


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("--tol", type=float, default=1e-9)
    args = ap.parse_args(argv)
    report = compare_trees(args.a, args.b, args.tol)
    bad = {f: d for f, d in report.items() if d}
    for f, d in report.items():
        print(f"{'DIFFERS' if d else 'equal  '} {f}")
        for line in d:
            print(f"          {line}")
    print(
        f"{len(report) - len(bad)} of {len(report)} datasets equal to {args.tol:g} (wall times and attributes left out)"
    )
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
