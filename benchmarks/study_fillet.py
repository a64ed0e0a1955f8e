"""Rounded block corners (``actuator.geometry.fillet``): do they carry the free ray past the corner-contact stall?

Not a test: a study whose figures are in docs/fea.md ("Rounded block corners").  Per fillet radius r and mesh h
(2D, P_B = 0, P_T 0 -> 300 kPa, contact on, the config's solver and contact settings, stops at 60 and 180 kPa):
status, load reached, load steps, cut-backs, Newton iterations, wall time, the free angle per unit (or blocked
moment) at 60 / 180 / 300 kPa, and for a ray that stops the solver's reason, which compares the tangent's
eigenvalue nearest zero at the last converged state with the one at rest (a limit point or a non-smooth stall).

    OMP_NUM_THREADS=1 python benchmarks/study_fillet.py [--cases 2:1:0,2:1:2] [--restarts] [--jobs 2]
        [--friction 0.5 --friction-factor 0.1 --out fillet_friction.csv]       -> benchmarks/out/fillet.csv

``--friction`` sets the Coulomb coefficient of the silicone self-contact (2D; ``actuator.contact.friction`` of the
engine, 0 by default) and ``--friction-factor`` its tangential penalty as a multiple of the normal one.

A case is ``dim:h:r[:case[:side]]`` (mm; case ``free`` or ``blocked``; side ``both`` (default), or ``bottom`` /
``top``: only that side's corners rounded, the other side's square, to tell which side's corners decide).
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from workflow.fem._config import layer_options, solve_unit_from_config  # noqa: E402
from workflow.fem._mesh import build_unit_mesh  # noqa: E402

OUT = ROOT / "benchmarks" / "out"
DEFAULT_CASES = (
    "2:2:0,2:1:0,2:0.5:0,2:0.25:0,2:2:2,2:1:1,2:1:2,2:0.5:0.5,2:0.5:1,2:0.5:2,2:0.25:0.5,2:0.25:1,2:0.25:2,"
    "2:1:0:blocked,2:1:1:blocked,2:1:2:blocked,2:0.5:2:blocked,2:0.25:2:blocked,"
    "2:1:2:free:bottom,2:1:2:free:top,2:0.5:1:free:bottom,2:0.5:1:free:top,2:0.25:1:free:bottom,3:2:2"
)


def run_case(spec: str, restarts: bool, friction: float = 0.0, friction_factor: float = 0.1) -> dict:
    parts = spec.split(":")
    dim, h, r = int(parts[0]), float(parts[1]), float(parts[2])
    case = parts[3] if len(parts) > 3 else "free"
    side = parts[4] if len(parts) > 4 else "both"
    act = dict(yaml.safe_load((ROOT / "config" / "config.yaml").read_text())["actuator"])
    act["geometry"] = {**act.get("geometry", {}), "fillet": r}
    if not restarts:
        act["restarts"] = []
    act["contact"] = {**act.get("contact", {}), "friction": friction, "friction_penalty_factor": friction_factor}
    um = build_unit_mesh(act["geometry"], h=h, dim=dim, **layer_options(act))
    if side != "both":  # put the other side's nodes back on the square geometry
        square = build_unit_mesh({**act["geometry"], "fillet": 0.0}, h=h, dim=dim, **layer_options(act)).mesh.p
        p = um.mesh.p.copy()
        other = p[1] > 0 if side == "bottom" else p[1] < 0
        p[:, other] = square[:, other]
        um.mesh = type(um.mesh)(p, um.mesh.t)
    t0 = time.perf_counter()
    res = solve_unit_from_config(act, dim, 300.0, 0.0, case, mesh=um, stops=(0.2, 0.6))
    wall = time.perf_counter() - t0
    key = "bending_angle_deg" if case == "free" else "bending_moment_nm"
    at = {round(s["p_top_kpa"]): s[key] for s in res.history}
    row = {
        "dim": dim,
        "h_mm": h,
        "fillet_mm": r,
        "rounded": side,
        "friction": friction,
        "friction_penalty_factor": friction_factor,
        "case": case,
        "status": res.status,
        "load_reached": res.load_factor,
        "steps": res.steps,
        "cutbacks": res.cutbacks,
        "newton_iterations": res.newton_iterations,
        "wall_time_s": wall,
        **{f"value_{p}kpa": at.get(p, np.nan) for p in (60, 180, 300)},
        "min_pocket_area_mm2": min((s.get("min_pocket_area_mm2", np.inf) for s in res.history), default=np.nan),
    }
    row["reason"] = res.reason  # a ray that stops: the solver's diagnosis of its tangent (workflow.fem._solve)
    print(spec, {k: row[k] for k in ("status", "load_reached", "steps", "cutbacks", "wall_time_s")}, flush=True)
    return row


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=DEFAULT_CASES)
    ap.add_argument("--restarts", action="store_true", help="with the config's restarts (default: first attempt only)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--friction", type=float, default=0.0)
    ap.add_argument("--friction-factor", type=float, default=0.1)
    ap.add_argument("--out", default="fillet.csv")
    args = ap.parse_args(argv)
    specs = [c for c in args.cases.split(",") if c]
    n = len(specs)
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(run_case, specs, [args.restarts] * n, [args.friction] * n, [args.friction_factor] * n))
    OUT.mkdir(exist_ok=True)
    df = pd.DataFrame(rows)
    df.to_csv(OUT / args.out, index=False)
    print(df.to_string())


if __name__ == "__main__":
    main()
