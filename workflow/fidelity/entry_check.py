"""Rule entry point of the FEA check's mesh study (``fidelity_check``).

Its own module: it runs the patient's finger-actuator FEA at several meshes
(minutes), which should not rerun when the speed-accuracy tables change
(:mod:`.entry`).  Angles deg, element sizes mm, wall times s.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.actuator.unit_model import load_unit_model
from workflow.cascade.model import solve_equilibrium
from workflow.cascade.patient import patient_cascade
from workflow.common.constants import JOINTS
from workflow.common.fidelity_choice import search_meshes
from workflow.common.provenance import write_dataset
from workflow.common.runlog import solved
from workflow.fea_check.applied import applied_limit, pressures_2d
from workflow.fea_check.check import check_exercise, gravity_state
from workflow.fea_check.entry import load_patient_setup, load_surrogate_angles
from workflow.fea_check.model import build_patient_fea

__all__ = ["write_check_study"]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------
# The FEA check at several meshes, against the reduced-order chains
# --------------------------------------------------------------------------
def write_check_study(
    out: str | Path,
    *,
    exercises: Sequence[str],
    h_mm: Sequence[float],
    patient_name: str,
    patient: Mapping,
    plan_nc: str,
    joint_loads_nc: str,
    moments_nc: str,
    ccd_nc: str,
    surrogate_2d: str,
    surrogate_3d: str,
    fea_cfg: Mapping,
    actuator_cfg: Mapping,
    cascade_cfg: Mapping,
    anthropometry: Mapping,
    unit_model_cfg: Mapping,
    config_slice: Any,
    search: str = "all",
    tolerance_deg: float = np.inf,
    penetration_bound_mm: float = np.inf,
    rule: str = "fidelity_check",
) -> xr.Dataset:
    """Rule ``fidelity_check``: the FEA check of ``exercises`` at each element size (actuator = finger h).

    Per mesh and exercise: joint angles, wall time (the mesh's gravity phase
    shared out over its exercises, plus the pressure phase), DOFs, status and
    contact penetration; the chains' predictions (the plan's and the 2D
    unit's at the applied pressures) with their time as the cheap stand-ins.

    ``search``: ``"all"`` solves every mesh; ``"coarsest_first"`` solves the
    finest (the reference) and then the others from the coarsest up, and stops
    at the first whose angles are within ``tolerance_deg`` of the reference with
    every exercise converged and its penetration within ``penetration_bound_mm``
    (:func:`workflow.common.fidelity_choice.search_meshes`); the meshes left out
    keep status ``NOT_SOLVED`` (-1) and NaN values.
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
    plan, finger, upg = s.plan, s.finger, s.units_per_group
    a3, a2, pm2, pm3 = load_surrogate_angles(surrogate_2d, surrogate_3d)
    ex = [str(e) for e in exercises]
    p3 = plan["pressure_kpa"].sel(exercise=ex).values
    p2, _ = pressures_2d(p3, a3, a2, p_max_2d_kpa=pm2, p_max_3d_kpa=pm3, limit=applied_limit(actuator_cfg, pm2))
    solver = dict(actuator_cfg.get("solver", {}))
    solver.update(dict(fea_cfg.get("solver", {})))
    hs = sorted((float(h) for h in h_mm), reverse=True)
    wall = np.full((len(hs), len(ex)), np.nan)
    ndofs = np.zeros(len(hs), dtype="i4")

    def solve_mesh(i: int):
        """Angles (exercise, joint), statuses and penetrations of the check at mesh i (wall times and DOFs kept)."""
        h = hs[i]
        ang_i, status_i, pen_i = np.full((len(ex), 3), np.nan), np.zeros(len(ex), dtype="i1"), np.full(len(ex), np.nan)
        t0 = time.perf_counter()
        fea = build_patient_fea(
            finger,
            upg,
            actuator_cfg=actuator_cfg,
            cascade_cfg=cascade_cfg,
            reference_dims_mm=s.reference_dims_mm,
            fea_cfg=dict(fea_cfg, h_actuator_mm=h, h_finger_mm=h),
        )
        grav = gravity_state(fea, solver)
        t_grav = (time.perf_counter() - t0) / len(ex)
        ndofs[i] = grav.ndofs
        for k, e in enumerate(ex):
            if grav.status != 0:
                ang_i[k], status_i[k], wall[i, k] = grav.joint_angles_deg, max(1, grav.status), t_grav
                continue
            c = check_exercise(fea, e, p2[k], solver, gravity=grav)
            ang_i[k], status_i[k] = c.angle_deg, c.result.status
            wall[i, k], pen_i[k] = t_grav + c.wall_time_s, c.result.max_penetration_mm
            log.info(
                "check %s at h = %g mm (%d dofs): %s deg, status %d, %.1f s, penetration %.3f mm",
                e,
                h,
                ndofs[i],
                np.round(ang_i[k], 2),
                status_i[k],
                wall[i, k],
                pen_i[k],
                extra=solved(status_i[k] != 0),
            )
        return ang_i, status_i, pen_i

    ang, status, pen, stop = search_meshes(
        len(hs), len(ex), solve_mesh, search, tolerance_deg=tolerance_deg, penetration_bound_mm=penetration_bound_mm
    )
    if stop is not None:
        i, err, left = stop
        log.info(
            "mesh study: h = %g mm is within %g deg of the finest (%.3g deg); h = %s mm left out (search %s)",
            hs[i],
            tolerance_deg,
            err,
            ", ".join(f"{hs[j]:g}" for j in left),
            search,
        )
    chains = {}
    plan_unit = {"2d": surrogate_2d, "3d": surrogate_3d}[cascade_cfg.get("surrogate", "3d")]
    for name, path, p in (("check_chain_plan", plan_unit, p3), ("check_chain_2d", surrogate_2d, p2)):
        ro = patient_cascade(finger, load_unit_model(path, **unit_model_cfg), cascade_cfg, upg)
        out_ang, out_t = [], []
        for k in range(len(ex)):
            t0 = time.perf_counter()
            out_ang.append(solve_equilibrium(ro, np.asarray(p[k]).ravel()).joint_angles_deg)
            out_t.append(time.perf_counter() - t0)
        chains[name] = (np.array(out_ang), np.array(out_t))
    ds = xr.Dataset(
        {
            "angle_deg": (
                ("h_mm", "exercise", "joint"),
                ang,
                {"units": "degree", "long_name": "joint angle reached in the FEA check"},
            ),
            "wall_time_s": (
                ("h_mm", "exercise"),
                wall,
                {
                    "units": "s",
                    "long_name": "pressure phase plus the mesh's model build and gravity phase shared over its exercises",
                },
            ),
            "ndofs": ("h_mm", ndofs, {"units": "1", "long_name": "degrees of freedom"}),
            "status": (
                ("h_mm", "exercise"),
                status,
                {"units": "1", "long_name": "solver status (0 = converged, -1 = not solved: a coarser mesh qualified)"},
            ),
            "max_penetration_mm": (
                ("h_mm", "exercise"),
                pen,
                {"units": "mm", "long_name": "largest contact penetration along the load path"},
            ),
            "chain_angle_deg": (
                ("chain", "exercise", "joint"),
                np.array([v[0] for v in chains.values()]),
                {"units": "degree", "long_name": "reduced-order chain's joint angle"},
            ),
            "chain_wall_time_s": (
                ("chain", "exercise"),
                np.array([v[1] for v in chains.values()]),
                {"units": "s", "long_name": "time of the chain's equilibrium"},
            ),
            "pressure_2d_kpa": (
                ("exercise", "group", "chamber"),
                p2,
                {"units": "kPa", "long_name": "pressures applied in 2D"},
            ),
        },
        coords={
            "h_mm": hs,
            "exercise": ex,
            "joint": list(JOINTS),
            "chain": list(chains),
            "group": plan["group"].values,
            "chamber": plan["chamber"].values,
        },
    )
    ds.attrs.update({"exercises": " ".join(ex), "patient": patient_name, "search": search})
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice=config_slice,
        title=f"FEA check of {', '.join(ex)} by element size, patient {patient_name}",
    )
    return ds
