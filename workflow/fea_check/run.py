"""The FEA check of a whole plan: gravity first, then every exercise at its
mapped 2D pressures (with the correction step where configured), gathered into
one dataset (angles deg, pressures kPa, forces N, moments N m).
"""

from __future__ import annotations

import logging
from typing import Any, Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.actuator.pressure_limit import PressureLimit
from workflow.cascade.model import solve_equilibrium
from workflow.common.constants import CHAMBERS, CHECK_MAPPING_STATUS, GROUPS, JOINTS, SOLVER_STATUS
from workflow.common.runlog import solved
from workflow.fea_check.applied import pressures_2d
from workflow.fea_check.check import ExerciseCheck, check_exercise, gravity_state, outcome, unit_bends_dataset
from workflow.fea_check.correction import Correction, _corrections_dataset, correct_exercise
from workflow.fea_check.model import PatientFEA
from workflow.fem.coupled import CoupledResult

__all__ = ["fea_check_dataset", "run_fea_check"]

log = logging.getLogger(__name__)


def fea_check_dataset(
    checks: Sequence[ExerciseCheck],
    plan: xr.Dataset,
    gravity: CoupledResult,
    *,
    tolerance_deg: float,
    width_mm: float,
    pressures_plan_kpa: np.ndarray,
    mapping_flag: np.ndarray,
    predicted_2d_deg: np.ndarray | None = None,
    corrections: Sequence[Correction] | None = None,
    notes: Mapping[str, Any] | None = None,
    unit_geometry: Mapping[str, Any] | None = None,
) -> xr.Dataset:
    """``fea_check.nc`` content (without provenance) for the checked exercises.

    ``predicted_2d_deg`` (exercise, joint): the reduced-order chain with the
    2D unit at the applied pressures; ``corrections``: per exercise, the
    correction step (adds the ``iteration`` dimension and ``corrected_*``);
    ``unit_geometry`` ({"groups": group per unit, "geometry": the actuator's}) adds each unit's bend.
    """
    ex = [c.exercise for c in checks]
    tgt = plan["target_angle_deg"].sel(exercise=ex, joint=list(JOINTS)).values
    pred = plan["predicted_angle_deg"].sel(exercise=ex, joint=list(JOINTS)).values
    lim = (
        np.abs(plan["active_limit_nm"].sel(joint=list(JOINTS)).values)
        if "active_limit_nm" in plan
        else np.full(3, np.nan)
    )
    ang = np.array([c.angle_deg for c in checks])
    status = np.array([c.result.status for c in checks], dtype="i1")
    lam = np.array([c.result.load_factor if c.result.phase == "pressure" else 0.0 for c in checks])
    converged = (status == 0) & (lam >= 1.0 - 1e-9)
    mom = np.array([c.max_actuator_moment_nm for c in checks])
    within_lim = np.all(~(np.abs(mom) > lim), axis=1)
    judged = [outcome(c, tgt[i], tolerance_deg, lim) for i, c in enumerate(checks)]
    achieved = np.array([j[0] for j in judged])
    reasons = ["; ".join(j[2]) for j in judged]
    flag_vals = np.array(sorted(SOLVER_STATUS), dtype="i1")
    map_vals = np.array(sorted(CHECK_MAPPING_STATUS), dtype="i1")
    plan_ach = plan["achieved"].sel(exercise=ex).values.astype(bool) if "achieved" in plan else np.full(len(ex), False)
    deg, nm = {"units": "degree"}, {"units": "N m"}
    ds = xr.Dataset(
        {
            "angle_deg": (
                ("exercise", "joint"),
                ang,
                {**deg, "long_name": "joint angle reached in the FEA (bone orientations)"},
            ),
            "target_angle_deg": (("exercise", "joint"), tgt, {**deg, "long_name": "target joint angle (Table 1)"}),
            "predicted_angle_deg": (
                ("exercise", "joint"),
                pred,
                {**deg, "long_name": "reduced-order prediction of the plan"},
            ),
            "angle_error_deg": (("exercise", "joint"), ang - tgt, {**deg, "long_name": "FEA minus target joint angle"}),
            "plan_error_deg": (
                ("exercise", "joint"),
                ang - pred,
                {**deg, "long_name": "FEA minus reduced-order prediction"},
            ),
            "droop_angle_deg": (
                "joint",
                gravity.joint_angles_deg,
                {**deg, "long_name": "joint angle under gravity at zero pressure (FEA)"},
            ),
            "achieved": (
                "exercise",
                achieved,
                {
                    "units": "1",
                    "long_name": f"converged, every joint within {tolerance_deg:g} deg of its target, moments within the active limits",
                },
            ),
            "achieved_plan": (
                "exercise",
                plan_ach,
                {"units": "1", "long_name": "achieved according to the reduced-order plan"},
            ),
            "reason": (
                "exercise",
                np.array(reasons, dtype=object),
                {"units": "1", "long_name": "why the exercise is not reached in the FEA (empty if reached)"},
            ),
            "pressure_kpa": (
                ("exercise", "group", "chamber"),
                np.array([c.pressures_kpa for c in checks]),
                {"units": "kPa", "long_name": "chamber pressure applied to the 2D model"},
            ),
            "pressure_plan_kpa": (
                ("exercise", "group", "chamber"),
                pressures_plan_kpa,
                {"units": "kPa", "long_name": "planned chamber pressure"},
            ),
            "mapping_status": (
                ("exercise", "group"),
                mapping_flag.astype("i1"),
                {
                    "units": "1",
                    "long_name": "how the 2D pressure pair was obtained from the plan's",
                    "flag_values": map_vals,
                    "flag_meanings": " ".join(CHECK_MAPPING_STATUS[int(v)] for v in map_vals),
                },
            ),
            "status": (
                "exercise",
                status,
                {
                    "units": "1",
                    "long_name": "solver status of the last phase",
                    "flag_values": flag_vals,
                    "flag_meanings": " ".join(SOLVER_STATUS[int(v)] for v in flag_vals),
                },
            ),
            "converged": ("exercise", converged, {"units": "1", "long_name": "pressures reached in full"}),
            "load_factor": (
                "exercise",
                lam,
                {"units": "1", "long_name": "last converged fraction of the pressures (0: gravity phase failed)"},
            ),
            "max_actuator_moment_nm": (
                ("exercise", "joint"),
                mom,
                {
                    **nm,
                    "long_name": "largest moment the actuator applies about the joint along the load path (spring minus finger weight)",
                },
            ),
            "actuator_moment_nm": (
                ("exercise", "joint"),
                np.array([c.actuator_moment_nm for c in checks]),
                {**nm, "long_name": "moment the actuator applies about the joint at the final state"},
            ),
            "spring_moment_nm": (
                ("exercise", "joint"),
                np.array([c.result.spring_moments for c in checks]) * width_mm * 1e-3,
                {**nm, "long_name": "passive joint moment at the final state"},
            ),
            "active_limit_nm": ("joint", lim, {**nm, "long_name": "active safety limit"}),
            "within_limits": (
                "exercise",
                within_lim,
                {"units": "1", "long_name": "every largest actuator moment within its active limit"},
            ),
            "max_strap_force_n": (
                ("exercise", "strap"),
                np.array([c.max_strap_force_n for c in checks]),
                {"units": "N", "long_name": "largest strap force along the load path (full width)"},
            ),
            "max_penetration_mm": (
                "exercise",
                np.array([c.result.max_penetration_mm for c in checks]),
                {"units": "mm", "long_name": "largest penetration along the load path (contact or overlap check)"},
            ),
            "overlap_depth_mm": (
                "exercise",
                np.array([c.result.overlap_depth_mm for c in checks]),
                {"units": "mm", "long_name": "deepest actuator node inside another element along the load path"},
            ),
            "min_pocket_area_mm2": (
                "exercise",
                np.array([c.result.min_pocket_area_mm2 for c in checks]),
                {"units": "mm2", "long_name": "smallest actuator pocket along the load path (36.4 at rest)"},
            ),
            "tip_angle_deg": (
                "exercise",
                np.array([c.result.tip_angle_deg for c in checks]),
                {**deg, "long_name": "rotation of the actuator's backbone at its tip"},
            ),
            "hand_slide_mm": (
                "exercise",
                np.array([c.result.slide_mm for c in checks]),
                {
                    "units": "mm",
                    "long_name": "how far the actuator's hand end slides along the hand, distal positive (section 3.2's "
                    "sliding support; the rail travel the pose needs)",
                },
            ),
            "newton_iterations": (
                "exercise",
                np.array([c.result.newton_iterations for c in checks], dtype="i4"),
                {"units": "1", "long_name": "Newton iterations of the pressure phase"},
            ),
            "load_steps": (
                "exercise",
                np.array([c.result.steps for c in checks], dtype="i4"),
                {"units": "1", "long_name": "load steps (accepted + rejected) of the pressure phase"},
            ),
            "wall_time_s": (
                "exercise",
                np.array([c.wall_time_s for c in checks]),
                {"units": "s", "long_name": "wall time of the pressure phase"},
            ),
            "peak_memory_mb": (
                "exercise",
                np.array([c.peak_memory_mb for c in checks]),
                {"units": "MiB", "long_name": "peak Python heap during the check (tracemalloc)"},
            ),
            "ndofs": (
                (),
                int(checks[0].result.ndofs) if checks else 0,
                {"units": "1", "long_name": "degrees of freedom"},
            ),
        },
        coords={
            "exercise": ex,
            "joint": list(JOINTS),
            "group": list(GROUPS),
            "chamber": list(CHAMBERS),
            "strap": ["PIP", "DIP"],
        },
    )
    if unit_geometry is not None and checks:
        ds = ds.merge(unit_bends_dataset(np.array([c.result.unit_bends_deg for c in checks]), **unit_geometry))
    if predicted_2d_deg is not None:
        p2d = np.asarray(predicted_2d_deg, float)
        ds["predicted_2d_angle_deg"] = (
            ("exercise", "joint"),
            p2d,
            {**deg, "long_name": "reduced-order chain with the 2D unit surrogate at the applied 2D pressures"},
        )
        ds["mapping_error_deg"] = (
            ("exercise", "joint"),
            p2d - pred,
            {**deg, "long_name": "what the 2D-to-3D mapping changes in the chain: 2D-unit minus planned prediction"},
        )
        ds["chain_error_deg"] = (
            ("exercise", "joint"),
            ang - p2d,
            {**deg, "long_name": "what the chain misses: FEA minus the chain with the 2D unit at the same pressures"},
        )
    if corrections:
        ds = ds.merge(_corrections_dataset(corrections, ex, tgt, tolerance_deg, lim))
    ds.attrs.update(
        {
            "tolerance_deg": float(tolerance_deg),
            "gravity_status": int(gravity.status),
            "gravity_load_factor": float(gravity.load_factor),
            "gravity_newton_iterations": int(gravity.newton_iterations),
            "gravity_wall_time_s": float(gravity.wall_time_s),
            **{k: (v if isinstance(v, (int, float, str)) else str(v)) for k, v in dict(notes or {}).items()},
        }
    )
    return ds


def run_fea_check(
    fea: PatientFEA,
    plan: xr.Dataset,
    *,
    exercises: Sequence[str] | None,
    solver: Mapping,
    tolerance_deg: float,
    angle_3d=None,
    angle_2d=None,
    p_max_2d_kpa: float = np.inf,
    p_max_3d_kpa: float = np.inf,
    ro_plan=None,
    ro_2d=None,
    correction: Mapping | None = None,
    plan_opts: Mapping | None = None,
    limit_2d: PressureLimit | None = None,
    unit_moments_nm: np.ndarray | None = None,
    notes: Mapping[str, Any] | None = None,
):
    """Gravity state, then every exercise -> (dataset, checks, gravity result, corrections).

    ``unit_moments_nm`` (exercise, group; N m per unit): the moment each group's unit carries in the plan; given,
    the 2D pressures match the angles under it (``angle_3d``/``angle_2d`` then take (P_T, P_B, M)), else the free
    angles (the paper's map, Fig. 17).

    ``limit_2d`` (:func:`applied_limit`) bounds every pressure applied, the
    correction step's too.

    ``ro_plan`` / ``ro_2d``: the reduced-order chain (``CascadeModel``) with
    the plan's and with the 2D unit surrogate; ``correction``: ``{max_iterations,
    min_change_kpa, out_of_reach}`` (needs ``ro_plan`` and ``plan_opts``, the keywords of
    :func:`workflow.cascade.plan_exercise` the plan was made with).
    """

    ex = [str(e) for e in plan["exercise"].values] if not exercises else [str(e) for e in exercises]
    p_plan = plan["pressure_kpa"].sel(exercise=ex, group=list(GROUPS), chamber=list(CHAMBERS)).values

    m_units = None if unit_moments_nm is None else np.asarray(unit_moments_nm, float)

    def to_2d(p3, m=m_units):
        return pressures_2d(
            p3, angle_3d, angle_2d, p_max_2d_kpa=p_max_2d_kpa, p_max_3d_kpa=p_max_3d_kpa, limit=limit_2d, m_ext_nm=m
        )

    p2, flag = to_2d(p_plan)
    targets = plan["target_angle_deg"].sel(exercise=ex, joint=list(JOINTS)).values
    lim = (
        np.abs(plan["active_limit_nm"].sel(joint=list(JOINTS)).values)
        if "active_limit_nm" in plan
        else np.full(3, np.nan)
    )
    grav = gravity_state(fea, solver)
    n_cor = int((correction or {}).get("max_iterations", 0)) if ro_plan is not None else 0
    checks, corrections, pred_2d = [], [], []
    for i, name in enumerate(ex):
        if grav.status != 0:  # no converged gravity state: nothing to ramp from
            c = ExerciseCheck(
                name,
                p2[i],
                grav,
                grav.joint_angles_deg,
                np.full(3, np.nan),
                np.full(3, np.nan),
                np.full(2, np.nan),
                0.0,
                0.0,
            )
        else:
            c = check_exercise(fea, name, p2[i], solver, gravity=grav)
        log.info(
            "%s: pressures %s kPa -> angles %s deg (target %s, plan %s), status %d at %.3f, %d its, %.1f s",
            name,
            np.round(p2[i].ravel(), 1),
            np.round(c.angle_deg, 1),
            targets[i],
            np.round(plan["predicted_angle_deg"].sel(exercise=name).values, 1),
            c.result.status,
            c.result.load_factor,
            c.result.newton_iterations,
            c.wall_time_s,
            extra=solved(c.result.status != 0) if grav.status == 0 else {},
        )
        checks.append(c)
        if ro_2d is not None:
            pred_2d.append(solve_equilibrium(ro_2d, p2[i].ravel()).joint_angles_deg)
        if n_cor and grav.status == 0:
            corrections.append(
                correct_exercise(
                    fea,
                    ro_plan,
                    name,
                    targets[i],
                    p_plan[i],
                    plan["predicted_angle_deg"].sel(exercise=name).values,
                    c,
                    to_2d=lambda p3, i=i: to_2d(p3, None if m_units is None else m_units[i])[0],
                    solver=solver,
                    gravity=grav,
                    tolerance_deg=tolerance_deg,
                    limits_nm=lim,
                    plan_opts=plan_opts or {},
                    max_iterations=n_cor,
                    min_change_kpa=float((correction or {}).get("min_change_kpa", 1.0)),
                    out_of_reach=(correction or {}).get("out_of_reach"),
                )
            )
            log.info("%s: correction step: %s", name, corrections[-1].stop_reason)
    ds = fea_check_dataset(
        checks,
        plan,
        grav,
        tolerance_deg=tolerance_deg,
        width_mm=fea.width_mm,
        pressures_plan_kpa=p_plan,
        mapping_flag=flag,
        predicted_2d_deg=np.array(pred_2d) if pred_2d else None,
        corrections=corrections if len(corrections) == len(checks) else None,
        notes={"model": fea.notes, **dict(notes or {})},
        unit_geometry={"groups": list(fea.setup.cm.act.chamber_group), "geometry": fea.setup.cm.act.geometry},
    )
    return ds, checks, grav, corrections
