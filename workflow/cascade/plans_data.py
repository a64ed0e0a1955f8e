"""A patient's plans as the contract's ``cascade_plan.nc`` content (without provenance), and every planner's side
by side.  Pressures kPa, angles deg, moments N m.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.cascade.model import SPANS, CascadeModel, pressures_table, solve_equilibrium
from workflow.cascade.planning import Plan
from workflow.cascade.stiffness import load_stiffness_nm_per_deg, span_stiffness_nm_per_deg
from workflow.common.constants import CASCADE_EQUILIBRIUM_STATUS, CHAMBERS, GROUPS, JOINTS

__all__ = ["planners_dataset", "plans_dataset"]


def plans_dataset(
    model: CascadeModel,
    plans: Sequence[Plan],
    *,
    tol_deg: float,
    active_limits_nm: Sequence[float] | None,
    notes: Mapping[str, str] | None = None,
):
    """The contract's ``cascade_plan.nc`` content (without provenance)."""
    ex = [p.exercise for p in plans]
    droop = solve_equilibrium(model, np.zeros(8))
    flag_vals = np.array(sorted(CASCADE_EQUILIBRIUM_STATUS), dtype="i1")
    lim = np.full(3, np.nan) if active_limits_nm is None else np.asarray(active_limits_nm, float)
    eqs = [p.equilibrium for p in plans]
    ds = xr.Dataset(
        {
            "pressure_kpa": (
                ("exercise", "group", "chamber"),
                np.array([pressures_table(p.pressures_kpa) for p in plans]),
                {"units": "kPa", "long_name": "planned chamber pressure"},
            ),
            "target_angle_deg": (
                ("exercise", "joint"),
                np.array([p.target_deg for p in plans]),
                {"units": "degree", "long_name": "target joint angle (Table 1)"},
            ),
            "predicted_angle_deg": (
                ("exercise", "joint"),
                np.array([e.joint_angles_deg for e in eqs]),
                {"units": "degree", "long_name": "joint angle at equilibrium under the planned pressures"},
            ),
            "angle_error_deg": (
                ("exercise", "joint"),
                np.array([e.joint_angles_deg - p.target_deg for e, p in zip(eqs, plans)]),
                {"units": "degree", "long_name": "predicted minus target joint angle"},
            ),
            "achieved": (
                "exercise",
                np.array([p.achieved for p in plans]),
                {"long_name": f"every joint within {tol_deg:g} deg of its target, moments within the active limits"},
            ),
            "reason": (
                "exercise",
                np.array([p.reason for p in plans], dtype=object),
                {"long_name": "why the exercise is not reached (empty if reached)"},
            ),
            "status": (
                "exercise",
                np.array([e.status for e in eqs], dtype="i1"),
                {
                    "long_name": "forward-solve status",
                    "flag_values": flag_vals,
                    "flag_meanings": " ".join(CASCADE_EQUILIBRIUM_STATUS[int(v)] for v in flag_vals),
                },
            ),
            "actuator_moment_nm": (
                ("exercise", "joint"),
                np.array([e.actuator_moments_nm for e in eqs]),
                {"units": "N m", "long_name": "flexion moment the actuator applies about the joint at equilibrium"},
            ),
            "required_moment_nm": (
                ("exercise", "joint"),
                np.array([p.required_moments_nm for p in plans]),
                {
                    "units": "N m",
                    "long_name": "moment per unit of the joint's span that holds the target pose (Table 7-like)",
                },
            ),
            "unit_target_angle_deg": (
                ("exercise", "group"),
                np.array([p.target_unit_angles_deg for p in plans]),
                {
                    "units": "degree",
                    "long_name": "unit bending angle at the target pose under the planned pressures (Table 7-like)",
                },
            ),
            "unit_angle_deg": (
                ("exercise", "group"),
                np.array([e.unit_angles_deg for e in eqs]),
                {"units": "degree", "long_name": "unit bending angle at equilibrium"},
            ),
            "unit_moment_nm": (
                ("exercise", "group"),
                np.array([e.unit_moments_nm for e in eqs]),
                {"units": "N m", "long_name": "bending moment each unit carries at equilibrium"},
            ),
            "strap_force_n": (
                ("exercise", "strap"),
                np.array([e.strap_forces_n for e in eqs]),
                {"units": "N", "long_name": "strap force transmitting the span moment (positive: pulls into flexion)"},
            ),
            "sum_sq_pressure_kpa2": (
                "exercise",
                np.array([float(p.pressures_kpa @ p.pressures_kpa) for p in plans]),
                {"units": "kPa2", "long_name": "objective: sum of squared pressures"},
            ),
            "active_limit_nm": ("joint", lim, {"units": "N m", "long_name": "active safety limit"}),
            "droop_angle_deg": (
                "joint",
                droop.joint_angles_deg,
                {"units": "degree", "long_name": "joint angle at zero pressure (gravity droop with the actuator on)"},
            ),
            "units_per_group": (
                "group",
                np.array([model.n_per_group[g] for g in GROUPS], dtype="i4"),
                {"units": "1", "long_name": "actuator units per group"},
            ),
            "segment_mass_kg": ("segment", model.finger.masses_kg, {"units": "kg", "long_name": "phalanx mass"}),
            "load_stiffness_nm_per_deg": (
                ("exercise", "joint"),
                np.array([load_stiffness_nm_per_deg(model, p.target_deg) for p in plans]),
                {"units": "N m / degree", "long_name": "|d required moment / d joint angle| at the target pose"},
            ),
        },
        coords={
            "exercise": ex,
            "group": list(GROUPS),
            "chamber": list(CHAMBERS),
            "joint": list(JOINTS),
            "strap": ["PIP", "DIP"],
            "segment": ["PP", "MP", "DP"],
        },
    )
    if hasattr(model.unit, "stiffness_nm_per_deg"):
        ds["span_stiffness_nm_per_deg"] = (
            ("exercise", "joint"),
            np.array(
                [
                    [
                        span_stiffness_nm_per_deg(model, j, p.pressures_kpa, p.equilibrium.actuator_moments_nm[j])[0]
                        for j in range(3)
                    ]
                    for p in plans
                ]
            ),
            {"units": "N m / degree", "long_name": "rotational stiffness of each joint's span of units (unit model)"},
        )
    ds.attrs.update(
        {
            "unit_mass_kg": model.unit_mass_kg,
            "unit_length_mm": model.unit_length_m * 1e3,
            "spans": "; ".join(f"{j}: {'+'.join(g)}" for j, g in SPANS.items()),
            "finger_mass_source": model.finger.mass_source,
            "droop_converged": int(droop.converged),
            **dict(notes or {}),
        }
    )
    return ds


def planners_dataset(by_planner: Mapping[str, Sequence[Plan]]):
    """Every planner's plans side by side (``planner`` dimension): pressures, predicted angles, reached.

    ``by_planner``: {planner: its plans of the same exercises, in the same order}.  The plan's own variables
    (``pressure_kpa`` ...) are the configured planner's; these let the validation compare the planners.
    """
    names = list(by_planner)
    ex = [p.exercise for p in by_planner[names[0]]]
    for name in names:
        if [p.exercise for p in by_planner[name]] != ex:
            raise ValueError(f"planner {name!r} planned other exercises than {names[0]!r}")
    return xr.Dataset(
        {
            "planner_pressure_kpa": (
                ("planner", "exercise", "group", "chamber"),
                np.array([[pressures_table(p.pressures_kpa) for p in by_planner[n]] for n in names]),
                {"units": "kPa", "long_name": "chamber pressure each planner plans"},
            ),
            "planner_predicted_angle_deg": (
                ("planner", "exercise", "joint"),
                np.array([[p.equilibrium.joint_angles_deg for p in by_planner[n]] for n in names]),
                {"units": "degree", "long_name": "joint angle at equilibrium under each planner's pressures"},
            ),
            "planner_achieved": (
                ("planner", "exercise"),
                np.array([[p.achieved for p in by_planner[n]] for n in names]),
                {"long_name": "exercise reached by each planner's plan (reduced-order chain)"},
            ),
        },
        coords={
            "planner": names,
            "exercise": ex,
            "group": list(GROUPS),
            "chamber": list(CHAMBERS),
            "joint": list(JOINTS),
        },
    )
