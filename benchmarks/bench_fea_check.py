"""Benchmark of the FEA check: not a test, a timing table.

The mean finger with the test springs of tests/test_cascade.py and a plan made
with the analytic unit of tests/test_cascade.py (LinearUnit), or a given
``cascade_plan.nc`` (with the patient's own finger and springs when its
``joint_loads.nc`` and the run's moments lie beside it, as in ``results/``); per mesh size (actuator h = finger h) and exercise: DOFs,
wall time and Newton iterations of the gravity phase (shared) and of the
pressure phase, load steps, peak memory (ru_maxrss of the case's own process,
and tracemalloc's Python heap), the angles reached and the status.  Each mesh
runs in a fresh process, so its peak memory is its own.

    python benchmarks/bench_fea_check.py                       # h = 2.5 and 2.0, TGE1..TGE5 -> benchmarks/out/bench_fea_check.csv
    python benchmarks/bench_fea_check.py --h 2.0 --exercises TGE2
    python benchmarks/bench_fea_check.py --plan results/patients/mean/cascade_plan.nc

The plan's (3D) pressures are applied unchanged unless --surrogates 2d.joblib 3d.joblib
is given.  Timings on a shared machine are noisy.
"""

from __future__ import annotations

import argparse
import csv
import multiprocessing as mp
import os
import resource
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's workflow package
from workflow.cascade import patient, planning, plans_data  # noqa: E402

OUT = Path(__file__).resolve().parent / "out"
ROOT = Path(__file__).resolve().parents[1]


def _case(h: float, exercises: list[str], plan_path: str | None, surrogates, q):
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ.setdefault("MKL_NUM_THREADS", "1")
    sys.path.insert(0, str(ROOT / "tests"))
    import numpy as np
    import xarray as xr
    import yaml
    from test_cascade import ACTUATOR, LinearUnit, springs
    from test_finger import DENSITIES, SECTION, mean_finger

    from workflow.cascade import model as C
    from workflow.fea_check.entry import load_surrogate_angles
    from workflow.fea_check.model import build_patient_fea
    from workflow.fea_check.run import run_fea_check

    cfg = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    finger = mean_finger(springs=springs(), densities=DENSITIES)
    if plan_path:
        plan = xr.load_dataset(plan_path)
        res = Path(plan_path).resolve().parents[2]  # results/patients/{patient}/cascade_plan.nc
        pdir = Path(plan_path).resolve().parent
        if (pdir / "joint_loads.nc").is_file():  # the patient's own finger and springs, as the workflow builds them
            finger, _ = patient.patient_finger(
                cfg["patients"].get(pdir.name, {"finger": "F3"}),
                xr.load_dataset(pdir / "joint_loads.nc"),
                xr.load_dataset(res / "musculoskeletal" / "moments.nc"),
                xr.load_dataset(res / "doe" / "ccd.nc"),
                cascade_cfg=dict(cfg["cascade"], section_points=str(SECTION)),
                anthropometry=cfg["anthropometry"],
            )
    else:
        model = C.build_cascade(finger, LinearUnit(), actuator_dims_mm=ACTUATOR)
        tg = {e: [v["mcp"], v["pip"], v["dip"]] for e, v in cfg["exercises"].items()}
        plan = plans_data.plans_dataset(
            model, planning.plan_patient(model, tg, tol_deg=5.0), tol_deg=5.0, active_limits_nm=None
        )
    upg = {g: int(v) for g, v in zip(plan["group"].values, plan["units_per_group"].values)}
    fea = build_patient_fea(
        finger,
        upg,
        actuator_cfg=cfg["actuator"],
        cascade_cfg=dict(cfg["cascade"], section_points=str(SECTION)),
        reference_dims_mm={k: v["mean"] for k, v in cfg["anthropometry"]["measures"].items()},
        fea_cfg={**cfg["fea_check"], "h_actuator_mm": h, "h_finger_mm": h},
    )
    solver = dict(cfg["actuator"]["solver"])
    solver.update(cfg["fea_check"]["solver"])
    a3, a2, pm2, pm3 = load_surrogate_angles(*(surrogates or (None, None)))
    ds, checks, grav, _ = run_fea_check(
        fea,
        plan,
        exercises=exercises,
        solver=solver,
        tolerance_deg=5.0,
        angle_3d=a3,
        angle_2d=a2,
        p_max_2d_kpa=pm2,
        p_max_3d_kpa=pm3,
    )
    rows = []
    for c in checks:
        rows.append(
            {
                "h_mm": h,
                "exercise": c.exercise,
                "ndofs": c.result.ndofs,
                "gravity_wall_s": round(grav.wall_time_s, 2),
                "gravity_newton": grav.newton_iterations,
                "pressure_wall_s": round(c.wall_time_s, 2),
                "pressure_newton": c.result.newton_iterations,
                "pressure_steps": c.result.steps,
                "status": c.result.status,
                "load_factor": round(c.result.load_factor, 4),
                "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
                "peak_heap_mb": round(c.peak_memory_mb, 1),
                "angles_deg": " ".join(f"{a:.1f}" for a in c.angle_deg),
                "target_deg": " ".join(f"{a:.0f}" for a in plan["target_angle_deg"].sel(exercise=c.exercise).values),
                "plan_deg": " ".join(f"{a:.1f}" for a in plan["predicted_angle_deg"].sel(exercise=c.exercise).values),
                "droop_deg": " ".join(f"{a:.1f}" for a in np.asarray(grav.joint_angles_deg)),
            }
        )
    q.put(rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--h", type=float, nargs="+", default=[2.5, 2.0])
    ap.add_argument("--exercises", nargs="+", default=["TGE1", "TGE2", "TGE3", "TGE4", "TGE5"])
    ap.add_argument("--plan", default=None)
    ap.add_argument("--surrogates", nargs=2, default=None, metavar=("SURROGATE_2D", "SURROGATE_3D"))
    ap.add_argument("--out", default=str(OUT / "bench_fea_check.csv"))
    a = ap.parse_args(argv)
    rows = []
    ctx = mp.get_context("spawn")
    for h in a.h:
        q = ctx.Queue()
        p = ctx.Process(target=_case, args=(h, a.exercises, a.plan, a.surrogates, q))
        p.start()
        got = q.get()
        p.join()
        for r in got:
            print(r, flush=True)
        rows += got
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    with open(a.out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
