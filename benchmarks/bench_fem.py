"""Benchmark of the unit FE model: not a test, a timing table.

Per case (2D/3D, element size, contact on/off, free/blocked), from 0 to
P_T = 300 kPa (P_B = 0): DOFs, wall time, Newton iterations, load steps,
cut-backs, the split of the time into the solid's tangent and residual-only
assemblies, contact, follower pressure, the reduction T^T K T and the linear
solves (with the number of tangent and residual-only evaluations), the
peak memory (ru_maxrss of the case's own process), the angle / moment, and
FElupe's time on the same mesh without contact (the model of
tests/_felupe_unit.py: equal substeps with FElupe's cut-back; Q1 paper, i.e.
our ``mixed`` technology, not the default enhanced paper).  Each case runs in
a fresh process, so its peak memory is its own.

It also gives the mesh convergence of the 3D free angle at 300 kPa with
contact: generalised Richardson extrapolation from the three 3D meshes
(Celik et al. 2008, J. Fluids Eng. 130:078001; representative element size
h_eff = (V / n_cells)^(1/3)), the observed order, each mesh's error against
the extrapolated angle and the fine-mesh GCI.

    python benchmarks/bench_fem.py                   # full table -> benchmarks/out/bench_fem.{csv,md}
    python benchmarks/bench_fem.py --quick           # coarse cases only
    python benchmarks/bench_fem.py --threads 2       # MKL / BLAS threads per case (default 1)
    python benchmarks/bench_fem.py --h3 2 1.25 0.7 --only-3d-free-contact   # Richardson meshes only

Timings on a shared machine are noisy: compare ratios within one run.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "out"
sys.path.insert(0, str(ROOT))  # the workflow package from this checkout (spawned cases inherit sys.path)
P_TOP = 300.0  # kPa

# timers the case process adds around the model's parts: name -> (module path, attribute)
_TIMED = {
    "t_solid_s": ("workflow.fem._assembly", "SolidAssembler.assemble"),
    "t_contact_s": ("workflow.fem._contact", "ContactPair.evaluate"),
    "t_pressure_s": ("workflow.fem._solve", "pressure_load"),
    "t_reduce_s": ("workflow.fem._linsolve", "reduce_matrix"),
}


def _instrument() -> dict:
    """Wrap the timed functions (this process only); count tangent and residual-only evaluations."""
    import importlib

    stats = {k: 0.0 for k in _TIMED}
    stats.update(n_tangent=0, n_residual=0, t_solid_tangent_s=0.0)

    def timed(name, fun):
        def wrapper(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return fun(*args, **kwargs)
            finally:
                dt = time.perf_counter() - t0
                stats[name] += dt
                if name == "t_solid_s" and kwargs.get("tangent", args[2] if len(args) > 2 else True):
                    stats["t_solid_tangent_s"] += dt

        return wrapper

    for name, (mod, attr) in _TIMED.items():
        owner = importlib.import_module(mod)
        *path, leaf = attr.split(".")
        for part in path:
            owner = getattr(owner, part)
        setattr(owner, leaf, timed(name, getattr(owner, leaf)))

    from workflow.fem import _solve

    evaluate = _solve.Model.evaluate

    def counted(self, u, lam, p_ref, tangent=True):
        stats["n_tangent" if tangent else "n_residual"] += 1
        return evaluate(self, u, lam, p_ref, tangent)

    _solve.Model.evaluate = counted
    return stats


def _mesh_size(um) -> float:
    """Representative element size h_eff = (V / n_cells)^(1/dim), mm."""
    from workflow import fem

    solid = fem.SolidAssembler(um.mesh, um.material, fem.material_constants({}))
    return float((solid.volume.sum() / solid.volume.size) ** (1.0 / um.dim))


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _case(args):
    """One solve of ours in this (fresh) process: the table row."""
    dim, h, contact, case, p = args
    stats = _instrument()
    from workflow import fem
    from workflow.fem import _linsolve

    um = fem.build_unit_mesh(h=h, dim=dim)
    r = fem.solve_unit(um, p, 0.0, case, contact)
    row = {k: v for k, v in r.as_dict().items() if k != "history"}
    row.update(
        stats,
        h_mm=h,
        h_eff_mm=_mesh_size(um),
        code="workflow.fem",
        peak_rss_mb=_peak_mb(),
        solver=_linsolve.default_solver.backend,
        analyses=_linsolve.default_solver.stats["analyses"],
    )
    return row


def _felupe_case(args):
    """FElupe's free solve without contact on our mesh, in this (fresh) process."""
    dim, h, p, nsteps = args
    sys.path.insert(0, str(ROOT / "tests"))
    from _felupe_unit import felupe_free_angles

    from workflow import fem

    um = fem.build_unit_mesh(h=h, dim=dim)
    mat = fem.material_constants({})
    t0 = time.perf_counter()
    info = {}
    ang = felupe_free_angles(um, [p], mat, nsteps=nsteps, info=info)
    return {
        "code": f"felupe ({nsteps} substeps, cut-back)",
        "dim": dim,
        "h_mm": h,
        "h_eff_mm": _mesh_size(um),
        "case": "free",
        "contact": False,
        "wall_time_s": time.perf_counter() - t0,
        "status": 0,
        "steps": info["increments"],
        "cutbacks": info["cutbacks"],
        "bending_angle_total_deg": float(ang[0]),
        "bending_angle_deg": float(ang[0]) / 3,
        "ndofs": dim * um.mesh.p.shape[1],
        "peak_rss_mb": _peak_mb(),
    }


def run_isolated(fun, args):
    """``fun(args)`` in a fresh process (spawned: no state, own peak memory); a crash becomes a row."""
    try:
        with mp.get_context("spawn").Pool(1, maxtasksperchild=1) as pool:
            return pool.apply(fun, (args,))
    except Exception as exc:  # e.g. FElupe missing: record why
        dim, h = args[0], args[1]
        return {"code": getattr(fun, "__name__", "?"), "dim": dim, "h_mm": h, "status": 3, "reason": repr(exc)}


def richardson(h: np.ndarray, phi: np.ndarray, safety: float = 1.25) -> dict:
    """Generalised Richardson extrapolation from three meshes (Celik et al. 2008).

    ``h`` representative sizes (any order), ``phi`` the values.  Solves
    p = |ln|e32/e21| + ln((r21^p - s)/(r32^p - s))| / ln r21 by fixed point
    (r = coarse/fine size ratios, e = differences from fine to coarse,
    s = sign(e32/e21); s < 0 is oscillatory convergence, where the estimate is
    unreliable), then phi_ext = (r21^p phi1 - phi2)/(r21^p - 1) and the
    fine-mesh GCI = safety |e21/phi1| / (r21^p - 1).
    """
    order = np.argsort(h)
    h1, h2, h3 = np.asarray(h, float)[order]
    f1, f2, f3 = np.asarray(phi, float)[order]
    r21, r32 = h2 / h1, h3 / h2
    e21, e32 = f2 - f1, f3 - f2
    out = {
        "order": np.nan,
        "extrapolated": np.nan,
        "gci_fine": np.nan,
        "r21": r21,
        "r32": r32,
        "monotone": bool(e21 * e32 > 0),
    }
    if e21 == 0 or e32 == 0:
        return out
    s = np.sign(e32 / e21)
    p = np.log(abs(e32 / e21)) / np.log(r21)
    for _ in range(500):
        p_new = abs(np.log(abs(e32 / e21)) + np.log((r21**p - s) / (r32**p - s))) / np.log(r21)
        if abs(p_new - p) < 1e-12:
            break
        p = p_new
    if s > 0 and np.log(abs(e32 / e21)) + np.log((r21**p - s) / (r32**p - s)) < 0:
        out["order"] = -p  # growing differences: the absolute value's root only (workflow.fidelity.analysis)
        return out
    out.update(
        order=p, extrapolated=(r21**p * f1 - f2) / (r21**p - 1.0), gci_fine=safety * abs(e21 / f1) / (r21**p - 1.0)
    )
    return out


def convergence_table(df):
    """Richardson figures of the 3D free angle with contact at the full load, one row per mesh."""
    if not {"code", "dim", "case", "contact", "status"} <= set(df.columns):
        return None
    sel = df[
        (df.code == "workflow.fem")
        & (df.dim == 3)
        & (df.case == "free")
        & (df.contact == True)  # noqa: E712
        & (df.status == 0)
    ].sort_values("h_eff_mm")
    if len(sel) < 3:
        return None
    sel = sel.iloc[:3]
    rich = richardson(sel.h_eff_mm.to_numpy(), sel.bending_angle_deg.to_numpy())
    out = sel[["h_mm", "h_eff_mm", "ndofs", "bending_angle_deg", "wall_time_s"]].copy()
    out["rel_error_vs_extrapolated"] = (out.bending_angle_deg - rich["extrapolated"]) / rich["extrapolated"]
    for k, v in rich.items():
        out[k] = v
    return out


def to_markdown(df, floatfmt: str = "{:.4g}") -> str:
    """A plain GitHub markdown table (no extra dependency)."""

    def fmt(v):
        if isinstance(v, (float, np.floating)):
            return "" if np.isnan(v) else floatfmt.format(v)
        return str(v)

    lines = ["| " + " | ".join(df.columns) + " |", "|" + "---|" * len(df.columns)]
    lines += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join(lines) + "\n"


COLUMNS = [
    "code",
    "dim",
    "h_mm",
    "h_eff_mm",
    "contact",
    "case",
    "ndofs",
    "status",
    "load_factor",
    "wall_time_s",
    "assembly_time_s",
    "solve_time_s",
    "newton_iterations",
    "steps",
    "cutbacks",
    "n_tangent",
    "n_residual",
    "t_solid_tangent_s",
    "t_solid_s",
    "t_contact_s",
    "t_pressure_s",
    "t_reduce_s",
    "analyses",
    "bending_angle_deg",
    "bending_moment_nm",
    "max_penetration_mm",
    "peak_rss_mb",
]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="coarse meshes only")
    ap.add_argument("--p", type=float, default=P_TOP, help="P_T at the end of the ray, kPa")
    ap.add_argument("--h2", type=float, nargs="*", default=None, help="2D element sizes (mm)")
    ap.add_argument("--h3", type=float, nargs="*", default=None, help="3D element sizes (mm)")
    ap.add_argument("--threads", type=int, default=1, help="MKL / BLAS threads per case")
    ap.add_argument(
        "--felupe-steps", type=int, default=20, help="FElupe substeps (its cut-back subdivides a substep that fails)"
    )
    ap.add_argument("--no-felupe", action="store_true")
    ap.add_argument("--only-3d-free-contact", action="store_true", help="the Richardson solves only")
    ap.add_argument("--tag", default="bench_fem", help="output file stem in benchmarks/out")
    a = ap.parse_args()
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = str(a.threads)  # inherited by the spawned case processes
    h2 = a.h2 if a.h2 is not None else ([1.0] if a.quick else [1.0, 0.5, 0.25])
    h3 = a.h3 if a.h3 is not None else ([2.0] if a.quick else [2.0, 1.5, 1.0])
    flags = [(c, k) for c in (False, True) for k in ("free", "blocked")]
    if a.only_3d_free_contact:
        h2, flags = [], [(True, "free")]
    jobs = [(_case, (2, h, c, k, a.p)) for h in h2 for c, k in flags]
    jobs += [(_case, (3, h, c, k, a.p)) for h in h3 for c, k in flags]
    if not (a.no_felupe or a.only_3d_free_contact):
        jobs += [(_felupe_case, (2, h, a.p, a.felupe_steps)) for h in h2]
        jobs += [(_felupe_case, (3, h, a.p, a.felupe_steps)) for h in h3]
    OUT.mkdir(parents=True, exist_ok=True)
    rows = []
    for fun, args in jobs:
        row = run_isolated(fun, args)
        row["threads"] = a.threads
        rows.append(row)
        print(json.dumps({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()}), flush=True)
    import pandas as pd

    df = pd.DataFrame(rows)
    df.to_csv(OUT / f"{a.tag}.csv", index=False)
    table = df[[c for c in COLUMNS + ["threads"] if c in df]]
    md = [f"# FEA benchmark: 0 -> {a.p:g} kPa, P_B = 0, {a.threads} thread(s) per case\n", to_markdown(table)]
    conv = convergence_table(df)
    if conv is not None:
        conv.to_csv(OUT / f"{a.tag}_richardson.csv", index=False)
        md += ["\n## 3D free angle per unit at full load with contact: Richardson extrapolation\n", to_markdown(conv)]
    (OUT / f"{a.tag}.md").write_text("\n".join(md))
    print(table.to_string(index=False))
    if conv is not None:
        print(conv.to_string(index=False))


if __name__ == "__main__":
    main()
