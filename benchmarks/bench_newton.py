"""Newton with contact against its targets, and what the convergence tolerance buys.  Not a test: a table.

Cases (P_B = 0, contact on, the workflow's element technology and solver unless said):

* the 2D unit at h = 1 mm (the sweeps' mesh), free and blocked, 0 -> 300 kPa, with the stops at 60 and
  180 kPa the unit check uses: load steps, cut-backs, Newton iterations (accepted steps and all attempts),
  median iterations per accepted step, wall time;
* the same rays at residual tolerances rtol = 1e-8, 1e-6 (default), 1e-4 and 3e-2 (the paper's 0.03 in MSC Marc,
  there on residual and displacement): whether the ray reaches 300 kPa, the free angle and blocked moment at
  60 / 180 / 300 kPa and their change against rtol = 1e-8;
* the 3D unit at h = 2 mm (the 3D sweeps' mesh), free, one ray to 300 kPa (``--no-3d`` leaves it out).

With ``--compare-lag`` each ray at the default tolerance runs twice in one run, with the tangent's volumetric
initial-stress pressure taken from the actual element volume and from the lagged (linearised) one (the default,
``workflow.fem._assembly.LAGGED_PRESSURE``), the 3D blocked ray added: same values, and the ratio of the two times.

With ``--compare-band`` the 3D rays (h = 1.4 mm, the FE study's pick, and 2 mm; free and blocked) run on the
0.01 mm contact band (2D's, and 3D's before) and on the 3D default (0.02 mm), the two of a pair at once in two
processes (one core each): iterations, the values and their change, and the time ratio.

With ``--compare-search`` the 3D rays (h = 2 mm free and blocked, h = 1.4 mm blocked) run twice in one run, with
and without the two savings that leave the path unchanged: the 3D contact search skipping slaves out of reach of
every facet (``workflow.fem._contact.REACH_FILTER``) and PARDISO's analysed pattern widened by a halo round new
entries (``DirectSolver.halo``): same values, the time ratio and the analyses.

With ``--compare-tolerance`` the 3D rays (h = 1.4 and 2 mm, free and blocked) run at the residual tolerance
rtol = 1e-6 (2D's, and 3D's before) beside the 3D default (rtol = 1e-2 and the increment test at 1e-2), then at
rtol = 1e-4 beside the paper's 0.03 on residual and increment, each pair at once: the values and their change
against 1e-6, and each pair's time ratio.

Each case runs in its own process with one BLAS / MKL thread.  Results: ``benchmarks/out/bench_newton.{json,md}``
(``bench_newton_lag.{json,md}`` with ``--compare-lag``, ``bench_newton_search.{json,md}`` with ``--compare-search``,
``bench_newton_band.{json,md}`` with ``--compare-band``, ``bench_newton_tolerance.{json,md}`` with
``--compare-tolerance``).

    python benchmarks/bench_newton.py [--no-3d] [--compare-lag | --compare-search | --compare-band | --compare-tolerance]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "out"
sys.path.insert(0, str(ROOT))
STOPS = (0.2, 0.6)  # 60 and 180 kPa on the 300 kPa ray
TOLERANCES = (1e-8, 1e-6, 1e-4, 3e-2)

#: Targets of the Newton work, and what each row of the table measures.
TARGETS = {
    "median_iterations": "median Newton iterations per converged step with contact <= 5",
    "steps_2d": "2D unit to 300 kPa in <= 20 load steps without cut-backs",
    "time_3d": "3D unit per ray at the mesh the FE study picks <= 2 min",
}


def _case(
    dim: int, h: float, case: str, solver: dict, lag: bool | None, queue, search: bool | None = None, band=None
) -> None:
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = "1"
    from workflow import fem
    from workflow.fem import _assembly, _contact, _linsolve, _solve

    solver = dict(solver)
    tag = solver.pop("tag", None)  # the ray's place in a side-by-side run
    if lag is not None:
        _assembly.LAGGED_PRESSURE = lag
    if search is not None:
        _contact.REACH_FILTER = search
        _linsolve.default_solver.halo = search

    t0 = time.perf_counter()
    copts = None if band is None else {"smoothing_mm": band}
    res = fem.solve_unit(
        {"dim": dim, "h": h}, 300.0, 0.0, case=case, contact=True, contact_options=copts, solver=solver, stops=STOPS
    )
    wall = time.perf_counter() - t0
    key = "bending_angle_deg" if case == "free" else "bending_moment_nm"
    resolved = _solve.by_dimension({**fem.DEFAULT_SOLVER, **solver}, dim)  # the settings the ray ran with
    at = {round(300.0 * hh["lam"]): hh[key] for hh in res.history if any(abs(hh["lam"] - s) < 1e-9 for s in STOPS)}
    if res.status == 0:
        at[300] = getattr(res, key)
    its = [int(hh["iterations"]) for hh in res.history]
    queue.put(
        {
            "tag": tag,
            "dim": dim,
            "h_mm": h,
            "case": case,
            "lagged_pressure": bool(_assembly.LAGGED_PRESSURE),
            "rtol": resolved["rtol"],
            "utol": resolved["utol"],
            "band_mm": fem.contact_band({} if copts is None else copts, dim),
            "status": int(res.status),
            "load_factor": float(res.load_factor),
            "steps": len(res.history),
            "cutbacks": int(res.cutbacks),
            "iterations_accepted": int(sum(its)),
            "iterations_all": int(res.newton_iterations),
            "median_iterations": float(np.median(its)) if its else float("nan"),
            "wall_s": round(wall, 2),
            "value_at_kpa": {str(k): float(v) for k, v in sorted(at.items())},
            "quantity": key,
            "linear_solver": _linsolve.default_solver.backend,
            "search_savings": bool(_contact.REACH_FILTER and _linsolve.default_solver.halo),
            "analyses": int(_linsolve.default_solver.stats["analyses"]),
            "factorisations": int(_linsolve.default_solver.stats["factorisations"]),
        }
    )


def run_case(
    dim: int, h: float, case: str, solver: dict | None = None, lag: bool | None = None, search: bool | None = None
) -> dict:
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    proc = ctx.Process(target=_case, args=(dim, h, case, dict(solver or {}), lag, q, search))
    proc.start()
    out = q.get()
    proc.join()
    print(json.dumps(out), flush=True)
    return out


def run_pair(dim: int, h: float, case: str, solvers: tuple, bands: tuple | None = None) -> list[dict]:
    """One ray per setting (a solver dict, and a contact band where ``bands`` gives one; None: the default), each in
    its own process, all at once (one core each, the same machine load), returned in the order given."""
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    bands = bands or (None,) * len(solvers)
    procs = [
        ctx.Process(target=_case, args=(dim, h, case, dict(s, tag=i), None, q, None, b))
        for i, (s, b) in enumerate(zip(solvers, bands))
    ]
    for p in procs:
        p.start()
    out = sorted((q.get() for _ in procs), key=lambda r: r["tag"])
    for p in procs:
        p.join()
    for r in out:
        print(json.dumps(r), flush=True)
    return out


def _utol(value) -> str:
    return "none" if value is None or value == float("inf") else f"{value:g}"


def _pairs_markdown(rows: list[dict], setting: dict) -> str:
    """The rays of side-by-side runs (``run_pair``): ``setting`` = {column header: the row's cell}; each value's
    change against the first row of its case, each time against the first ray of its pair."""
    lines = [
        "| case | "
        + " | ".join(setting)
        + " | reached | steps | cut-backs | iterations (all attempts) | median it./step "
        "| wall s | value at 60 / 180 / 300 kPa | change against the case's first row | time ratio in its pair |",
        "|---|" + "---|" * len(setting) + "---|---|---|---|---|---|---|---|---|",
    ]
    first = {}
    for i, r in enumerate(rows):
        ref = first.setdefault((r["dim"], r["h_mm"], r["case"]), r)
        vals = [r["value_at_kpa"].get(p) for p in ("60", "180", "300")]
        refs = [ref["value_at_kpa"].get(p) for p in ("60", "180", "300")]
        change = " / ".join(
            "" if v is None or v0 is None else f"{100 * (v - v0) / abs(v0):+.4f} %" for v, v0 in zip(vals, refs)
        )
        ratio = f"{r['wall_s'] / rows[i - r['tag']]['wall_s']:.2f}" if r["tag"] else ""
        values = " / ".join("stopped" if v is None else f"{v:.7g}" for v in vals)
        lines.append(
            f"| {r['dim']}D h = {r['h_mm']} {r['case']} | " + " | ".join(cell(r) for cell in setting.values()) + " | "
            f"{100 * r['load_factor']:.0f} % | {r['steps']} | {r['cutbacks']} | {r['iterations_accepted']} "
            f"({r['iterations_all']}) | {r['median_iterations']:g} | {r['wall_s']:.1f} | {values} | "
            f"{'' if r is ref else change} | {ratio} |"
        )
    return "\n".join(lines) + "\n"


def _markdown(rows: list[dict]) -> str:
    lines = ["| case | rtol | reached | steps | cut-backs | iterations (all attempts) | median it./step | wall s |"]
    lines.append("|---|---|---|---|---|---|---|---|")
    for r in rows:
        lines.append(
            f"| {r['dim']}D h = {r['h_mm']} {r['case']} | {r['rtol']:g} | {100 * r['load_factor']:.0f} % | "
            f"{r['steps']} | {r['cutbacks']} | {r['iterations_accepted']} ({r['iterations_all']}) | "
            f"{r['median_iterations']:g} | {r['wall_s']:.1f} |"
        )
    lines += ["", "Tolerance study (2D h = 1 mm): value and change against rtol = 1e-8", ""]
    lines.append("| case | rtol | 60 kPa | 180 kPa | 300 kPa |")
    lines.append("|---|---|---|---|---|")
    ref = {r["case"]: r["value_at_kpa"] for r in rows if r["dim"] == 2 and r["rtol"] == TOLERANCES[0]}
    for r in rows:
        if r["dim"] != 2 or r["case"] not in ref:
            continue
        cells = []
        for p in ("60", "180", "300"):
            v, v0 = r["value_at_kpa"].get(p), ref[r["case"]].get(p)
            cells.append("stopped" if v is None else f"{v:.6g} ({100 * (v - v0) / abs(v0):+.3f} %)")
        lines.append(f"| {r['case']} | {r['rtol']:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _lag_markdown(rows: list[dict]) -> str:
    lines = [
        "| case | volumetric pressure in the tangent | reached | steps | cut-backs | iterations (all attempts) "
        "| median it./step | wall s | value at 300 kPa | time ratio lagged / actual |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    by = {(r["dim"], r["case"], r["lagged_pressure"]): r for r in rows}
    for r in rows:
        other = by.get((r["dim"], r["case"], False))
        ratio = f"{r['wall_s'] / other['wall_s']:.2f}" if r["lagged_pressure"] and other else ""
        v = r["value_at_kpa"].get("300")
        lines.append(
            f"| {r['dim']}D h = {r['h_mm']} {r['case']} | {'lagged' if r['lagged_pressure'] else 'actual'} | "
            f"{100 * r['load_factor']:.0f} % | {r['steps']} | {r['cutbacks']} | {r['iterations_accepted']} "
            f"({r['iterations_all']}) | {r['median_iterations']:g} | {r['wall_s']:.1f} | "
            f"{'stopped' if v is None else f'{v:.7g}'} | {ratio} |"
        )
    return "\n".join(lines) + "\n"


def _search_markdown(rows: list[dict]) -> str:
    lines = [
        "| case | reach filter and halo | reached | steps | iterations (all attempts) | PARDISO analyses / "
        "factorisations | wall s | value at 300 kPa | time ratio with / without |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    by = {(r["dim"], r["h_mm"], r["case"], r["search_savings"]): r for r in rows}
    for r in rows:
        other = by.get((r["dim"], r["h_mm"], r["case"], False))
        ratio = f"{r['wall_s'] / other['wall_s']:.2f}" if r["search_savings"] and other else ""
        v = r["value_at_kpa"].get("300")
        lines.append(
            f"| {r['dim']}D h = {r['h_mm']} {r['case']} | {'on' if r['search_savings'] else 'off'} | "
            f"{100 * r['load_factor']:.0f} % | {r['steps']} | {r['iterations_accepted']} ({r['iterations_all']}) | "
            f"{r['analyses']} / {r['factorisations']} | {r['wall_s']:.1f} | "
            f"{'stopped' if v is None else f'{v:.7g}'} | {ratio} |"
        )
    return "\n".join(lines) + "\n"


def _write(stem: str, data: dict, markdown: str) -> int:
    """``benchmarks/out/<stem>.json`` and ``.md``; the table printed too."""
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / f"{stem}.json").write_text(json.dumps(data, indent=2))
    (OUT / f"{stem}.md").write_text(markdown)
    print(markdown)
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--no-3d", action="store_true", help="leave out the 3D rays")
    ap.add_argument("--compare-lag", action="store_true", help="each ray with the actual and the lagged pressure")
    ap.add_argument("--compare-search", action="store_true", help="3D rays with and without the search savings")
    ap.add_argument(
        "--compare-band",
        action="store_true",
        help="3D rays at 1.4 and 2 mm on the 0.01 mm band and the 3D default, side by side",
    )
    ap.add_argument(
        "--compare-tolerance",
        action="store_true",
        help="3D rays at 1.4 and 2 mm: rtol 1e-6 beside the 3D default, then 1e-4 beside the paper's 0.03 / 0.03",
    )
    args = ap.parse_args(argv)
    rows = []
    if args.compare_tolerance:
        off = float("inf")  # no increment test
        pairs = (({"rtol": 1e-6, "utol": off}, {}), ({"rtol": 1e-4, "utol": off}, {"rtol": 0.03, "utol": 0.03}))
        for h, case in ((1.4, "free"), (1.4, "blocked"), (2.0, "free"), (2.0, "blocked")):
            for pair in pairs:
                rows += run_pair(3, h, case, pair)
        table = _pairs_markdown(rows, {"rtol": lambda r: f"{r['rtol']:g}", "utol": lambda r: _utol(r["utol"])})
        return _write("bench_newton_tolerance", {"targets": TARGETS, "rows": rows}, table)
    if args.compare_band:
        for h, case in ((1.4, "free"), (1.4, "blocked"), (2.0, "free"), (2.0, "blocked")):
            rows += run_pair(3, h, case, ({}, {}), bands=(0.01, None))  # None: the 3D default band
        table = _pairs_markdown(rows, {"band (mm)": lambda r: f"{r['band_mm']:g}"})
        return _write("bench_newton_band", {"targets": TARGETS, "rows": rows}, table)
    if args.compare_search:
        for dim, h, case in ((3, 2.0, "blocked"), (3, 2.0, "free"), (3, 1.4, "blocked")):
            for search in (False, True):
                rows.append(run_case(dim, h, case, {}, None, search))
        return _write("bench_newton_search", {"rows": rows}, _search_markdown(rows))
    if args.compare_lag:
        cases = [(2, 1.0, "free"), (2, 1.0, "blocked")] + (
            [] if args.no_3d else [(3, 2.0, "free"), (3, 2.0, "blocked")]
        )
        for dim, h, case in cases:
            for lag in (False, True):
                rows.append(run_case(dim, h, case, {}, lag))
        return _write("bench_newton_lag", {"targets": TARGETS, "rows": rows}, _lag_markdown(rows))
    for case in ("free", "blocked"):
        for rtol in TOLERANCES:
            rows.append(run_case(2, 1.0, case, {"rtol": rtol}))
    if not args.no_3d:
        rows.append(run_case(3, 2.0, "free", {}))
    return _write("bench_newton", {"targets": TARGETS, "rows": rows}, _markdown(rows))


if __name__ == "__main__":
    raise SystemExit(main())
