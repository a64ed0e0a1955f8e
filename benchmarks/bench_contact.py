"""Contact study of the 2D unit: not a test, figures -> benchmarks/out/contact_*.csv.

Parts (P_B = 0, P_T = 60/180/300 kPa, plane strain, per unit, full 20 mm width):

* ``convergence``: free angle and blocked moment with contact at h = 2, 1, 0.5,
  0.25 mm: status, pressure reached, largest penetration, DOFs, wall time,
  Newton iterations -> ``contact_convergence.csv``; Richardson extrapolation
  and observed order from each three nested meshes -> ``contact_richardson.csv``.
* ``penalty``: penalty factor 30/100/300 (eps = factor mu0 / 1 mm) at h = 1 mm:
  free angle, blocked moment, penetration -> ``contact_penalty.csv``.
* ``normals``: smoothed (default) against facet master normals at h = 0.5 mm
  over several step sequences (the former stall depends on where the steps
  land) -> ``contact_normals.csv``.
* ``normals3d``: the 3D unit (P_B = 0, first attempt, no restarts) with smoothed (default) against facet master
  normals, free and blocked rays, both in one run -> ``contact_normals3d.csv``.
* ``felupe``: FElupe with its own contact (``SmoothedGapContact`` of
  tests/_felupe_unit.py, on the same contact surfaces) against ours with the
  same element technology (``formulation="mixed"``) on the same mesh, free
  angles and error / |theta(300 kPa)|, both wall times in the same run ->
  ``contact_felupe.csv``.

    OMP_NUM_THREADS=1 python benchmarks/bench_contact.py                      # everything
    python benchmarks/bench_contact.py --parts penalty,felupe --h 2,1          # a subset
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without the editable install

from workflow import fem  # noqa: E402
from workflow.fem._contact import contact_pairs_from_mesh
from workflow.fem._solve import DEFAULT_SOLVER, solve_path
from workflow.fem._unit import _measure_factory

OUT = Path(__file__).resolve().parent / "out"
P_KPA = np.array([60.0, 180.0, 300.0])


def _at(history: list, key: str) -> list:
    """Values of ``key`` at the pressures P_KPA (NaN where the ray stopped short)."""
    out = []
    for q in P_KPA:
        hit = [h[key] for h in history if abs(h["p_top_kpa"] - q) < 1e-6]
        out.append(hit[0] if hit else np.nan)
    return out


def _row(res, h: float, **extra) -> dict:
    """One result row: per-unit angle (deg) / full-width moment (N m) at P_KPA and the run's figures."""
    key = "bending_angle_deg" if res.case == "free" else "bending_moment_nm"
    vals = _at(res.history, key)
    row = {
        "h_mm": h,
        "case": res.case,
        "ndofs": res.ndofs,
        "status": res.status,
        "reason": res.reason,
        "p_reached_kpa": res.load_factor * P_KPA[-1],
        "max_penetration_mm": res.max_penetration_mm,
        "min_gap_mm": min((r["gmin"] for r in res.history), default=np.inf),
        "wall_time_s": res.wall_time_s,
        "newton_iterations": res.newton_iterations,
        "steps": res.steps,
        "cutbacks": res.cutbacks,
        "end_hold": END_HOLD["value"] if res.case == "blocked" else "",
    }
    row.update({f"{key}_{int(q)}": v for q, v in zip(P_KPA, vals)})
    row.update(extra)
    return row


#: end nodes held plane in case blocked (config ``actuator.end_hold``; set by --end-hold)
END_HOLD = {"value": "backbone"}


def _solve(h: float, case: str, **contact) -> object:
    um = fem.build_unit_mesh(h=h, dim=2)
    return fem.solve_unit(
        um,
        P_KPA[-1],
        0.0,
        case,
        True,
        contact_options=contact or None,
        stops=tuple(P_KPA / P_KPA[-1]),
        end_hold=END_HOLD["value"],
    )


def convergence(hs) -> pd.DataFrame:
    rows = []
    for h in hs:
        for case in ("free", "blocked"):
            res = _solve(h, case)
            rows.append(_row(res, h))
            print(pd.Series(rows[-1]).to_dict(), flush=True)
    return pd.DataFrame(rows)


def richardson(df: pd.DataFrame) -> pd.DataFrame:
    """Observed order p = log2(d1 / d2) and a3 + (a3 - a2) / (2^p - 1) from each nested triple (h, h/2, h/4)."""
    rows = []
    for case, key in (("free", "bending_angle_deg"), ("blocked", "bending_moment_nm")):
        sub = df[df.case == case].sort_values("h_mm", ascending=False)
        hs = list(sub.h_mm)
        for i in range(len(hs) - 2):
            if not np.isclose(hs[i], 2 * hs[i + 1]) or not np.isclose(hs[i + 1], 2 * hs[i + 2]):
                continue
            for q in P_KPA:
                a = sub[f"{key}_{int(q)}"].to_numpy()[i : i + 3]
                d1, d2 = a[0] - a[1], a[1] - a[2]
                ok = np.all(np.isfinite(a)) and d1 * d2 > 0 and abs(d2) < abs(d1)
                p = np.log2(d1 / d2) if ok else np.nan
                ext = a[2] + (a[2] - a[1]) / (2**p - 1) if ok else np.nan
                rows.append(
                    {
                        "case": case,
                        "quantity": key,
                        "p_kpa": q,
                        "h_mm": "/".join(f"{v:g}" for v in hs[i : i + 3]),
                        "coarse": a[0],
                        "medium": a[1],
                        "fine": a[2],
                        "observed_order": p,
                        "richardson": ext,
                        "fine_error_pct": 100 * (a[2] / ext - 1) if ok else np.nan,
                        "medium_error_pct": 100 * (a[1] / ext - 1) if ok else np.nan,
                    }
                )
    return pd.DataFrame(rows)


def penalty(h: float = 1.0, factors=(30.0, 100.0, 300.0)) -> pd.DataFrame:
    rows = []
    for k in factors:
        for case in ("free", "blocked"):
            rows.append(
                _row(
                    _solve(h, case, penalty_factor=k),
                    h,
                    penalty_factor=k,
                    eps_mpa_per_mm=fem.contact_penalty(fem.material_constants({}), {"penalty_factor": k}),
                )
            )
            print(rows[-1], flush=True)
    return pd.DataFrame(rows)


#: step sequences of the normals part: the stall depends on where the steps land
VARIANTS = {
    "default": ({}, False),
    "stops 60/180/300": ({}, True),
    "initial_step 0.05": ({"initial_step": 0.05}, False),
    "max_step 0.1": ({"max_step": 0.1}, False),
    "initial_step 0.2": ({"initial_step": 0.2}, False),
}


def normals(h: float = 0.5) -> pd.DataFrame:
    """Free rays with smoothed and with facet master normals over several step sequences."""
    rows = []
    um = fem.build_unit_mesh(h=h, dim=2)
    opts = dict(fem.DEFAULT_CONTACT)
    for name, (solver, use_stops) in VARIANTS.items():
        for smooth in (True, False):
            model = fem.unit_model(um, P_KPA[-1], 0.0, "free", True)
            model.contacts = contact_pairs_from_mesh(
                um, opts["search_mm"], opts["extend"], opts["smoothing_mm"], smooth_normals=smooth
            )
            t0 = time.perf_counter()
            res = solve_path(
                model,
                um.mesh.p,
                dict(DEFAULT_SOLVER, **solver),
                _measure_factory(um, model, "free", P_KPA[-1], 0.0),
                stops=tuple(P_KPA / P_KPA[-1]) if use_stops else (),
            )
            last = res.history[-1] if res.history else {"bending_angle_deg": np.nan}
            rows.append(
                {
                    "h_mm": h,
                    "steps_variant": name,
                    "smooth_normals": smooth,
                    "status": res.status,
                    "reason": res.reason,
                    "p_reached_kpa": res.lam * P_KPA[-1],
                    "bending_angle_deg_reached": last["bending_angle_deg"],
                    "newton_iterations": res.iterations,
                    "steps": res.steps,
                    "cutbacks": res.cutbacks,
                    "wall_time_s": time.perf_counter() - t0,
                }
            )
            print(rows[-1], flush=True)
    return pd.DataFrame(rows)


def normals3d(hs, cases=("free", "blocked")) -> pd.DataFrame:
    """3D unit rays with smoothed and with facet master normals (the solver's defaults, first attempt)."""
    rows = []
    for h in hs:
        um = fem.build_unit_mesh(h=h, dim=3)
        for case in cases:
            for smooth in (True, False):
                res = fem.solve_unit(
                    um,
                    P_KPA[-1],
                    0.0,
                    case,
                    True,
                    contact_options={"smooth_normals": smooth},
                    stops=tuple(P_KPA / P_KPA[-1]),
                )
                hold = fem.DEFAULT_END_HOLD if case == "blocked" else ""  # the engine's, as the sweeps
                rows.append(_row(res, h, smooth_normals=smooth, end_hold=hold))
                print(pd.Series(rows[-1]).to_dict(), flush=True)
    return pd.DataFrame(rows)


def felupe_check(hs) -> pd.DataFrame:
    """Free angles (total, deg) of both codes with contact on the same mesh; ours (mixed) first, then FElupe."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from _felupe_unit import felupe_free_angles

    rows = []
    mat = fem.material_constants({})
    for h in hs:
        um = fem.build_unit_mesh(h=h, dim=2)
        # same element technology as FElupe's (Q1 paper), so only the contact treatments differ
        res = fem.solve_unit(um, P_KPA[-1], 0.0, "free", True, formulation="mixed", stops=tuple(P_KPA / P_KPA[-1]))
        ours = np.array(_at(res.history, "bending_angle_total_deg"))
        info = {}
        t0 = time.perf_counter()
        try:
            theirs = felupe_free_angles(um, P_KPA, mat, contact=True, eps=fem.contact_penalty(mat, {}), info=info)
        except Exception as exc:  # FElupe's Newton / cut-back gave up (e.g. at h = 2 mm): a row, not a crash
            theirs = np.full(P_KPA.size, np.nan)
            info = {"wall_time_s": time.perf_counter() - t0, "min_gap_mm": np.nan, "reason": str(exc)[-200:]}
        err = np.abs(ours - theirs) / abs(theirs[-1])
        for q, a, b, e in zip(P_KPA, ours, theirs, err):
            rows.append(
                {
                    "h_mm": h,
                    "ndofs": res.ndofs,
                    "p_kpa": q,
                    "ours_deg_per_unit": a / 3,
                    "felupe_deg_per_unit": b / 3,
                    "error_pct_of_theta300": 100 * e,
                    "ours_status": res.status,
                    "ours_wall_time_s": res.wall_time_s,
                    "felupe_wall_time_s": info["wall_time_s"],
                    "ours_max_penetration_mm": res.max_penetration_mm,
                    "felupe_min_gap_mm": info["min_gap_mm"],
                    "felupe_reason": info.get("reason", ""),
                }
            )
        print(rows[-3:], flush=True)
    return pd.DataFrame(rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default="convergence,penalty,normals,normals3d,felupe")
    ap.add_argument("--h", default="2,1,0.5,0.25", help="element sizes (mm) of the convergence part")
    ap.add_argument("--felupe-h", default="1,0.5", help="element sizes (mm) of the FElupe part")
    ap.add_argument("--normals-h", default="0.5", help="element size (mm) of the normals part")
    ap.add_argument("--normals3d-h", default="2", help="element sizes (mm) of the normals3d part")
    ap.add_argument(
        "--end-hold",
        default="backbone",
        choices=fem.END_HOLDS,
        help="end nodes held plane in case blocked (as config actuator.end_hold)",
    )
    args = ap.parse_args(argv)
    END_HOLD["value"] = args.end_hold
    parts = args.parts.split(",")
    OUT.mkdir(parents=True, exist_ok=True)
    if "convergence" in parts:
        df = convergence([float(v) for v in args.h.split(",")])
        df.to_csv(OUT / "contact_convergence.csv", index=False)
        richardson(df).to_csv(OUT / "contact_richardson.csv", index=False)
    if "penalty" in parts:
        penalty().to_csv(OUT / "contact_penalty.csv", index=False)
    if "normals" in parts:
        normals(float(args.normals_h)).to_csv(OUT / "contact_normals.csv", index=False)
    if "normals3d" in parts:
        normals3d([float(v) for v in args.normals3d_h.split(",")]).to_csv(OUT / "contact_normals3d.csv", index=False)
    if "felupe" in parts:
        felupe_check([float(v) for v in args.felupe_h.split(",")]).to_csv(OUT / "contact_felupe.csv", index=False)


if __name__ == "__main__":
    main()
