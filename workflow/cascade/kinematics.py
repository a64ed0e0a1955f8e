"""The shape of a solved cascade: the free shape under pressure, the backbone
polyline of the units, and the moment balance at each joint of a pose.

Angles deg, lengths m, moments N m.
"""

from __future__ import annotations

import numpy as np

from workflow.cascade.finger import gravity_moments_nm
from workflow.cascade.model import (
    CascadeModel,
    Equilibrium,
    _span_angles_deg,
    actuator_gravity_moments_nm,
    pressures_table,
    pressures_vector,
)

__all__ = ["free_shape", "backbone_polyline", "moment_residuals"]


def free_shape(model: CascadeModel, pressures_kpa, m_ext_nm: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Stand-alone actuator (no finger, no gravity): unit angles (deg, per unit)
    and the backbone polyline (m) from the hand end, under a uniform moment."""
    pt = pressures_table(pressures_vector(pressures_kpa))[model.unit_group]
    th = model.bends_deg(model.unit.angle_deg(pt[:, 0], pt[:, 1], np.full(model.n_units, m_ext_nm)), model.end_weights)
    return th, backbone_polyline(model, th)


def backbone_polyline(
    model: CascadeModel, unit_angles_deg: np.ndarray, start=None, heading_rad: float = 0.0
) -> np.ndarray:
    """Backbone nodes (N+1, 2) in m: each unit an arc of length L_R bent by its angle."""
    th = np.deg2rad(np.asarray(unit_angles_deg, float))
    L = model.unit_length_m
    p = np.array([model.base_x_m, model.unit_ref[0, 1]]) if start is None else np.asarray(start, float)
    nodes = [p]
    psi = heading_rad
    for t in th:
        # Chord of an arc of length L turning by -t (flexion turns clockwise).
        chord = L if abs(t) < 1e-9 else L * np.sin(t / 2) / (t / 2)
        mid = psi - t / 2
        p = p + chord * np.array([np.cos(mid), np.sin(mid)])
        psi -= t
        nodes.append(p)
    return np.array(nodes)


def moment_residuals(model: CascadeModel, eq: Equilibrium) -> dict[str, np.ndarray]:
    """Out-of-balance of an equilibrium: joint moments (N m) and span bends (deg).

    ``joint_nm``: spring - finger gravity - actuator gravity - actuator moment,
    recomputed from the pose; ``span_deg``: the unit model's bend of each span
    under the carried moment (called directly) minus the joint angle.
    """
    f = model.finger
    th = eq.joint_angles_deg
    spring = np.array([float(sp.moment_nm(t)) for sp, t in zip(f.springs, th)])
    joint = spring - gravity_moments_nm(f, th) - actuator_gravity_moments_nm(model, th) - eq.actuator_moments_nm
    _, span = _span_angles_deg(model, eq.pressures_kpa, eq.actuator_moments_nm)
    return {"joint_nm": joint, "span_deg": span - th}
