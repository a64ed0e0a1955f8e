"""FEA check of one planned exercise (paper section 3.2, Fig. 18-21); the whole plan is :mod:`.run`.

Per patient: the whole actuator of the plan (``units_per_group``) strapped to
the planar finger (:mod:`workflow.fea_check.model`), gravity first (one solve,
shared by the exercises), then each exercise's planned pressures ramped from
zero.  A point that does not converge is kept with its last converged load
factor (``load_factor`` < 1, ``status`` > 0) and measured there.

Pressures.  The 2D section is stiffer than the 3D actuator (
paper section 3.2): when the plan was made with the 3D surrogate, each
(P_T, P_B) pair is scaled to the 2D pair of the same ratio and the same free
angle with the 2D-to-3D mapping (:func:`workflow.actuator.mapping.map_pairs`), as the
paper's Table 9 did; pairs with P_T = P_B keep their pressures (no bend either
way), pairs whose 3D angle lies beyond the 2D sweep are capped at its edge
(``mapping_status`` records both).  ``map_pressures: false`` applies the plan's
pressures unchanged.  No applied pressure exceeds the silicone's limit
(``actuator.material.p_limit_kpa``) or, when mapped, the 2D sweep's range
(:mod:`workflow.actuator.pressure_limit`); a pair cut back to it is flagged too.

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
FEA misses, a bounded quasi-Newton inverse on the FEA (:mod:`.correction`):
the chain's Jacobian as the first estimate, Broyden's update from each FEA
solve, at most ``max_iterations`` solves; it stops early when the bounds block
progress (a step changes no pressure by ``min_change_kpa``, or the chain's linearised response misses the target by
more than ``out_of_reach`` tolerances anywhere inside the bounds).  The best
check (fewest joints out of tolerance, then the least total error) is kept
as ``corrected_*``; every iteration's pressures and angles are stored.
"""

from __future__ import annotations

import logging
import time
import tracemalloc
from dataclasses import dataclass, replace
from typing import Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.common.constants import GROUPS, JOINTS
from workflow.common.runlog import solved
from workflow.fea_check.model import PatientFEA
from workflow.fem import cumulative_attempts, first_converged
from workflow.fem.actuator import jam_angle_deg
from workflow.fem.coupled import CoupledResult, solve_coupled

__all__ = ["ExerciseCheck", "outcome", "check_exercise", "gravity_state", "solve_with_restarts", "unit_bends_dataset"]

log = logging.getLogger(__name__)


def solve_with_restarts(
    fea: PatientFEA,
    pressures: Mapping,
    solver: Mapping,
    u_gravity: np.ndarray | None = None,
    contact: Mapping | None = None,
    first_attempt: int = 0,
) -> CoupledResult:
    """``solve_coupled``, and if it stalls, again from the same start with each of ``fea.restarts`` applied over the
    previous ones (contact band mm, solver options); the first full solve, else the one that got furthest.

    ``contact`` (default the setup's) are the contact settings of the first attempt; ``first_attempt`` starts at that
    attempt of the list (1: with the first restart applied) and tries the ones it skipped last, so that a start the
    restart cannot take (a wider band inverting an element at rest, as in the authors' section) still solves.

    From a solved state (``u_gravity``, an equilibrium of ``contact``) every attempt keeps those contact settings and
    varies the solver options only: a band wider than the state's puts the nodes resting inside it deep into the
    penalty at the first step (the authors' section, gravity solved with the configured band: each exercise's restart
    with the wider band inverted an element at once). Attempts that become alike are tried once.
    """

    def solve(contact: dict, opts: dict) -> CoupledResult:
        return solve_coupled(replace(fea.setup, contact=contact), pressures, solver=opts, u_gravity=u_gravity)

    base = fea.setup.contact if contact is None else {**dict(fea.setup.contact or {}), **dict(contact)}
    attempts = cumulative_attempts(base, solver, fea.restarts)
    if u_gravity is not None and contact is not None:
        pinned = [(dict(base), s) for _, s in attempts]
        attempts = [a for i, a in enumerate(pinned) if a not in pinned[:i]]
    k = min(first_attempt, len(attempts) - 1)
    return first_converged(attempts[k:] + attempts[:k], solve, label="finger-actuator solve")[0]


def gravity_state(fea: PatientFEA, solver: Mapping) -> CoupledResult:
    """The finger and actuator under their weight alone (zero pressure); logs its status, droop and cost.

    Starts at attempt ``fea.gravity_first_attempt`` of the restarts: with the configured 0.01 mm band the blocks'
    first corner contact stalled gravity on every mesh and finger measured (at 5-60 % of the weight, 50-140 s lost
    each time), and the first restart, solved from zero again, is what every check then started from.
    """
    grav = solve_with_restarts(fea, {}, solver, first_attempt=fea.gravity_first_attempt)
    log.info(
        "gravity: status %d at load factor %.3f, droop %s deg, %d Newton iterations, %.1f s",
        grav.status,
        grav.load_factor,
        np.round(grav.joint_angles_deg, 2),
        grav.newton_iterations,
        grav.wall_time_s,
        extra=solved(grav.status != 0),
    )
    return grav


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


def outcome(
    check: ExerciseCheck, target_deg: np.ndarray, tolerance_deg: float, limits_nm: np.ndarray
) -> tuple[bool, tuple[int, float], list[str]]:
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
    reasons += [
        f"{JOINTS[j]} moment {check.max_actuator_moment_nm[j]:.3g} N m above the active limit {limits_nm[j]:.3g}"
        for j in np.flatnonzero(over)
    ]
    score = (int(np.sum(off)) + (0 if converged else 3), float(np.nansum(np.abs(err))))
    return converged and not off.any() and not over.any(), score, reasons


def check_exercise(
    fea: PatientFEA, name: str, pressures_kpa: np.ndarray, solver: Mapping, gravity: CoupledResult | None = None
) -> ExerciseCheck:
    """Ramp one exercise's pressures (group, chamber) kPa from the gravity state; never raises for divergence."""
    t0 = time.perf_counter()
    tracemalloc.start()
    p = {g: (float(pressures_kpa[i, 0]), float(pressures_kpa[i, 1])) for i, g in enumerate(GROUPS)}
    # from the gravity state, with the contact band it is an equilibrium of: a narrower band at the start would put
    # nodes that sit inside the wider band deep into the penalty (measured: the first step then inverts an element)
    res = solve_with_restarts(
        fea,
        p,
        solver,
        u_gravity=None if gravity is None else gravity.state,
        contact=None if gravity is None else gravity.contact,
    )
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    if res.unit_bends_deg is not None:
        log.info("%s: %s", name, _unit_bend_summary(res.unit_bends_deg, fea.setup.cm.act))
    W = fea.width_mm
    hist = [h for h in res.history if h.get("phase") == "pressure"] or res.history
    act = (
        np.array(
            [h["spring_moments"] - h["gravity_moments"] for h in hist] or [res.spring_moments - res.gravity_moments]
        )
        * W
        * 1e-3
    )
    straps = np.array([[res.max_strap_force.get(j, np.nan) for j in ("PIP", "DIP")]]) * W
    return ExerciseCheck(
        exercise=name,
        pressures_kpa=np.asarray(pressures_kpa, float),
        result=res,
        angle_deg=res.joint_angles_deg,
        max_actuator_moment_nm=_signed_peak(act),
        actuator_moment_nm=act[-1],
        max_strap_force_n=straps[0],
        peak_memory_mb=peak / 2**20,
        wall_time_s=time.perf_counter() - t0,
    )


def unit_bends_dataset(
    bends_deg: np.ndarray, *, groups: Sequence[str], geometry: Mapping, dims: Sequence[str] = ("exercise",)
) -> xr.Dataset:
    """Each actuator unit's bend (``unit_bend_deg``, ``dims`` then ``unit``, hand end first) beside the angle at which
    its concave side's blocks would meet if rigid (``jam_angle_deg``, :func:`workflow.fem.actuator.jam_angle_deg`);
    the FEA check's (per exercise) and the stand-alone actuators' (per exercise and model)."""
    bends = np.asarray(bends_deg, float)
    return xr.Dataset(
        {
            "unit_bend_deg": (
                (*dims, "unit"),
                bends,
                {
                    "units": "degree",
                    "long_name": "bend of each actuator unit (L_R, gap centre to gap centre), hand end first, flexion "
                    "positive (the FEA check: at the plan's own pressures, before any correction step)",
                },
            ),
            "jam_angle_deg": (
                (),
                jam_angle_deg(geometry),
                {
                    "units": "degree",
                    "long_name": "bend per unit at which neighbouring blocks on the concave side meet if rigid: "
                    "gap / (paper/2 + base layer + block height)",
                },
            ),
        },
        coords={"unit": np.arange(bends.shape[-1]), "unit_group": ("unit", [str(g) for g in groups])},
    )


def _unit_bend_summary(bends_deg: np.ndarray, act) -> str:
    """Each group's range of unit bends against the jam angle, for the log (deg)."""
    groups = np.asarray(act.chamber_group)
    parts = [
        f"{g} {bends_deg[groups == g].min():.1f}-{bends_deg[groups == g].max():.1f}" for g in dict.fromkeys(groups)
    ]
    return f"units bend {', '.join(parts)} deg (concave side's blocks meet at {jam_angle_deg(act.geometry):.2f} deg)"
