"""Timing of the OpenSim backend. Not a test: run it by hand.

    python benchmarks/bench_opensim.py [--repeats 200] [--processes 2]

Reports
- one moment evaluation: set one joint angle, equilibrate the muscles of one
  finger, read tendon forces, sum force x moment arm and add the passive
  joint structures' moment (median of repeats);
- one CCD run in-process (four fingers, 5-degree grid, two activations);
- the 15-run sampling on ``--processes`` worker processes (a pool, as
  ``snakemake -c2`` runs independent jobs two at a time, but without
  Snakemake's per-job interpreter start-up).
Scale factors come from resources/table03_04_ccd_scaling.csv.
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
from multiprocessing import get_context
from pathlib import Path

import pandas as pd

from workflow.musculoskeletal import opensim_backend as ob
from workflow.musculoskeletal import opensim_model as om

REPO = Path(__file__).resolve().parents[1]
TABLE = REPO / "resources" / "table03_04_ccd_scaling.csv"
PARAMS = REPO / "config" / "finger_muscles.yaml"
FINGERS = ("F2", "F3", "F4", "F5")


def _factors(table: pd.DataFrame, marker: str) -> dict:
    return {b: tuple(float(table.loc[marker, f"{b}_{a}"]) for a in "XYZ") for b in om.BODIES}


def one_evaluation(model_path: Path, table: pd.DataFrame, repeats: int) -> float:
    """Median wall time (s) of one moment evaluation (F3 MCP at 45 deg, activation 1)."""
    model = ob.load_model(model_path)
    ob.scale_model(model, _factors(table, "Original"), FINGERS)
    state = model.initSystem()
    coord = model.getCoordinateSet().get(om.joint_coordinate_name("F3", "MCP"))
    muscles = [
        m
        for m in (model.getMuscles().get(i) for i in range(model.getMuscles().getSize()))
        if m.getName().startswith("F3_")
    ]
    structures = ob._joint_structures(model, "F3")["MCP"]
    times = []
    for k in range(repeats):
        t0 = time.perf_counter()
        coord.setValue(state, math.radians(45.0 + 1e-3 * (k % 2)), False)
        for m in muscles:
            m.setActivation(state, 1.0)
        model.equilibrateMuscles(state)
        model.realizeDynamics(state)
        moment = sum(m.getTendonForce(state) * m.computeMomentArm(state, coord) for m in muscles)
        moment += structures.calcLimitForce(state)
        times.append(time.perf_counter() - t0)
    assert math.isfinite(moment)
    return statistics.median(times)


def _run_job(args: tuple[str, dict, int]) -> float:
    model_path, factors, run = args
    t0 = time.perf_counter()
    ob.sample_run(model_path, factors, run, FINGERS)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=200)
    ap.add_argument("--processes", type=int, default=2)
    args = ap.parse_args()
    table = pd.read_csv(TABLE).set_index("marker")
    with tempfile.TemporaryDirectory() as tmp:
        model_path = Path(tmp) / "finger_reference.osim"
        t0 = time.perf_counter()
        om.write_model(om.load_parameters(PARAMS), model_path, FINGERS, _factors(table, "Original"))
        t_model = time.perf_counter() - t0
        t_eval = one_evaluation(model_path, table, args.repeats)
        t_run = _run_job((str(model_path), _factors(table, "Original"), 9))
        jobs = [(str(model_path), _factors(table, m), i) for i, m in enumerate(table.index, start=1)]
        t0 = time.perf_counter()
        with get_context("spawn").Pool(args.processes) as pool:
            per_job = pool.map(_run_job, jobs)
        t_all = time.perf_counter() - t0
    n = (
        len(FINGERS)
        * sum(len([a for a in ob.angle_grid() if lo <= a <= hi]) for lo, hi in om.JOINT_RANGE_DEG.values())
        * 2
    )
    print(f"build + write reference model (4 fingers): {t_model:8.3f} s")
    print(f"one moment evaluation (equilibrate + moment): {t_eval * 1e3:8.3f} ms (median of {args.repeats})")
    print(f"one CCD run in-process ({n} samples): {t_run:8.3f} s")
    print(f"15 runs on {args.processes} processes: {t_all:8.3f} s wall (jobs {min(per_job):.2f}-{max(per_job):.2f} s)")


if __name__ == "__main__":
    main()
