"""The pressures the 2D FE models apply for a plan's 3D pressures: the 2D-to-3D mapping (paper section 3.2,
Fig. 17) bounded by the silicone's limit and the 2D sweep's range.

A module of its own so that the stand-alone actuators' rule does not import the finger-actuator check.  Pressures kPa.
"""

from __future__ import annotations

from typing import Callable, Mapping

import numpy as np

from workflow.actuator.mapping import map_pairs
from workflow.actuator.pressure_limit import PressureLimit, clip_pressures, material_limit, smallest

__all__ = ["DIAGONAL_OFFSET", "applied_limit", "pressures_2d"]

#: relative offset of the bottom pressure at which a pair with P_T = P_B takes its scale (see `pressures_2d`)
DIAGONAL_OFFSET = 0.05


def applied_limit(actuator_cfg: Mapping | None, p_max_2d_kpa: float = np.inf) -> PressureLimit:
    """Bound (kPa) of every pressure applied to a 2D model: the silicone's limit and the 2D sweep's range."""
    return smallest(
        material_limit((actuator_cfg or {}).get("material")),
        PressureLimit(float(p_max_2d_kpa), "the range the 2D surrogate's sweep sampled"),
    )


def pressures_2d(
    p3: np.ndarray,
    angle_3d: Callable | None,
    angle_2d: Callable | None,
    *,
    p_max_2d_kpa: float,
    p_max_3d_kpa: float = np.inf,
    limit: PressureLimit | None = None,
    m_ext_nm: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """2D pressures (..., 2) for 3D pairs ``p3`` (..., 2: top, bottom) in kPa, and the mapping flag per pair.

    Without surrogates (``angle_3d`` is None) the pressures are returned
    unchanged (flag 3).  A pair with P_T = P_B (flag 1) takes the scale of the pair
    (P_T, (1 - ``DIAGONAL_OFFSET``) P_B), where the free-angle map is defined, if that pair maps.  Every pressure returned is at most ``p_max_2d_kpa``
    and ``limit`` (:func:`applied_limit`); a pair cut back to that is flag 4.
    With ``m_ext_nm`` (N m per unit, shape ``p3.shape[:-1]``) the angles are
    matched under that end moment, and ``angle_3d``/``angle_2d`` take
    (P_T, P_B, M) (`UnitModel.angle_deg`; see `workflow.actuator.mapping`).
    """
    p3 = np.asarray(p3, float)
    limit = smallest(limit, PressureLimit(float(p_max_2d_kpa), "the 2D pressure range"))
    if angle_3d is None or angle_2d is None:
        p2, flag = p3.copy(), np.full(p3.shape[:-1], 3, dtype=np.int8)
    else:
        p_edge = limit.kpa  # the search stays inside the limit: "not reached" rather than a pair beyond it
        r = map_pairs(
            p3[..., 0],
            p3[..., 1],
            angle_3d,
            angle_2d,
            p_max_2d_kpa=p_edge,
            p_max_3d_kpa=p_max_3d_kpa,
            m_ext_nm=m_ext_nm,
        )
        p2 = np.stack([r["p_top_2d_kpa"], r["p_bottom_2d_kpa"]], axis=-1)
        flag = np.zeros(p3.shape[:-1], dtype=np.int8)
        eq = r["status"] == 1
        p2[eq] = p3[eq]
        flag[eq] = 1
        if np.any(eq):
            # on the diagonal the free angles are 0 in both models and the map is 0/0: such a pair takes the scale
            # of the pair of the same top pressure just off the diagonal, so the map stays continuous across it
            # (kept unscaled, 299/300 kPa became about 114/115 kPa in 2D while 300/300 stayed 300/300)
            near = map_pairs(
                p3[..., 0][eq],
                (1.0 - DIAGONAL_OFFSET) * p3[..., 1][eq],
                angle_3d,
                angle_2d,
                p_max_2d_kpa=p_edge,
                p_max_3d_kpa=p_max_3d_kpa,
                m_ext_nm=None if m_ext_nm is None else np.asarray(m_ext_nm, float)[eq],
            )
            ok = near["status"] == 0
            scaled = p3[eq]
            scaled[ok] = scaled[ok] * near["scale"][ok][:, None]
            p2[eq] = scaled
        out = r["status"] == 2
        pmax = np.maximum(p3[..., 0], p3[..., 1])
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.where(pmax > 0, p_edge / pmax, 1.0)
        p2[out] = p3[out] * s[out][..., None]
        flag[out] = 2
    p2, cut = clip_pressures(p2, limit, what="pressures applied to the 2D model")
    flag[cut.any(axis=-1)] = 4
    return p2, flag
