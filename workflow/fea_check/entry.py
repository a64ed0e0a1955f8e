"""Rule entry points of the FEA check (``fea_check``) and of the stand-alone actuators' join (``standalone_actuator``;
their FEA per exercise is :mod:`.entry_standalone`):
read the plan and the patient's inputs, build the FE model, run the check, write
the dataset, the deformed meshes (.vtu) and the poses plot.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.actuator.pressure_limit import material_limit
from workflow.actuator.stiffness import StiffnessTable
from workflow.actuator.unit_model import UnitModel, load_unit_model
from workflow.cascade.calibration import calibrated
from workflow.cascade.finger import Finger
from workflow.cascade.patient import patient_cascade, patient_finger, plan_limit, plan_options
from workflow.common.constants import GROUPS, JOINTS
from workflow.common.provenance import open_result, write_dataset
from workflow.common.vtu import write_vtu
from workflow.fea_check.applied import applied_limit
from workflow.fea_check.entry_standalone import load_surrogate_angles
from workflow.fea_check.model import build_patient_fea
from workflow.fea_check.plots import plot_fea_poses, plot_standalone
from workflow.fea_check.run import run_fea_check
from workflow.fea_check.standalone import merge_exercises

__all__ = [
    "PatientSetup",
    "load_patient_setup",
    "load_surrogate_angles",
    "with_measured_stiffness",
    "write_fea_check",
    "write_standalone",
]

log = logging.getLogger(__name__)


@dataclass
class PatientSetup:
    """What a patient's FEA check starts from: the plan, the loads, the finger and the units per group."""

    plan: xr.Dataset
    loads: xr.Dataset
    finger: Finger
    spring_note: str
    units_per_group: dict[str, int]
    reference_dims_mm: dict[str, float]


def load_patient_setup(
    patient: Mapping[str, Any],
    *,
    plan_nc: str,
    joint_loads_nc: str,
    moments_nc: str,
    ccd_nc: str,
    cascade_cfg: Mapping,
    anthropometry: Mapping,
) -> PatientSetup:
    """The one loader of a patient's FEA setup (the check and its mesh study): read the plan and the loads,
    build the finger with its springs from the joint loads, take the plan's units per group (mm, kg, N m)."""
    plan = open_result(plan_nc)
    loads = open_result(joint_loads_nc)
    finger, spring_note = patient_finger(
        patient,
        loads,
        open_result(moments_nc),
        open_result(ccd_nc),
        cascade_cfg=cascade_cfg,
        anthropometry=anthropometry,
    )
    upg = {str(g): int(v) for g, v in zip(plan["group"].values, plan["units_per_group"].values)}
    ref = {k: float(v["mean"]) for k, v in anthropometry["measures"].items()}
    return PatientSetup(plan, loads, finger, spring_note, upg, ref)


def with_measured_stiffness(unit: UnitModel, stiffness_nc: str | Path | None) -> UnitModel:
    """``unit`` taking the stiffness table of a ``unit_stiffness.nc`` where |theta_free| is below the study's
    window (its ``delta_deg``), i.e. near P_T = P_B; ``unit`` itself without a file or where the study has no table."""
    if not stiffness_nc:
        return unit
    ds = open_result(stiffness_nc)
    try:
        table = StiffnessTable.from_study(ds)
    except ValueError as exc:
        log.warning("unit stiffness table not used (%s): the 2D chain keeps the secant stiffness", exc)
        return unit
    delta = float(ds.attrs["delta_deg"])
    log.info("2D chain: the measured stiffness table near P_T = P_B (|theta_free| < %g deg per unit)", delta / 2)
    return replace(unit, measured_stiffness=table, measured_window_deg=delta)


def write_fea_check(
    patient_name: str,
    patient: Mapping[str, Any],
    *,
    plan_nc: str,
    joint_loads_nc: str,
    moments_nc: str,
    ccd_nc: str,
    out_nc: str,
    out_vtu: Sequence[str],
    out_png: str | None,
    fea_cfg: Mapping,
    actuator_cfg: Mapping,
    cascade_cfg: Mapping,
    anthropometry: Mapping,
    config_slice: Any,
    surrogate_2d: str | None = None,
    surrogate_3d: str | None = None,
    unit_model_cfg: Mapping | None = None,
    unit_stiffness_nc: str | None = None,
    rule: str = "fea_check",
    notes: Mapping[str, Any] | None = None,
):
    """The rule's entry point: build the patient's FE model, check the plan, write .nc, .vtu per exercise, plot.

    With the surrogates and ``unit_model_cfg`` (config ``surrogates.unit_model``)
    the reduced-order chains are built too: the 2D-unit prediction and the
    correction step (config ``fea_check.correction``).  With ``unit_stiffness_nc``
    (a ``unit_stiffness.nc``; config ``fea_check.unit_stiffness``) the 2D unit's
    chain takes its measured stiffness table near P_T = P_B.
    """

    s = load_patient_setup(
        patient,
        plan_nc=plan_nc,
        joint_loads_nc=joint_loads_nc,
        moments_nc=moments_nc,
        ccd_nc=ccd_nc,
        cascade_cfg=cascade_cfg,
        anthropometry=anthropometry,
    )
    plan, finger, spring_note, upg = s.plan, s.finger, s.spring_note, s.units_per_group
    fea = build_patient_fea(
        finger,
        upg,
        actuator_cfg=actuator_cfg,
        cascade_cfg=cascade_cfg,
        reference_dims_mm=s.reference_dims_mm,
        fea_cfg=fea_cfg,
    )
    log.info("patient %s: %s; units %s; springs: %s", patient_name, fea.notes, upg, spring_note)
    use_map = bool(fea_cfg.get("map_pressures", True)) and cascade_cfg.get("surrogate", "3d") == "3d"
    a3, a2, pm2, pm3 = load_surrogate_angles(surrogate_2d, surrogate_3d) if use_map else (None, None, np.inf, np.inf)
    if use_map and a3 is None:
        log.warning("no surrogates given: the plan's 3D pressures are applied to the 2D model unchanged")
    ro_plan = ro_2d = None
    if unit_model_cfg is not None and surrogate_2d and surrogate_3d:
        units = {"2d": surrogate_2d, "3d": surrogate_3d}
        unit_2d = with_measured_stiffness(load_unit_model(surrogate_2d, **unit_model_cfg), unit_stiffness_nc)
        ro_2d = patient_cascade(finger, unit_2d, cascade_cfg, upg)
        ro_plan = patient_cascade(
            finger, load_unit_model(units[cascade_cfg.get("surrogate", "3d")], **unit_model_cfg), cascade_cfg, upg
        )
        if "chain_span_gain" in plan:  # the chain the plan was made with (calibrated or the paper's)
            gain, comp = plan["chain_span_gain"].values, plan["chain_span_compliance_rad_per_nm"].values
            ro_2d, ro_plan = calibrated(ro_2d, gain, comp), calibrated(ro_plan, gain, comp)
    # the 2D pressures: the paper's free-angle map, or the angles matched under the moment each unit carries
    m_units = None
    if a3 is not None and fea_cfg.get("pressure_map", "free_angle") == "loaded":
        if ro_plan is None:
            raise ValueError("fea_check.pressure_map = loaded needs the unit model (surrogates.unit_model)")
        # the chains above already hold both unit models (the plan's is the 3D one whenever the map is used)
        a3, a2 = ro_plan.unit.angle_deg, ro_2d.unit.angle_deg
        ex = list(fea_cfg.get("exercises") or plan["exercise"].values)
        m_units = plan["unit_moment_nm"].sel(exercise=ex, group=list(GROUPS)).values
        log.info("2D pressures matched under the plan's unit moments (fea_check.pressure_map = loaded)")
    if unit_stiffness_nc and ro_2d is not None and m_units is None:
        # the correction's Jacobian is the plan chain's; the 2D chain reaches the pressures only through the loaded map
        log.warning(
            "fea_check.unit_stiffness: the measured stiffness changes only the 2D chain's recorded prediction here, not "
            "the applied pressures (they take it only through the loaded 2D-to-3D map: fea_check.pressure_map = loaded, "
            "with the map in use)"
        )
    material = material_limit(actuator_cfg.get("material"))
    limit_plan = plan_limit(cascade_cfg, None if ro_plan is None else ro_plan.unit, material)
    limit_2d = applied_limit(actuator_cfg, pm2)
    log.info("patient %s: re-planned pressures <= %s; applied pressures <= %s", patient_name, limit_plan, limit_2d)
    plan_opts = plan_options(
        cascade_cfg,
        plan["active_limit_nm"].sel(joint=list(JOINTS)).values if "active_limit_nm" in plan else None,
        limit_plan,
    )
    solver = dict(actuator_cfg.get("solver", {}))
    solver.update(dict(fea_cfg.get("solver", {})))
    ds, checks, grav, corrections = run_fea_check(
        fea,
        plan,
        exercises=fea_cfg.get("exercises") or None,
        solver=solver,
        tolerance_deg=float(cascade_cfg["tolerance_deg"]),
        angle_3d=a3,
        angle_2d=a2,
        p_max_2d_kpa=pm2,
        p_max_3d_kpa=pm3,
        ro_plan=ro_plan,
        ro_2d=ro_2d,
        correction=fea_cfg.get("correction"),
        plan_opts=plan_opts,
        limit_2d=limit_2d,
        unit_moments_nm=m_units,
        notes={
            "patient": patient_name,
            "springs": spring_note,
            "p_limit_kpa": limit_2d.kpa,
            "p_limit_source": limit_2d.source,
            "p_limit_plan_kpa": limit_plan.kpa,
            "p_limit_plan_source": limit_plan.source,
            "pressures": (
                ("2D-to-3D mapped under the plan's unit moments" if m_units is not None else "2D-to-3D mapped")
                if a3 is not None
                else "plan's, unchanged"
            ),
            "h_actuator_mm": float(fea_cfg.get("h_actuator_mm", 2.0)),
            "unit_stiffness_2d": "measured table near P_T = P_B"
            if unit_stiffness_nc and ro_2d is not None
            else "secant M_blocked / theta_free",
            **dict(notes or {}),
        },
    )
    # the finger the check was built on: the patient's own dimensions (coded levels or measurements)
    dims = dict(finger.dimensions_mm)
    ds["finger_dimension_mm"] = xr.DataArray(
        np.array([dims[k] for k in dims], float),
        dims="measure",
        coords={"measure": list(dims)},
        attrs={"units": "mm", "long_name": "finger dimension of the FE finger (Table 2 codes)"},
    )
    ds.attrs["finger_model"] = str(patient.get("model", "human"))
    write_dataset(
        ds,
        out_nc,
        rule=rule,
        config_slice=config_slice,
        title=f"2D FEA check of the cascade plan of patient {patient_name}",
    )
    by_name = {c.exercise: c for c in checks}
    for path in out_vtu:
        name = Path(path).stem.split("_")[-1]
        c = by_name.get(name)
        cm = fea.setup.cm
        write_vtu(
            cm.mesh,
            c.result.u if c is not None else grav.u,
            path,
            deform=True,
            cell_data={"material": cm.material, "body": cm.body},
        )
    if out_png:
        cm = fea.setup.cm
        corrected = [c.checks[c.best].result.u if c.best else None for c in corrections] if corrections else None
        plot_fea_poses(
            cm.mesh.p,
            cm.mesh.t,
            cm.material,
            [c.result.u for c in checks],
            ds,
            finger,
            out_png,
            title=f"patient {patient_name}",
            corrected_states=corrected,
        )
    return ds


def write_standalone(
    patient_name: str,
    *,
    part_ncs: Sequence[str],
    out_nc: str,
    out_png: str | None,
    config_slice: Any,
    rule: str = "standalone_actuator",
) -> xr.Dataset:
    """Join the exercises solved apart into the patient's stand-alone dataset and draw it (Fig. 22)."""
    ds = merge_exercises([open_result(p) for p in part_ncs])
    ds.attrs["patient"] = patient_name
    write_dataset(
        ds,
        out_nc,
        rule=rule,
        config_slice=config_slice,
        title=f"Stand-alone whole actuators at the plan's pressures, patient {patient_name}",
    )
    if out_png:
        plot_standalone(ds, out_png, title=f"patient {patient_name}")
    return ds
