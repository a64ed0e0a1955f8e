"""Mesh convergence of the 3D unit on a systematic family: not a test, figures -> benchmarks/out/mesh_family_3d.csv.

The meshes h = 2 / 1.4 / 1 mm refine the unit's intervals at different steps (a 2 mm wall gets 1, 1 and 2
elements), so their differences need not shrink by a constant factor (docs/fea.md, "Self-contact").  Here every
interval's element count of the h = 4 mm mesh, the paper and base layers included, is multiplied by ``refine`` =
2, 3, 4 (`build_unit_mesh(..., refine=r)`): each element keeps its shape and its size is divided by r, so the
nominal sizes 2, 1.33, 1 mm are exact and the refinement ratios 1.5 and 1.33.  Per mesh the blocked and the free
ray to P_T = 300 kPa (P_B = 0) with the config's contact, solver and restarts, values at 60 / 180 / 300 kPa; then
the observed order, Richardson limit and grid convergence index (Celik et al. 2008) per quantity, and the default
2 mm mesh's value (read from ``--default`` rows or solved here) against the limit.

Each ray is appended to the CSV as soon as it ends, and a rerun skips the rays already there (interrupting loses
only the ray under way).  One core: ``OMP_NUM_THREADS=1 python benchmarks/study_mesh_family_3d.py``; the r = 4 free
ray takes over an hour.

    python benchmarks/study_mesh_family_3d.py --refine 2,3,4 --cases blocked,free
    python benchmarks/study_mesh_family_3d.py --summary      # the table from the CSV only
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout without the editable install

from workflow.fem import build_unit_mesh  # noqa: E402
from workflow.fem._config import layer_options, solve_unit_from_config  # noqa: E402
from workflow.fidelity.analysis import richardson  # noqa: E402

OUT = ROOT / "benchmarks" / "out"
CSV = OUT / "mesh_family_3d.csv"
BASE_H = 4.0  # mm: the family's coarsest counts
P_KPA = (60.0, 180.0, 300.0)
KEY = {"free": "bending_angle_deg", "blocked": "bending_moment_nm"}


def _actuator() -> dict:
    return dict(yaml.safe_load((ROOT / "config" / "config.yaml").read_text())["actuator"])


def solve_ray(refine: int | None, case: str) -> dict:
    """One ray; ``refine`` None = the config's default 3D mesh (h_3d_mm)."""
    act = _actuator()
    if refine is None:
        h = float(act["mesh"]["h_3d_mm"])
        um = build_unit_mesh(act["geometry"], h=h, dim=3, **layer_options(act))
    else:
        h = BASE_H / refine
        um = build_unit_mesh(act["geometry"], h=BASE_H, dim=3, refine=refine, **layer_options(act))
    stops = tuple(p / P_KPA[-1] for p in P_KPA[:-1])
    t0 = time.perf_counter()
    res = solve_unit_from_config(act, 3, P_KPA[-1], 0.0, case, mesh=um, stops=stops)
    row = {
        "mesh": "default" if refine is None else f"refine{refine}",
        "refine": 0 if refine is None else refine,
        "h_mm": h,
        "cells": um.mesh.t.shape[1],
        "ndofs": res.ndofs,
        "case": case,
        "status": res.status,
        "reason": res.reason,
        "p_reached_kpa": res.load_factor * P_KPA[-1],
        "attempt": res.attempt,
        "contact_smoothing_mm": res.contact_smoothing_mm,
        "steps": res.steps,
        "cutbacks": res.cutbacks,
        "newton_iterations": res.newton_iterations,
        "wall_time_s": time.perf_counter() - t0,
    }
    for p in P_KPA:
        hit = [s[KEY[case]] for s in res.history if abs(s["p_top_kpa"] - p) < 1e-6]
        row[f"{KEY[case]}_{int(p)}"] = hit[0] if hit else np.nan
    return row


def summary(df: pd.DataFrame) -> pd.DataFrame:
    """Per case and pressure: the family's three values, observed order, limit, GCI, default mesh vs the limit."""
    rows = []
    fam = df[df["refine"] > 0].sort_values("refine")
    for case, key in KEY.items():
        f = fam[fam["case"] == case]
        d = df[(df["refine"] == 0) & (df["case"] == case)]
        for p in P_KPA:
            col = f"{key}_{int(p)}"
            if len(f) < 3:
                continue
            h, v = f["h_mm"].to_numpy()[-3:], f[col].to_numpy()[-3:]
            r = richardson(h, v)
            dflt = float(d[col].iloc[-1]) if len(d) else np.nan
            rows.append(
                {
                    "case": case,
                    "p_kpa": p,
                    **{f"h{hh:.3g}": vv for hh, vv in zip(h, v)},
                    "order": r.order,
                    "asymptotic": r.asymptotic,
                    "limit": r.limit,
                    "gci_finest_pct": 100 * r.gci_fine,
                    "default_2mm": dflt,
                    "default_vs_limit_pct": 100 * (dflt - r.limit) / abs(r.limit) if r.asymptotic else np.nan,
                    "family_2mm_vs_limit_pct": 100 * (v[np.argmax(h)] - r.limit) / abs(r.limit)
                    if r.asymptotic
                    else np.nan,
                }
            )
    return pd.DataFrame(rows)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--refine", default="2,3,4", help="multipliers of the h = 4 mm counts")
    ap.add_argument("--cases", default="blocked,free")
    ap.add_argument("--default", action="store_true", help="also solve the default 2 mm mesh's rays")
    ap.add_argument("--summary", action="store_true", help="only print the table from the CSV")
    a = ap.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    if not a.summary:
        done = pd.read_csv(CSV) if CSV.exists() else pd.DataFrame(columns=["mesh", "case"])
        todo = [(None, c) for c in a.cases.split(",")] if a.default else []
        todo += [(int(r), c) for r in a.refine.split(",") for c in a.cases.split(",")]
        for r, case in todo:
            name = "default" if r is None else f"refine{r}"
            if ((done["mesh"] == name) & (done["case"] == case)).any():
                continue
            print(f"{name} {case} ...", flush=True)
            row = solve_ray(r, case)
            print(row, flush=True)
            done = pd.concat([done, pd.DataFrame([row])], ignore_index=True)
            done.to_csv(CSV, index=False)
    df = pd.read_csv(CSV)
    with pd.option_context("display.width", 250, "display.max_columns", 30):
        print(df.drop(columns=["reason"]).to_string(index=False))
        print(summary(df).to_string(index=False))


if __name__ == "__main__":
    main()
