"""The correction step of the FEA check: when the FEA misses an exercise's
target, a bounded quasi-Newton inverse on the FEA itself (:mod:`.inverse`):
the reduced-order chain's Jacobian at the plan as the first estimate, Broyden's
update from every FEA solve, the pressures within zero and the plan's limit,
P_CMC tied to P_MCP where the plan ties them, and in the directions the three
angles leave free the planner's objective (least pressure; the planners that
co-pressurise on purpose stay near the plan).  It stops at the tolerance, at the budget of FEA
solves, or where the bounds block progress (naming the chambers): no step changes a pressure, or the chain's
linearised response cannot come near the target anywhere inside the bounds.  An exercise
counts as reached only when the FEA reaches it.

Pressures kPa, angles deg.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.cascade.model import CascadeModel, pressures_table, pressures_vector, solve_equilibrium
from workflow.common.runlog import solved
from workflow.fea_check.check import ExerciseCheck, check_exercise, outcome
from workflow.fea_check.inverse import bounded_broyden, tie_matrix
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


def chain_jacobian(ro: CascadeModel, p8: np.ndarray, p_max: float, step_kpa: float = 5.0) -> np.ndarray:
    """d(joint angles)/d(pressures) (3, 8; deg/kPa) of the reduced-order chain at ``p8``, by central differences
    (one-sided at a bound)."""
    J = np.zeros((3, 8))
    for i in range(8):
        lo, hi = max(p8[i] - step_kpa, 0.0), min(p8[i] + step_kpa, p_max)
        if hi <= lo:
            continue
        a, b = p8.copy(), p8.copy()
        a[i], b[i] = lo, hi
        J[:, i] = (solve_equilibrium(ro, b).joint_angles_deg - solve_equilibrium(ro, a).joint_angles_deg) / (hi - lo)
    return J


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
    out_of_reach: float | None = None,
) -> Correction:
    """The bounded quasi-Newton inverse on the FEA from the plan's check (see the module docstring).

    ``ro``: the reduced-order chain the plan was made with; ``p_plan`` (4, 2)
    its pressures (kPa) and ``predicted_deg`` its angles there; ``first`` the
    FEA check of the plan; ``to_2d``: (4, 2) planned -> (4, 2) applied 2D
    pressures; ``plan_opts``: keywords of :func:`workflow.cascade.plan_exercise` (its ``p_max_kpa`` and
    ``tie_cmc_mcp`` bound and tie the pressures, its ``planner`` sets the objective in the directions the angles
    leave free); ``max_iterations``: FEA solves at most; ``min_change_kpa``: a
    step that changes no pressure by this much means the bounds block progress; ``out_of_reach`` (tolerances;
    None: off): so does a target the linearised response misses by more than this anywhere inside the bounds.
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
    if outcome(first, target, tolerance_deg, limits_nm)[0]:
        cor.stop_reason = "reached by the plan"
        return cor
    if first.result.status != 0:
        cor.stop_reason = "the plan's own FEA check did not converge: no correction attempted"
        return cor
    p_max = float(plan_opts.get("p_max_kpa", 300.0))
    p8 = pressures_vector(np.asarray(p_plan, float).ravel())

    def forward(p: np.ndarray):
        p3 = pressures_table(p)
        p2 = to_2d(p3)
        chk = check_exercise(fea, name, p2, solver, gravity=gravity)
        cor.pressures_kpa.append(p3)
        cor.pressures_2d_kpa.append(p2)
        cor.checks.append(chk)
        cor.predicted_deg.append(solve_equilibrium(ro, p).joint_angles_deg)
        ok = chk.result.status == 0
        log.info(
            "%s correction %d: plan %s kPa (2D %s) -> FEA %s deg (target %s), status %d",
            name,
            len(cor.checks) - 1,
            np.round(p3.ravel(), 1),
            np.round(np.asarray(p2).ravel(), 1),
            np.round(chk.angle_deg, 1),
            target,
            chk.result.status,
            extra=solved(not ok),
        )
        return chk.angle_deg, ok

    tie = tie_matrix(8, [(0, 2), (1, 3)]) if plan_opts.get("tie_cmc_mcp", True) else None
    # in the directions the three angles leave free, the planner's own objective: least pressure, or (the planners
    # that co-pressurise on purpose) stay near the plan's pressures
    z_ref = None
    if plan_opts.get("planner", "least_pressure") != "least_pressure":
        z_ref = np.linalg.lstsq(np.eye(8) if tie is None else tie, np.asarray(p8, float), rcond=None)[0]
    inv = bounded_broyden(
        forward,
        p8,
        first.angle_deg,
        first.result.status == 0,
        target,
        chain_jacobian(ro, p8, p_max),
        lo=0.0,
        hi=p_max,
        tol=float(tolerance_deg),
        budget=int(max_iterations),
        E=tie,
        z_ref=z_ref,
        min_step_kpa=float(min_change_kpa),
        out_of_reach=None if out_of_reach is None else float(out_of_reach),
    )

    # the kept iterate: the safety limits held first, then fewest joints off target (a stalled solve counts 3 more),
    # then least error
    def rank(c: ExerciseCheck):
        return (
            bool(np.any(np.abs(c.max_actuator_moment_nm) > limits_nm)),
            *outcome(c, target, tolerance_deg, limits_nm)[1],
        )

    cor.best = min(range(len(cor.checks)), key=lambda k: rank(cor.checks[k]))
    reached = outcome(cor.checks[cor.best], target, tolerance_deg, limits_nm)[0]
    cor.stop_reason = (
        f"reached after {cor.iterations} correction(s)"
        if reached
        else inv.reason + (" (angles within tolerance, a safety limit exceeded)" if inv.reached else "")
    )
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
