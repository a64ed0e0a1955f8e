"""The chain's calibration against the 2D finger-actuator FEA (rule ``chain_calibration``; the fit is
:mod:`workflow.cascade.calibration`).

Upstream of the plans (no cycle): the FEA runs at two lists of 2D pressure sets fixed in advance, on the calibration
patient's finger under the actuator the config lays on it, each set ramped from the gravity state as the check ramps
an exercise.  The *fit* list (``cascade.calibration.fit_pressures_2d_kpa``) gives the states the chain is fitted to,
the ramp's states at ``path_points`` load factors; the *held-out* list, Table 8's rows mapped to 2D as the check maps
a plan (paper section 3.2, Table 9), judges it and is never fitted.  A solve that stops short gives the states it
reached (at their pressures).  The chain is the one the check compares with (the 2D unit model).
"""

from __future__ import annotations

import logging
import time
from typing import Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.cascade.calibration import ChainCalibration, calibrated, chain_angles, fit_chain
from workflow.cascade.model import CascadeModel
from workflow.common.constants import GROUPS, JOINTS, PRESSURE_NAMES, SOLVER_STATUS
from workflow.common.runlog import solved
from workflow.fea_check.check import check_exercise, gravity_state
from workflow.fea_check.model import PatientFEA

__all__ = ["path_states", "run_chain_calibration"]

log = logging.getLogger(__name__)


def path_states(history: Sequence[Mapping], p8: np.ndarray, points: Sequence[float]) -> tuple[np.ndarray, ...]:
    """The ramp's converged pressure-phase states nearest each load factor of ``points`` (none beyond the last).

    Returns pressures (k, 8) kPa (``lam * p8``), joint angles (k, 3) deg and load factors (k,).
    """
    hist = [h for h in history if h.get("phase") == "pressure" and "joint_angles_deg" in h]
    if not hist:
        return np.zeros((0, 8)), np.zeros((0, 3)), np.zeros(0)
    lam = np.array([h["lam"] for h in hist], float)
    pick = []
    for q in points:
        if q > lam[-1] + 1e-9:
            continue
        i = int(np.argmin(np.abs(lam - q)))
        if i not in pick:
            pick.append(i)
    if lam[-1] < min(points) - 1e-9:  # stopped before the first point: its last state still says something
        pick = [len(lam) - 1]
    pick = sorted(pick)
    P = lam[pick, None] * np.asarray(p8, float)[None, :]
    A = np.array([hist[i]["joint_angles_deg"] for i in pick], float)
    return P, A, lam[pick]


def run_chain_calibration(
    fea: PatientFEA,
    chain: CascadeModel,
    sets: Mapping[str, np.ndarray],
    held_out: Sequence[str],
    *,
    solver: Mapping,
    path_points: Sequence[float] = (0.25, 0.5, 0.75, 1.0),
    gain_bounds: tuple[float, float] = (0.1, 1.5),
    compliance_bounds_rad_per_nm: tuple[float, float] = (-20.0, 20.0),
) -> tuple[xr.Dataset, ChainCalibration]:
    """FEA of every set of ``sets`` ({name: (8,) 2D kPa}), the chain fitted to those not in ``held_out``.

    Returns the dataset (every state: pressures, FEA angles, chain angles before and after; per set: status, load
    factor reached, time) and the calibration.
    """
    t0 = time.perf_counter()
    grav = gravity_state(fea, solver)
    if grav.status != 0:
        raise RuntimeError(f"the calibration finger's gravity state did not converge ({grav.reason}): nothing to fit")
    names = list(sets)
    rows, per_set = [], []
    for k, name in enumerate(names):
        p8 = np.asarray(sets[name], float)
        chk = check_exercise(fea, name, p8.reshape(4, 2), solver, gravity=grav)
        res = chk.result
        P, A, lam = path_states(res.history, p8, path_points)
        role = "held_out" if name in held_out else "fit"
        log.info(
            "%s (%s) %d/%d: %s kPa -> status %d at %.3f, %d states, final angles %s deg, %.1f s",
            name,
            role,
            k + 1,
            len(names),
            np.round(p8, 1),
            res.status,
            res.load_factor,
            len(lam),
            np.round(chk.angle_deg, 2),
            chk.wall_time_s,
            extra=solved(res.status != 0),
        )
        per_set.append((res.status, res.load_factor, chk.wall_time_s, res.newton_iterations))
        for i in range(len(lam)):
            rows.append((name, role, lam[i], P[i], A[i]))
    if not rows:
        raise RuntimeError("no FEA state converged in any calibration set: nothing to fit")
    set_of = np.array([r[0] for r in rows])
    role = np.array([r[1] for r in rows])
    P = np.array([r[3] for r in rows])
    A = np.array([r[4] for r in rows])
    fit = role == "fit"
    if fit.sum() < 2:
        raise RuntimeError(f"{int(fit.sum())} FEA state(s) of the fit list converged: too few to fit the chain")
    before, ok_b = chain_angles(chain, P, A)
    cal = fit_chain(
        chain, P[fit], A[fit], gain_bounds=gain_bounds, compliance_bounds_rad_per_nm=compliance_bounds_rad_per_nm
    )
    after, ok_a = chain_angles(calibrated(chain, cal.gain, cal.compliance_rad_per_nm), P, A)
    log.info(
        "chain fitted (%s, %d evaluations): gains %s, compliances %s rad/N m; RMS over the fit states %.2f -> %.2f deg",
        cal.message,
        cal.evaluations,
        np.round(cal.gain, 3),
        np.round(cal.compliance_rad_per_nm, 3),
        cal.rms_before_deg,
        cal.rms_after_deg,
    )
    err_b, err_a = before - A, after - A
    st = np.array(per_set)
    ds = xr.Dataset(
        {
            "pressure_2d_kpa": (("state", "pressure"), P, {"units": "kPa", "long_name": "2D pressures of the state"}),
            "angle_fea_deg": (("state", "joint"), A, {"units": "degree", "long_name": "joint angle in the FEA"}),
            "angle_chain_before_deg": (
                ("state", "joint"),
                before,
                {
                    "units": "degree",
                    "long_name": "joint angle of the chain before calibration (2D unit; cascade.jam as configured)",
                },
            ),
            "angle_chain_after_deg": (
                ("state", "joint"),
                after,
                {"units": "degree", "long_name": "joint angle of the calibrated chain (2D unit)"},
            ),
            "error_before_deg": (("state", "joint"), err_b, {"units": "degree", "long_name": "chain before - FEA"}),
            "error_after_deg": (("state", "joint"), err_a, {"units": "degree", "long_name": "chain after - FEA"}),
            "chain_converged": (
                ("state", "stage"),
                np.stack([ok_b, ok_a], axis=1),
                {"units": "1", "long_name": "the chain's equilibrium converged"},
            ),
            "set_status": (
                ("set",),
                st[:, 0].astype("i1"),
                {
                    "units": "1",
                    "long_name": "FEA solve status of the set's ramp (0 = full load)",
                    "flag_values": np.array(sorted(SOLVER_STATUS), dtype="i1"),
                    "flag_meanings": " ".join(SOLVER_STATUS[int(v)] for v in sorted(SOLVER_STATUS)),
                },
            ),
            "set_load_factor": (("set",), st[:, 1], {"units": "1", "long_name": "load factor the FEA reached"}),
            "set_wall_time_s": (("set",), st[:, 2], {"units": "s", "long_name": "FEA wall time of the set"}),
            "set_newton_iterations": (
                ("set",),
                st[:, 3].astype("i4"),
                {"units": "1", "long_name": "Newton iterations"},
            ),
            "set_pressure_2d_kpa": (
                ("set", "pressure"),
                np.array([sets[n] for n in names], float),
                {"units": "kPa", "long_name": "the set's 2D pressures at full load"},
            ),
            "set_max_error_before_deg": (
                ("set",),
                np.array([np.nanmax(np.abs(err_b[set_of == n]), initial=np.nan) for n in names]),
                {"units": "degree", "long_name": "largest |chain - FEA| over the set's states, before"},
            ),
            "set_max_error_after_deg": (
                ("set",),
                np.array([np.nanmax(np.abs(err_a[set_of == n]), initial=np.nan) for n in names]),
                {"units": "degree", "long_name": "largest |chain - FEA| over the set's states, after"},
            ),
            "span_gain": (
                ("joint",),
                cal.gain,
                {"units": "1", "long_name": "share of the span's bend that turns the joint"},
            ),
            "span_compliance_rad_per_nm": (
                ("joint",),
                cal.compliance_rad_per_nm,
                {"units": "rad / (N m)", "long_name": "span rotation per span moment beyond the straps' give"},
            ),
        },
        coords={
            "state": np.arange(len(rows)),
            "set_name": ("state", set_of),
            "role": ("state", role),
            "load_factor": ("state", np.array([r[2] for r in rows], float)),
            "set": names,
            "set_role": ("set", ["held_out" if n in held_out else "fit" for n in names]),
            "pressure": list(PRESSURE_NAMES),
            "joint": list(JOINTS),
            "stage": ["before", "after"],
        },
    )
    held = role == "held_out"
    ds.attrs.update(
        {
            "rms_fit_before_deg": cal.rms_before_deg,
            "rms_fit_after_deg": cal.rms_after_deg,
            "rms_held_out_before_deg": float(np.sqrt(np.nanmean(err_b[held] ** 2))) if held.any() else np.nan,
            "rms_held_out_after_deg": float(np.sqrt(np.nanmean(err_a[held] ** 2))) if held.any() else np.nan,
            "max_error_held_out_before_deg": float(np.nanmax(np.abs(err_b[held]), initial=np.nan)),
            "max_error_held_out_after_deg": float(np.nanmax(np.abs(err_a[held]), initial=np.nan)),
            "fit_status": cal.status,
            "fit_message": cal.message,
            "fit_evaluations": cal.evaluations,
            "gravity_droop_deg": np.asarray(grav.joint_angles_deg, float),
            "groups": ", ".join(GROUPS),
            "wall_time_s": round(time.perf_counter() - t0, 1),
        }
    )
    return ds, cal
