"""The variants' FEA checks joined: per variant and exercise the joint angles the FEA reached (after the correction
step, where it ran), reached or not, and the largest strap force and actuator moment against the safety limits.

Pure: takes the checks as datasets (``results/authors_study/{variant}/{patient}/fea_check.nc``), returns one.
Angles in degrees, moments in N m, forces in N (full actuator width).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.common.constants import JOINTS
from workflow.fea_check.outcome import final_outcome

__all__ = ["final_state", "study_dataset"]


def final_state(check: xr.Dataset) -> xr.Dataset:
    """One check's outcome per exercise: the best corrected state where the correction ran, else the first solve
    (:func:`workflow.fea_check.outcome.final_outcome`), with its loads against the safety limits."""
    final = final_outcome(check)
    limit = check["active_limit_nm"].sel(joint=list(JOINTS))
    moment = check["max_actuator_moment_nm"].sel(joint=list(JOINTS))
    return xr.Dataset(
        {
            "angle_deg": final["angle_deg"],
            "target_angle_deg": check["target_angle_deg"].sel(joint=list(JOINTS)).astype(float),
            "reached": final["reached"],
            "converged": check["converged"].astype(bool),
            "load_factor": check["load_factor"].astype(float),
            "max_strap_force_n": check["max_strap_force_n"].max("strap").astype(float),
            "max_actuator_moment_nm": np.abs(moment).max("joint").astype(float),
            "moment_share_of_limit": (np.abs(moment) / limit).max("joint").astype(float),
            "within_limits": check["within_limits"].astype(bool),
            "reason": check["reason"].astype(str),
        }
    )


def study_dataset(checks: Mapping[str, xr.Dataset], changes: Mapping[str, Sequence[str]]) -> xr.Dataset:
    """Join the variants' checks (variant -> dataset; every variant has one: a failed solve is an outcome in it).

    ``changes``: per variant the config keys it overrides (shown in the table). Exercises are the union over the
    variants; an exercise a variant did not check stays NaN / False.
    """
    names = list(checks)
    states = [final_state(ds) for ds in checks.values()]
    exercises = sorted({str(e) for s in states for e in s["exercise"].values})
    ds = xr.concat([s.reindex(exercise=exercises) for s in states], dim="variant", join="outer", data_vars="all")
    ds = ds.assign_coords(variant=names)
    for name in ("reached", "converged", "within_limits"):
        ds[name] = ds[name].fillna(False).astype(bool)
    ds["reason"] = ds["reason"].fillna("").astype(object)
    deg, nm = {"units": "degree"}, {"units": "N m"}
    attrs = {
        "angle_deg": {**deg, "long_name": "joint angle the FEA reached (after the correction step where it ran)"},
        "target_angle_deg": {**deg, "long_name": "the exercise's target joint angle"},
        "reached": {"units": "1", "long_name": "every joint within the tolerance, moments within the active limits"},
        "converged": {"units": "1", "long_name": "the first solve took the pressures in full"},
        "load_factor": {"units": "1", "long_name": "last converged fraction of the first solve's pressures"},
        "max_strap_force_n": {"units": "N", "long_name": "largest strap force along the load path"},
        "max_actuator_moment_nm": {**nm, "long_name": "largest actuator moment about any joint along the load path"},
        "moment_share_of_limit": {"units": "1", "long_name": "largest actuator moment / the joint's active limit"},
        "within_limits": {"units": "1", "long_name": "every actuator moment within its active limit"},
        "reason": {"units": "1", "long_name": "why the first solve missed the exercise (empty if it reached it)"},
    }
    for k, a in attrs.items():
        ds[k].attrs.update(a)
    ds["n_reached"] = ("variant", ds["reached"].sum("exercise").values.astype("i4"), {"units": "1"})
    ds["changes"] = ("variant", np.array(["; ".join(changes.get(v, ())) for v in names], dtype=object))
    ds["changes"].attrs["long_name"] = "config keys the variant overrides"
    return ds
