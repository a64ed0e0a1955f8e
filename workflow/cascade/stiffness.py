"""Stiffness of the actuator's spans and of the load they hold, for the stiffness planner (`workflow.cascade.planning`).

A joint's span is the units that take up its rotation (`workflow.cascade.model.SPANS`), in series. The load is the
moment the actuator must supply at a pose (joint spring less gravity); its stiffness is how much more it must supply
per degree. Angles deg, moments N m, pressures kPa.
"""

from __future__ import annotations

import numpy as np

from workflow.cascade.model import CascadeModel, _required_moments, _span_compliance

__all__ = ["span_stiffness_nm_per_deg", "load_stiffness_nm_per_deg"]


def span_stiffness_nm_per_deg(model, joint: int, p8: np.ndarray, m_nm: float = 0.0) -> np.ndarray:
    """Rotational stiffness of a joint's span (N m per degree of joint rotation) at pressures ``p8`` (n, 8) kPa: its
    units in series and the span's give, 1 / (g sum_g n_g / k_g + c), with k_g the unit model's stiffness
    (``stiffness_nm_per_deg``; with the chain's jam model divided by the slope of its bend at the unit's angle under
    the span moment ``m_nm`` (N m): a unit past its jam angle is that much stiffer), g the span's gain and c its give
    in degrees per N m (the straps' and the calibrated rest, :mod:`workflow.cascade.model`)."""
    unit = model.unit
    if not hasattr(unit, "stiffness_nm_per_deg"):
        raise TypeError(f"{type(unit).__name__} has no stiffness_nm_per_deg: the stiffness planner needs one")
    counts = model.span_counts()[joint]
    p8 = np.atleast_2d(np.asarray(p8, float))
    compliance = np.zeros(p8.shape[0])
    for g in range(4):
        if counts[g]:
            pt, pb = p8[:, 2 * g], p8[:, 2 * g + 1]
            k = np.asarray(unit.stiffness_nm_per_deg(pt, pb), float)
            if model.jam is not None:  # a jammed unit follows a tenth of its moment's change: stiffer by that much
                k = k / model.jam.bend_slope(unit.angle_deg(pt, pb, float(m_nm)), model.group_end_share[g])
            compliance = compliance + counts[g] / k
    compliance = float(model.span_gain[joint]) * compliance + np.rad2deg(_span_compliance(model)[joint])
    with np.errstate(divide="ignore"):
        return np.where(compliance > 0, 1.0 / compliance, np.inf)


def load_stiffness_nm_per_deg(model: CascadeModel, angles_deg: np.ndarray, step_deg: float = 0.5) -> np.ndarray:
    """|d m*_X / d theta_X| per joint (N m per degree) at the pose: how much more the actuator must give per degree."""
    out = np.zeros(3)
    for j in range(3):
        up, dn = np.array(angles_deg, float), np.array(angles_deg, float)
        up[j] += step_deg
        dn[j] -= step_deg
        out[j] = abs(_required_moments(model, up)[0][j] - _required_moments(model, dn)[0][j]) / (2 * step_deg)
    return out
