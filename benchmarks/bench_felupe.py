"""Mesh-converged free angle of the unit without contact: ours (enhanced paper) against FElupe (Q1), extrapolated.

FElupe has no equivalent of our enhanced-strain (incompatible-mode) paper
layer, so per mesh the two codes differ (its Q1 paper shear-locks in bending);
both should converge to the same continuum solution.  For each mesh of a
sequence: the total free bending angle (deg; per unit = total / 3) of the
unit (Chung & Venter 2024, section 2.4; Table 5 silicone, paper E = 1200 MPa,
nu = 0.2) at P_T = 60/180/300 kPa, P_B = 0, without contact, from

* ours, ``formulation="enhanced_paper"`` (the default),
* FElupe (tests/_felupe_unit.py: mean-dilatation Q1 silicone, Q1 paper),
* optionally ours ``formulation="mixed"`` (``--mixed-dims``): the same
  technology as FElupe's, which must match it per mesh,

with each solve's wall time (same run, one after the other), then per code and
pressure the Richardson extrapolation of the three finest meshes: observed
order p = ln((f1 - f2) / (f2 - f3)) / ln r and limit f3 + (f3 - f2) / (r^p - 1)
(f1 coarse ... f3 fine, r the ratio of representative element sizes
h_eff = (V / n_cells)^(1/dim); where the two ratios differ (3D: 2 -> 1.4 -> 1
mm is not nested) the generalised form d12 / d23 = r32^p (r21^p - 1) /
(r32^p - 1), solved for p by fixed point, Celik et al. 2008, J. Fluids Eng.
130:078001).  The two codes' limits are compared (target: within 2 %).

    OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 python benchmarks/bench_felupe.py          # 2D 1/0.5/0.25, 3D 2/1.4/1 mm
    python benchmarks/bench_felupe.py --h3 2 1.4                # 3D without the 1 mm mesh
    python benchmarks/bench_felupe.py --h2 --h3 1 --append      # add solves to the CSV already there

-> benchmarks/out/bench_felupe.csv (one row per solve), bench_felupe_richardson.csv,
bench_felupe.md (the tables, also printed).  Timings on a shared machine are
noisy: compare within one run.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # before numpy / PARDISO load: one thread unless asked otherwise

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "out"
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # this checkout's workflow package; the FElupe model

from workflow import fem  # noqa: E402

P_KPA = np.array([60.0, 180.0, 300.0])
KEY = ["code", "dim", "h_mm"]


def h_eff(um) -> float:
    """Representative element size (V / n_cells)^(1/dim), mm."""
    solid = fem.SolidAssembler(um.mesh, um.material, fem.material_constants({}))
    return float((solid.volume.sum() / solid.volume.size) ** (1.0 / um.dim))


def solve_ours(um, formulation: str, atol: float | None = None, solver: dict | None = None) -> dict:
    solver = dict(solver or {})
    if atol is not None:
        # the same absolute residual as FElupe's, and no increment test (utol = inf; 3D's default has one)
        solver.update(rtol=0.0, atol=atol, utol=float("inf"))
    res = fem.solve_unit(
        um, P_KPA[-1], 0.0, "free", False, formulation=formulation, stops=tuple(P_KPA / P_KPA[-1]), solver=solver
    )
    at = {round(r["p_top_kpa"], 6): r["bending_angle_total_deg"] for r in res.history}
    row = {
        "status": res.status,
        "reason": res.reason,
        "p_reached_kpa": res.load_factor * P_KPA[-1],
        "wall_time_s": res.wall_time_s,
        "steps": res.steps,
        "iterations": res.newton_iterations,
        "cutbacks": res.cutbacks,
    }
    row.update({f"theta_{int(q)}_deg": at.get(round(q, 6), np.nan) for q in P_KPA})
    return row


def solve_felupe(um, nsteps: int, atol: float | None = None) -> dict:
    from _felupe_unit import felupe_free_angles

    info = {}
    # partial: if its cut-back gives up, the pressures reached still count (NaN beyond)
    ang = felupe_free_angles(um, P_KPA, fem.material_constants({}), nsteps=nsteps, info=info, partial=True, atol=atol)
    row = {
        "status": info["status"],
        "reason": info["reason"][:160],
        "p_reached_kpa": info["p_reached_kpa"],
        "wall_time_s": info["wall_time_s"],
        "steps": info["increments"],
        "iterations": np.nan,
        "cutbacks": info["cutbacks"],
    }
    row.update({f"theta_{int(q)}_deg": float(a) for q, a in zip(P_KPA, ang)})
    return row


def richardson(h, f) -> dict:
    """Observed order and limit from three meshes (any order of ``h``; h in mm, f the values)."""
    order = np.argsort(h)[::-1]  # coarse first
    h1, h2, h3 = np.asarray(h, float)[order]
    f1, f2, f3 = np.asarray(f, float)[order]
    r21, r32 = h1 / h2, h2 / h3
    d12, d23 = f1 - f2, f2 - f3
    out = {"r21": r21, "r32": r32, "order": np.nan, "limit": np.nan, "monotone": bool(d12 * d23 > 0)}
    if not out["monotone"]:
        return out  # oscillating (or no change): no order
    q = np.log(d12 / d23)
    p = q / np.log(r32)
    if not np.isclose(r21, r32, rtol=1e-6):
        for _ in range(200):  # d12 / d23 = r32^p (r21^p - 1) / (r32^p - 1)
            if p <= 0:
                break
            p_new = (q - np.log((r21**p - 1.0) / (r32**p - 1.0))) / np.log(r32)
            if abs(p_new - p) < 1e-12:
                p = p_new
                break
            p = p_new
    out["order"] = p
    if p > 0:
        out["limit"] = f3 + (f3 - f2) / (r32**p - 1.0)
    return out


def tables(df: pd.DataFrame):
    """Richardson rows (per dim, code, pressure) and the comparison of the limits."""
    rich = []
    for (dim, code), grp in df.groupby(["dim", "code"]):
        for q in P_KPA:
            col = f"theta_{int(q)}_deg"
            sub = grp[np.isfinite(grp[col])].sort_values("h_eff_mm").iloc[:3]  # the three finest that reached q
            if len(sub) < 3:
                continue
            f = sub[col].to_numpy()
            r = richardson(sub.h_eff_mm.to_numpy(), f)
            rich.append(
                {
                    "dim": dim,
                    "code": code,
                    "p_kpa": q,
                    "h_mm": "/".join(f"{v:g}" for v in sub.h_mm[::-1]),
                    "coarse": f[2],
                    "medium": f[1],
                    "fine": f[0],
                    **r,
                    "fine_error_pct": 100 * (f[0] / r["limit"] - 1),
                }
            )
    rich = pd.DataFrame(rich)
    comp = []
    if len(rich):
        for (dim, q), sub in rich.groupby(["dim", "p_kpa"]):
            lim = dict(zip(sub.code, sub.limit))
            if "ours enhanced_paper" in lim and "felupe Q1" in lim:
                a, b = lim["ours enhanced_paper"], lim["felupe Q1"]
                comp.append(
                    {"dim": dim, "p_kpa": q, "ours_limit_deg": a, "felupe_limit_deg": b, "diff_pct": 100 * (a / b - 1)}
                )
    return rich, pd.DataFrame(comp)


def to_markdown(df: pd.DataFrame, fmt: str = "{:.4g}") -> str:
    def cell(v):
        if isinstance(v, (float, np.floating)):
            return "" if np.isnan(v) else fmt.format(v)
        return str(v)

    lines = ["| " + " | ".join(map(str, df.columns)) + " |", "|" + "---|" * len(df.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--h2", type=float, nargs="*", default=[1.0, 0.5, 0.25], help="2D element sizes, mm")
    ap.add_argument("--h3", type=float, nargs="*", default=[2.0, 1.4, 1.0], help="3D element sizes, mm")
    ap.add_argument(
        "--mixed-dims",
        type=int,
        nargs="*",
        default=[2],
        help="also solve ours with formulation mixed (FElupe's technology) in these dims",
    )
    ap.add_argument(
        "--felupe-steps",
        type=lambda v: [float(x) for x in v.split(",")] if "," in v else int(v),
        default=20,
        help="FElupe substeps (cut back where one fails): a number of equal ones, or their end pressures in kPa, "
        "e.g. 60,180,300",
    )
    ap.add_argument(
        "--atol",
        type=float,
        default=None,
        help="both codes converge on this absolute residual of the free dofs (N); default: each its own "
        "(ours 1e-6 relative to |f_ext| + |reactions|, FElupe 1e-8 relative to the reactions)",
    )
    ap.add_argument(
        "--solver",
        type=json.loads,
        default={},
        help="our step settings, JSON (workflow.fem DEFAULT_SOLVER keys), e.g. "
        '\'{"predictor": true, "line_search": false, "grow_below_iter": 4}\'',
    )
    ap.add_argument("--append", action="store_true", help="keep the rows of the CSV already there, skip their solves")
    ap.add_argument("--tag", default="bench_felupe", help="output file stem in benchmarks/out")
    a = ap.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    csv = OUT / f"{a.tag}.csv"
    rows = pd.read_csv(csv).to_dict("records") if a.append and csv.is_file() else []
    setting = {
        "atol": np.nan if a.atol is None else a.atol,
        "solver": json.dumps(a.solver, sort_keys=True),
        "felupe_steps": str(a.felupe_steps),
    }
    done = {(r["code"], int(r["dim"]), float(r["h_mm"]), r.get("solver", "{}"), r.get("atol")) for r in rows}
    for dim, hs in ((2, a.h2), (3, a.h3)):
        for h in hs:
            um = fem.build_unit_mesh(h=h, dim=dim)
            base = {
                "dim": dim,
                "h_mm": h,
                "h_eff_mm": h_eff(um),
                "ndofs": dim * um.mesh.p.shape[1],
                "cells": um.mesh.t.shape[1],
            }
            solves = [
                ("ours enhanced_paper", lambda: solve_ours(um, "enhanced_paper", a.atol, a.solver)),
                ("felupe Q1", lambda: solve_felupe(um, a.felupe_steps, a.atol)),
            ]
            if dim in a.mixed_dims:
                solves.append(("ours mixed", lambda: solve_ours(um, "mixed", a.atol, a.solver)))
            for code, run in solves:
                if (code, dim, float(h), setting["solver"], setting["atol"]) in done:
                    continue
                rows.append({"code": code, **base, **setting, **run()})
                print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in rows[-1].items()}, flush=True)
                pd.DataFrame(rows).to_csv(csv, index=False)  # after every solve: a long run keeps what it has
    df = pd.DataFrame(rows)
    rich, comp = tables(df)
    rich.to_csv(OUT / f"{a.tag}_richardson.csv", index=False)
    cols = [
        "code",
        "dim",
        "h_mm",
        "h_eff_mm",
        "ndofs",
        "status",
        "p_reached_kpa",
        "theta_60_deg",
        "theta_180_deg",
        "theta_300_deg",
        "wall_time_s",
        "steps",
        "iterations",
        "cutbacks",
    ]
    md = [
        "# Free angle without contact (total, deg; per unit = / 3), P_B = 0\n",
        to_markdown(df.sort_values(["dim", "h_mm", "code"], ascending=[True, False, True])[cols]),
        "\n## Richardson extrapolation of the three finest meshes (r from h_eff)\n",
        to_markdown(
            rich[
                [
                    "dim",
                    "code",
                    "p_kpa",
                    "h_mm",
                    "coarse",
                    "medium",
                    "fine",
                    "r21",
                    "r32",
                    "order",
                    "limit",
                    "fine_error_pct",
                ]
            ]
        )
        if len(rich)
        else "(fewer than three meshes)\n",
        "\n## Limits: ours (enhanced paper) against FElupe (Q1)\n",
        to_markdown(comp) if len(comp) else "-\n",
    ]
    text = "\n".join(md)
    (OUT / f"{a.tag}.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
