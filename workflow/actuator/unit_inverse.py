"""The unit model's inverse: the pressures that give a unit angle under an
external end moment, on one pressure ray, along an iso-angle curve, or of
least norm.  Pressures kPa, angles deg, moments N m; status
:data:`workflow.common.constants.UNIT_INVERSE_STATUS`.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.optimize import minimize_scalar

from workflow.actuator.unit_model import UnitModel

__all__ = ["pressures_on_ray", "iso_angle_pairs", "min_norm_pressures"]


# -- inverse queries --------------------------------------------------------
def _ray_points(t, ratio):
    """Pressures on the ray of ratio P_B/P_T = ``ratio`` (inf: P_T = 0) whose larger pressure is t."""
    ratio = np.asarray(ratio, float)
    top = np.where(ratio <= 1.0, 1.0, 1.0 / np.where(ratio > 0, ratio, 1.0))
    bot = np.where(ratio <= 1.0, ratio, 1.0)
    return t * top, t * bot


def _first_roots(
    fn: Callable[[np.ndarray, np.ndarray], np.ndarray], grid: np.ndarray, values: np.ndarray, xtol: float
) -> np.ndarray:
    """Per row, the smallest root of fn at the row's first sign change on its grid; NaN if none.

    ``grid`` and ``values`` are (rows, n); ``fn(x, rows)`` evaluates the rows'
    functions at x (rows,) in one vectorised call.  Refined by bisection on all
    rows at once (robust on the steps of a KNN surrogate) to ``xtol``.
    """
    grid = np.asarray(grid, float)
    values = np.asarray(values, float)
    sign = np.sign(values)
    change = (sign[:, :-1] * sign[:, 1:] <= 0) & np.isfinite(values[:, :-1]) & np.isfinite(values[:, 1:])
    has = change.any(axis=1)
    rows = np.flatnonzero(has)
    root = np.full(grid.shape[0], np.nan)
    if rows.size == 0:
        return root
    j = np.argmax(change[rows], axis=1)
    lo, hi = grid[rows, j].copy(), grid[rows, j + 1].copy()
    f_lo, f_hi = values[rows, j].copy(), values[rows, j + 1].copy()
    width = float(np.max(hi - lo))
    n_iter = int(np.ceil(np.log2(max(width, xtol) / xtol))) + 1
    for _ in range(n_iter):
        mid = 0.5 * (lo + hi)
        f_mid = np.asarray(fn(mid, rows), float)
        left = np.sign(f_mid) * np.sign(f_lo) <= 0  # root in [lo, mid]
        hi = np.where(left, mid, hi)
        f_hi = np.where(left, f_mid, f_hi)
        lo = np.where(left, lo, mid)
        f_lo = np.where(left, f_lo, f_mid)
    out = 0.5 * (lo + hi)
    out = np.where(f_lo == 0.0, lo, out)  # an exact zero at the grid's start stays there
    root[rows] = out
    return root


def pressures_on_ray(
    model: UnitModel,
    angle_deg,
    m_ext_nm,
    ratio,
    *,
    p_max_kpa: float | None = None,
    n_grid: int = 61,
    xtol_kpa: float = 1e-3,
) -> dict[str, np.ndarray]:
    """Lowest pressures on the ray P_B/P_T = ``ratio`` giving ``angle_deg`` under ``m_ext_nm``.

    ``ratio`` in [0, inf] (inf = bottom chamber only); the ray's larger
    pressure runs over 0..p_max.  Broadcasts its arguments; returns
    ``p_top_kpa``, ``p_bottom_kpa`` (NaN if unreachable) and ``status``
    (`UNIT_INVERSE_STATUS`).
    """
    p_max = model.p_max_kpa if p_max_kpa is None else p_max_kpa
    a, m, r = (
        x.ravel()
        for x in np.broadcast_arrays(
            np.asarray(angle_deg, float), np.asarray(m_ext_nm, float), np.asarray(ratio, float)
        )
    )
    shape = np.broadcast_shapes(np.shape(angle_deg), np.shape(m_ext_nm), np.shape(ratio))
    t = np.broadcast_to(np.linspace(0.0, p_max, n_grid), (a.size, n_grid))
    pt_grid, pb_grid = _ray_points(t, r[:, None])
    vals = model.angle_deg(pt_grid, pb_grid, m[:, None]) - a[:, None]

    def fn(x, rows):
        pt, pb = _ray_points(x, r[rows])
        return model.angle_deg(pt, pb, m[rows]) - a[rows]

    t_root = _first_roots(fn, t, vals, xtol_kpa)
    pt, pb = _ray_points(t_root, r)
    return {
        "p_top_kpa": pt.reshape(shape),
        "p_bottom_kpa": pb.reshape(shape),
        "status": np.where(np.isnan(t_root), 1, 0).reshape(shape),
    }


def _iso(
    model: UnitModel, angle_deg: float, m_ext_nm: float, p_max: float, phi: np.ndarray, n_grid: int, xtol_kpa: float
) -> np.ndarray:
    """First crossing radius rho (kPa) on each direction phi (rad); NaN where none inside the square."""
    frac = np.linspace(0.0, 1.0, n_grid)
    edge = p_max / np.maximum(np.cos(phi), np.sin(phi))  # rho at the edge of [0, p_max]^2
    rho = frac[None, :] * edge[:, None]
    c, s = np.cos(phi), np.sin(phi)
    vals = model.angle_deg(rho * c[:, None], rho * s[:, None], m_ext_nm) - angle_deg

    def fn(x, rows):
        return model.angle_deg(x * c[rows], x * s[rows], m_ext_nm) - angle_deg

    return _first_roots(fn, rho, vals, xtol_kpa)


def iso_angle_pairs(
    model: UnitModel,
    angle_deg: float,
    m_ext_nm: float = 0.0,
    *,
    p_max_kpa: float | None = None,
    n_directions: int = 91,
    n_grid: int = 61,
    xtol_kpa: float = 1e-3,
) -> dict[str, np.ndarray]:
    """The (P_T, P_B) pairs giving ``angle_deg`` under ``m_ext_nm``: the first crossing on each
    direction phi in [0, 90] deg (P_T = rho cos phi, P_B = rho sin phi) inside the square [0, p_max]^2.

    Returns ``phi_deg``, ``p_top_kpa``, ``p_bottom_kpa`` and ``norm_kpa`` (= rho) per direction
    (NaN where the direction does not reach the angle).
    """
    p_max = model.p_max_kpa if p_max_kpa is None else p_max_kpa
    phi = np.linspace(0.0, np.pi / 2, n_directions)
    root = _iso(model, float(angle_deg), float(m_ext_nm), p_max, phi, n_grid, xtol_kpa)
    return {
        "phi_deg": np.degrees(phi),
        "p_top_kpa": root * np.cos(phi),
        "p_bottom_kpa": root * np.sin(phi),
        "norm_kpa": root,
    }


def min_norm_pressures(
    model: UnitModel,
    angle_deg,
    m_ext_nm=0.0,
    *,
    p_max_kpa: float | None = None,
    n_directions: int = 91,
    n_grid: int = 61,
    xtol_kpa: float = 1e-3,
) -> dict[str, np.ndarray]:
    """The (P_T, P_B) of least sqrt(P_T^2 + P_B^2) giving ``angle_deg`` under ``m_ext_nm``.

    Scans `iso_angle_pairs`, then refines the best direction with a bounded
    scalar search between its neighbours.  Broadcasts over ``angle_deg`` and
    ``m_ext_nm``; returns ``p_top_kpa``, ``p_bottom_kpa`` (NaN if unreachable)
    and ``status`` (`UNIT_INVERSE_STATUS`).
    """
    p_max = model.p_max_kpa if p_max_kpa is None else p_max_kpa
    a, m = np.broadcast_arrays(np.asarray(angle_deg, float), np.asarray(m_ext_nm, float))
    pt_out, pb_out = np.full(a.size, np.nan), np.full(a.size, np.nan)
    for i in range(a.size):
        iso = iso_angle_pairs(
            model,
            float(a.flat[i]),
            float(m.flat[i]),
            p_max_kpa=p_max,
            n_directions=n_directions,
            n_grid=n_grid,
            xtol_kpa=xtol_kpa,
        )
        norm = iso["norm_kpa"]
        if np.all(np.isnan(norm)):
            continue
        j = int(np.nanargmin(norm))
        best = (norm[j], iso["phi_deg"][j])
        lo = iso["phi_deg"][max(j - 1, 0)]
        hi = iso["phi_deg"][min(j + 1, norm.size - 1)]
        if hi > lo and norm[j] > 0:

            def f(ph_deg, i=i):
                r = _iso(model, float(a.flat[i]), float(m.flat[i]), p_max, np.radians([ph_deg]), n_grid, xtol_kpa)
                return r[0] if np.isfinite(r[0]) else np.inf

            res = minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": 1e-3})
            if np.isfinite(res.fun) and res.fun < best[0]:
                best = (res.fun, res.x)
        pt_out[i] = best[0] * np.cos(np.radians(best[1]))
        pb_out[i] = best[0] * np.sin(np.radians(best[1]))
    return {
        "p_top_kpa": pt_out.reshape(a.shape),
        "p_bottom_kpa": pb_out.reshape(a.shape),
        "status": np.where(np.isnan(pt_out), 1, 0).reshape(a.shape),
    }
