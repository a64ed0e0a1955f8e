"""Rule entry points of the cascade stage (``cascade_plan``,
``validate_cascade``): read a patient's loads and the unit model, plan every
exercise, write the plan and its poses plot; compare the plans with Tables 8
and 10.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import xarray as xr

from workflow.actuator.sampled_region import flag_pressure_table
from workflow.cascade.calibration import calibrated
from workflow.cascade.patient import chain_note as describe_chain
from workflow.cascade.patient import patient_cascade, patient_finger, plan_limit, plan_options
from workflow.cascade.planning import PLANNERS, plan_exercise
from workflow.cascade.plans_data import planners_dataset, plans_dataset
from workflow.cascade.plots import plot_poses, plot_validation
from workflow.cascade.validation import compare_planners, compare_pressures, compare_unit_moments, read_pressure_table
from workflow.common.constants import JOINTS
from workflow.common.provenance import open_result, write_dataset

__all__ = ["write_cascade_plan", "write_cascade_validation"]


def read_calibration(calibration_nc: str | Path, patient_name: str) -> tuple[np.ndarray, np.ndarray, str]:
    """The span gains and compliances (rad/N m, per joint) of a chain calibration (``chain_calibration.nc``) and a
    note on them; a fit that did not converge raises, a calibration on another patient's finger warns."""
    cal = open_result(calibration_nc)
    if int(cal.attrs["fit_status"]) <= 0:  # least_squares: 0 = evaluations spent, -1 = bad input
        raise RuntimeError(f"{calibration_nc}: the chain's fit did not converge ({cal.attrs['fit_message']})")
    if str(cal.attrs["patient"]) != patient_name:
        logging.getLogger(__name__).warning(
            "patient %s: the chain calibrated on patient %s's finger is applied to this one (the gains describe "
            "the actuator's coupling to a finger, fitted on one)",
            patient_name,
            cal.attrs["patient"],
        )
    gain, compliance = cal["span_gain"].values, cal["span_compliance_rad_per_nm"].values
    note = (
        f"calibrated to the 2D FEA of patient {cal.attrs['patient']}: gains {np.round(gain, 3).tolist()}, "
        f"compliances {np.round(compliance, 3).tolist()} rad/N m; held-out error "
        f"{cal.attrs['max_error_held_out_before_deg']:.1f} -> {cal.attrs['max_error_held_out_after_deg']:.1f} deg"
    )
    return gain, compliance, note


def write_cascade_plan(
    patient_name: str,
    patient: Mapping[str, Any],
    unit: Any,
    *,
    ccd_nc: str,
    moments_nc: str,
    joint_loads_nc: str,
    out_nc: str,
    out_png: str | None,
    cascade_cfg: Mapping[str, Any],
    anthropometry: Mapping[str, Any],
    config_slice: Any,
    rule: str = "cascade_plan",
    sampled_region: Any = None,
    notes: Mapping[str, str] | None = None,
    material_limit: Any = None,
    calibration_nc: str | None = None,
):
    """Build the patient's finger and actuator, plan every exercise, write the plan (and poses plot).

    ``calibration_nc``: the chain's calibration (``chain_calibration.nc``), whose span gains and compliances the
    chain then plans with; stored as ``chain_span_gain`` and ``chain_span_compliance_rad_per_nm`` either way.

    ``unit`` is the unit response object (see :class:`UnitResponse`);
    ``cascade_cfg`` the config's ``cascade`` section; ``material_limit`` the
    silicone's pressure limit (:func:`workflow.actuator.pressure_limit.material_limit`):
    no planned pressure exceeds :func:`plan_limit`, recorded in the attrs
    ``p_limit_kpa`` and ``p_limit_source``.  ``sampled_region`` (a
    `workflow.stability.SampledRegion` of the surrogate's sweep), if given,
    flags planned (P_T, P_B) pairs outside the converged FE samples or nearest
    a failed one: ``pressure_in_sampled_region`` and a warning in the log.
    ``notes`` go into the attrs (e.g. the surrogate's fidelity and why).
    """
    import logging
    import time

    log = logging.getLogger(__name__)
    c = cascade_cfg
    loads = open_result(joint_loads_nc)
    fing, spring_note = patient_finger(
        patient, loads, open_result(moments_nc), open_result(ccd_nc), cascade_cfg=c, anthropometry=anthropometry
    )
    finger_name = str(patient.get("finger", "F3"))
    model = patient_cascade(fing, unit, c)
    chain_note = "the paper's chain (no calibration)"
    if calibration_nc is not None:
        gain, compliance, chain_note = read_calibration(calibration_nc, patient_name)
        model = calibrated(model, gain, compliance)
    chain_note = describe_chain(model, chain_note)
    log.info("patient %s: chain: %s", patient_name, chain_note)
    limits = loads["active_limit_nm"].sel(joint=list(JOINTS)).values
    targets = {
        str(e): loads["target_angle_deg"].sel(exercise=e, joint=list(JOINTS)).values for e in loads["exercise"].values
    }
    log.info(
        "patient %s: units per group %s, finger masses %s kg (%s); springs: %s",
        patient_name,
        model.n_per_group,
        np.round(fing.masses_kg, 4),
        fing.mass_source,
        spring_note,
    )
    limit = plan_limit(c, unit, material_limit)
    log.info("patient %s: every planned pressure <= %s", patient_name, limit)
    t0 = time.perf_counter()
    chosen = str(c.get("planner", "paper"))
    by_planner = {}
    for planner in PLANNERS:
        if planner != chosen and planner == "stiffness" and not hasattr(unit, "stiffness_nm_per_deg"):
            log.warning("patient %s: the unit model has no stiffness; the stiffness planner is left out", patient_name)
            continue
        opts = {**plan_options(c, limits, limit), "planner": planner}
        by_planner[planner] = [plan_exercise(model, t, exercise=name, **opts) for name, t in targets.items()]
        for p in by_planner[planner]:
            if np.any(p.pressures_kpa > limit.kpa):  # the search is bounded: this is a bug, not a plan to write
                raise RuntimeError(
                    f"patient {patient_name} {p.exercise} ({planner}): planned {p.pressures_kpa.max():.1f} kPa "
                    f"above {limit}"
                )
    plans = []
    for p in by_planner[chosen]:
        name, t = p.exercise, p.target_deg
        log.info(
            "%s: %s pressures %s kPa, predicted %s deg (target %s) %s",
            name,
            "reached" if p.achieved else "NOT reached",
            np.round(p.pressures_kpa, 1),
            np.round(p.equilibrium.joint_angles_deg, 1),
            t,
            p.reason,
        )
        plans.append(p)
    ds = plans_dataset(
        model,
        plans,
        tol_deg=c["tolerance_deg"],
        active_limits_nm=limits,
        notes={
            "patient": patient_name,
            "finger": finger_name,
            "springs": spring_note,
            "planning_wall_time_s": round(time.perf_counter() - t0, 3),  # every planner's plans
            "p_limit_kpa": limit.kpa,
            "p_limit_source": limit.source,
            "planner": chosen,
            "stiffness_margin": float(c.get("stiffness_margin", 1.0)),
            **dict(notes or {}),
        },
    )
    ds = ds.merge(planners_dataset(by_planner))
    ds["chain_span_gain"] = (
        "joint",
        np.asarray(model.span_gain, float),
        {"units": "1", "long_name": "share of each span's bend that turns its joint (1: the paper's chain)"},
    )
    ds["chain_span_compliance_rad_per_nm"] = (
        "joint",
        np.asarray(model.span_compliance_rad_per_nm, float),
        {"units": "rad / (N m)", "long_name": "span rotation per span moment beyond the straps' give"},
    )
    ds.attrs["chain"] = chain_note
    for planner, pl in by_planner.items():
        log.info(
            "planner %s: reaches %s; pressures (kPa) %s",
            planner,
            [p.exercise for p in pl if p.achieved] or "none",
            "; ".join(f"{p.exercise} {np.round(p.pressures_kpa).astype(int).tolist()}" for p in pl),
        )
    if sampled_region is not None:
        # the surrogate is an extrapolation outside its samples: flag, do not stop

        ds["pressure_in_sampled_region"], msgs = flag_pressure_table(
            ds["pressure_kpa"], sampled_region, label=f"patient {patient_name}: "
        )
        for m in msgs:
            log.warning(m)
    write_dataset(
        ds, out_nc, rule=rule, config_slice=config_slice, title=f"Cascade pressure plan of patient {patient_name}"
    )
    if out_png:
        plot_poses(model, plans, out_png, title=f"patient {patient_name}")
    return ds


def write_cascade_validation(
    plan_nc: str | Path,
    tables: Mapping[str, str | Path],
    out_nc: str | Path,
    *,
    config_slice,
    rule: str = "validate_cascade",
    plot: str | Path | None = None,
    rel_floor_kpa: float = 10.0,
    table07: str | Path | None = None,
    dummy_plan_nc: str | Path | None = None,
) -> xr.Dataset:
    """Read the mean finger's plan and the paper's tables, write ``results/validation/cascade.nc``.

    ``tables``: {name: pressure table CSV} (Tables 8 and 10); ``table07``: the
    unit-moment targets, compared when given; ``dummy_plan_nc``: the PLA
    dummy finger's plan, compared with ``table10`` (the paper's experiment).
    """

    plan = open_result(plan_nc)
    plans = {"table10": open_result(dummy_plan_nc)} if dummy_plan_nc and "table10" in tables else None
    refs = {k: read_pressure_table(v) for k, v in tables.items()}
    ds = compare_pressures(plan, refs, rel_floor_kpa, plans)
    ds = ds.merge(compare_planners(plan, refs, rel_floor_kpa, plans))
    if table07 is not None:
        ds = ds.merge(compare_unit_moments(plan, table07))
    ds.attrs["patient"] = str(plan.attrs.get("patient", ""))
    write_dataset(
        ds, out_nc, rule=rule, config_slice=config_slice, title="Planned pressures against the paper's Tables 8 and 10"
    )
    if plot:
        plot_validation(ds, plot)
    return ds
