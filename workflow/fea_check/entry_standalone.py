"""Rule entry point of the stand-alone whole actuators' FEA (paper Fig. 22): ``standalone_exercise`` solves one
exercise's models (joined and drawn by ``standalone_actuator``, :func:`workflow.fea_check.entry.write_standalone`).

A module of its own because a rule's inputs are the code it imports: the minutes of 3D FEA per exercise must not
rerun when the finger-actuator check or the figures change.
"""

from __future__ import annotations

import logging
from typing import Any, Mapping

import numpy as np
import xarray as xr

from workflow.actuator.surrogates import load_surrogate
from workflow.common.constants import CHAMBERS, GROUPS
from workflow.common.provenance import open_result, write_dataset
from workflow.fea_check.applied import applied_limit, pressures_2d
from workflow.fea_check.standalone import MODELS, standalone_dataset

__all__ = ["load_surrogate_angles", "write_standalone_exercise"]

log = logging.getLogger(__name__)


def load_surrogate_angles(surrogate_2d: str | None, surrogate_3d: str | None):
    """(angle_3d, angle_2d, p_max_2d, p_max_3d) from the fitted surrogates, or Nones when not given."""
    if not surrogate_2d or not surrogate_3d:
        return None, None, np.inf, np.inf

    s2, s3 = load_surrogate(surrogate_2d), load_surrogate(surrogate_3d)
    return s3.angle_deg, s2.angle_deg, float(s2.p_max_kpa), float(s3.p_max_kpa)


def write_standalone_exercise(
    exercise: str,
    *,
    plan_nc: str,
    out_nc: str,
    fea_cfg: Mapping,
    actuator_cfg: Mapping,
    cascade_cfg: Mapping,
    config_slice: Any,
    surrogate_2d: str | None = None,
    surrogate_3d: str | None = None,
    rule: str = "standalone_exercise",
) -> xr.Dataset:
    """Solve one exercise's stand-alone models (2D mapped, 2D and 3D at the plan's pressures) and write them."""
    plan = open_result(plan_nc)
    if exercise not in [str(e) for e in plan["exercise"].values]:
        raise ValueError(f"exercise {exercise!r} is not in the plan {plan_nc}")
    sa = dict(fea_cfg.get("standalone", {}))
    use_map = bool(fea_cfg.get("map_pressures", True)) and cascade_cfg.get("surrogate", "3d") == "3d"
    a3, a2, pm2, pm3 = load_surrogate_angles(surrogate_2d, surrogate_3d) if use_map else (None, None, np.inf, np.inf)
    p_plan = plan["pressure_kpa"].sel(exercise=[exercise], group=list(GROUPS), chamber=list(CHAMBERS)).values
    p2, flag = pressures_2d(p_plan, a3, a2, p_max_2d_kpa=pm2, p_max_3d_kpa=pm3, limit=applied_limit(actuator_cfg, pm2))
    solver = dict(actuator_cfg.get("solver", {}))
    solver.update(dict(fea_cfg.get("solver", {})))
    ds = standalone_dataset(
        plan,
        exercises=[exercise],
        models=list(sa.get("models", MODELS)),
        actuator_cfg=actuator_cfg,
        h_2d_mm=float(fea_cfg.get("h_actuator_mm", 2.0)),
        h_3d_mm=sa.get("h_3d_mm", [4.0, 3.0]),
        solver=solver,
        p2=p2,
        flag=flag,
        restarts=list(fea_cfg.get("restarts", [])),
    )
    write_dataset(
        ds,
        out_nc,
        rule=rule,
        config_slice=config_slice,
        title=f"Stand-alone whole actuators at the plan's pressures of {exercise}",
    )
    return ds
