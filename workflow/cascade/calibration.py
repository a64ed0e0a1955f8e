"""The reduced-order chain calibrated to the finger-actuator FEA.

The chain (:mod:`workflow.cascade.model`) turns each joint by its span's units' bend less the straps' give.  In the
2D finger-actuator FEA (paper section 3.2) the thick actuator is held to the finger only by contact and two straps,
so part of its bend lifts it off the finger instead of turning the joint, and the flesh under it gives.  Two free
parameters per joint's span stand for that: a gain ``g_X`` (the share of the units' bend that turns the joint) and
a compliance ``c_X`` (rad per N m of span moment, beyond the straps'; positive: the joint lags the units), so that

    theta_X = g_X * sum_units theta_unit(P, m_X) - (c_strap,X + c_X) m_X.

They are fitted by least squares (``scipy.optimize.least_squares``, bounded) to the joint angles of FEA solves at a
list of pressure sets fixed in advance (each ramp's states at a few load factors), with the same unit model the FEA
is made of (the 2D unit), and the fit is judged on a second list held out from it.  Pure functions: no I/O.
Angles deg, pressures kPa, moments N m.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np
from scipy.optimize import least_squares

from workflow.cascade.model import CascadeModel, solve_equilibrium

__all__ = ["ChainCalibration", "calibrated", "chain_angles", "fit_chain"]

#: residual of a point whose chain equilibrium fails (deg): large, finite, so the fit steers away from it
FAILED_DEG = 90.0


@dataclass
class ChainCalibration:
    """Fitted span gains (1) and compliances (rad / N m) per joint, and how the fit went."""

    gain: np.ndarray
    compliance_rad_per_nm: np.ndarray
    rms_before_deg: float
    rms_after_deg: float
    status: int  # scipy's least_squares status (> 0: converged)
    message: str
    evaluations: int


def calibrated(model: CascadeModel, gain: Sequence[float], compliance_rad_per_nm: Sequence[float]) -> CascadeModel:
    """The chain with these span gains and compliances (one value per joint, MCP/PIP/DIP)."""
    return replace(
        model,
        span_gain=np.asarray(gain, float).copy(),
        span_compliance_rad_per_nm=np.asarray(compliance_rad_per_nm, float).copy(),
    )


def chain_angles(
    model: CascadeModel, pressures_kpa: np.ndarray, x0_deg: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Joint angles (n, 3) deg of the chain at each row of ``pressures_kpa`` (n, 8) and whether each converged.

    ``x0_deg`` (n, 3): starting poses (e.g. the FEA's), else straight.
    """
    P = np.atleast_2d(np.asarray(pressures_kpa, float))
    out = np.full((P.shape[0], 3), np.nan)
    ok = np.zeros(P.shape[0], bool)
    for i, p in enumerate(P):
        eq = solve_equilibrium(model, p, x0_deg=None if x0_deg is None else x0_deg[i])
        out[i], ok[i] = eq.joint_angles_deg, eq.converged
    return out, ok


def _residuals(model, P, A, x):
    ang, ok = chain_angles(calibrated(model, x[:3], x[3:]), P, A)
    r = ang - A
    r[~ok] = FAILED_DEG
    return r.ravel()


def fit_chain(
    model: CascadeModel,
    pressures_kpa: np.ndarray,
    angles_fea_deg: np.ndarray,
    *,
    gain_bounds: tuple[float, float] = (0.1, 1.5),
    compliance_bounds_rad_per_nm: tuple[float, float] = (-20.0, 20.0),
) -> ChainCalibration:
    """Span gains and compliances that bring the chain's joint angles to the FEA's at these pressures.

    ``pressures_kpa`` (n, 8) and ``angles_fea_deg`` (n, 3): the FEA's states (the pressures each converged at).
    Least squares over all joints and states, from the paper's chain (g = 1, c = 0), within the bounds.
    """
    P = np.atleast_2d(np.asarray(pressures_kpa, float))
    A = np.atleast_2d(np.asarray(angles_fea_deg, float))
    if P.shape[0] != A.shape[0] or P.shape[1] != 8 or A.shape[1] != 3:
        raise ValueError(f"pressures (n, 8) and angles (n, 3) expected, got {P.shape} and {A.shape}")
    if P.shape[0] < 2:
        raise ValueError(f"{P.shape[0]} FEA state(s): too few to fit six parameters' worth of chain")
    x0 = np.r_[np.ones(3), np.zeros(3)]
    lo = np.r_[np.full(3, gain_bounds[0]), np.full(3, compliance_bounds_rad_per_nm[0])]
    hi = np.r_[np.full(3, gain_bounds[1]), np.full(3, compliance_bounds_rad_per_nm[1])]
    r0 = _residuals(model, P, A, x0)
    # x_scale: a gain step of 0.1 and a compliance step of 1 rad / N m move the angles by similar amounts
    sol = least_squares(
        lambda x: _residuals(model, P, A, x),
        np.clip(x0, lo, hi),
        bounds=(lo, hi),
        x_scale=np.r_[np.full(3, 0.1), np.ones(3)],
    )
    return ChainCalibration(
        gain=sol.x[:3].copy(),
        compliance_rad_per_nm=sol.x[3:].copy(),
        rms_before_deg=float(np.sqrt(np.mean(r0**2))),
        rms_after_deg=float(np.sqrt(np.mean(sol.fun**2))),
        status=int(sol.status),
        message=str(sol.message),
        evaluations=int(sol.nfev),
    )
