"""Benchmark of the unit FE model (issue 4 item 9): not a test, a timing table.

Per case (2D/3D, element size, contact on/off, free/blocked): DOFs, wall time
from 0 to P_T = 300 kPa (P_B = 0), Newton iterations, load steps, cut-backs,
assembly vs linear-solve time, peak memory (ru_maxrss of the child process),
the angle/moment, and FElupe's time on the same 2D mesh without contact.
Each case runs in its own process so that the peak memory is per case.

    python benchmarks/bench_fem.py              # default table -> benchmarks/out/bench_fem.csv
    python benchmarks/bench_fem.py --quick      # coarse cases only
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import resource
import sys
import time
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / "out"


def _case(args):
    dim, h, contact, case, p = args
    from workflow import fem

    um = fem.build_unit_mesh(h=h, dim=dim)
    r = fem.solve_unit(um, p, 0.0, case, contact)
    row = {k: v for k, v in r.as_dict().items() if k != "history"}
    row.update(h_mm=h, code="workflow.fem", peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    return row


def _felupe_case(args):
    dim, h, p = args
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from test_fem_felupe import felupe_free_angles

    from workflow import fem

    um = fem.build_unit_mesh(h=h, dim=dim)
    t0 = time.perf_counter()
    ang = felupe_free_angles(um, [p], fem.material_constants({}))
    return {"dim": dim, "h_mm": h, "case": "free", "contact": False, "code": "felupe (60 fixed steps)",
            "wall_time_s": time.perf_counter() - t0, "bending_angle_total_deg": float(ang[0]),
            "bending_angle_deg": float(ang[0]) / 3, "ndofs": 2 * um.mesh.p.shape[1], "status": 0,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def run_isolated(fun, args):
    with mp.get_context("spawn").Pool(1) as pool:
        return pool.apply(fun, (args,))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--p", type=float, default=300.0)
    ap.add_argument("--no-3d", action="store_true")
    ap.add_argument("--h2", type=float, nargs="*", default=None, help="2D element sizes (mm)")
    ap.add_argument("--h3", type=float, nargs="*", default=None, help="3D element sizes (mm)")
    a = ap.parse_args()
    h2 = a.h2 if a.h2 is not None else ([1.0] if a.quick else [1.0, 0.5, 0.25])
    h3 = a.h3 if a.h3 is not None else ([2.0] if a.quick else [2.0, 1.0])
    cases = [(2, h, c, k, a.p) for h in h2 for c in (False, True) for k in ("free", "blocked")]
    if not a.no_3d:
        cases += [(3, h, c, k, a.p) for h in h3 for c in (False, True) for k in ("free", "blocked")]
    rows = []
    OUT.mkdir(parents=True, exist_ok=True)
    for c in cases:
        row = run_isolated(_case, c)
        rows.append(row)
        print(json.dumps({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()}), flush=True)
    for h in h2:
        try:
            row = run_isolated(_felupe_case, (2, h, a.p))
        except Exception as exc:  # FElupe is optional; record why it is missing
            row = {"dim": 2, "h_mm": h, "code": "felupe", "status": 3, "reason": repr(exc)}
        rows.append(row)
        print(json.dumps(row), flush=True)
    import pandas as pd

    df = pd.DataFrame(rows)
    tag = "_".join(["2d"] + [f"{h:g}" for h in h2] + (["3d"] + [f"{h:g}" for h in h3] if not a.no_3d else []))
    df.to_csv(OUT / f"bench_fem_{tag}.csv", index=False)
    cols = ["code", "dim", "h_mm", "contact", "case", "ndofs", "status", "load_factor", "wall_time_s", "assembly_time_s",
            "solve_time_s", "newton_iterations", "steps", "cutbacks", "bending_angle_deg", "bending_moment_nm",
            "max_penetration_mm", "peak_rss_mb"]
    print(df[[c for c in cols if c in df]].to_string(index=False))


if __name__ == "__main__":
    main()
