"""Tables of the run report: datasets -> pandas DataFrames -> standalone HTML pages.

Snakemake's HTML report shows a ``.html`` result inline, so each table is
written as a small self-contained page (`html_page`).  One function per
dataset, each pure (a dataset in, a DataFrame out); units in the column names.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import xarray as xr

from workflow.fidelity.analysis import METHOD_GROUPS, group_errors

__all__ = [
    "scaling_table",
    "musculoskeletal_table",
    "unit_check_table",
    "surrogate_cv_table",
    "mapping_table",
    "cascade_validation_table",
    "reached_table",
    "cascade_plan_table",
    "joint_loads_table",
    "TABLES",
    "speed_accuracy_table",
]


def scaling_table(ds: xr.Dataset) -> pd.DataFrame:
    """Scale factors against Tables 3-4: per body and axis, max and mean |ours - paper| over the 15 runs."""
    err = ds["abs_error"]
    rows = []
    for b in ds["body"].values:
        for a in ds["axis"].values:
            e = err.sel(body=b, axis=a).values
            i = int(np.nanargmax(e))
            rows.append(
                {
                    "body": str(b),
                    "axis": str(a),
                    "max |error|": float(np.nanmax(e)),
                    "mean |error|": float(np.nanmean(e)),
                    "run of max": str(ds["marker"].values[i]),
                }
            )
    return pd.DataFrame(rows).set_index(["body", "axis"])


def musculoskeletal_table(ds: xr.Dataset) -> pd.DataFrame:
    """Our OpenSim moments against the authors' export, per response (empty if the export is absent)."""
    if ds.sizes.get("response", 0) == 0:
        return pd.DataFrame({"note": ["the authors' export was absent: no comparison (reference_missing = 1)"]})
    rows = []
    for r in ds["response"].values:
        d = ds.sel(response=r)
        row = {
            "response": str(r),
            "mean |ours| (N m)": float(np.nanmean(np.abs(d["ours"]))),
            "mean |reference| (N m)": float(np.nanmean(np.abs(d["reference"]))),
            "median rel. error": float(np.nanmedian(d["rel_error"])) if np.isfinite(d["rel_error"]).any() else np.nan,
        }
        if "sign_agrees" in d:
            row["sign agrees (runs)"] = f"{int(d['sign_agrees'].sum())}/{d.sizes['run']}"
        rows.append(row)
    return pd.DataFrame(rows).set_index("response")


def unit_check_table(ds: xr.Dataset) -> pd.DataFrame:
    """Free angle, blocked moment, status, penetration and wall time per FE model and top pressure."""
    rows = []
    for m in ds["model"].values:
        for p in ds["p_top_kpa"].values:
            d = ds.sel(model=m, p_top_kpa=p)
            rows.append(
                {
                    "model": str(m).upper(),
                    "P_T (kPa)": float(p),
                    "free angle per unit (deg)": float(d["bending_angle_deg"]),
                    "blocked moment per unit (N m)": float(d["bending_moment_nm"]),
                    "status free / blocked": f"{int(d['status'].sel(case='free'))} / {int(d['status'].sel(case='blocked'))}",
                    "max penetration free / blocked (mm)": f"{float(d['max_penetration_mm'].sel(case='free')):.4f} / "
                    f"{float(d['max_penetration_mm'].sel(case='blocked')):.4f}",
                    "wall time free / blocked (s)": f"{float(d['wall_time_s'].sel(case='free')):.1f} / "
                    f"{float(d['wall_time_s'].sel(case='blocked')):.1f}",
                }
            )
    return pd.DataFrame(rows).set_index(["model", "P_T (kPa)"])


def surrogate_cv_table(ds: xr.Dataset) -> pd.DataFrame:
    """Mean over folds of R^2, MAE and RMSE per FE model, regressor and target; the score and the choice."""
    rows = []
    for f in ds["fea"].values:
        for r in ds["regressor"].values:
            row = {
                "FE model": str(f).upper(),
                "regressor": str(r),
                "score (RMSE/std)": float(ds["score"].sel(fea=f, regressor=r)),
                "chosen": "yes" if bool(ds["selected"].sel(fea=f, regressor=r)) else "",
            }
            for t in ds["target"].values:
                u = "deg" if str(t) == "angle" else "N m"
                d = ds.sel(fea=f, regressor=r, target=t)
                row[f"{t} R2"] = float(d["r2"].mean())
                row[f"{t} MAE ({u})"] = float(d["mae"].mean())
                row[f"{t} RMSE ({u})"] = float(d["rmse"].mean())
            rows.append(row)
    return pd.DataFrame(rows).set_index(["FE model", "regressor"])


def mapping_table(ds: xr.Dataset) -> pd.DataFrame:
    """Table 8's 3D pressures and the mapped 2D pressures per exercise and group."""
    rows = []
    for e in ds["exercise"].values:
        for g in ds["group"].values:
            d = ds.sel(exercise=e, group=g)
            rows.append(
                {
                    "exercise": str(e),
                    "group": str(g),
                    "3D P_T / P_B (kPa)": f"{float(d['pressure_3d_kpa'].sel(chamber='top')):.1f} / "
                    f"{float(d['pressure_3d_kpa'].sel(chamber='bottom')):.1f}",
                    "2D P_T / P_B (kPa)": f"{float(d['pressure_2d_kpa'].sel(chamber='top')):.1f} / "
                    f"{float(d['pressure_2d_kpa'].sel(chamber='bottom')):.1f}",
                    "scale": float(d["scale"]),
                    "angle 3D (deg)": float(d["angle_3d_deg"]),
                    "status": int(d["status"]),
                    "reason": str(d["reason"].values),
                }
            )
    return pd.DataFrame(rows).set_index(["exercise", "group"])


def cascade_validation_table(ds: xr.Dataset) -> pd.DataFrame:
    """Our planned pressures beside Tables 8 and 10, per exercise and chamber pressure (kPa).

    ``ours`` may have a ``table`` dimension (a different plan, e.g. the dummy finger's, against Table 10).
    """
    rows = []
    for e in ds["exercise"].values:
        for p in ds["pressure"].values:
            row = {"exercise": str(e), "pressure": str(p)}
            for t in ds["table"].values:
                ours = ds["ours"].sel(exercise=e, pressure=p)
                row[f"ours for {t} (kPa)"] = float(ours.sel(table=t) if "table" in ours.dims else ours)
                row[f"{t} (kPa)"] = float(ds["reference"].sel(table=t, exercise=e, pressure=p))
                row[f"|error| vs {t} (kPa)"] = float(ds["abs_error"].sel(table=t, exercise=e, pressure=p))
            rows.append(row)
    return pd.DataFrame(rows).set_index(["exercise", "pressure"])


def reached_table(ds: xr.Dataset) -> pd.DataFrame:
    """Exercises we reach against each of the paper's sets (Table 8 planned, 2D FEA, dummy finger)."""
    out = pd.DataFrame(
        {
            str(s): ["yes" if v else "no" for v in ds["paper_reached"].sel(paper_set=s).values]
            for s in ds["paper_set"].values
        },
        index=[str(e) for e in ds["exercise"].values],
    )
    out.insert(0, "ours", ["yes" if v else "no" for v in ds["ours_achieved"].values])
    out.loc["agreement"] = [""] + [f"{float(v):.0%}" for v in ds["reached_agreement"].values]
    return out


def cascade_plan_table(ds: xr.Dataset) -> pd.DataFrame:
    """One patient's plan: the eight pressures, target and predicted angles, reached or why not."""
    rows = []
    for e in ds["exercise"].values:
        d = ds.sel(exercise=e)
        row = {"exercise": str(e)}
        for g in d["group"].values:
            row[f"{g} T/B (kPa)"] = (
                f"{float(d['pressure_kpa'].sel(group=g, chamber='top')):.0f} / "
                f"{float(d['pressure_kpa'].sel(group=g, chamber='bottom')):.0f}"
            )
        row["target MCP/PIP/DIP (deg)"] = " / ".join(f"{v:.0f}" for v in d["target_angle_deg"].values)
        row["predicted (deg)"] = " / ".join(f"{v:.1f}" for v in d["predicted_angle_deg"].values)
        row["reached"] = "yes" if bool(d["achieved"]) else "no"
        if "pressure_in_sampled_region" in d:
            row["in sampled region"] = "yes" if bool(d["pressure_in_sampled_region"].all()) else "NO"
        row["reason"] = str(d["reason"].values)
        rows.append(row)
    return pd.DataFrame(rows).set_index("exercise")


def joint_loads_table(ds: xr.Dataset) -> pd.DataFrame:
    """Passive joint moments per exercise with their prediction interval, and the active limits (N m)."""
    rows = []
    for e in ds["exercise"].values:
        row = {"exercise": str(e)}
        for j in ds["joint"].values:
            d = ds.sel(exercise=e, joint=j)
            row[f"{j} target (deg)"] = float(d["target_angle_deg"]) if "target_angle_deg" in d else np.nan
            row[f"{j} passive (N m)"] = (
                f"{float(d['passive_moment_nm']):.4f} "
                f"[{float(d['passive_moment_lo_nm']):.4f}, {float(d['passive_moment_hi_nm']):.4f}]"
            )
        rows.append(row)
    row = {"exercise": "active limit"}
    for j in ds["joint"].values:
        row[f"{j} target (deg)"] = (
            float(ds["active_limit_angle_deg"].sel(joint=j)) if "active_limit_angle_deg" in ds else np.nan
        )
        row[f"{j} passive (N m)"] = f"{float(ds['active_limit_nm'].sel(joint=j)):.4f}"
    rows.append(row)
    return pd.DataFrame(rows).set_index("exercise")


def speed_accuracy_table(ds: xr.Dataset) -> pd.DataFrame:
    """Per method: wall time, one-off setup time and, per quantity group, the largest error (Pareto marked *)."""

    rows = []
    for i, m in enumerate(ds["method"].values):
        row = {
            "method": str(m),
            "family": str(ds["family"].values[i]),
            "wall time (s)": float(ds["wall_time_s"].values[i]),
        }
        if "setup_time_s" in ds and float(ds["setup_time_s"].values[i]) > 0:
            row["setup (s)"] = float(ds["setup_time_s"].values[i])
        for title, prefix, unit in METHOD_GROUPS:
            e = float(group_errors(ds, prefix).values[i])
            if np.isfinite(e):
                q = [str(x) for x in ds["quantity"].values if str(x).startswith(prefix)]
                front = bool(ds["pareto"].sel({"method": m, "quantity": q}).any())
                rel = "relative" in unit
                row[title] = (f"{100 * e:.2f} %" if rel else f"{e:.2f}") + (" *" if front else "")
        rows.append(row)
    return pd.DataFrame(rows).set_index("method")


# name -> (title, [(caption, table function)], dataset attributes quoted as notes)
TABLES = {
    "scaling": (
        "Scale factors against Tables 3-4",
        [("|ours - paper| per body and axis over the 15 runs", scaling_table)],
        ("max_abs_error_excluding_paper_inconsistency", "paper_inconsistency"),
    ),
    "musculoskeletal": ("OpenSim backend against the authors' export", [("per response", musculoskeletal_table)], ()),
    "unit_check": (
        "FE unit check (Fig. 12 points)",
        [("per FE model and top pressure, P_B = 0", unit_check_table)],
        (),
    ),
    "surrogate_cv": ("Surrogate cross-validation", [("mean over folds", surrogate_cv_table)], ("selection_rule",)),
    "mapping": ("2D-to-3D pressure mapping of Table 8", [("per exercise and group", mapping_table)], ("method",)),
    "cascade_validation": (
        "Planned pressures against the paper (Tables 8 and 10)",
        [
            ("exercises reached, ours against each of the paper's sets", reached_table),
            ("pressures per exercise and chamber", cascade_validation_table),
        ],
        ("patient",),
    ),
    "cascade_plan": ("Cascade plan", [("per exercise", cascade_plan_table)], ("patient", "springs")),
    "speed_accuracy": (
        "Speed against accuracy",
        [
            (
                "per method: the largest error per quantity group (* = on the Pareto front of one of its quantities)",
                speed_accuracy_table,
            )
        ],
        (),
    ),
    "joint_loads": (
        "Joint loads and safety limits",
        [("passive moment [prediction interval] per exercise; active limit", joint_loads_table)],
        ("patient", "coded_norm"),
    ),
}
