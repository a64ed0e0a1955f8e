"""Mesh convergence of the unit on a systematic family (3D; 2D with ``--dim 2``): not a test, figures ->
benchmarks/out/mesh_family_{3d,2d}*.csv.

The meshes h = 2 / 1.4 / 1 mm refine the unit's intervals at different steps (a 2 mm wall gets 1, 1 and 2
elements), so their differences need not shrink by a constant factor (docs/fea.md, "Self-contact").  Here every
interval's element count of the h = 4 mm mesh, the paper and base layers included, is multiplied by ``refine`` =
2, 3, 4 (`build_unit_mesh(..., refine=r)`): each element keeps its shape and its size is divided by r, so the
nominal sizes 2, 1.33, 1 mm are exact and the refinement ratios 1.5 and 1.33.  Per mesh the blocked and the free
ray to P_T = 300 kPa (P_B = 0) with the config's contact, solver and restarts, values at 60 / 180 / 300 kPa; then
the observed order, Richardson limit and grid convergence index (Celik et al. 2008) per quantity from the three
finest meshes that reached that pressure, and the default mesh's value against the limit (3D: the ``--default``
rows; 2D: refine = 1, which is the default mesh).

Each ray is appended to the CSV as soon as it ends, and a rerun skips the rays already there (interrupting loses
only the ray under way).  One core: ``OMP_NUM_THREADS=1 python benchmarks/study_mesh_family_3d.py``; the r = 4 free
ray takes over an hour.

    python benchmarks/study_mesh_family_3d.py --refine 2,3,4 --cases blocked,free
    python benchmarks/study_mesh_family_3d.py --summary      # the table from the CSV only

``--dim 2`` runs the same study on the 2D unit (plane strain), whose meshes of h = 1, 0.5, 0.25, 0.125 mm are
nested already (every interval of Table 6 is a whole number of 0.125 mm): the family is the h = 1 mm counts times
``refine`` = 1, 2, 4, 8, r = 1 being the default mesh, figures -> benchmarks/out/mesh_family_2d.csv.  The 2D free
rays of the finer meshes stop before 300 kPa (docs/fea.md, "Mesh convergence"), so ``--pressures`` sets the rays'
end and stops (kPa; default 60,180,300), e.g. ``--dim 2 --pressures 5,60 --refine 1,2,4,8 --cases free`` (-> mesh_family_2d_5-60.csv).

``--refine 1x2,2x4,...`` refines the length and the height (the paper and base layers with it) by factors of their
own, to separate the two directions' errors (figures -> ``..._aniso.csv``; the summary is then a table of the value
over both factors and each direction's observed order along the finest row and column).
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
BASE_H = {3: 4.0, 2: 1.0}  # mm: the family's coarsest counts (2D: the default mesh itself)
P_KPA = (60.0, 180.0, 300.0)
KEY = {"free": "bending_angle_deg", "blocked": "bending_moment_nm"}


def _actuator(band: float | None = None, contact: bool = True) -> dict:
    """The config's actuator section; ``band`` (mm) replaces the contact band and drops the restarts that only
    widen it, so that every mesh's value is on the same band; ``contact`` False switches contact off."""
    act = dict(yaml.safe_load((ROOT / "config" / "config.yaml").read_text())["actuator"])
    if not contact:
        act["contact"] = dict(act["contact"], enabled=False)
    if band is not None:
        act["contact"] = dict(act["contact"], smoothing_mm=band)
        # every restart keeps its other settings, none changes the band
        act["restarts"] = [
            {k: v for k, v in r.items() if k != "contact"} for r in act.get("restarts", []) if set(r) - {"contact"}
        ]
    return act


def _csv(dim: int, p_kpa=P_KPA, band: float | None = None, aniso: bool = False, contact: bool = True) -> Path:
    """One CSV per dimension, set of pressures and contact band (rays that differ in these do not share rows);
    ``aniso``: the meshes refined by direction."""
    tail = "" if tuple(p_kpa) == P_KPA else "_" + "-".join(f"{p:g}" for p in p_kpa)
    tail += "" if band is None else f"_band{band:g}"
    tail += "" if contact else "_nocontact"
    return OUT / f"mesh_family_{dim}d{tail}{'_aniso' if aniso else ''}.csv"


def _refine_token(tok: str) -> int | tuple[int, ...]:
    """``"4"`` -> 4 (every direction), ``"1x4"`` -> (1, 4) (along the length x through the height; 3D: the width
    as the length), ``"2x4x4"`` -> (2, 4, 4) (3D: length x height x width)."""
    if "x" not in tok:
        return int(tok)
    r = tuple(int(v) for v in tok.split("x"))
    if len(r) not in (2, 3):
        raise SystemExit(f"--refine token {tok!r}: one factor, or length x height [x width]")
    return r


def _mesh_name(refine) -> str:
    """CSV name of a mesh: ``default``, ``refine4`` or ``refine1x4`` / ``refine2x4x4``."""
    if refine is None:
        return "default"
    return "refine" + ("x".join(str(v) for v in refine) if isinstance(refine, tuple) else str(refine))


def solve_ray(
    refine: int | tuple[int, int] | None,
    case: str,
    dim: int = 3,
    p_kpa=P_KPA,
    band: float | None = None,
    contact: bool = True,
) -> dict:
    """One ray to ``p_kpa[-1]`` landing on the others; ``refine`` None = the config's default mesh (h_3d_mm / h_2d_mm),
    a pair = (along the length, through the height) factors."""
    act = _actuator(band, contact)
    if refine is None:
        h = float(act["mesh"][f"h_{dim}d_mm"])
        um = build_unit_mesh(act["geometry"], h=h, dim=dim, **layer_options(act))
    else:
        um = build_unit_mesh(act["geometry"], h=BASE_H[dim], dim=dim, refine=refine, **layer_options(act))
        h = BASE_H[dim] / um.refine[0]
    rl, rh, rw = (0, 0, 0) if refine is None else um.refine  # the mesh's own (length, height, width) factors
    stops = tuple(p / p_kpa[-1] for p in p_kpa[:-1])
    t0 = time.perf_counter()
    res = solve_unit_from_config(act, dim, p_kpa[-1], 0.0, case, mesh=um, stops=stops)
    row = {
        "mesh": _mesh_name(refine),
        "refine": rl,
        "refine_height": rh,
        "refine_width": rw,
        "h_mm": h,
        "h_height_mm": h if refine is None else BASE_H[dim] / rh,
        "cells": um.mesh.t.shape[1],
        "ndofs": res.ndofs,
        "case": case,
        "status": res.status,
        "reason": res.reason,
        "p_reached_kpa": res.load_factor * p_kpa[-1],
        "attempt": res.attempt,
        "contact_smoothing_mm": res.contact_smoothing_mm,
        "steps": res.steps,
        "cutbacks": res.cutbacks,
        "newton_iterations": res.newton_iterations,
        "wall_time_s": time.perf_counter() - t0,
    }
    for p in p_kpa:
        hit = [s[KEY[case]] for s in res.history if abs(s["p_top_kpa"] - p) < 1e-6]
        row[f"{KEY[case]}_{int(p)}"] = hit[0] if hit else np.nan
    return row


def _reached(f: pd.DataFrame, col: str):
    """(h, values) of the family's meshes that reached the column's pressure, coarse to fine; None below three."""
    ok = f[col].notna().to_numpy() if col in f else np.zeros(len(f), bool)
    return (f["h_mm"].to_numpy()[ok], f[col].to_numpy()[ok]) if ok.sum() >= 3 else None


def summary(df: pd.DataFrame, p_kpa=P_KPA, dim: int = 3) -> pd.DataFrame:
    """Per case and pressure: the three finest values that reached it, observed order, limit, GCI, default mesh vs
    the limit (2D: refine = 1 is the default mesh)."""
    rows = []
    fam = df[df["refine"] > 0].sort_values("refine")
    for case, key in KEY.items():
        f = fam[fam["case"] == case]
        d = df[(df["refine"] == (1 if dim == 2 else 0)) & (df["case"] == case)]
        for p in p_kpa:
            col = f"{key}_{int(p)}"
            hv = _reached(f, col)
            if hv is None:
                continue
            h, v = hv[0][-3:], hv[1][-3:]
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
                    "default": dflt,
                    "default_vs_limit_pct": 100 * (dflt - r.limit) / abs(r.limit) if r.asymptotic else np.nan,
                    "coarsest_vs_limit_pct": 100 * (v[np.argmax(h)] - r.limit) / abs(r.limit)
                    if r.asymptotic
                    else np.nan,
                }
            )
    return pd.DataFrame(rows)


def direction_table(df: pd.DataFrame, p_kpa=P_KPA, dim: int = 2) -> str:
    """Per case and pressure, the value on each (length, height) refinement: rows the height's factor, columns the
    length's; then each direction's observed order and limit from the three finest factors along it (the other at
    its finest), where the three are asymptotic."""
    out = []
    for case, key in KEY.items():
        f = df[(df["case"] == case) & (df["refine"] > 0)]
        for p in p_kpa:
            col = f"{key}_{int(p)}"
            if f.empty or col not in f or f[col].notna().sum() == 0:
                continue
            tab = f.pivot_table(index="refine_height", columns="refine", values=col)
            out.append(f"{case}, {p:g} kPa (rows: height factor, columns: length factor)\n{tab.round(5).to_string()}")
            for name, line in (("height", tab.iloc[:, -1]), ("length", tab.iloc[-1, :])):
                line = line.dropna()
                if len(line) >= 3:
                    r = richardson(BASE_H[dim] / line.index.to_numpy()[-3:], line.to_numpy()[-3:])
                    out.append(
                        f"  along the {name} (other factor at its finest): order {r.order:.2f}, limit {r.limit:.5f}"
                        f"{'' if r.asymptotic else ' (not asymptotic)'}"
                    )
    return "\n".join(out)


def plot_convergence(frames, path: str) -> None:
    """Log-log plot of |value - limit| / |limit| against h per CSV (``frames``: (table, label)), case and pressure,
    the limit from the three finest meshes where they are asymptotic; a slope-1 guide."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    fig, ax = plt.subplots(figsize=(6, 4.2))
    hs = set()
    for df, label in frames:
        fam = df[df["refine"] > 0].sort_values("refine")
        for case, key in KEY.items():
            f = fam[fam["case"] == case]
            for col in [c for c in f.columns if c.startswith(key + "_")]:
                hv = _reached(f, col)
                if hv is None:
                    continue
                h, v = hv
                r = richardson(h[-3:], v[-3:])
                if not r.asymptotic:
                    continue
                hs.update(h.tolist())
                lab = f"{case}, {col.rsplit('_', 1)[1]} kPa, {label} (order {r.order:.2f})"
                ax.loglog(h, np.abs(v - r.limit) / abs(r.limit) * 100, "o-", label=lab)
    hh = np.array([min(hs), max(hs)])
    ax.loglog(hh, 3.0 * hh / hh.max(), "k:", label="slope 1")
    ax.set_xticks(sorted(hs), [f"{v:g}" for v in sorted(hs)])
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("element size h (mm)")
    ax.set_ylabel("distance from the Richardson limit (%)")
    ax.legend(fontsize=7)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dim", type=int, choices=(2, 3), default=3)
    ap.add_argument("--refine", default="2,3,4", help="multipliers of the h = 4 mm (3D) / 1 mm (2D) counts")
    ap.add_argument("--cases", default="blocked,free")
    ap.add_argument("--pressures", default="60,180,300", help="kPa: the rays' stops and end (P_B = 0)")
    ap.add_argument("--default", action="store_true", help="also solve the default mesh's rays")
    ap.add_argument("--band", type=float, default=None, help="mm: one contact band for every ray (no band restarts)")
    ap.add_argument("--no-contact", action="store_true", help="without contact (a comparison, never a choice)")
    ap.add_argument("--summary", action="store_true", help="only print the table from the CSV")
    ap.add_argument("--plot", default=None, help="PNG: each quantity's distance from its Richardson limit against h")
    ap.add_argument(
        "--plot-also", default="", help="other CSVs of this study whose curves join the plot (comma-separated)"
    )
    a = ap.parse_args(argv)
    p_kpa = tuple(float(p) for p in a.pressures.split(","))
    tokens = [_refine_token(t) for t in a.refine.split(",")]
    aniso = any(isinstance(t, tuple) for t in tokens)
    CSV = _csv(a.dim, p_kpa, a.band, aniso, not a.no_contact)
    OUT.mkdir(parents=True, exist_ok=True)
    if not a.summary:
        done = pd.read_csv(CSV) if CSV.exists() else pd.DataFrame(columns=["mesh", "case"])
        todo = [(None, c) for c in a.cases.split(",")] if a.default else []
        todo += [(r, c) for r in tokens for c in a.cases.split(",")]
        for r, case in todo:
            name = _mesh_name(r)
            if ((done["mesh"] == name) & (done["case"] == case)).any():
                continue
            print(f"{name} {case} ...", flush=True)
            row = solve_ray(r, case, a.dim, p_kpa, a.band, not a.no_contact)
            print(row, flush=True)
            done = pd.concat([done, pd.DataFrame([row])], ignore_index=True)
            done.to_csv(CSV, index=False)
    df = pd.read_csv(CSV)
    with pd.option_context("display.width", 250, "display.max_columns", 30):
        print(df.drop(columns=["reason"]).to_string(index=False))
        print(direction_table(df, p_kpa, a.dim) if aniso else summary(df, p_kpa, a.dim).to_string(index=False))
    if a.plot and aniso:
        raise SystemExit(
            "--plot draws a family refined in every direction; the meshes refined by direction have a table"
        )
    if a.plot:

        def label(stem: str) -> str:  # the band, where the CSV has one
            return stem[stem.find("band") :].replace("band", "band ") + " mm" if "band" in stem else "config's band"

        others = [(pd.read_csv(c), label(Path(c).stem)) for c in a.plot_also.split(",") if c]
        plot_convergence([(df, label(CSV.stem)), *others], a.plot)


if __name__ == "__main__":
    main()
