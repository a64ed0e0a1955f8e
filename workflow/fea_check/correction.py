"""The correction step of the FEA check: when the FEA misses an exercise's
target, re-plan on a reduced-order chain whose unit response is scaled to what
the FEA did, and check again, never beyond the pressure limit.

Pressures kPa, angles deg.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.cascade.model import SPANS, CascadeModel, pressures_table
from workflow.cascade.planning import plan_exercise
from workflow.common.constants import GROUPS, JOINTS
from workflow.common.runlog import solved
from workflow.fea_check.check import ExerciseCheck, check_exercise, outcome
from workflow.fea_check.model import PatientFEA
from workflow.fem.coupled import CoupledResult

__all__ = ["Correction", "correct_exercise"]

log = logging.getLogger(__name__)


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


def correct_exercise(
    fea: PatientFEA,
    ro: CascadeModel,
    name: str,
    target_deg: np.ndarray,
    p_plan: np.ndarray,
    predicted_deg: np.ndarray,
    first: ExerciseCheck,
    *,
    to_2d: Callable,
    solver: Mapping,
    gravity: CoupledResult,
    tolerance_deg: float,
    limits_nm: np.ndarray,
    plan_opts: Mapping,
    max_iterations: int,
    min_change_kpa: float = 1.0,
) -> Correction:
    """Re-plan with the FEA's angles until the FEA reaches the target (see the module docstring).

    ``ro``: the reduced-order chain the plan was made with; ``p_plan`` (4, 2)
    its pressures (kPa) and ``predicted_deg`` its angles there; ``first`` the
    FEA check of the plan; ``to_2d``: (4, 2) planned -> (4, 2) applied 2D
    pressures; ``plan_opts``: keywords of :func:`workflow.cascade.plan_exercise`.
    """

    target = np.asarray(target_deg, float)
    cor = Correction(
        [np.asarray(p_plan, float)],
        [np.asarray(first.pressures_kpa, float)],
        [first],
        [np.asarray(predicted_deg, float)],
        0,
        "",
    )
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
            cor.stop_reason = (
                f"{', '.join(stuck)} short of target with the chambers that would move "
                f"{'it' if len(stuck) == 1 else 'them'} at the {p_max:g} kPa limit: no re-plan can reach it"
            )
            break
        if np.max(np.abs(p3 - cor.pressures_kpa[-1])) < min_change_kpa:
            cor.stop_reason = f"re-plan {k} changes no pressure by {min_change_kpa:g} kPa" + (
                f" ({new.reason})" if new.reason else ""
            )
            break
        p2 = to_2d(p3)
        chk = check_exercise(fea, name, p2, solver, gravity=gravity)
        cor.pressures_kpa.append(p3)
        cor.pressures_2d_kpa.append(p2)
        cor.checks.append(chk)
        cor.predicted_deg.append(new.equilibrium.joint_angles_deg)
        ok, score, _ = outcome(chk, target, tolerance_deg, limits_nm)
        log.info(
            "%s correction %d: plan %s kPa (2D %s) -> FEA %s deg (target %s), status %d, %s",
            name,
            k,
            np.round(p3.ravel(), 1),
            np.round(p2.ravel(), 1),
            np.round(chk.angle_deg, 1),
            target,
            chk.result.status,
            "reached" if ok else "not reached",
            extra=solved(chk.result.status != 0),
        )
        if score < best_score:
            cor.best, best_score = k, score
        if ok:
            cor.stop_reason = f"reached after {k} correction(s)"
            break
    else:
        cor.stop_reason = cor.stop_reason or f"not reached in {int(max_iterations)} correction(s)"
    return cor


def _corrections_dataset(
    corrections: Sequence[Correction], ex: Sequence[str], tgt: np.ndarray, tolerance_deg: float, lim: np.ndarray
) -> xr.Dataset:
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
            "iteration_angle_deg": (
                ("exercise", "iteration", "joint"),
                ang,
                {**deg, "long_name": "joint angle in the FEA per correction iteration (0: the plan)"},
            ),
            "iteration_predicted_angle_deg": (
                ("exercise", "iteration", "joint"),
                pred,
                {**deg, "long_name": "reduced-order chain's angle at that iteration's pressures"},
            ),
            "iteration_pressure_kpa": (
                ("exercise", "iteration", *gc),
                p3,
                {**kpa, "long_name": "planned pressure per correction iteration (the plan's surrogate)"},
            ),
            "iteration_pressure_2d_kpa": (
                ("exercise", "iteration", *gc),
                p2,
                {**kpa, "long_name": "pressure applied to the 2D model per correction iteration"},
            ),
            "correction_iterations": (
                "exercise",
                np.array([c.iterations for c in corrections], dtype="i4"),
                {"units": "1", "long_name": "FEA re-checks run by the correction step"},
            ),
            "correction_best": (
                "exercise",
                np.array([c.best for c in corrections], dtype="i4"),
                {"units": "1", "long_name": "iteration kept as corrected (fewest joints off target, then least error)"},
            ),
            "correction_reason": (
                "exercise",
                np.array([c.stop_reason for c in corrections], dtype=object),
                {"units": "1", "long_name": "why the correction step stopped"},
            ),
            "corrected_angle_deg": (
                ("exercise", "joint"),
                np.array([b.angle_deg for b in best]),
                {**deg, "long_name": "joint angle in the FEA at the corrected pressures"},
            ),
            "corrected_pressure_kpa": (
                ("exercise", *gc),
                np.array([c.pressures_kpa[c.best] for c in corrections]),
                {**kpa, "long_name": "corrected plan (the plan's surrogate)"},
            ),
            "corrected_pressure_2d_kpa": (
                ("exercise", *gc),
                np.array([c.pressures_2d_kpa[c.best] for c in corrections]),
                {**kpa, "long_name": "corrected pressure applied to the 2D model"},
            ),
            "achieved_corrected": (
                "exercise",
                ok,
                {
                    "units": "1",
                    "long_name": f"reached in the FEA after the correction step (within {tolerance_deg:g} deg, limits held)",
                },
            ),
        },
        coords={"exercise": list(ex), "iteration": np.arange(n_it)},
    )
