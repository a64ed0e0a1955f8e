"""A unit's bending stiffness under co-pressurisation in 3D beside 2D: the middle unit of a chain of five.

Not a test: figures for docs/actuator.md ("A unit's stiffness under co-pressurisation").  The same study as the rule
``unit_stiffness`` (`workflow.actuator.stiffness.rotation_stiffness`: free, blocked and end rotations of +-delta per
unit about the blocked state), on the 3D half model at the FE study's 3D mesh and on the 2D section at its 2D mesh,
in one run so that the two can be compared pair by pair.  Stiffness in N m per degree per unit, full width.

    OMP_NUM_THREADS=1 python benchmarks/study_stiffness_3d.py [--pairs 0:0,100:100,200:200,150:0] [--jobs 2]
        -> benchmarks/out/stiffness_3d.csv
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from workflow import fem  # noqa: E402
from workflow.actuator.moment_check import chain_mesh  # noqa: E402
from workflow.actuator.stiffness import DEFAULT_STIFFNESS, SOLVES, rotation_stiffness  # noqa: E402

OUT = ROOT / "benchmarks" / "out"


def run(dim: int, pair: tuple[float, float]) -> list[dict]:
    act = dict(yaml.safe_load((ROOT / "config" / "config.yaml").read_text())["actuator"])
    st = {**DEFAULT_STIFFNESS, **dict(act.get("stiffness") or {})}
    unit = fem.unit_mesh_from_config(act, dim)
    chain = chain_mesh(unit, int(st["chain_units"]), **fem.layer_options(act))
    t0 = time.perf_counter()
    res = rotation_stiffness(chain, [pair], delta_deg=float(st["delta_deg"]), actuator=act)
    rows = []
    for j, (name, _, _) in enumerate(SOLVES):
        rows.append(
            {
                "dim": dim,
                "h_mm": unit.h,
                "p_top_kpa": pair[0],
                "p_bottom_kpa": pair[1],
                "solve": name,
                "status": int(res["status"][0, j]),
                "load_factor": float(res["load_factor"][0, j]),
                "moment_nm": float(res["moment_nm"][0, j]),
                "mid_angle_deg": float(res["mid_angle_deg"][0, j]),
                "wall_time_s": float(res["wall_time_s"][0, j]),
                "k_nm_per_deg": float(res["k_nm_per_deg"][0]),
            }
        )
    print(dim, pair, f"k = {res['k_nm_per_deg'][0]:.5g} N m/deg, {time.perf_counter() - t0:.0f} s", flush=True)
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", default="0:0,100:100,200:200,150:0")
    ap.add_argument("--dims", default="3,2")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args(argv)
    pairs = [tuple(float(v) for v in s.split(":")) for s in args.pairs.split(",") if s]
    tasks = [(int(d), p) for d in args.dims.split(",") for p in pairs]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = [r for rs in pool.map(run, *zip(*tasks)) for r in rs]
    df = pd.DataFrame(rows)
    OUT.mkdir(exist_ok=True)
    df.to_csv(OUT / "stiffness_3d.csv", index=False)
    k = df.groupby(["p_top_kpa", "p_bottom_kpa", "dim"])["k_nm_per_deg"].first().unstack("dim")
    if {2, 3} <= set(k.columns):
        k["ratio_3d_2d"] = k[3] / k[2]
    print(df.to_string())
    print(k.to_string())


if __name__ == "__main__":
    main()
