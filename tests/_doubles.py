"""Shared test doubles and fixtures' data (tests only, never production physics).

* Analytic doubles of the FE unit response, with the symmetries the real unit
  has: swapping P_T and P_B negates angle and moment, and P_T = P_B gives zero.
* The paper's mean middle finger (Table 2 means and SDs) with linear joint
  springs, for the finger, cascade and FEA-check tests.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from workflow.actuator import sweep
from workflow.cascade import finger as F


def double_angle(pt, pb):
    """Free bending angle per unit, deg: antisymmetric, stiffening with mean pressure."""
    pt, pb = np.asarray(pt, float), np.asarray(pb, float)
    return 12.0 * np.tanh((pt - pb) / 250.0) * (1.0 - 0.2 * (pt + pb) / 600.0)


def double_moment(pt, pb):
    """Blocked moment per unit, N m: antisymmetric."""
    pt, pb = np.asarray(pt, float), np.asarray(pb, float)
    return 2.0e-3 * (pt - pb) * (1.0 + 0.1 * (pt + pb) / 600.0)


def double_solver(direction, scales):
    """A ray solver in the sweep's tuple form: every sample converged."""
    pt, pb = scales * direction[0], scales * direction[1]
    n = scales.size
    return (pt, pb, double_angle(pt, pb), double_moment(pt, pb), np.zeros(n, int), np.full(n, 3), np.full(n, 0.01))


def double_response(n_ratios=6, n_pressures=8, p_max=300.0, n_shards=2):
    """A merged sweep of the double (the response_{2d,3d}.nc layout)."""
    shards = [
        sweep.run_shard(
            double_solver, shard=i, n_shards=n_shards, p_max_kpa=p_max, n_ratios=n_ratios, n_pressures=n_pressures
        )
        for i in range(n_shards)
    ]
    return sweep.merge_shards(shards, n_ratios=n_ratios, n_pressures=n_pressures)


# --- The mean middle finger (Table 2) ---------------------------------------------------------------
#: The authors' section points of the mean finger (carried into resources/ with their citation).
SECTION = Path(__file__).resolve().parents[1] / "resources" / "finger_section_points_mean_finger.csv"

# Table 2 means and SDs (mm), the paper's mean middle finger.
MEASURES = {
    "D3DP": (11.8, 1.52),
    "D3DIP": (12.7, 1.42),
    "D3MP": (14.1, 1.71),
    "D3PIP": (16.6, 1.66),
    "D3PP": (17.3, 2.00),
    "D3MCP": (25.5, 2.85),
    "B3DP": (16.5, 1.83),
    "B3DIP": (16.8, 1.62),
    "B3MP": (17.6, 1.99),
    "B3PIP": (19.4, 2.02),
    "B3PP": (18.6, 2.08),
    "L3DP": (26.5, 2.47),
    "L3MP": (30.6, 2.74),
    "L3PP": (50.6, 3.79),
    "L3MC": (76.8, 6.69),
}
DENSITIES = {"flesh_proximal": 4000.0, "flesh_middle": 1500.0, "flesh_distal": 2000.0, "bone": 2000.0}


def measures():
    return {k: {"mean": m, "sd": s} for k, (m, s) in MEASURES.items()}


def linear_springs(k=(0.058 / 90, 0.0285 / 100, 0.00324 / 80)):
    return [F.JointSpring.linear(v) for v in k]


def mean_finger(**kw):
    dims = F.patient_dimensions_mm(measures(), {"depth": 0, "length": 0, "breadth": 0})
    kw.setdefault("section_points", SECTION)
    return F.build_finger(dims, kw.pop("springs", linear_springs()), kw.pop("densities", DENSITIES), **kw)
