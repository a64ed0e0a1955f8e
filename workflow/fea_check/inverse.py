"""Bounded quasi-Newton inverse on an expensive forward model (the FEA check of one exercise).

Unknowns: the chamber pressures p (kPa, the eight of :data:`PRESSURE_NAMES`, or fewer free ones through ``tie``:
p = E z, e.g. the CMC group's pressures equal to the MCP group's).  The forward model maps p to the three joint
angles y(p) (deg) and may fail (a stalled FE solve).  Each iteration solves, within the pressure bounds,

    min_dz  |J E dz - (y* - y)|^2 + w |z + dz - z_ref|^2,   lo <= z + dz <= hi,  |dz|_inf <= max_step

(``scipy.optimize.lsq_linear``): the first term drives the angles to the target, the second, weighted by
``w = regularisation * |J E|_F^2 / n``, keeps the planner's objective in the directions the three angles leave
free (``z_ref = 0``: least pressure; the plan's own pressures: stay near the plan).  J starts as the reduced-order
chain's Jacobian and is corrected by Broyden's update from each forward solve,
J += (dy - J dp) dp^T / dp^T dp.  A failed forward solve halves that step, from the best iterate so far.

It stops when every angle is within the tolerance (reached), when the budget of forward solves is spent, or when the
bounds block progress: the bounded step changes no pressure by ``min_step_kpa`` while the target is missed, or
(``out_of_reach``) the linearised response J, over the whole box and with no step limit, still misses some angle by
more than ``out_of_reach`` tolerances, so that no forward solve inside the bounds is expected to reach the target
(where the first J, the reduced-order chain's, bends more than the FEA, as on the checks measured, the test errs on
the side of trying; the Broyden updates bring J to the FEA's slopes).  The chambers that block are those at a
bound whose pressure the unbounded step would push past it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from scipy.optimize import lsq_linear

from workflow.common.constants import JOINTS, PRESSURE_NAMES

__all__ = ["InverseResult", "bounded_broyden", "tie_matrix"]


@dataclass
class InverseResult:
    """Every iterate of the inverse: iterate 0 is the start (its forward solve given, not counted in the budget)."""

    pressures_kpa: list = field(default_factory=list)  # (n,) per iterate
    angles_deg: list = field(default_factory=list)  # (3,) forward angles per iterate (NaN where it failed)
    ok: list = field(default_factory=list)  # forward solve converged
    best: int = 0
    reached: bool = False
    reason: str = ""
    blocking: list = field(default_factory=list)  # pressures at a bound that stop progress

    @property
    def solves(self) -> int:
        """Forward solves the inverse ran (the start's not counted)."""
        return len(self.pressures_kpa) - 1


def tie_matrix(n: int = 8, ties: Sequence[tuple[int, int]] = ()) -> np.ndarray:
    """E (n, m): p = E z, where each (follower, leader) pair makes p[follower] = p[leader]."""
    follower = {f: l for f, l in ties}
    free = [i for i in range(n) if i not in follower]
    E = np.zeros((n, len(free)))
    for k, i in enumerate(free):
        E[i, k] = 1.0
    for f, lead in follower.items():
        E[f, free.index(lead)] = 1.0
    return E


def _score(err: np.ndarray) -> float:
    return float(np.max(np.abs(err))) if np.all(np.isfinite(err)) else np.inf


def _blocking(J, err, z, lo_z, hi_z, E, names, min_step_kpa) -> tuple[list, list]:
    """The free pressures at a bound that the unbounded least-squares step would push past it: their names (tied
    ones joined by /) and 'name at value kPa' for the stop's reason."""
    free = np.linalg.lstsq(J, err, rcond=None)[0]  # where the unbounded step would go
    at_hi = (z >= hi_z - 1e-9) & (free > min_step_kpa)
    at_lo = (z <= lo_z + 1e-9) & (free < -min_step_kpa)
    cols = np.flatnonzero(at_hi | at_lo)
    blocking = ["/".join(names[int(i)] for i in np.flatnonzero(E[:, c])) for c in cols]
    return blocking, [f"{nm} at {z[c]:g} kPa" for nm, c in zip(blocking, cols)]


def bounded_broyden(
    forward: Callable[[np.ndarray], tuple[np.ndarray, bool]],
    p0: np.ndarray,
    y0: np.ndarray,
    ok0: bool,
    target: np.ndarray,
    J0: np.ndarray,
    *,
    lo: float | np.ndarray,
    hi: float | np.ndarray,
    tol: float,
    budget: int,
    E: np.ndarray | None = None,
    z_ref: np.ndarray | None = None,
    regularisation: float = 1e-3,
    max_step_kpa: float = 100.0,
    min_step_kpa: float = 1.0,
    out_of_reach: float | None = None,
    names: Sequence[str] = PRESSURE_NAMES,
    angle_names: Sequence[str] = JOINTS,
) -> InverseResult:
    """Pressures whose forward angles reach ``target`` within ``tol`` (see the module docstring).

    ``forward(p) -> (angles (3,), converged)``; ``p0`` (n,) the start with its forward result ``y0``, ``ok0``;
    ``J0`` (3, n) the first estimate of dy/dp (deg/kPa); ``lo``/``hi`` bounds on every pressure (kPa);
    ``budget`` forward solves at most; ``E`` (n, m) the tie (default: none); ``z_ref`` (m,) the planner's
    preferred pressures (default 0: least pressure); ``out_of_reach`` (tolerances; None: off) stops before a
    forward solve when the linearised response cannot come that close to the target anywhere inside the bounds.
    """
    p0 = np.asarray(p0, float)
    n = p0.size
    E = np.eye(n) if E is None else np.asarray(E, float)
    m = E.shape[1]
    # a tied group's bounds: the tightest of its members'
    lo_p, hi_p = np.broadcast_to(np.asarray(lo, float), (n,)), np.broadcast_to(np.asarray(hi, float), (n,))
    lo_z = np.array([lo_p[E[:, c] > 0].max() for c in range(m)])
    hi_z = np.array([hi_p[E[:, c] > 0].min() for c in range(m)])
    z = np.linalg.lstsq(E, p0, rcond=None)[0]
    if not np.allclose(E @ z, p0, atol=1e-6) or np.any(z < lo_z - 1e-6) or np.any(z > hi_z + 1e-6):
        raise ValueError("the start's pressures break the tie or the bounds: its angles would not belong to it")
    z_ref = np.zeros(m) if z_ref is None else np.asarray(z_ref, float)
    target = np.asarray(target, float)
    J = np.asarray(J0, float) @ E  # in the free pressures
    res = InverseResult([E @ z], [np.asarray(y0, float)], [bool(ok0)])
    if not ok0:
        res.reason = "the start's forward solve did not converge: no step attempted"
        return res
    best_z, best_y, best_score = z, np.asarray(y0, float), _score(target - y0)
    room = float(max_step_kpa)  # largest change of any pressure in the next step (kPa)
    while True:
        err = target - best_y
        if best_score <= tol:
            res.reached, res.reason = True, f"reached after {res.solves} forward solve(s)"
            break
        if res.solves >= budget:
            res.reason = f"not reached within the budget of {budget} forward solve(s)"
            break
        if out_of_reach is not None:
            # the best the linearised response can do anywhere in the box: a miss of several tolerances there is
            # out of reach of every step inside the bounds, and a forward solve would only confirm it
            miss = err - J @ lsq_linear(J, err, bounds=(lo_z - best_z, hi_z - best_z + 1e-12)).x
            k = int(np.argmax(np.abs(miss)))
            if abs(miss[k]) > out_of_reach * tol:
                res.blocking, where = _blocking(J, err, best_z, lo_z, hi_z, E, names, min_step_kpa)
                res.reason = (
                    f"the bounds block progress: inside them the linearised response still misses {angle_names[k]} "
                    f"by {abs(miss[k]):.1f} deg after {res.solves} forward solve(s)"
                    + (f" ({', '.join(where)})" if where else "")
                )
                break
        w = regularisation * float(np.sum(J * J)) / m
        A = np.vstack([J, np.sqrt(w) * np.eye(m)])
        b = np.concatenate([err, -np.sqrt(w) * (best_z - z_ref)])
        lb = np.maximum(lo_z - best_z, -room)
        ub = np.minimum(hi_z - best_z, room)
        dz = lsq_linear(A, b, bounds=(lb, ub + 1e-12)).x
        if np.max(np.abs(dz)) < min_step_kpa and room < max_step_kpa:
            res.reason = (
                f"the step shrank below {min_step_kpa:g} kPa after {res.solves} forward solve(s) that stalled or "
                "did not improve"
            )
            break
        if np.max(np.abs(dz)) < min_step_kpa:
            res.blocking, where = _blocking(J, err, best_z, lo_z, hi_z, E, names, min_step_kpa)
            res.reason = "the bounds block progress" + (f" ({', '.join(where)})" if where else "")
            break
        z_new = best_z + dz
        y_new, ok = forward(E @ z_new)
        y_new = np.asarray(y_new, float)
        res.pressures_kpa.append(E @ z_new)
        res.angles_deg.append(y_new if ok else np.full(3, np.nan))
        res.ok.append(bool(ok))
        if not ok or not np.all(np.isfinite(y_new)):
            # half the step that failed (not of the box: a step inside the box would come back unchanged)
            room = 0.5 * float(np.max(np.abs(dz)))
            continue
        dy = y_new - best_y
        J = J + np.outer(dy - J @ dz, dz) / float(dz @ dz)
        score = _score(target - y_new)
        if score < best_score:
            best_z, best_y, best_score = z_new, y_new, score
            res.best = len(res.pressures_kpa) - 1
            room = min(float(max_step_kpa), 2 * room)
        else:
            room = 0.5 * float(np.max(np.abs(dz)))
    return res
