"""FEA check of every planned exercise (paper section 3.2, Fig. 18-21).

Per patient: the whole actuator of the plan (``units_per_group``) strapped to
the planar finger (:mod:`workflow.fea_model`), gravity first (one solve,
shared by the exercises), then each exercise's planned pressures ramped from
zero.  A point that does not converge is kept with its last converged load
factor (``load_factor`` < 1, ``status`` > 0) and measured there.

Pressures.  The 2D section is stiffer than the 3D actuator (
paper section 3.2): when the plan was made with the 3D surrogate, each
(P_T, P_B) pair is scaled to the 2D pair of the same ratio and the same free
angle with the 2D-to-3D mapping (:func:`workflow.mapping.map_pairs`), as the
paper's Table 9 did; pairs with P_T = P_B keep their pressures (no bend either
way), pairs whose 3D angle lies beyond the 2D sweep are capped at its edge
(``mapping_status`` records both).  ``map_pressures: false`` applies the plan's
pressures unchanged.  No applied pressure exceeds the silicone's limit
(``actuator.material.p_limit_kpa``) or, when mapped, the 2D sweep's range
(:mod:`workflow.pressure_limit`); a pair cut back to it is flagged too.

Outcome per exercise: joint angles from the bones' orientations, error
against the targets (Table 1) and against the plan's reduced-order
prediction, the largest strap force and the largest moment the actuator
applies about each joint (spring moment minus the moment of the finger's
weight, both from the FE state) against the active safety limits, and
``achieved`` = converged to the full load, every joint within the plan's
tolerance and every moment within its limit.  Full-width values: the 2D
per-mm results times the actuator width.  Angles deg, moments N m, forces N.

Where the FEA and the plan part.  Beside the plan's own prediction (its
reduced-order chain with the unit surrogate it planned with), the chain is
solved with the 2D unit surrogate at the 2D pressures applied
(``predicted_2d_angle_deg``): plan minus that is what the 2D-to-3D mapping
changes (it matches free angles, not blocked moments), that minus the FEA is
what the chain's kinematics miss (all units of a span bending alike, no
contact geometry).

Correction step (``correction.max_iterations`` > 0).  For an exercise the
FEA misses, the plan is re-made with the FEA's angles: the reduced-order
chain is asked for ``target - (FEA - chain)`` at the current pressures, the
new pressures are mapped to 2D and checked again, at most
``max_iterations`` times; it stops early when the re-plan changes no pressure
by ``min_change_kpa`` (the spans sit at their pressure limit, say).  The best
check (fewest joints out of tolerance, then the least total error) is kept
as ``corrected_*``; every iteration's pressures and angles are stored.
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

from workflow.cascade import CHAMBERS, GROUPS, CascadeModel
from workflow.fea_model import PatientFEA
from workflow.fem import STATUS_FLAGS
from workflow.fem._coupled import CoupledResult, solve_coupled
from workflow.finger import JOINTS
from workflow.pressure_limit import PressureLimit, clip_pressures, material_limit, smallest
from workflow.runlog import solved

__all__ = ["MAPPING_FLAGS", "applied_limit", "pressures_2d", "ExerciseCheck", "outcome", "Correction", "correct_exercise", "check_exercise",
           "gravity_state", "fea_check_dataset", "write_deformed", "run_fea_check", "write_fea_check"]

log = logging.getLogger(__name__)

#: How each 2D pressure pair was obtained.
MAPPING_FLAGS = {0: "mapped", 1: "equal_pressures_kept", 2: "capped_at_2d_grid_edge", 3: "unchanged",
                 4: "cut_back_to_the_pressure_limit"}


def applied_limit(actuator_cfg: Mapping | None, p_max_2d_kpa: float = np.inf) -> PressureLimit:
    """Bound (kPa) of every pressure applied to a 2D model: the silicone's limit and the 2D sweep's range."""
    return smallest(material_limit((actuator_cfg or {}).get("material")),
                    PressureLimit(float(p_max_2d_kpa), "the range the 2D surrogate's sweep sampled"))


def pressures_2d(p3: np.ndarray, angle_3d: Callable | None, angle_2d: Callable | None, *, p_max_2d_kpa: float,
                 p_max_3d_kpa: float = np.inf, limit: PressureLimit | None = None) -> tuple[np.ndarray, np.ndarray]:
    """2D pressures (..., 2) for 3D pairs ``p3`` (..., 2: top, bottom) in kPa, and the mapping flag per pair.

    Without surrogates (``angle_3d`` is None) the pressures are returned
    unchanged (flag 3).  Every pressure returned is at most ``p_max_2d_kpa``
    and ``limit`` (:func:`applied_limit`); a pair cut back to that is flag 4.
    """
    p3 = np.asarray(p3, float)
    limit = smallest(limit, PressureLimit(float(p_max_2d_kpa), "the 2D pressure range"))
    if angle_3d is None or angle_2d is None:
        p2, flag = p3.copy(), np.full(p3.shape[:-1], 3, dtype=np.int8)
    else:
        from workflow.mapping import map_pairs

        p_edge = limit.kpa  # the search stays inside the limit: "not reached" rather than a pair beyond it
        r = map_pairs(p3[..., 0], p3[..., 1], angle_3d, angle_2d, p_max_2d_kpa=p_edge, p_max_3d_kpa=p_max_3d_kpa)
        p2 = np.stack([r["p_top_2d_kpa"], r["p_bottom_2d_kpa"]], axis=-1)
        flag = np.zeros(p3.shape[:-1], dtype=np.int8)
        eq = r["status"] == 1
        p2[eq] = p3[eq]
        flag[eq] = 1
        out = r["status"] == 2
        pmax = np.maximum(p3[..., 0], p3[..., 1])
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.where(pmax > 0, p_edge / pmax, 1.0)
        p2[out] = p3[out] * s[out][..., None]
        flag[out] = 2
    p2, cut = clip_pressures(p2, limit, what="pressures applied to the 2D model")
    flag[cut.any(axis=-1)] = 4
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


def outcome(check: ExerciseCheck, target_deg: np.ndarray, tolerance_deg: float,
            limits_nm: np.ndarray) -> tuple[bool, tuple[int, float], list[str]]:
    """(achieved, score, reasons) of one check: score = (joints off target, total |error| deg), smaller is better.

    Achieved = the pressures reached in full, every joint within
    ``tolerance_deg`` of its target, every largest actuator moment within its
    active limit.
    """
    res, ang = check.result, np.asarray(check.angle_deg, float)
    lam = res.load_factor if res.phase == "pressure" else 0.0
    converged = res.status == 0 and lam >= 1.0 - 1e-9
    err = ang - np.asarray(target_deg, float)
    off = np.abs(err) > tolerance_deg
    over = np.abs(check.max_actuator_moment_nm) > limits_nm
    reasons = [] if converged else [f"stopped at load factor {lam:.3f} of the {res.phase} phase ({res.reason})"]
    reasons += [f"{JOINTS[j]} off target by {err[j]:+.1f} deg" for j in np.flatnonzero(off)]
    reasons += [f"{JOINTS[j]} moment {check.max_actuator_moment_nm[j]:.3g} N m above the active limit {limits_nm[j]:.3g}"
                for j in np.flatnonzero(over)]
    score = (int(np.sum(off)) + (0 if converged else 3), float(np.nansum(np.abs(err))))
    return converged and not off.any() and not over.any(), score, reasons


@dataclass
class Correction:
    """The correction step of one exercise: iteration 0 is the plan's own check."""

    pressures_kpa: list  # (group, chamber) planned (plan's surrogate) per iteration
    pressures_2d_kpa: list  # applied in the 2D model
    checks: list  # ExerciseCheck per iteration
    predicted_deg: list  # the reduced-order chain's angles at that iteration's pressures
    best: int
    stop_reason: str

    @property
    def iterations(self) -> int:
        """FEA re-checks run after the plan's own."""
        return len(self.checks) - 1


def _saturated_joints(angle_deg, target_deg, tolerance_deg, p_now, p_new, p_max) -> list[str]:
    """Joints off target whose driving chambers (top to flex, bottom to extend, over the joint's span) sit at
    ``p_max`` now and in the re-plan: more of the same pressure is not available."""
    from workflow.cascade import SPANS

    out = []
    for j, joint in enumerate(JOINTS):
        miss = float(target_deg[j] - angle_deg[j])
        if abs(miss) <= tolerance_deg:
            continue
        c = 0 if miss > 0 else 1
        rows = [GROUPS.index(g) for g in SPANS[joint]]
        if all(min(p_now[r, c], p_new[r, c]) >= p_max * (1 - 1e-6) for r in rows):
            out.append(joint)
    return out


def correct_exercise(fea: PatientFEA, ro: CascadeModel, name: str, target_deg: np.ndarray, p_plan: np.ndarray,
                     predicted_deg: np.ndarray, first: ExerciseCheck, *, to_2d: Callable, solver: Mapping,
                     gravity: CoupledResult, tolerance_deg: float, limits_nm: np.ndarray, plan_opts: Mapping,
                     max_iterations: int, min_change_kpa: float = 1.0) -> Correction:
    """Re-plan with the FEA's angles until the FEA reaches the target (see the module docstring).

    ``ro``: the reduced-order chain the plan was made with; ``p_plan`` (4, 2)
    its pressures (kPa) and ``predicted_deg`` its angles there; ``first`` the
    FEA check of the plan; ``to_2d``: (4, 2) planned -> (4, 2) applied 2D
    pressures; ``plan_opts``: keywords of :func:`workflow.cascade.plan_exercise`.
    """
    from workflow.cascade import plan_exercise, pressures_table

    target = np.asarray(target_deg, float)
    cor = Correction([np.asarray(p_plan, float)], [np.asarray(first.pressures_kpa, float)], [first],
                     [np.asarray(predicted_deg, float)], 0, "")
    ok, best_score, _ = outcome(first, target, tolerance_deg, limits_nm)
    if ok:
        cor.stop_reason = "reached by the plan"
        return cor
    p_max = float(plan_opts.get("p_max_kpa", np.inf))
    for k in range(1, int(max_iterations) + 1):
        offset = cor.checks[-1].angle_deg - cor.predicted_deg[-1]
        new = plan_exercise(ro, target - offset, exercise=name, **plan_opts)
        p3 = pressures_table(new.pressures_kpa)
        stuck = _saturated_joints(cor.checks[-1].angle_deg, target, tolerance_deg, cor.pressures_kpa[-1], p3, p_max)
        if stuck:
            cor.stop_reason = (f"{', '.join(stuck)} short of target with the chambers that would move "
                               f"{'it' if len(stuck) == 1 else 'them'} at the {p_max:g} kPa limit: no re-plan can reach it")
            break
        if np.max(np.abs(p3 - cor.pressures_kpa[-1])) < min_change_kpa:
            cor.stop_reason = (f"re-plan {k} changes no pressure by {min_change_kpa:g} kPa"
                               + (f" ({new.reason})" if new.reason else ""))
            break
        p2 = to_2d(p3)
        chk = check_exercise(fea, name, p2, solver, gravity=gravity)
        cor.pressures_kpa.append(p3)
        cor.pressures_2d_kpa.append(p2)
        cor.checks.append(chk)
        cor.predicted_deg.append(new.equilibrium.joint_angles_deg)
        ok, score, _ = outcome(chk, target, tolerance_deg, limits_nm)
        log.info("%s correction %d: plan %s kPa (2D %s) -> FEA %s deg (target %s), status %d, %s", name, k,
                 np.round(p3.ravel(), 1), np.round(p2.ravel(), 1), np.round(chk.angle_deg, 1), target,
                 chk.result.status, "reached" if ok else "not reached", extra=solved(chk.result.status != 0))
        if score < best_score:
            cor.best, best_score = k, score
        if ok:
            cor.stop_reason = f"reached after {k} correction(s)"
            break
    else:
        cor.stop_reason = cor.stop_reason or f"not reached in {int(max_iterations)} correction(s)"
    return cor


def check_exercise(fea: PatientFEA, name: str, pressures_kpa: np.ndarray, solver: Mapping,
                   gravity: CoupledResult | None = None) -> ExerciseCheck:
    """Ramp one exercise's pressures (group, chamber) kPa from the gravity state; never raises for divergence."""
    t0 = time.perf_counter()
    tracemalloc.start()
    p = {g: (float(pressures_kpa[i, 0]), float(pressures_kpa[i, 1])) for i, g in enumerate(GROUPS)}
    res = solve_coupled(fea.setup, p, solver=solver, u_gravity=None if gravity is None else gravity.state)
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


def _corrections_dataset(corrections: Sequence[Correction], ex: Sequence[str], tgt: np.ndarray, tolerance_deg: float,
                         lim: np.ndarray) -> xr.Dataset:
    """The correction step's variables: every iteration (0 = the plan's check) and the best one."""
    n_it = max(c.iterations for c in corrections) + 1
    shape = (len(ex), n_it)
    ang = np.full(shape + (3,), np.nan)
    pred = np.full_like(ang, np.nan)
    p3 = np.full(shape + (4, 2), np.nan)
    p2 = np.full_like(p3, np.nan)
    for i, c in enumerate(corrections):
        for k, chk in enumerate(c.checks):
            ang[i, k], pred[i, k] = chk.angle_deg, c.predicted_deg[k]
            p3[i, k], p2[i, k] = c.pressures_kpa[k], c.pressures_2d_kpa[k]
    best = [c.checks[c.best] for c in corrections]
    ok = np.array([outcome(b, tgt[i], tolerance_deg, lim)[0] for i, b in enumerate(best)])
    deg, kpa = {"units": "degree"}, {"units": "kPa"}
    gc = ("group", "chamber")
    return xr.Dataset(
        {
            "iteration_angle_deg": (("exercise", "iteration", "joint"), ang, {**deg, "long_name": "joint angle in the FEA per correction iteration (0: the plan)"}),
            "iteration_predicted_angle_deg": (("exercise", "iteration", "joint"), pred, {**deg, "long_name": "reduced-order chain's angle at that iteration's pressures"}),
            "iteration_pressure_kpa": (("exercise", "iteration", *gc), p3, {**kpa, "long_name": "planned pressure per correction iteration (the plan's surrogate)"}),
            "iteration_pressure_2d_kpa": (("exercise", "iteration", *gc), p2, {**kpa, "long_name": "pressure applied to the 2D model per correction iteration"}),
            "correction_iterations": ("exercise", np.array([c.iterations for c in corrections], dtype="i4"), {"units": "1", "long_name": "FEA re-checks run by the correction step"}),
            "correction_best": ("exercise", np.array([c.best for c in corrections], dtype="i4"), {"units": "1", "long_name": "iteration kept as corrected (fewest joints off target, then least error)"}),
            "correction_reason": ("exercise", np.array([c.stop_reason for c in corrections], dtype=object), {"units": "1", "long_name": "why the correction step stopped"}),
            "corrected_angle_deg": (("exercise", "joint"), np.array([b.angle_deg for b in best]), {**deg, "long_name": "joint angle in the FEA at the corrected pressures"}),
            "corrected_pressure_kpa": (("exercise", *gc), np.array([c.pressures_kpa[c.best] for c in corrections]), {**kpa, "long_name": "corrected plan (the plan's surrogate)"}),
            "corrected_pressure_2d_kpa": (("exercise", *gc), np.array([c.pressures_2d_kpa[c.best] for c in corrections]), {**kpa, "long_name": "corrected pressure applied to the 2D model"}),
            "achieved_corrected": ("exercise", ok, {"units": "1", "long_name": f"reached in the FEA after the correction step (within {tolerance_deg:g} deg, limits held)"}),
        },
        coords={"exercise": list(ex), "iteration": np.arange(n_it)},
    )


def fea_check_dataset(checks: Sequence[ExerciseCheck], plan: xr.Dataset, gravity: CoupledResult, *,
                      tolerance_deg: float, width_mm: float, pressures_plan_kpa: np.ndarray, mapping_flag: np.ndarray,
                      predicted_2d_deg: np.ndarray | None = None, corrections: Sequence[Correction] | None = None,
                      notes: Mapping[str, Any] | None = None) -> xr.Dataset:
    """``fea_check.nc`` content (without provenance) for the checked exercises.

    ``predicted_2d_deg`` (exercise, joint): the reduced-order chain with the
    2D unit at the applied pressures; ``corrections``: per exercise, the
    correction step (adds the ``iteration`` dimension and ``corrected_*``).
    """
    ex = [c.exercise for c in checks]
    tgt = plan["target_angle_deg"].sel(exercise=ex, joint=list(JOINTS)).values
    pred = plan["predicted_angle_deg"].sel(exercise=ex, joint=list(JOINTS)).values
    lim = np.abs(plan["active_limit_nm"].sel(joint=list(JOINTS)).values) if "active_limit_nm" in plan else np.full(3, np.nan)
    ang = np.array([c.angle_deg for c in checks])
    status = np.array([c.result.status for c in checks], dtype="i1")
    lam = np.array([c.result.load_factor if c.result.phase == "pressure" else 0.0 for c in checks])
    converged = (status == 0) & (lam >= 1.0 - 1e-9)
    mom = np.array([c.max_actuator_moment_nm for c in checks])
    within_lim = np.all(~(np.abs(mom) > lim), axis=1)
    judged = [outcome(c, tgt[i], tolerance_deg, lim) for i, c in enumerate(checks)]
    achieved = np.array([j[0] for j in judged])
    reasons = ["; ".join(j[2]) for j in judged]
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
                                   {"units": "mm", "long_name": "largest penetration along the load path (contact or overlap check)"}),
            "overlap_depth_mm": ("exercise", np.array([c.result.overlap_depth_mm for c in checks]),
                                 {"units": "mm", "long_name": "deepest actuator node inside another element along the load path"}),
            "min_pocket_area_mm2": ("exercise", np.array([c.result.min_pocket_area_mm2 for c in checks]),
                                    {"units": "mm2", "long_name": "smallest actuator pocket along the load path (36.4 at rest)"}),
            "tip_angle_deg": ("exercise", np.array([c.result.tip_angle_deg for c in checks]), {**deg, "long_name": "rotation of the actuator's backbone at its tip"}),
            "newton_iterations": ("exercise", np.array([c.result.newton_iterations for c in checks], dtype="i4"), {"units": "1", "long_name": "Newton iterations of the pressure phase"}),
            "load_steps": ("exercise", np.array([c.result.steps for c in checks], dtype="i4"), {"units": "1", "long_name": "load steps (accepted + rejected) of the pressure phase"}),
            "wall_time_s": ("exercise", np.array([c.wall_time_s for c in checks]), {"units": "s", "long_name": "wall time of the pressure phase"}),
            "peak_memory_mb": ("exercise", np.array([c.peak_memory_mb for c in checks]), {"units": "MiB", "long_name": "peak Python heap during the check (tracemalloc)"}),
            "ndofs": ((), int(checks[0].result.ndofs) if checks else 0, {"units": "1", "long_name": "degrees of freedom"}),
        },
        coords={"exercise": ex, "joint": list(JOINTS), "group": list(GROUPS), "chamber": list(CHAMBERS), "strap": ["PIP", "DIP"]},
    )
    if predicted_2d_deg is not None:
        p2d = np.asarray(predicted_2d_deg, float)
        ds["predicted_2d_angle_deg"] = (("exercise", "joint"), p2d, {
            **deg, "long_name": "reduced-order chain with the 2D unit surrogate at the applied 2D pressures"})
        ds["mapping_error_deg"] = (("exercise", "joint"), p2d - pred, {
            **deg, "long_name": "what the 2D-to-3D mapping changes in the chain: 2D-unit minus planned prediction"})
        ds["chain_error_deg"] = (("exercise", "joint"), ang - p2d, {
            **deg, "long_name": "what the chain misses: FEA minus the chain with the 2D unit at the same pressures"})
    if corrections:
        ds = ds.merge(_corrections_dataset(corrections, ex, tgt, tolerance_deg, lim))
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
                  p_max_3d_kpa: float = np.inf, ro_plan=None, ro_2d=None, correction: Mapping | None = None,
                  plan_opts: Mapping | None = None, limit_2d: PressureLimit | None = None,
                  notes: Mapping[str, Any] | None = None):
    """Gravity state, then every exercise -> (dataset, checks, gravity result, corrections).

    ``limit_2d`` (:func:`applied_limit`) bounds every pressure applied, the
    correction step's too.

    ``ro_plan`` / ``ro_2d``: the reduced-order chain (``CascadeModel``) with
    the plan's and with the 2D unit surrogate; ``correction``: ``{max_iterations,
    min_change_kpa}`` (needs ``ro_plan`` and ``plan_opts``, the keywords of
    :func:`workflow.cascade.plan_exercise` the plan was made with).
    """
    from workflow.cascade import solve_equilibrium

    ex = [str(e) for e in plan["exercise"].values] if not exercises else [str(e) for e in exercises]
    p_plan = plan["pressure_kpa"].sel(exercise=ex, group=list(GROUPS), chamber=list(CHAMBERS)).values

    def to_2d(p3):
        return pressures_2d(p3, angle_3d, angle_2d, p_max_2d_kpa=p_max_2d_kpa, p_max_3d_kpa=p_max_3d_kpa,
                            limit=limit_2d)

    p2, flag = to_2d(p_plan)
    targets = plan["target_angle_deg"].sel(exercise=ex, joint=list(JOINTS)).values
    lim = np.abs(plan["active_limit_nm"].sel(joint=list(JOINTS)).values) if "active_limit_nm" in plan else np.full(3, np.nan)
    grav = gravity_state(fea, solver)
    log.info("gravity: status %d at load factor %.3f, droop %s deg, %d Newton iterations, %.1f s",
             grav.status, grav.load_factor, np.round(grav.joint_angles_deg, 2), grav.newton_iterations,
             grav.wall_time_s, extra=solved(grav.status != 0))
    n_cor = int((correction or {}).get("max_iterations", 0)) if ro_plan is not None else 0
    checks, corrections, pred_2d = [], [], []
    for i, name in enumerate(ex):
        if grav.status != 0:  # no converged gravity state: nothing to ramp from
            c = ExerciseCheck(name, p2[i], grav, grav.joint_angles_deg, np.full(3, np.nan), np.full(3, np.nan),
                              np.full(2, np.nan), 0.0, 0.0)
        else:
            c = check_exercise(fea, name, p2[i], solver, gravity=grav)
        log.info("%s: pressures %s kPa -> angles %s deg (target %s, plan %s), status %d at %.3f, %d its, %.1f s",
                 name, np.round(p2[i].ravel(), 1), np.round(c.angle_deg, 1), targets[i],
                 np.round(plan["predicted_angle_deg"].sel(exercise=name).values, 1),
                 c.result.status, c.result.load_factor, c.result.newton_iterations, c.wall_time_s,
                 extra=solved(c.result.status != 0) if grav.status == 0 else {})
        checks.append(c)
        if ro_2d is not None:
            pred_2d.append(solve_equilibrium(ro_2d, p2[i].ravel()).joint_angles_deg)
        if n_cor and grav.status == 0:
            corrections.append(correct_exercise(
                fea, ro_plan, name, targets[i], p_plan[i], plan["predicted_angle_deg"].sel(exercise=name).values, c,
                to_2d=lambda p3: to_2d(p3)[0], solver=solver, gravity=grav, tolerance_deg=tolerance_deg,
                limits_nm=lim, plan_opts=plan_opts or {}, max_iterations=n_cor,
                min_change_kpa=float((correction or {}).get("min_change_kpa", 1.0))))
            log.info("%s: correction step: %s", name, corrections[-1].stop_reason)
    ds = fea_check_dataset(checks, plan, grav, tolerance_deg=tolerance_deg, width_mm=fea.width_mm,
                           pressures_plan_kpa=p_plan, mapping_flag=flag,
                           predicted_2d_deg=np.array(pred_2d) if pred_2d else None,
                           corrections=corrections if len(corrections) == len(checks) else None,
                           notes={"model": fea.notes, **dict(notes or {})})
    return ds, checks, grav, corrections


def write_fea_check(patient_name: str, patient: Mapping[str, Any], *, plan_nc: str, joint_loads_nc: str, moments_nc: str,
                    ccd_nc: str, out_nc: str, out_vtu: Sequence[str], out_png: str | None, fea_cfg: Mapping,
                    actuator_cfg: Mapping, cascade_cfg: Mapping, anthropometry: Mapping, config_slice: Any,
                    surrogate_2d: str | None = None, surrogate_3d: str | None = None,
                    unit_model_cfg: Mapping | None = None, rule: str = "fea_check",
                    notes: Mapping[str, Any] | None = None):
    """The rule's entry point: build the patient's FE model, check the plan, write .nc, .vtu per exercise, plot.

    With the surrogates and ``unit_model_cfg`` (config ``surrogates.unit_model``)
    the reduced-order chains are built too: the 2D-unit prediction and the
    correction step (config ``fea_check.correction``).
    """
    from workflow.cascade import patient_cascade, patient_finger, plan_limit, plan_options
    from workflow.fea_model import build_patient_fea
    from workflow.provenance import open_result, write_dataset

    plan = open_result(plan_nc)
    loads = open_result(joint_loads_nc)
    finger, spring_note = patient_finger(patient, loads, open_result(moments_nc), open_result(ccd_nc),
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
    ro_plan = ro_2d = None
    if unit_model_cfg is not None and surrogate_2d and surrogate_3d:
        from workflow.unit_model import load_unit_model

        units = {"2d": surrogate_2d, "3d": surrogate_3d}
        ro_2d = patient_cascade(finger, load_unit_model(surrogate_2d, **unit_model_cfg), cascade_cfg, upg)
        ro_plan = patient_cascade(finger, load_unit_model(units[cascade_cfg.get("surrogate", "3d")], **unit_model_cfg),
                                  cascade_cfg, upg)
    material = material_limit(actuator_cfg.get("material"))
    limit_plan = plan_limit(cascade_cfg, None if ro_plan is None else ro_plan.unit, material)
    limit_2d = applied_limit(actuator_cfg, pm2)
    log.info("patient %s: re-planned pressures <= %s; applied pressures <= %s", patient_name, limit_plan, limit_2d)
    plan_opts = plan_options(cascade_cfg, plan["active_limit_nm"].sel(joint=list(JOINTS)).values
                             if "active_limit_nm" in plan else None, limit_plan)
    solver = dict(actuator_cfg.get("solver", {}))
    solver.update(dict(fea_cfg.get("solver", {})))
    ds, checks, grav, corrections = run_fea_check(fea, plan, exercises=fea_cfg.get("exercises") or None, solver=solver,
                                     tolerance_deg=float(cascade_cfg["tolerance_deg"]), angle_3d=a3, angle_2d=a2,
                                     p_max_2d_kpa=pm2, p_max_3d_kpa=pm3, ro_plan=ro_plan, ro_2d=ro_2d,
                                     correction=fea_cfg.get("correction"), plan_opts=plan_opts, limit_2d=limit_2d,
                                     notes={"patient": patient_name, "springs": spring_note,
                                            "p_limit_kpa": limit_2d.kpa, "p_limit_source": limit_2d.source,
                                            "p_limit_plan_kpa": limit_plan.kpa, "p_limit_plan_source": limit_plan.source,
                                            "pressures": "2D-to-3D mapped" if a3 is not None else "plan's, unchanged",
                                            "h_actuator_mm": float(fea_cfg.get("h_actuator_mm", 2.0)),
                                            **dict(notes or {})})
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
        corrected = [c.checks[c.best].result.u if c.best else None for c in corrections] if corrections else None
        plot_fea_poses(cm.mesh.p, cm.mesh.t, cm.material, [c.result.u for c in checks], ds, finger, out_png,
                       title=f"patient {patient_name}", corrected_states=corrected)
    return ds
