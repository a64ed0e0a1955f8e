"""The patients against the design region: the response surfaces' scaled
prediction variance at each patient's coded levels (a quadratic model on the
CCD) and which exercises each plan reaches.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np
import xarray as xr

__all__ = ["quadratic_terms", "scaled_prediction_variance", "design_range_table", "feasibility_table"]


# ---------------------------------------------------------------------------
# 5. Response surfaces outside the design sphere; exercises with no feasible pressures
# ---------------------------------------------------------------------------
def quadratic_terms(x: np.ndarray) -> np.ndarray:
    """Columns of the ten-term quadratic model (1, x_i, x_i^2, x_i x_j) of coded levels x (n, 3)."""
    x = np.atleast_2d(np.asarray(x, float))
    d, le, b = x[:, 0], x[:, 1], x[:, 2]
    return np.column_stack([np.ones(len(x)), d, le, b, d**2, le**2, b**2, d * le, d * b, le * b])


def scaled_prediction_variance(design: np.ndarray, x: np.ndarray) -> np.ndarray:
    """N f(x)^T (F^T F)^-1 f(x) of the quadratic model on ``design`` (N runs x 3, coded) at ``x`` (m x 3).

    The variance of a response-surface prediction at x in units of sigma^2/N:
    a property of the design alone, small inside the design sphere and growing
    roughly as |x|^4 outside it.
    """
    F = quadratic_terms(design)
    M = np.linalg.pinv(F.T @ F)
    f = quadratic_terms(x)
    return F.shape[0] * np.einsum("ij,jk,ik->i", f, M, f)


def design_range_table(loads: Mapping[str, xr.Dataset], design: np.ndarray | None = None) -> xr.Dataset:
    """Per patient: coded levels, ||x||, max |x_i|, ``in_design_range`` and (with ``design``) the scaled
    prediction variance of the quadratic model at the patient's levels."""
    names = list(loads)
    dims = ["depth", "length", "breadth"]
    x = np.array([[float(loads[p]["x"].sel(dimension=d)) for d in dims] for p in names]).reshape(len(names), 3)
    norm = np.linalg.norm(x, axis=1)
    mx = np.max(np.abs(x), axis=1)
    data = {
        "x": (("patient", "dimension"), x, {"units": "1", "long_name": "coded levels"}),
        "coded_norm": ("patient", norm, {"units": "1", "long_name": "||x||_2"}),
        "max_abs_coded": ("patient", mx, {"units": "1", "long_name": "max |x_i|"}),
        "in_design_range": (
            "patient",
            np.array([bool(loads[p]["in_design_range"]) for p in names]),
            {"long_name": "||x|| <= 1 and every |x_i| <= 1 (joint_loads.nc)"},
        ),
    }
    if design is not None:
        data["prediction_variance"] = (
            "patient",
            scaled_prediction_variance(design, x),
            {"units": "1", "long_name": "scaled prediction variance N Var(y_hat)/sigma^2 of the quadratic CCD model"},
        )
    return xr.Dataset(data, coords={"patient": names, "dimension": dims})


def feasibility_table(plans: Mapping[str, xr.Dataset]) -> xr.Dataset:
    """Per patient and exercise: ``achieved`` and ``reason`` from ``cascade_plan.nc``."""
    names = list(plans)
    ex = list(dict.fromkeys(e for p in names for e in plans[p]["exercise"].values.tolist()))
    ach = np.zeros((len(names), len(ex)), bool)
    why = np.full((len(names), len(ex)), "not planned", dtype=object)
    for i, p in enumerate(names):
        for e in plans[p]["exercise"].values:
            j = ex.index(e)
            ach[i, j] = bool(plans[p]["achieved"].sel(exercise=e))
            why[i, j] = str(plans[p]["reason"].sel(exercise=e).values)
    return xr.Dataset(
        {
            "achieved": (("patient", "exercise"), ach, {"long_name": "exercise reached by the plan"}),
            "reason": (("patient", "exercise"), why, {"long_name": "why not (empty if reached)"}),
        },
        coords={"patient": names, "exercise": ex},
    )
