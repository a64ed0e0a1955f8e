"""2D -> 3D pressure mapping (paper section 3.2, Fig. 17).

For a 3D pressure pair P = (P_T, P_B) with 3D free angle theta_3D(P), the 2D pair
is s * P, where the scale s > 0 solves

    theta_2D(s P_T, s P_B) = theta_3D(P_T, P_B),

so the ratio P_B/P_T is kept (this also works when P_T = 0).  s is found by
bracketing: theta_2D is evaluated on a grid of s from 0 to the edge of the 2D
sweep (s_max = p_max_2d / max(P_T, P_B)), the first sign change of the
mismatch is refined with Brent's method, so the smallest such s is returned.
On a piecewise-constant surrogate (KNN) the root is where the surrogate's
mismatch changes sign, i.e. within one step of the KNN's staircase.

No answer, with a reason, when
* P_T = P_B: theta_3D = 0 and every s fits (``equal_pressures``);
* the 3D angle is not reached before the 2D grid ends (``outside_2d_grid``):
  the 2D surrogate would only extrapolate beyond it.
A 3D pair beyond the 3D sweep is mapped but flagged (``in_3d_grid`` false).

Under load (``m_ext_nm``, beyond the paper). The free-angle map matches the two units with nothing attached; in an
actuator each unit bends against the moment its neighbours and the finger put on it, and at the mapped pressures the
2D unit can be much weaker than the 3D one. With the moment M a unit is expected to carry, the same scale search
matches the angles under that moment, theta_2D(s P, M) = theta_3D(P, M) (the unit model's spring,
`workflow.actuator.unit_model`); the callables then take (P_T, P_B, M). M = 0 is the free-angle map.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd
import xarray as xr
from scipy.optimize import brentq

from workflow.common.constants import CHAMBERS, GROUPS, MAPPING_STATUS

__all__ = ["map_pairs", "read_planned_pressures", "read_unit_moments", "mapping_dataset"]

_REASONS = {
    0: "",
    1: "P_T = P_B: zero 3D angle, no unique scale",
    2: "3D angle not reached within the 2D sweep's pressure range",
}

ArrayFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


def map_pairs(
    p_top_3d_kpa,
    p_bottom_3d_kpa,
    angle_3d: ArrayFn,
    angle_2d: ArrayFn,
    *,
    p_max_2d_kpa: float,
    p_max_3d_kpa: float = np.inf,
    n_grid: int = 201,
    xtol: float = 1e-9,
    equal_tol_kpa: float = 1e-6,
    m_ext_nm=None,
) -> dict[str, np.ndarray]:
    """Map 3D pressure pairs (kPa, any matching shapes) to 2D pairs of the same ratio and angle.

    ``angle_3d`` and ``angle_2d`` are vectorised callables (P_T, P_B) -> free
    angle per unit (deg), e.g. fitted surrogates' ``angle_deg``; with ``m_ext_nm``
    (N m per unit, broadcast to the pairs) callables (P_T, P_B, M) -> angle under
    that end moment, e.g. `UnitModel.angle_deg`, and the angles are matched under
    it.  Returns arrays
    of the input shape: ``scale``, ``p_top_2d_kpa``, ``p_bottom_2d_kpa``,
    ``angle_3d_deg``, ``angle_2d_deg`` (2D angle at the mapped pair), ``status``
    (`MAPPING_STATUS`) and ``in_3d_grid``.
    """
    pt, pb = np.broadcast_arrays(np.asarray(p_top_3d_kpa, float), np.asarray(p_bottom_3d_kpa, float))
    shape = pt.shape
    pt, pb = pt.ravel(), pb.ravel()
    loaded = m_ext_nm is not None
    m = np.broadcast_to(np.asarray(m_ext_nm if loaded else 0.0, float), shape).ravel()

    def angle_2d_at(i):
        """The 2D angle as a function of (P_T, P_B) for pair i (under its moment when loaded)."""
        return (lambda t, b: angle_2d(t, b, m[i])) if loaded else angle_2d

    th3 = np.asarray(angle_3d(pt, pb, m) if loaded else angle_3d(pt, pb), float).ravel()
    scale = np.full(pt.size, np.nan)
    status = np.zeros(pt.size, dtype=np.int32)
    equal = np.abs(pt - pb) <= equal_tol_kpa
    status[equal] = 1
    frac = np.linspace(0.0, 1.0, n_grid)
    for i in np.flatnonzero(~equal):
        a2 = angle_2d_at(i)
        s_max = p_max_2d_kpa / max(pt[i], pb[i])
        s = frac * s_max
        g_grid = np.asarray(a2(s * pt[i], s * pb[i]), float).ravel() - th3[i]
        sign = np.sign(g_grid)
        idx = np.flatnonzero(sign[:-1] * sign[1:] <= 0)
        if idx.size == 0:
            status[i] = 2
            continue
        j = int(idx[0])
        if g_grid[j] == 0.0:
            scale[i] = s[j]
        elif g_grid[j + 1] == 0.0:
            scale[i] = s[j + 1]
        else:

            def g(x, i=i, a2=a2):
                return float(np.asarray(a2(np.array([x * pt[i]]), np.array([x * pb[i]]))).ravel()[0] - th3[i])

            scale[i] = brentq(g, s[j], s[j + 1], xtol=xtol)
    p2t, p2b = scale * pt, scale * pb
    ok = np.isfinite(scale)
    th2 = np.full(pt.size, np.nan)
    if ok.any():
        args = (p2t[ok], p2b[ok], m[ok]) if loaded else (p2t[ok], p2b[ok])
        th2[ok] = np.asarray(angle_2d(*args), float).ravel()
    out = {
        "scale": scale,
        "p_top_2d_kpa": p2t,
        "p_bottom_2d_kpa": p2b,
        "angle_3d_deg": th3,
        "angle_2d_deg": th2,
        "status": status,
        "in_3d_grid": np.maximum(pt, pb) <= p_max_3d_kpa,
    }
    return {k: v.reshape(shape) for k, v in out.items()}


def read_planned_pressures(path: str | Path) -> pd.DataFrame:
    """Table 8 layout (exercise, P_<GROUP>_T, P_<GROUP>_B in kPa) -> frame indexed by exercise."""
    df = pd.read_csv(path).set_index("exercise")
    missing = [f"P_{g}_{c}" for g in GROUPS for c in "TB" if f"P_{g}_{c}" not in df]
    if missing:
        raise ValueError(f"{path}: missing columns {missing}")
    return df


def read_unit_moments(path: str | Path, exercises: list[str]) -> np.ndarray:
    """Table 7 layout (exercise, M_<GROUP>_Nm) -> moments per unit (exercise, group) in N m, NaN for an exercise the
    table lacks."""
    tab = pd.read_csv(path).set_index("exercise")
    return np.array([[float(tab.loc[e, f"M_{g}_Nm"]) if e in tab.index else np.nan for g in GROUPS] for e in exercises])


def mapping_dataset(
    planned: pd.DataFrame, angle_3d: ArrayFn, angle_2d: ArrayFn, *, p_max_2d_kpa: float, p_max_3d_kpa: float, **kwargs
) -> xr.Dataset:
    """Map every (exercise, group) pair of a Table 8 frame -> ``mapping_2d3d.nc`` content."""
    ex = list(planned.index)
    p3 = np.stack(
        [np.stack([planned[f"P_{g}_T"].to_numpy(float), planned[f"P_{g}_B"].to_numpy(float)], axis=-1) for g in GROUPS],
        axis=1,
    )  # (exercise, group, chamber)
    r = map_pairs(
        p3[..., 0], p3[..., 1], angle_3d, angle_2d, p_max_2d_kpa=p_max_2d_kpa, p_max_3d_kpa=p_max_3d_kpa, **kwargs
    )
    p2 = np.stack([r["p_top_2d_kpa"], r["p_bottom_2d_kpa"]], axis=-1)
    dims2, dims3 = ("exercise", "group"), ("exercise", "group", "chamber")
    ds = xr.Dataset(
        {
            "pressure_3d_kpa": (dims3, p3, {"units": "kPa", "long_name": "planned 3D chamber pressure (Table 8)"}),
            "pressure_2d_kpa": (
                dims3,
                p2,
                {"units": "kPa", "long_name": "2D chamber pressure of the same ratio giving the 3D angle"},
            ),
            "scale": (dims2, r["scale"], {"units": "1", "long_name": "scale s: 2D pressures = s * 3D pressures"}),
            "angle_3d_deg": (
                dims2,
                r["angle_3d_deg"],
                {"units": "degree", "long_name": "3D surrogate free angle per unit at the 3D pair"},
            ),
            "angle_2d_deg": (
                dims2,
                r["angle_2d_deg"],
                {"units": "degree", "long_name": "2D surrogate free angle per unit at the 2D pair"},
            ),
            "status": (
                dims2,
                r["status"],
                {
                    "units": "1",
                    "long_name": "mapping status",
                    "flag_values": np.array(sorted(MAPPING_STATUS), dtype=np.int32),
                    "flag_meanings": " ".join(MAPPING_STATUS[k] for k in sorted(MAPPING_STATUS)),
                },
            ),
            "reason": (
                dims2,
                np.vectorize(_REASONS.get, otypes=[object])(r["status"]),
                {"units": "1", "long_name": "why no 2D pair was found (empty if mapped)"},
            ),
            "in_3d_grid": (
                dims2,
                r["in_3d_grid"],
                {"units": "1", "long_name": "3D pair inside the 3D sweep's pressure range"},
            ),
        },
        coords={"exercise": ex, "group": list(GROUPS), "chamber": list(CHAMBERS)},
    )
    ds.attrs["p_max_2d_kpa"] = float(p_max_2d_kpa)
    ds.attrs["p_max_3d_kpa"] = float(p_max_3d_kpa)
    ds.attrs["method"] = "scale s with theta_2D(s P_T, s P_B) = theta_3D(P_T, P_B), bracketing + Brent"
    return ds
