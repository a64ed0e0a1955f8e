"""Analytic test doubles of the FE unit response (tests only, never production physics).

They have the symmetries the real unit has: swapping P_T and P_B negates angle and
moment, and P_T = P_B gives zero.
"""

from __future__ import annotations

import numpy as np

from workflow import sweep


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
    shards = [sweep.run_shard(double_solver, shard=i, n_shards=n_shards, p_max_kpa=p_max, n_ratios=n_ratios,
                              n_pressures=n_pressures) for i in range(n_shards)]
    return sweep.merge_shards(shards, n_ratios=n_ratios, n_pressures=n_pressures)
