"""Our planned pressures for the mean finger against the paper's Tables 8 and 10.

Per pressure (eight per exercise) the absolute error in kPa and the relative
error where the reference is at least ``rel_floor_kpa`` (10 kPa,
by default); the exercises we reach against each of the paper's three
sets separately: planned in 3D (Table 8: all five), reached
in its 2D finger-actuator FEA (TGE1-3), reached on the dummy finger (Table 10:
TGE1-2).  Agreement with Table 8 is indicative only: the paper summed unit
moments along the chain, and Table 10 was measured on a PLA
dummy finger.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd
import xarray as xr

from workflow.actuator.mapping import read_unit_moments
from workflow.cascade.model import SPANS
from workflow.common.constants import GROUPS, PRESSURE_NAMES

__all__ = ["PAPER_REACHED", "read_pressure_table", "compare_pressures", "compare_planners", "compare_unit_moments"]

#: Exercises the paper reached, per set.
PAPER_REACHED: Mapping[str, Sequence[str]] = {
    "planned_3d": ("TGE1", "TGE2", "TGE3", "TGE4", "TGE5"),
    "fea_2d": ("TGE1", "TGE2", "TGE3"),
    "dummy": ("TGE1", "TGE2"),
}


def read_pressure_table(path: str | Path) -> pd.DataFrame:
    """A paper pressure table (kPa), indexed by exercise, columns :data:`PRESSURE_NAMES`."""
    df = pd.read_csv(path).set_index("exercise")
    missing = [c for c in PRESSURE_NAMES if c not in df.columns]
    if missing:
        raise ValueError(f"{path}: missing columns {missing}")
    return df[list(PRESSURE_NAMES)].astype(float)


def compare_pressures(
    plan: xr.Dataset,
    references: Mapping[str, pd.DataFrame],
    rel_floor_kpa: float = 10.0,
    plans: Mapping[str, xr.Dataset] | None = None,
) -> xr.Dataset:
    """Errors of the plan's pressures against each reference table.

    ``plan``: a ``cascade_plan.nc`` dataset; ``references``: {name: table},
    the names becoming the ``table`` dimension.  ``plans``: {name: plan} for
    tables compared with another plan than ``plan`` (Table 10 with the dummy
    finger's).  Exercises missing from a table are NaN there.
    """
    ex = [str(e) for e in plan["exercise"].values]
    names = list(references)
    plans = dict(plans or {})
    compared = [plans.get(n, plan) for n in names]
    ours_t = np.stack([pl["pressure_kpa"].sel(exercise=ex).values.reshape(len(ex), 8) for pl in compared])
    ours = ours_t[0] if not plans else ours_t
    ref = np.full((len(names), len(ex), 8), np.nan)
    for r, name in enumerate(names):
        tab = references[name]
        for i, e in enumerate(ex):
            if e in tab.index:
                ref[r, i] = tab.loc[e].values
    abs_err = np.abs(ours_t - ref)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(ref >= rel_floor_kpa, abs_err / ref, np.nan)
    achieved = np.asarray(plan["achieved"].values).astype(bool)
    sets = list(PAPER_REACHED)
    paper = np.array([[e in PAPER_REACHED[s] for e in ex] for s in sets])
    # the dummy-finger experiment is compared with the dummy's plan when there is one
    dummy = plans.get("table10")
    ours_sets = np.array(
        [
            np.asarray(dummy["achieved"].values).astype(bool) if (dummy is not None and "dummy" in s) else achieved
            for s in sets
        ]
    )
    agree = paper == ours_sets
    ours_dims = ("exercise", "pressure") if not plans else ("table", "exercise", "pressure")
    patients = [str(pl.attrs.get("patient", "")) for pl in compared]
    ds = xr.Dataset(
        {
            "ours": (
                ours_dims,
                ours,
                {
                    "units": "kPa",
                    "long_name": "our planned pressure",
                    "patient_per_table": ", ".join(f"{n}: {p}" for n, p in zip(names, patients)),
                },
            ),
            "reference": (("table", "exercise", "pressure"), ref, {"units": "kPa", "long_name": "paper's pressure"}),
            "abs_error": (
                ("table", "exercise", "pressure"),
                abs_err,
                {"units": "kPa", "long_name": "|ours - reference|"},
            ),
            "rel_error": (
                ("table", "exercise", "pressure"),
                rel,
                {
                    "units": "1",
                    "long_name": f"|ours - reference| / reference (NaN where reference < {rel_floor_kpa:g} kPa)",
                },
            ),
            "mean_abs_error": (
                ("table",),
                np.nanmean(abs_err.reshape(len(names), -1), axis=1),
                {"units": "kPa", "long_name": "mean absolute error over the table's cells"},
            ),
            "ours_achieved": (("exercise",), achieved, {"long_name": "exercise reached by our plan"}),
            "paper_reached": (("paper_set", "exercise"), paper, {"long_name": "exercise reached in the paper's set"}),
            "reached_agreement": (
                ("paper_set",),
                agree.mean(axis=1),
                {"units": "1", "long_name": "share of exercises where ours and the paper's set agree"},
            ),
        },
        coords={"table": names, "exercise": ex, "pressure": list(PRESSURE_NAMES), "paper_set": sets},
    )
    ds.attrs["rel_floor_kpa"] = rel_floor_kpa
    return ds


def compare_planners(
    plan: xr.Dataset,
    references: Mapping[str, pd.DataFrame],
    rel_floor_kpa: float = 10.0,
    plans: Mapping[str, xr.Dataset] | None = None,
) -> xr.Dataset:
    """Every planner's distance to each reference table (the ``planner_*`` variables of a plan).

    Per planner and table: the median and worst relative error over the table's cells of at least ``rel_floor_kpa``
    (its nonzero cells), the mean absolute error over all its cells (kPa), and which exercises the planner's plan
    reaches in the reduced-order chain.  ``plans`` as in :func:`compare_pressures` (Table 10 with the dummy's plan).
    An empty dataset where the plans carry no ``planner`` dimension.
    """
    plans = dict(plans or {})
    names = list(references)
    compared = [plans.get(n, plan) for n in names]
    if any("planner_pressure_kpa" not in pl for pl in compared):
        return xr.Dataset()
    planners = [p for p in plan["planner"].values if all(p in pl["planner"].values for pl in compared)]
    ex = [str(e) for e in plan["exercise"].values]
    med = np.full((len(planners), len(names)), np.nan)
    worst, mae = med.copy(), med.copy()
    reached = np.zeros((len(planners), len(names), len(ex)), bool)
    pressures = np.full((len(planners), len(names), len(ex), 8), np.nan)
    for r, (name, pl) in enumerate(zip(names, compared)):
        tab = references[name]
        ref = np.array([tab.loc[e].values if e in tab.index else np.full(8, np.nan) for e in ex])
        for i, planner in enumerate(planners):
            ours = pl["planner_pressure_kpa"].sel(planner=planner, exercise=ex).values.reshape(len(ex), 8)
            pressures[i, r] = ours
            err = np.abs(ours - ref)
            big = ref >= rel_floor_kpa
            rel = err[big] / ref[big]
            if rel.size:
                med[i, r], worst[i, r] = np.median(rel), np.max(rel)
            mae[i, r] = np.nanmean(err)
            reached[i, r] = pl["planner_achieved"].sel(planner=planner, exercise=ex).values.astype(bool)
    return xr.Dataset(
        {
            "planner_median_rel_error": (
                ("planner", "table"),
                med,
                {"units": "1", "long_name": f"median |ours - paper| / paper over cells >= {rel_floor_kpa:g} kPa"},
            ),
            "planner_worst_rel_error": (
                ("planner", "table"),
                worst,
                {"units": "1", "long_name": f"largest |ours - paper| / paper over cells >= {rel_floor_kpa:g} kPa"},
            ),
            "planner_mean_abs_error": (
                ("planner", "table"),
                mae,
                {"units": "kPa", "long_name": "mean |ours - paper| over all the table's cells"},
            ),
            "planner_ours": (
                ("planner", "table", "exercise", "pressure"),
                pressures,
                {"units": "kPa", "long_name": "each planner's pressure, from the plan compared with the table"},
            ),
            "planner_reached": (
                ("planner", "table", "exercise"),
                reached,
                {"long_name": "exercise reached by the planner's plan compared with the table (reduced-order chain)"},
            ),
        },
        coords={"planner": planners, "table": names, "exercise": ex, "pressure": list(PRESSURE_NAMES)},
    )


def compare_unit_moments(plan: xr.Dataset, table07: str | Path) -> xr.Dataset:
    """Per-unit moments at the target pose (ours) beside Table 7's, per exercise and group.

    Ours: ``required_moment_nm`` of the joint whose span holds the group (CMC
    and MCP: MCP).  The paper's came from tip-force measurements divided over
    eight chambers, so only signs and ordering compare.
    """

    ex = [str(e) for e in plan["exercise"].values]
    joint_of = {g: j for j, gs in SPANS.items() for g in gs}
    ours = np.array(
        [[float(plan["required_moment_nm"].sel(exercise=e, joint=joint_of[g])) for g in GROUPS] for e in ex]
    )
    ref = read_unit_moments(table07, ex)
    return xr.Dataset(
        {
            "unit_moment_ours_nm": (
                ("exercise", "group"),
                ours,
                {"units": "N m", "long_name": "our per-unit moment holding the target pose"},
            ),
            "unit_moment_table07_nm": (
                ("exercise", "group"),
                ref,
                {"units": "N m", "long_name": "paper's target moment per unit (Table 7)"},
            ),
            "unit_moment_sign_agrees": (
                ("exercise", "group"),
                np.sign(ours) == np.sign(ref),
                {"long_name": "ours and Table 7 have the same sign"},
            ),
        },
        coords={"exercise": ex, "group": list(GROUPS)},
    )
