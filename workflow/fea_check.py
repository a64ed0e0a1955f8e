"""FEA check of every planned exercise (issue 9, paper section 3.2, Fig. 18-21).

Per patient: the whole actuator of the plan (``units_per_group``) strapped to
the planar finger (:mod:`workflow.fea_model`), gravity first (one solve,
shared by the exercises), then each exercise's planned pressures ramped from
zero.  A point that does not converge is kept with its last converged load
factor (``load_factor`` < 1, ``status`` > 0) and measured there.

Pressures.  The 2D section is stiffer than the 3D actuator (CLARIFICATIONS 7,
paper section 3.2): when the plan was made with the 3D surrogate, each
(P_T, P_B) pair is scaled to the 2D pair of the same ratio and the same free
angle with the 2D-to-3D mapping (:func:`workflow.mapping.map_pairs`), as the
paper's Table 9 did; pairs with P_T = P_B keep their pressures (no bend either
way), pairs whose 3D angle lies beyond the 2D sweep are capped at its edge
(``mapping_status`` records both).  ``map_pressures: false`` applies the plan's
pressures unchanged.

Outcome per exercise: joint angles from the bones' orientations, error
against the targets (Table 1) and against the plan's reduced-order
prediction, the largest strap force and the largest moment the actuator
applies about each joint (spring moment minus the moment of the finger's
weight, both from the FE state) against the active safety limits, and
``achieved`` = converged to the full load, every joint within the plan's
tolerance and every moment within its limit.  Full-width values: the 2D
per-mm results times the actuator width.  Angles deg, moments N m, forces N.
"""

from __future__ import annotations

import logging
import time
import tracemalloc
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.cascade import CHAMBERS, GROUPS
from workflow.fea_model import PatientFEA
from workflow.fem import STATUS_FLAGS
from workflow.fem._coupled import CoupledResult, solve_coupled
from workflow.finger import JOINTS

__all__ = ["MAPPING_FLAGS", "pressures_2d", "ExerciseCheck", "check_exercise", "gravity_state", "fea_check_dataset",
           "write_deformed"]

log = logging.getLogger(__name__)

#: How each 2D pressure pair was obtained.
MAPPING_FLAGS = {0: "mapped", 1: "equal_pressures_kept", 2: "capped_at_2d_grid_edge", 3: "unchanged"}


def pressures_2d(p3: np.ndarray, angle_3d: Callable | None, angle_2d: Callable | None, *, p_max_2d_kpa: float,
                 p_max_3d_kpa: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
    """2D pressures (..., 2) for 3D pairs ``p3`` (..., 2: top, bottom) in kPa, and the mapping flag per pair.

    Without surrogates (``angle_3d`` is None) the pressures are returned
    unchanged (flag 3).
    """
    p3 = np.asarray(p3, float)
    if angle_3d is None or angle_2d is None:
        return p3.copy(), np.full(p3.shape[:-1], 3, dtype=np.int8)
    from workflow.mapping import map_pairs

    r = map_pairs(p3[..., 0], p3[..., 1], angle_3d, angle_2d, p_max_2d_kpa=p_max_2d_kpa, p_max_3d_kpa=p_max_3d_kpa)
    p2 = np.stack([r["p_top_2d_kpa"], r["p_bottom_2d_kpa"]], axis=-1)
    flag = np.zeros(p3.shape[:-1], dtype=np.int8)
    eq = r["status"] == 1
    p2[eq] = p3[eq]
    flag[eq] = 1
    out = r["status"] == 2
    pmax = np.maximum(p3[..., 0], p3[..., 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(pmax > 0, p_max_2d_kpa / pmax, 1.0)
    p2[out] = p3[out] * s[out][..., None]
    flag[out] = 2
    return p2, flag


def gravity_state(fea: PatientFEA, solver: Mapping) -> CoupledResult:
    """The finger and actuator under their weight alone (zero pressure)."""
    return solve_coupled(fea.setup, {}, solver=solver)


@dataclass
class ExerciseCheck:
    """One exercise's FEA check (full-width values; see the module docstring)."""

    exercise: str
    pressures_kpa: np.ndarray  # (group, chamber) applied in the FE model
    result: CoupledResult
    angle_deg: np.ndarray
    max_actuator_moment_nm: np.ndarray  # largest |spring - finger weight| over the path, signed at its peak
    actuator_moment_nm: np.ndarray  # at the final state
    max_strap_force_n: np.ndarray  # (PIP, DIP)
    peak_memory_mb: float
    wall_time_s: float = 0.0


def _signed_peak(a: np.ndarray) -> np.ndarray:
    """Per column, the entry of largest magnitude (with its sign)."""
    a = np.atleast_2d(a)
    return a[np.argmax(np.abs(a), axis=0), np.arange(a.shape[1])]


def check_exercise(fea: PatientFEA, name: str, pressures_kpa: np.ndarray, solver: Mapping,
                   gravity: CoupledResult | None = None) -> ExerciseCheck:
    """Ramp one exercise's pressures (group, chamber) kPa from the gravity state; never raises for divergence."""
    t0 = time.perf_counter()
    tracemalloc.start()
    p = {g: (float(pressures_kpa[i, 0]), float(pressures_kpa[i, 1])) for i, g in enumerate(GROUPS)}
    res = solve_coupled(fea.setup, p, solver=solver, u_gravity=None if gravity is None else gravity.u)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    W = fea.width_mm
    hist = [h for h in res.history if h.get("phase") == "pressure"] or res.history
    act = np.array([h["spring_moments"] - h["gravity_moments"] for h in hist] or
                   [res.spring_moments - res.gravity_moments]) * W * 1e-3
    straps = np.array([[res.max_strap_force.get(j, np.nan) for j in ("PIP", "DIP")]]) * W
    return ExerciseCheck(
        exercise=name, pressures_kpa=np.asarray(pressures_kpa, float), result=res, angle_deg=res.joint_angles_deg,
        max_actuator_moment_nm=_signed_peak(act), actuator_moment_nm=act[-1], max_strap_force_n=straps[0],
        peak_memory_mb=peak / 2**20, wall_time_s=time.perf_counter() - t0)


def fea_check_dataset(checks: Sequence[ExerciseCheck], plan: xr.Dataset, gravity: CoupledResult, *,
                      tolerance_deg: float, width_mm: float, pressures_plan_kpa: np.ndarray, mapping_flag: np.ndarray,
                      notes: Mapping[str, Any] | None = None) -> xr.Dataset:
    """``fea_check.nc`` content (without provenance) for the checked exercises."""
    ex = [c.exercise for c in checks]
    tgt = plan["target_angle_deg"].sel(exercise=ex, joint=list(JOINTS)).values
    pred = plan["predicted_angle_deg"].sel(exercise=ex, joint=list(JOINTS)).values
    lim = np.abs(plan["active_limit_nm"].sel(joint=list(JOINTS)).values) if "active_limit_nm" in plan else np.full(3, np.nan)
    ang = np.array([c.angle_deg for c in checks])
    status = np.array([c.result.status for c in checks], dtype="i1")
    lam = np.array([c.result.load_factor if c.result.phase == "pressure" else 0.0 for c in checks])
    converged = (status == 0) & (lam >= 1.0 - 1e-9)
    within_tol = np.all(np.abs(ang - tgt) <= tolerance_deg, axis=1)
    mom = np.array([c.max_actuator_moment_nm for c in checks])
    within_lim = np.all(~(np.abs(mom) > lim), axis=1)
    achieved = converged & within_tol & within_lim
    reasons = []
    for i, c in enumerate(checks):
        r = []
        if not converged[i]:
            r.append(f"stopped at load factor {lam[i]:.3f} of the {c.result.phase} phase ({c.result.reason})")
        for j in np.flatnonzero(np.abs(ang[i] - tgt[i]) > tolerance_deg):
            r.append(f"{JOINTS[j]} off target by {ang[i, j] - tgt[i, j]:+.1f} deg")
        for j in np.flatnonzero(np.abs(mom[i]) > lim):
            r.append(f"{JOINTS[j]} moment {mom[i, j]:.3g} N m above the active limit {lim[j]:.3g}")
        reasons.append("; ".join(r))
    flag_vals = np.array(sorted(STATUS_FLAGS), dtype="i1")
    map_vals = np.array(sorted(MAPPING_FLAGS), dtype="i1")
    plan_ach = plan["achieved"].sel(exercise=ex).values.astype(bool) if "achieved" in plan else np.full(len(ex), False)
    deg, nm = {"units": "degree"}, {"units": "N m"}
    ds = xr.Dataset(
        {
            "angle_deg": (("exercise", "joint"), ang, {**deg, "long_name": "joint angle reached in the FEA (bone orientations)"}),
            "target_angle_deg": (("exercise", "joint"), tgt, {**deg, "long_name": "target joint angle (Table 1)"}),
            "predicted_angle_deg": (("exercise", "joint"), pred, {**deg, "long_name": "reduced-order prediction of the plan"}),
            "angle_error_deg": (("exercise", "joint"), ang - tgt, {**deg, "long_name": "FEA minus target joint angle"}),
            "plan_error_deg": (("exercise", "joint"), ang - pred, {**deg, "long_name": "FEA minus reduced-order prediction"}),
            "droop_angle_deg": ("joint", gravity.joint_angles_deg, {**deg, "long_name": "joint angle under gravity at zero pressure (FEA)"}),
            "achieved": ("exercise", achieved, {"units": "1", "long_name": f"converged, every joint within {tolerance_deg:g} deg of its target, moments within the active limits"}),
            "achieved_plan": ("exercise", plan_ach, {"units": "1", "long_name": "achieved according to the reduced-order plan"}),
            "reason": ("exercise", np.array(reasons, dtype=object), {"units": "1", "long_name": "why the exercise is not reached in the FEA (empty if reached)"}),
            "pressure_kpa": (("exercise", "group", "chamber"), np.array([c.pressures_kpa for c in checks]),
                             {"units": "kPa", "long_name": "chamber pressure applied to the 2D model"}),
            "pressure_plan_kpa": (("exercise", "group", "chamber"), pressures_plan_kpa, {"units": "kPa", "long_name": "planned chamber pressure"}),
            "mapping_status": (("exercise", "group"), mapping_flag.astype("i1"), {
                "units": "1", "long_name": "how the 2D pressure pair was obtained from the plan's",
                "flag_values": map_vals, "flag_meanings": " ".join(MAPPING_FLAGS[int(v)] for v in map_vals)}),
            "status": ("exercise", status, {"units": "1", "long_name": "solver status of the last phase",
                                            "flag_values": flag_vals, "flag_meanings": " ".join(STATUS_FLAGS[int(v)] for v in flag_vals)}),
            "converged": ("exercise", converged, {"units": "1", "long_name": "pressures reached in full"}),
            "load_factor": ("exercise", lam, {"units": "1", "long_name": "last converged fraction of the pressures (0: gravity phase failed)"}),
            "max_actuator_moment_nm": (("exercise", "joint"), mom, {**nm, "long_name": "largest moment the actuator applies about the joint along the load path (spring minus finger weight)"}),
            "actuator_moment_nm": (("exercise", "joint"), np.array([c.actuator_moment_nm for c in checks]), {**nm, "long_name": "moment the actuator applies about the joint at the final state"}),
            "spring_moment_nm": (("exercise", "joint"), np.array([c.result.spring_moments for c in checks]) * width_mm * 1e-3,
                                 {**nm, "long_name": "passive joint moment at the final state"}),
            "active_limit_nm": ("joint", lim, {**nm, "long_name": "active safety limit"}),
            "within_limits": ("exercise", within_lim, {"units": "1", "long_name": "every largest actuator moment within its active limit"}),
            "max_strap_force_n": (("exercise", "strap"), np.array([c.max_strap_force_n for c in checks]),
                                  {"units": "N", "long_name": "largest strap force along the load path (full width)"}),
            "max_penetration_mm": ("exercise", np.array([c.result.max_penetration_mm for c in checks]),
                                   {"units": "mm", "long_name": "largest contact penetration along the load path"}),
            "tip_angle_deg": ("exercise", np.array([c.result.tip_angle_deg for c in checks]), {**deg, "long_name": "rotation of the actuator's backbone at its tip"}),
            "newton_iterations": ("exercise", np.array([c.result.newton_iterations for c in checks], dtype="i4"), {"units": "1", "long_name": "Newton iterations of the pressure phase"}),
            "load_steps": ("exercise", np.array([c.result.steps for c in checks], dtype="i4"), {"units": "1", "long_name": "load steps (accepted + rejected) of the pressure phase"}),
            "wall_time_s": ("exercise", np.array([c.wall_time_s for c in checks]), {"units": "s", "long_name": "wall time of the pressure phase"}),
            "peak_memory_mb": ("exercise", np.array([c.peak_memory_mb for c in checks]), {"units": "MiB", "long_name": "peak Python heap during the check (tracemalloc)"}),
            "ndofs": ((), int(checks[0].result.ndofs) if checks else 0, {"units": "1", "long_name": "degrees of freedom"}),
        },
        coords={"exercise": ex, "joint": list(JOINTS), "group": list(GROUPS), "chamber": list(CHAMBERS), "strap": ["PIP", "DIP"]},
    )
    ds.attrs.update({
        "tolerance_deg": float(tolerance_deg),
        "gravity_status": int(gravity.status),
        "gravity_load_factor": float(gravity.load_factor),
        "gravity_newton_iterations": int(gravity.newton_iterations),
        "gravity_wall_time_s": float(gravity.wall_time_s),
        **{k: (v if isinstance(v, (int, float, str)) else str(v)) for k, v in dict(notes or {}).items()},
    })
    return ds


def write_deformed(fea: PatientFEA, u: np.ndarray, path: str | Path) -> Path:
    """The deformed coupled mesh (.vtu): displacement, material and body per cell."""
    from skfem.io.meshio import to_meshio

    cm = fea.setup.cm
    d = u.reshape(-1, 2)
    m = to_meshio(cm.mesh, point_data={"displacement": np.column_stack([d, np.zeros(len(d))])})
    m.points = np.column_stack([cm.mesh.p.T + d, np.zeros(len(d))])
    m.cell_data["material"] = [cm.material.astype(np.int32)]
    m.cell_data["body"] = [cm.body.astype(np.int32)]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    m.write(path)
    return path


def load_surrogate_angles(surrogate_2d: str | None, surrogate_3d: str | None):
    """(angle_3d, angle_2d, p_max_2d, p_max_3d) from the fitted surrogates, or Nones when not given."""
    if not surrogate_2d or not surrogate_3d:
        return None, None, np.inf, np.inf
    from workflow.surrogates import load_surrogate

    s2, s3 = load_surrogate(surrogate_2d), load_surrogate(surrogate_3d)
    return s3.angle_deg, s2.angle_deg, float(s2.p_max_kpa), float(s3.p_max_kpa)


def run_fea_check(fea: PatientFEA, plan: xr.Dataset, *, exercises: Sequence[str] | None, solver: Mapping,
                  tolerance_deg: float, angle_3d=None, angle_2d=None, p_max_2d_kpa: float = np.inf,
                  p_max_3d_kpa: float = np.inf, notes: Mapping[str, Any] | None = None):
    """Gravity state, then every exercise -> (dataset, checks, gravity result)."""
    ex = [str(e) for e in plan["exercise"].values] if not exercises else [str(e) for e in exercises]
    p_plan = plan["pressure_kpa"].sel(exercise=ex, group=list(GROUPS), chamber=list(CHAMBERS)).values
    p2, flag = pressures_2d(p_plan, angle_3d, angle_2d, p_max_2d_kpa=p_max_2d_kpa, p_max_3d_kpa=p_max_3d_kpa)
    grav = gravity_state(fea, solver)
    log.info("gravity: status %d at load factor %.3f, droop %s deg, %d Newton iterations, %.1f s",
             grav.status, grav.load_factor, np.round(grav.joint_angles_deg, 2), grav.newton_iterations,
             grav.wall_time_s)
    checks = []
    for i, name in enumerate(ex):
        if grav.status != 0:  # no converged gravity state: nothing to ramp from
            c = ExerciseCheck(name, p2[i], grav, grav.joint_angles_deg, np.full(3, np.nan), np.full(3, np.nan),
                              np.full(2, np.nan), 0.0, 0.0)
        else:
            c = check_exercise(fea, name, p2[i], solver, gravity=grav)
        log.info("%s: pressures %s kPa -> angles %s deg (target %s, plan %s), status %d at %.3f, %d its, %.1f s",
                 name, np.round(p2[i].ravel(), 1), np.round(c.angle_deg, 1),
                 plan["target_angle_deg"].sel(exercise=name).values, np.round(plan["predicted_angle_deg"].sel(exercise=name).values, 1),
                 c.result.status, c.result.load_factor, c.result.newton_iterations, c.wall_time_s)
        checks.append(c)
    ds = fea_check_dataset(checks, plan, grav, tolerance_deg=tolerance_deg, width_mm=fea.width_mm,
                           pressures_plan_kpa=p_plan, mapping_flag=flag, notes={"model": fea.notes, **dict(notes or {})})
    return ds, checks, grav


def write_fea_check(patient_name: str, patient: Mapping[str, Any], *, plan_nc: str, joint_loads_nc: str, moments_nc: str,
                    ccd_nc: str, out_nc: str, out_vtu: Sequence[str], out_png: str | None, fea_cfg: Mapping,
                    actuator_cfg: Mapping, cascade_cfg: Mapping, anthropometry: Mapping, config_slice: Any,
                    surrogate_2d: str | None = None, surrogate_3d: str | None = None, rule: str = "fea_check"):
    """The rule's entry point: build the patient's FE model, check the plan, write .nc, .vtu per exercise, plot."""
    from workflow.cascade import patient_finger
    from workflow.fea_model import build_patient_fea
    from workflow.provenance import write_dataset

    plan = xr.load_dataset(plan_nc)
    loads = xr.load_dataset(joint_loads_nc)
    finger, spring_note = patient_finger(patient, loads, xr.load_dataset(moments_nc), xr.load_dataset(ccd_nc),
                                         cascade_cfg=cascade_cfg, anthropometry=anthropometry)
    upg = {g: int(v) for g, v in zip(plan["group"].values, plan["units_per_group"].values)}
    fea = build_patient_fea(finger, upg, actuator_cfg=actuator_cfg, cascade_cfg=cascade_cfg,
                            reference_dims_mm={k: float(v["mean"]) for k, v in anthropometry["measures"].items()},
                            fea_cfg=fea_cfg)
    log.info("patient %s: %s; units %s; springs: %s", patient_name, fea.notes, upg, spring_note)
    use_map = bool(fea_cfg.get("map_pressures", True)) and cascade_cfg.get("surrogate", "3d") == "3d"
    a3, a2, pm2, pm3 = load_surrogate_angles(surrogate_2d, surrogate_3d) if use_map else (None, None, np.inf, np.inf)
    if use_map and a3 is None:
        log.warning("no surrogates given: the plan's 3D pressures are applied to the 2D model unchanged")
    solver = dict(actuator_cfg.get("solver", {}))
    solver.update(dict(fea_cfg.get("solver", {})))
    ds, checks, grav = run_fea_check(fea, plan, exercises=fea_cfg.get("exercises") or None, solver=solver,
                                     tolerance_deg=float(cascade_cfg["tolerance_deg"]), angle_3d=a3, angle_2d=a2,
                                     p_max_2d_kpa=pm2, p_max_3d_kpa=pm3,
                                     notes={"patient": patient_name, "springs": spring_note,
                                            "pressures": "2D-to-3D mapped" if a3 is not None else "plan's, unchanged"})
    write_dataset(ds, out_nc, rule=rule, config_slice=config_slice,
                  title=f"2D FEA check of the cascade plan of patient {patient_name}")
    by_name = {c.exercise: c for c in checks}
    for path in out_vtu:
        name = Path(path).stem.split("_")[-1]
        c = by_name.get(name)
        write_deformed(fea, c.result.u if c is not None else grav.u, path)
    if out_png:
        from workflow.plots_fea_check import plot_fea_poses

        cm = fea.setup.cm
        plot_fea_poses(cm.mesh.p, cm.mesh.t, cm.material, [c.result.u for c in checks], ds, finger, out_png,
                       title=f"patient {patient_name}")
    return ds
