"""Rule entry point of the chain's calibration (``chain_calibration``): build the calibration patient's finger and
the actuator the config lays on it, map Table 8 to 2D for the held-out list, run the FEA of both lists, fit the
chain (:mod:`.calibration`), write the dataset and its figure.
"""

from __future__ import annotations

import logging
from typing import Any, Mapping

import numpy as np
import pandas as pd

from workflow.actuator.unit_model import load_unit_model
from workflow.cascade.patient import patient_cascade, patient_finger
from workflow.common.constants import PRESSURE_NAMES
from workflow.common.provenance import open_result, write_dataset
from workflow.fea_check.applied import applied_limit, pressures_2d
from workflow.fea_check.calibration import run_chain_calibration
from workflow.fea_check.entry_standalone import load_surrogate_angles
from workflow.fea_check.model import build_patient_fea
from workflow.fea_check.plots import plot_chain_calibration

__all__ = ["calibration_sets", "write_chain_calibration"]

log = logging.getLogger(__name__)


def calibration_sets(
    calibration_cfg: Mapping[str, Any], table08: pd.DataFrame, to_2d, limit_kpa: float
) -> tuple[dict[str, np.ndarray], list[str]]:
    """{name: 2D pressures (8,) kPa} of the fit list (``fit_1`` ...) and the held-out list (Table 8's exercises,
    mapped to 2D by ``to_2d``: (n, 4, 2) 3D -> 2D), and the held-out names.  A fit set that is not eight pressures
    within [0, ``limit_kpa``] is refused before any FEA runs."""
    sets = {}
    for k, p in enumerate(calibration_cfg["fit_pressures_2d_kpa"], start=1):
        p = np.asarray(p, float)
        if p.shape != (8,) or np.any(p < 0) or np.any(p > limit_kpa) or not np.all(np.isfinite(p)):
            raise ValueError(
                f"cascade.calibration.fit_pressures_2d_kpa[{k - 1}] = {p.tolist()}: eight pressures "
                f"({', '.join(PRESSURE_NAMES)}) within 0 and {limit_kpa:g} kPa expected"
            )
        sets[f"fit_{k}"] = p
    p3 = table08[list(PRESSURE_NAMES)].to_numpy(float).reshape(-1, 4, 2)
    p2, _ = to_2d(p3)
    held = [str(e) for e in table08.index]
    for e, p in zip(held, p2.reshape(-1, 8)):
        sets[e] = p
    return sets, held


def write_chain_calibration(
    patient_name: str,
    patient: Mapping[str, Any],
    *,
    joint_loads_nc: str,
    moments_nc: str,
    ccd_nc: str,
    surrogate_2d: str,
    surrogate_3d: str,
    table08_csv: str,
    out_nc: str,
    out_png: str | None,
    calibration_cfg: Mapping[str, Any],
    fea_cfg: Mapping[str, Any],
    actuator_cfg: Mapping[str, Any],
    cascade_cfg: Mapping[str, Any],
    anthropometry: Mapping[str, Any],
    unit_model_cfg: Mapping[str, Any],
    config_slice: Any,
    rule: str = "chain_calibration",
):
    """The calibration of the chain on ``patient``'s finger (see :mod:`.calibration`); returns the dataset."""
    loads = open_result(joint_loads_nc)
    finger, spring_note = patient_finger(
        patient,
        loads,
        open_result(moments_nc),
        open_result(ccd_nc),
        cascade_cfg=cascade_cfg,
        anthropometry=anthropometry,
    )
    chain = patient_cascade(finger, load_unit_model(surrogate_2d, **unit_model_cfg), cascade_cfg)
    a3, a2, pm2, pm3 = load_surrogate_angles(surrogate_2d, surrogate_3d)
    limit = applied_limit(actuator_cfg, pm2)

    def to_2d(p3):
        return pressures_2d(p3, a3, a2, p_max_2d_kpa=pm2, p_max_3d_kpa=pm3, limit=limit)

    table08 = pd.read_csv(table08_csv).set_index("exercise")
    sets, held = calibration_sets(calibration_cfg, table08, to_2d, limit.kpa)
    ref = {k: float(v["mean"]) for k, v in anthropometry["measures"].items()}
    fea = build_patient_fea(
        finger,
        chain.n_per_group,
        actuator_cfg=actuator_cfg,
        cascade_cfg=cascade_cfg,
        reference_dims_mm=ref,
        fea_cfg=fea_cfg,
    )
    log.info(
        "calibration on patient %s: %s; units %s; springs: %s; %d fit sets, held out %s",
        patient_name,
        fea.notes,
        chain.n_per_group,
        spring_note,
        len(sets) - len(held),
        held,
    )
    solver = dict(actuator_cfg.get("solver", {}))
    solver.update(dict(fea_cfg.get("solver", {})))
    ds, cal = run_chain_calibration(
        fea,
        chain,
        sets,
        held,
        solver=solver,
        path_points=tuple(calibration_cfg["path_points"]),
        gain_bounds=tuple(calibration_cfg["gain_bounds"]),
        compliance_bounds_rad_per_nm=tuple(calibration_cfg["compliance_bounds_rad_per_nm"]),
    )
    ds.attrs.update(
        {
            "patient": patient_name,
            "units_per_group": str(chain.n_per_group),
            "h_actuator_mm": float(fea_cfg["h_actuator_mm"]),
            "held_out": "Table 8 (Chung & Venter 2024) mapped to 2D as the FEA check maps a plan",
        }
    )
    write_dataset(
        ds, out_nc, rule=rule, config_slice=config_slice, title="The reduced-order chain calibrated to the 2D FEA"
    )
    if out_png:
        plot_chain_calibration(ds, out_png)
    return ds
