"""Which 2D-to-3D pressure map makes the 2D stand-alone actuator agree with the 3D one under the same end load?

Not a test: a study (docs/actuator.md, "2D–3D mapping", under load), run so far for one set (``--sets 200:0``): each
3D stand-alone solve at 4 mm takes 30-45 min of a core; with the FEA check's budget of 150 steps the tip-force solves
stopped short of their load, with 400 (the default here) they reach it. The paper's map (section
3.2, Fig. 17) matches the free angles of the 2D and 3D units; the loaded map matches their angles under the moment
a unit carries, with the unit model's linear spring theta(P, M) = theta_free(P) (1 - M / M_blocked(P)) (paper
section 2.4; ``workflow.actuator.unit_model``). Here both maps are built from FE rays of the units on the same
meshes as the stand-alone actuators (3D h = 4 mm half model, 2D h = 2 mm: the workflow's stand-alone meshes), so
only the map differs between the two 2D actuators.

Per pressure set (every group at the same (P_T, P_B), 3D) and tip force F (N, along +y, against the flexion; dead,
ramped with the pressures):

1. the 3D stand-alone actuator (layout ``--layout``, hand end clamped) at (P_T, P_B) and F;
2. each group's moment M_g = F (x_tip - x_g) about the middle of its units on the 3D actuator's deformed backbone
   (the moment the 3D units actually carry);
3. the 2D pressures of each group by the free-angle map and by the loaded map under M_g;
4. the 2D stand-alone actuator at each and F: tip angle and backbone against the 3D one.

    OMP_NUM_THREADS=1 python benchmarks/study_map_standalone.py [--sets 100:0,200:0,200:100] [--forces 0,0.5]
        [--layout 4,5,6,6] [--max-steps 400] [--jobs 1]                                        -> benchmarks/out/map_standalone.csv
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

from workflow import fem  # noqa: E402
from workflow.common.constants import GROUPS  # noqa: E402
from workflow.fem._config import layer_options, solve_unit_from_config  # noqa: E402
from workflow.fem._mesh import build_actuator_mesh, build_unit_mesh  # noqa: E402
from workflow.fem.actuator import solve_standalone  # noqa: E402

OUT = ROOT / "benchmarks" / "out"
H = {2: 2.0, 3: 4.0}  # the stand-alone meshes of the workflow (fea_check.h_actuator_mm, standalone.h_3d_mm[0])


def _config(max_steps: int | None = None):
    cfg = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    act, fc = dict(cfg["actuator"]), dict(cfg["fea_check"])
    solver = {**dict(act.get("solver", {})), **dict(fc.get("solver", {}))}
    if max_steps:  # the stand-alone solves' step budget (None: the FEA check's; main() passes --max-steps)
        solver["max_steps"] = max_steps
    return act, solver, list(fc.get("restarts", []))


def unit_rays(spec: str) -> dict:
    """Free angle (deg per unit) and blocked moment (N m) along the ray 0 -> (P_T, P_B) x 1.5 of one unit mesh."""
    dim, pt, pb = spec.split(":")
    dim, pt, pb = int(dim), float(pt), float(pb)
    act, _, _ = _config()
    um = build_unit_mesh(act["geometry"], h=H[dim], dim=dim, **layer_options(act))
    out = {"dim": dim, "ray": (pt, pb)}
    for case, key in (("free", "bending_angle_deg"), ("blocked", "bending_moment_nm")):
        res = solve_unit_from_config(act, dim, pt, pb, case, mesh=um, stops=tuple(np.linspace(0.05, 0.95, 19)))
        lam = np.array([0.0] + [s["p_top_kpa"] / pt for s in res.history])
        val = np.array([0.0] + [s[key] for s in res.history])
        out[case] = (lam, val, res.status, res.load_factor)
    return out


def standalone(args) -> dict:
    """One stand-alone solve: dim, {group: (P_T, P_B)} in kPa, tip force N, layout, step budget (None: the
    check's); with the config's restarts."""
    dim, press, force, layout, max_steps = args
    act, solver, restarts = _config(max_steps)
    um = build_actuator_mesh(act["geometry"], dict(zip(GROUPS, layout)), h=H[dim], dim=dim, **layer_options(act))
    contact = {k: v for k, v in dict(act.get("contact", {})).items() if k != "enabled"}
    spent = []

    def solve(contact_opts, opts):
        r = solve_standalone(
            um, press, material=act.get("material"), contact_options=contact_opts, solver=opts, tip_force_n=force
        )
        spent.append(r.wall_time_s)
        return r

    r, k = fem.first_converged(fem.cumulative_attempts(contact, solver, restarts), solve, label=f"{dim}D {press}")
    return {
        "status": r.status,
        "load_factor": r.load_factor,
        "tip_angle_deg": r.tip_angle_deg,
        "backbone": r.backbone_mm,
        "ref": r.backbone_ref_mm,
        "ndofs": r.ndofs,
        "wall_time_s": float(sum(spent)),
        "attempt": k,
        "tip_history": r.tip_history,
    }


def _spring(ray, scale_kpa, p_ray_max, m_nm):
    """theta(P, M) = theta_f (1 - M / M_b) along a ray, at pressures scale_kpa (kPa of the ray's larger pressure)."""
    lam_f, th, _, _ = ray["free"]
    lam_b, mb, _, _ = ray["blocked"]
    s = np.asarray(scale_kpa, float) / p_ray_max
    t = np.interp(s, lam_f, th, right=np.nan)
    b = np.interp(s, lam_b, mb, right=np.nan)
    return t * (1.0 - m_nm / np.where(np.abs(b) > 1e-12, b, np.nan)) if m_nm else t


def map_group(ray2, ray3, p3_kpa, m_nm):
    """2D pressure (kPa, the ray's larger one) whose 2D unit angle under m_nm equals the 3D unit's at p3_kpa."""
    pmax = max(ray3["ray"])
    target = _spring(ray3, p3_kpa, pmax, m_nm)
    grid = np.linspace(0.0, max(ray2["ray"]), 3001)[1:]
    mism = _spring(ray2, grid, max(ray2["ray"]), m_nm) - target
    idx = np.flatnonzero(np.isfinite(mism[:-1]) & (np.sign(mism[:-1]) != np.sign(mism[1:])))
    if not idx.size:
        return np.nan
    j = idx[0]
    return float(grid[j] - mism[j] * (grid[j + 1] - grid[j]) / (mism[j + 1] - mism[j]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", default="100:0,200:0,200:100", help="3D (P_T:P_B) per set, kPa, every group alike")
    ap.add_argument("--forces", default="0,0.5", help="tip forces, N (whole actuator, against the flexion)")
    ap.add_argument("--layout", default="4,5,6,6", help="units per group CMC, MCP, PIP, DIP")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", default="map_standalone.csv")
    ap.add_argument(
        "--max-steps", type=int, default=400, help="step budget of the stand-alone solves (the check's 150 stop short)"
    )
    args = ap.parse_args()
    sets = [tuple(float(v) for v in s.split(":")) for s in args.sets.split(",")]
    forces = [float(f) for f in args.forces.split(",")]
    layout = [int(v) for v in args.layout.split(",")]
    t0 = time.perf_counter()
    ratios = sorted({b / a for a, b in sets})
    specs = [f"{d}:300:{300 * r:g}" for r in ratios for d in (2, 3)]
    with ProcessPoolExecutor(args.jobs) as pool:
        rays = dict(zip([(int(s[0]), r) for r in ratios for s in ("2", "3")], pool.map(unit_rays, specs)))
        for key, ray in rays.items():
            print(f"unit ray {key}: free reached {ray['free'][3]:.2f}, blocked {ray['blocked'][3]:.2f}", flush=True)
        jobs3 = [(3, {g: pset for g in GROUPS}, f, layout, args.max_steps) for pset in sets for f in forces]
        res3 = list(pool.map(standalone, jobs3))
        rows, jobs2, r3_of_row = [], [], []
        for (_, press, f, _, _), r3 in zip(jobs3, res3):
            pset = press[GROUPS[0]]
            ratio = pset[1] / pset[0]
            x, ref = r3["backbone"][:, 0], r3["ref"][:, 0]
            bounds = np.cumsum([0] + layout) / sum(layout) * ref.max()
            mids = 0.5 * (bounds[:-1] + bounds[1:])
            m_g = [f * (x[-1] - np.interp(c, ref, x)) * 1e-3 for c in mids]  # N m, the 3D units' lever
            for kind in ("free", "loaded"):
                p2 = [map_group(rays[2, ratio], rays[3, ratio], pset[0], m if kind == "loaded" else 0.0) for m in m_g]
                press2 = {g: (p, p * ratio) for g, p in zip(GROUPS, p2)}
                rows.append({"p_top_3d": pset[0], "p_bottom_3d": pset[1], "tip_force_n": f, "map": kind})
                rows[-1].update({f"p2_{g}": p for g, p in zip(GROUPS, p2)})
                rows[-1].update({f"m_{g}_nm": m for g, m in zip(GROUPS, m_g)})
                jobs2.append((2, press2, f, layout, args.max_steps))
                r3_of_row.append(r3)
        res2 = list(pool.map(standalone, jobs2))
    for row, r2, r3 in zip(rows, res2, r3_of_row):
        st = np.linspace(0.0, r3["ref"][:, 0].max(), 41)
        c3 = np.stack([np.interp(st, r3["ref"][:, 0], r3["backbone"][:, d]) for d in (0, 1)], 1)
        c2 = np.stack([np.interp(st, r2["ref"][:, 0], r2["backbone"][:, d]) for d in (0, 1)], 1)
        row.update(
            {
                "tip_3d_deg": r3["tip_angle_deg"],
                "status_3d": r3["status"],
                "load_3d": r3["load_factor"],
                "time_3d_s": r3["wall_time_s"],
                "tip_2d_deg": r2["tip_angle_deg"],
                "status_2d": r2["status"],
                "load_2d": r2["load_factor"],
                "tip_error_deg": r2["tip_angle_deg"] - r3["tip_angle_deg"],
                # where either stopped short: both tip angles at the smaller load factor reached (interpolated along
                # each solve's accepted steps), so that the two are compared at the same load
                "load_common": (lc := min(r2["load_factor"], r3["load_factor"])),
                "tip_error_at_common_deg": float(
                    np.interp(lc, *r2["tip_history"].T) - np.interp(lc, *r3["tip_history"].T)
                ),
                "backbone_rms_mm": float(np.sqrt(np.mean(np.sum((c2 - c3) ** 2, axis=1)))),
            }
        )
    df = pd.DataFrame(rows)
    OUT.mkdir(exist_ok=True)
    df.to_csv(OUT / args.out, index=False)
    with pd.option_context("display.width", 250, "display.max_columns", 40):
        print(df.round(3).to_string(index=False))
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
