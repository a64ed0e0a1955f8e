"""Planning the pressures of each exercise on the reduced-order cascade.

Per exercise, the moments the actuator must supply at the target pose follow
directly (``m*_X = spring_X(theta*_X) - G_X(theta*)``, the paper's Table 7
logic).  Per span, a grid search (no gradients, so piecewise-constant
surrogates such as KNN work) finds the pressures of least sum of squares whose
bend under ``m*_X`` lies within ``tol - margin`` of the target; the coupled
forward model then checks the pose, the angle tolerance and the active safety
limits (``|m_X| <= limit_X``), halving the span goal when the pose drifts out.
``P_CMC`` may be tied to ``P_MCP`` as in all the paper's plans.

Which of the pressures that bend a span within the goal a plan takes is the planner's choice (``planner``):

* ``least_pressure``: the least sum of squares;
* ``stiffness``: the least sum of squares among those whose span holds the pose with a stiffness margin s: the span's
  rotational stiffness (its units in series, k_span = 1 / sum_g n_g / k_g(P), N m per degree of span bend, from the
  unit model) at least s times the load's, |d m*_X / d theta_X| (the joint spring less gravity, by central
  differences at the target pose). Where no pressures reach that, the stiffest of those that bend the span right.
  Co-pressurising both chambers of a group raises k_g at the same bend, which the least-pressure rule never does.
* ``paper``: the paper's own rule (section 3.1, Tables 7 -> 8) on our unit targets: per span, every unit bends by
  the same angle under the span's moment; the pressures start where the unit's *free* angle is that angle on the
  top-pressure curve of the limit (Fig. 11 read at 300 kPa), and the top pressure alone then moves until the unit
  gives that angle under the moment (the bottom held), see `_span_plan_paper`.  It co-pressurises every group that
  is to stay (nearly) straight, as Tables 8 and 10 do.  The config's default (``cascade.planner``).

Pressures kPa, angles deg, moments N m.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from workflow.cascade.model import (
    SPANS,
    CascadeModel,
    Equilibrium,
    _required_moments,
    _span_angles_deg,
    _span_compliance,
    group_bends_deg,
    solve_equilibrium,
)
from workflow.cascade.stiffness import load_stiffness_nm_per_deg, span_stiffness_nm_per_deg
from workflow.common.constants import CASCADE_EQUILIBRIUM_STATUS, GROUPS, JOINTS, PRESSURE_NAMES

__all__ = ["PLANNERS", "Plan", "plan_exercise", "plan_patient"]

#: The planners of the module docstring.
PLANNERS = ("least_pressure", "stiffness", "paper")


# --------------------------------------------------------------------------
# Planning
# --------------------------------------------------------------------------
@dataclass
class Plan:
    """Planned pressures for one exercise and what the forward model predicts.

    ``required_moments_nm``: the span moments that hold the target pose (the
    Table-7-like unit moment targets); ``target_unit_angles_deg``: per group,
    the unit angle at the target pose under the planned pressures.
    """

    exercise: str
    target_deg: np.ndarray
    pressures_kpa: np.ndarray
    equilibrium: Equilibrium
    achieved: bool
    reason: str
    required_moments_nm: np.ndarray
    target_unit_angles_deg: np.ndarray


def _span_setup(model, joint: int, m_req: float, target: float, tie: bool):
    """The pressures a span's plan sets and its bend error as a function of them.

    Returns ``idx`` (indices into the eight pressures the span's groups own; with ``tie`` the MCP pair drives CMC
    too), ``full`` (P (n, k) kPa -> the eight pressures (n, 8)) and ``bend`` (P (n, k) -> the span's bend minus
    ``target`` under the span moment ``m_req``, deg, the straps' compliance included).
    """
    groups = [GROUPS.index(g) for g in SPANS[JOINTS[joint]]]
    idx = [2 * g + c for g in groups for c in (0, 1)]
    if tie and joint == 0:
        idx = [2, 3]
    counts = model.span_counts()[joint]
    give = np.rad2deg(_span_compliance(model)[joint] * m_req)
    gain = float(model.span_gain[joint])

    def full(P):
        p8 = np.zeros((P.shape[0], 8))
        p8[:, idx] = P
        if tie and joint == 0:
            p8[:, 0:2] = p8[:, 2:4]
        return p8

    def bend(P):
        p8 = full(P)
        out = np.full(P.shape[0], -give - target)
        for g in range(4):
            if counts[g]:
                th = group_bends_deg(model, g, p8[:, 2 * g], p8[:, 2 * g + 1], np.full(P.shape[0], m_req))
                out += gain * counts[g] * np.asarray(th, float)
        return out

    return idx, full, bend


def _span_plan(
    model,
    joint: int,
    m_req: float,
    target: float,
    goal: float,
    p_max: float,
    tie: bool,
    n_coarse: int = 61,
    k_required: float | None = None,
) -> tuple[dict[int, float], float]:
    """Least-squares pressures of one span by grid search (no gradients, so a
    piecewise-constant surrogate such as KNN works too).

    Returns {index into the eight pressures: kPa} and the bend error (deg) at
    the target pose.  Feasible: the least sum of squares with
    ``|bend - target| <= goal`` (and, with ``k_required`` in N m/deg, a span
    stiffness of at least that, else the stiffest feasible); otherwise the
    pressures closest to the target.
    """
    idx, full, bend = _span_setup(model, joint, m_req, target, tie)
    k = len(idx)

    def search(lo, hi, n):
        axes = [np.linspace(l, h, n) for l, h in zip(lo, hi)]
        P = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, k)
        e = bend(P)
        ok = np.abs(e) <= goal
        if np.any(ok) and k_required is not None:
            ks = span_stiffness_nm_per_deg(model, joint, full(P[ok]), m_req)
            stiff = ks >= k_required
            if np.any(stiff):
                cand = np.flatnonzero(ok)[stiff]
                i = cand[np.argmin(np.sum(P[cand] ** 2, axis=1))]
            else:
                i = np.flatnonzero(ok)[np.argmax(ks)]
            return P[i], float(e[i]), True
        if np.any(ok):
            i = np.flatnonzero(ok)[np.argmin(np.sum(P[ok] ** 2, axis=1))]
            return P[i], float(e[i]), True
        i = int(np.lexsort((np.sum(P**2, axis=1), np.round(np.abs(e), 9)))[0])
        return P[i], float(e[i]), False

    n = n_coarse if k == 2 else max(9, int(round(n_coarse**0.5)))
    step = p_max / (n - 1)
    P, e, feas = search(np.zeros(k), np.full(k, p_max), n)
    for _ in range(3):  # refine around the best point
        lo, hi = np.maximum(P - step, 0.0), np.minimum(P + step, p_max)
        n_f = 21 if k == 2 else 7
        P, e, feas = search(lo, hi, n_f)
        step = step * 2 / (n_f - 1)
    return dict(zip(idx, P)), e


def _nearest_zero(f: np.ndarray, x: np.ndarray, x0: float) -> tuple[float, bool]:
    """The zero of samples ``f`` on the grid ``x`` nearest ``x0`` (linear between the samples) and True; where ``f``
    has none, the sample of least ``|f|`` and False.

    Samples within round-off of zero count as zeros (the free angle on the diagonal P_T = P_B is 0 only to 1e-16).
    """
    s = np.where(np.abs(f) <= 1e-9 * max(float(np.max(np.abs(f))), 1e-300), 0.0, np.sign(f))
    zeros = list(x[s == 0])
    i = np.flatnonzero(s[:-1] * s[1:] < 0)
    zeros += list(x[i] - f[i] * (x[i + 1] - x[i]) / (f[i + 1] - f[i]))
    if not zeros:
        return float(x[np.argmin(np.abs(f))]), False
    zeros = np.asarray(zeros, float)
    return float(zeros[np.argmin(np.abs(zeros - x0))]), True


def _span_plan_paper(
    model, joint: int, m_req: float, target: float, p_max: float, tie: bool, n: int = 601
) -> tuple[dict[int, float], float]:
    """The paper's rule for one span (section 3.1, Figs. 11a-b, Tables 7 -> 8), applied to our unit targets.

    Every unit of the span gets the same pressures and the same targets: the angle theta_u that makes the span's
    bend the target under the span moment ``m_req`` (N m per unit, the Table 7 analogue), i.e. the target less the
    span's give, over the span's gain times its units (1 and the straps' give in the paper's chain).  (a) On the
    unit's top-pressure curve at the limit (Fig. 11 at 300 kPa), the pressure ratio whose *free* angle is theta_u:
    P_T = p_max and P_B from theta_f(P_T, P_B) = theta_u (mirrored, P_B = p_max, for theta_u < 0); where no ratio
    gives it, the one that comes closest (P_B = 0 where even the top alone bends too little).  (b) The moment the
    unit must deliver is then added by moving the top pressure alone, the bottom held (the paper: along the top
    pressure's axis, the stiffness kept): the P_T nearest (a) with theta(P_T, P_B, m_req) = theta_u.  Where no P_T in
    [0, p_max] does, the bottom pressure moves instead, the top held; where neither, the pressures on those two lines
    that come closest, and the span misses its target.  Returns {index into the eight pressures: kPa} and the span's
    bend error (deg).
    """
    idx, _, bend = _span_setup(model, joint, m_req, target, tie)
    n_units = int(model.span_counts()[joint].sum())
    if n_units == 0:
        raise ValueError(f"the {JOINTS[joint]} span has no units: nothing to plan")
    give = np.rad2deg(_span_compliance(model)[joint] * m_req)
    theta_u = (target + give) / (float(model.span_gain[joint]) * n_units)
    # the mean bend of the span's units, all at the same pressures: linear in the free-end weight, so one unit-model
    # evaluation at the span's mean weight
    share = float(model.span_counts()[joint] @ model.group_end_share) / n_units

    def unit_bend(pt, pb, m):
        return model.bends_deg(model.unit.angle_deg(pt, pb, m), share)

    x = np.linspace(0.0, p_max, n)
    at_max = np.full(n, p_max)
    # (a) the free angle's point on the limit's top-pressure curve
    if theta_u >= 0:
        pt, (pb, _) = p_max, _nearest_zero(np.asarray(unit_bend(at_max, x, 0.0), float) - theta_u, x, p_max)
    else:
        (pt, _), pb = _nearest_zero(np.asarray(unit_bend(x, at_max, 0.0), float) - theta_u, x, p_max), p_max
    # (b) the moment: the top moves, the bottom held; else the bottom moves, the top held; else the closest of both

    def pair_of(p):
        return np.tile(np.asarray(p, float), len(idx) // 2)[None, :]

    m = np.full(n, m_req)
    t, ok_t = _nearest_zero(np.asarray(unit_bend(x, np.full(n, pb), m), float) - theta_u, x, pt)
    if ok_t:
        pt_pb = (t, pb)
    else:
        b, ok_b = _nearest_zero(np.asarray(unit_bend(np.full(n, pt), x, m), float) - theta_u, x, pb)
        cands = [(pt, b)] if ok_b else [(pt, pb), (t, pb), (pt, b)]
        pt_pb = min(cands, key=lambda c: abs(float(bend(pair_of(c))[0])))
    P = pair_of(pt_pb)
    return dict(zip(idx, P[0])), float(bend(P)[0])


def plan_exercise(
    model: CascadeModel,
    target_deg: Sequence[float],
    *,
    exercise: str = "",
    tol_deg: float = 5.0,
    active_limits_nm: Sequence[float] | None = None,
    p_max_kpa: float = 300.0,
    tie_cmc_mcp: bool = True,
    margin_deg: float = 0.25,
    max_rounds: int = 5,
    planner: str = "least_pressure",
    stiffness_margin: float = 1.0,
) -> Plan:
    """Pressures for one exercise (see the module docstring).

    Per span, the pressures of least sum of squares whose bend under the
    target-pose moment is within ``tol - margin`` of the target; then the
    coupled forward model checks the pose.  If a joint lands outside the
    tolerance (the pose, not the target, sets the moments), the plan is
    repeated -- with the moments of the reached pose for spans that cannot
    reach their target, else with half the span goal -- at most ``max_rounds``
    times, and the best round is kept.  ``planner`` and ``stiffness_margin``:
    see the module docstring.  Angles deg, moments N m, pressures kPa.
    """
    if planner not in PLANNERS:
        raise ValueError(f"planner {planner!r}: one of {PLANNERS}")
    target = np.asarray(target_deg, float)
    limits = None if active_limits_nm is None else np.abs(np.asarray(active_limits_nm, float))
    m_req, *_ = _required_moments(model, target)
    goal = tol_deg - margin_deg
    # Pose at which the span moments are evaluated: the target, except for
    # joints whose span cannot reach it -- those stay where the forward model
    # puts them, so the other spans plan for the moments they will really see.
    theta_eval = target.copy()
    best = None
    k_req = [None] * 3
    if planner == "stiffness":
        k_req = list(stiffness_margin * load_stiffness_nm_per_deg(model, target))
    for _ in range(max_rounds):
        m_eval, *_ = _required_moments(model, theta_eval)
        p8 = np.zeros(8)
        span_err = np.zeros(3)
        for j in range(3):
            if planner == "paper":
                sol, span_err[j] = _span_plan_paper(model, j, m_eval[j], target[j], p_max_kpa, tie_cmc_mcp)
            else:
                sol, span_err[j] = _span_plan(
                    model, j, m_eval[j], target[j], goal, p_max_kpa, tie_cmc_mcp, k_required=k_req[j]
                )
            for i, v in sol.items():
                p8[i] = v
        if tie_cmc_mcp:
            p8[0:2] = p8[2:4]
        eq = solve_equilibrium(model, p8, x0_deg=theta_eval)
        e = np.abs(eq.joint_angles_deg - target) if eq.converged else np.full(3, np.inf)
        score = (int(np.sum(e > tol_deg)), float(np.sum(e)))
        if best is None or score < best[2]:
            best = (p8, eq, score)
        if score[0] == 0 or not eq.converged:
            break
        unreachable = np.abs(span_err) > goal
        if np.any(unreachable):
            new_eval = np.where(unreachable, eq.joint_angles_deg, target)
            if np.max(np.abs(new_eval - theta_eval)) < 0.1:
                break
            theta_eval = new_eval
        elif planner == "paper":  # its spans hit their bends exactly: a smaller goal changes nothing
            break
        else:
            goal *= 0.5
    p8, eq, _ = best
    err = eq.joint_angles_deg - target
    reasons = []
    if not eq.converged:
        reasons.append(f"forward model did not converge ({CASCADE_EQUILIBRIUM_STATUS[eq.status]})")
    for j in np.flatnonzero(np.abs(err) > tol_deg):
        groups = SPANS[JOINTS[j]]
        at_bound = [
            PRESSURE_NAMES[2 * GROUPS.index(g) + c]
            for g in groups
            for c in (0, 1)
            if p8[2 * GROUPS.index(g) + c] >= p_max_kpa * (1 - 1e-6)
        ]
        reasons.append(
            f"{JOINTS[j]} off target by {err[j]:+.1f} deg (tolerance {tol_deg:g} deg; "
            f"needs {m_req[j]:.3g} N m over {'+'.join('LA_' + g for g in groups)})"
            + (f", {', '.join(at_bound)} at the {p_max_kpa:g} kPa limit" if at_bound else "")
        )
    if limits is not None:
        for j in np.flatnonzero(np.abs(eq.actuator_moments_nm) > limits):
            reasons.append(
                f"active safety limit exceeded at {JOINTS[j]} ({eq.actuator_moments_nm[j]:.3g} vs {limits[j]:.3g} N m)"
            )
    unit_target, _ = _span_angles_deg(model, p8, m_req)
    return Plan(
        exercise=exercise,
        target_deg=target,
        pressures_kpa=p8,
        equilibrium=eq,
        achieved=not reasons,
        reason="; ".join(reasons),
        required_moments_nm=m_req,
        target_unit_angles_deg=unit_target,
    )


def plan_patient(model: CascadeModel, targets: Mapping[str, Sequence[float]], **kw) -> list[Plan]:
    """:func:`plan_exercise` for every exercise of ``targets`` ({name: (MCP, PIP, DIP) deg})."""
    return [plan_exercise(model, t, exercise=name, **kw) for name, t in targets.items()]
