"""Entry point of the layout search: every layout within the bounds planned on the chain and ranked (the choice among
those the FEA checked is :mod:`workflow.layout.entry_choice`, apart so that editing it or the figure does not rerun
the search). Angles deg, pressures kPa, lengths mm, masses g."""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from workflow.cascade.calibration import calibrated
from workflow.cascade.entry import read_calibration
from workflow.cascade.patient import chain_note, patient_cascade, patient_finger, plan_limit, plan_options
from workflow.cascade.planning import plan_exercise
from workflow.common.constants import GROUPS, JOINTS
from workflow.common.provenance import open_result, write_dataset
from workflow.layout.search import LayoutOutcome, candidate_layouts, overhang_mm, search_layouts

__all__ = ["write_layout_search"]

log = logging.getLogger(__name__)


def write_layout_search(
    patient_name: str,
    patient: Mapping[str, Any],
    unit: Any,
    *,
    ccd_nc: str,
    moments_nc: str,
    joint_loads_nc: str,
    cascade_cfg: Mapping[str, Any],
    anthropometry: Mapping[str, Any],
    layout_cfg: Mapping[str, Any],
    out_nc: str | Path,
    config_slice: Any,
    calibration_nc: str | None = None,
    material_limit: Any = None,
    rule: str = "layout_search",
) -> xr.Dataset:
    """Plan every exercise on every candidate layout (the chain, calibrated when ``calibration_nc`` is given) and
    rank the layouts; write ``out_nc``."""
    c = cascade_cfg
    loads = open_result(joint_loads_nc)
    fing, _ = patient_finger(
        patient, loads, open_result(moments_nc), open_result(ccd_nc), cascade_cfg=c, anthropometry=anthropometry
    )
    base = patient_cascade(fing, unit, c)
    gains = compl = None
    chain = "the paper's chain (no calibration)"
    if calibration_nc is not None:
        gains, compl, chain = read_calibration(calibration_nc, patient_name)
    chain = chain_note(base, chain)
    lr_mm, mass_g = base.unit_length_m * 1e3, base.unit_mass_kg * 1e3
    tip_mm, shift_mm = fing.tip_x_m * 1e3, float(c.get("layout_shift_mm", 0.0))
    cands = candidate_layouts(
        layout_cfg["bounds"],
        unit_length_mm=lr_mm,
        unit_mass_g=mass_g,
        max_length_mm=float(layout_cfg["max_length_mm"]),
        max_mass_g=float(layout_cfg["max_mass_g"]),
        tip_mm=tip_mm,
        max_overhang_mm=float(layout_cfg["max_overhang_mm"]),
        layout_shift_mm=shift_mm,
        max_candidates=int(layout_cfg["max_candidates"]),
    )
    limits = loads["active_limit_nm"].sel(joint=list(JOINTS)).values
    limit = plan_limit(c, unit, material_limit)
    opts = {**plan_options(c, limits, limit), "planner": str(c.get("planner", "paper"))}
    targets = {
        str(e): loads["target_angle_deg"].sel(exercise=e, joint=list(JOINTS)).values for e in loads["exercise"].values
    }
    log.info(
        "patient %s: %d layouts within the bounds (unit %.2f mm, %.2f g; tip %.1f mm past the MCP joint, at most "
        "%g mm overhang); chain: %s; planner %s",
        patient_name,
        len(cands),
        lr_mm,
        mass_g,
        tip_mm,
        float(layout_cfg["max_overhang_mm"]),
        chain,
        opts["planner"],
    )

    def evaluate(layout):
        m = patient_cascade(fing, unit, c, units_per_group=dict(zip(GROUPS, layout)))
        if gains is not None:
            m = calibrated(m, gains, compl)
        plans = [plan_exercise(m, t, exercise=name, **opts) for name, t in targets.items()]
        p = np.array([pl.pressures_kpa for pl in plans])
        return LayoutOutcome(layout, tuple(bool(pl.achieved) for pl in plans), float(p.mean()), p)

    t0 = time.perf_counter()
    step = max(1, len(cands) // 10)

    def progress(i, n):
        if i % step == 0 or i == n:
            log.info("layouts planned: %d of %d, %.1f s", i, n, time.perf_counter() - t0)

    outcomes, order = search_layouts(cands, evaluate, progress)
    rank = np.empty(len(cands), dtype="i4")
    rank[order] = np.arange(len(cands))
    units = np.array(cands, dtype="i4")
    ex = list(targets)
    ds = xr.Dataset(
        {
            "units": (("candidate", "group"), units, {"units": "1", "long_name": "units per group"}),
            "reached": (
                ("candidate", "exercise"),
                np.array([o.reached for o in outcomes]),
                {"units": "1", "long_name": "reached on the chain"},
            ),
            "n_reached": ("candidate", np.array([o.n_reached for o in outcomes], dtype="i4"), {"units": "1"}),
            "mean_pressure_kpa": (
                "candidate",
                np.array([o.mean_pressure_kpa for o in outcomes]),
                {"units": "kPa", "long_name": "mean planned chamber pressure over the exercises"},
            ),
            "pressure_kpa": (
                ("candidate", "exercise", "pressure"),
                np.array([o.pressures_kpa for o in outcomes]),
                {"units": "kPa", "long_name": "planned pressures (P_T, P_B per group, Table 8's order)"},
            ),
            "length_mm": ("candidate", units.sum(axis=1) * lr_mm, {"units": "mm"}),
            "mass_g": ("candidate", units.sum(axis=1) * mass_g, {"units": "g"}),
            "overhang_mm": (
                "candidate",
                np.array(
                    [overhang_mm(u, unit_length_mm=lr_mm, tip_mm=tip_mm, layout_shift_mm=shift_mm) for u in cands]
                ),
                {"units": "mm", "long_name": "how far the actuator reaches past the fingertip (negative: short of it)"},
            ),
            "rank": ("candidate", rank, {"units": "1", "long_name": "0 = best on the chain"}),
        },
        coords={"candidate": np.arange(len(cands)), "group": list(GROUPS), "exercise": ex, "pressure": np.arange(8)},
    )
    ds.attrs.update(
        {
            "patient": patient_name,
            "chain": chain,
            "planner": opts["planner"],
            "tip_mm": tip_mm,
            "search_wall_time_s": time.perf_counter() - t0,
        }
    )
    best = order[0]
    log.info(
        "patient %s: best on the chain %s reaches %d of %d (%s) at %.1f kPa mean; default %s",
        patient_name,
        dict(zip(GROUPS, cands[best])),
        outcomes[best].n_reached,
        len(ex),
        ", ".join(e for e, r in zip(ex, outcomes[best].reached) if r) or "none",
        outcomes[best].mean_pressure_kpa,
        base.n_per_group,
    )
    write_dataset(ds, out_nc, rule=rule, config_slice=config_slice, title="Layouts searched on the reduced-order chain")
    return ds
