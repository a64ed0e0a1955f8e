"""Rule entry point of one FE case of the fidelity study (``fidelity_fem``).

Its own module, so that the rule's inputs (the code it runs) hold the FE engine
only: changing how the study is judged (:mod:`.entry`) does not rerun minutes
of FEA.  Units: kPa, deg, N m, s.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import xarray as xr

from workflow import fem
from workflow.common.fidelity_choice import P_STUDY, FemCase, case_actuator
from workflow.common.provenance import write_dataset
from workflow.common.rays import ray_config_sha256, shared_stops
from workflow.common.runlog import solved

__all__ = ["write_fem_case"]

log = logging.getLogger(__name__)


def write_fem_case(
    case_name: str,
    out: str | Path,
    *,
    actuator: Mapping[str, Any],
    config_slice: Any,
    p_top_kpa: Sequence[float] = P_STUDY,
    iteration_budget: int | None = None,
    sweep: Mapping[str, Any] | None = None,
    rule: str = "fidelity_fem",
) -> xr.Dataset:
    """Rule ``fidelity_fem``: the unit check of one case -> ``results/fidelity/fem/{case}.nc``.

    Free angle and blocked moment per unit at ``p_top_kpa`` (P_B = 0) with
    their wall times (:func:`workflow.fem.unit_check`, retries included).
    ``iteration_budget``: Newton iterations per ray, restarts included (None:
    the actuator's own); a ray that spends it is recorded as failed (status 2).
    ``sweep``: the model's sweep config (``p_max_kpa``, ``n_pressures``) where
    the case shares the sweep's P_B = 0 ray
    (:func:`workflow.common.fidelity_choice.shares_sweep_ray`): the rays also
    land on its samples and the file keeps their paths, from which a sweep on
    this mesh takes that ray (:func:`workflow.actuator.fe_solver.studied_ray`).
    """

    case = FemCase.parse(case_name)
    act = case_actuator(actuator, case, iteration_budget)
    extra = shared_stops(p_top_kpa, sweep)  # () where the sweep's ray cannot be this one
    t0 = time.perf_counter()
    ds, deformed = fem.unit_check(act, (case.model,), p_top_kpa, extra_stops=extra, keep_paths=bool(extra))
    wall = time.perf_counter() - t0
    ds = ds.squeeze("model", drop=True)
    ds["case_wall_time_s"] = (
        (),
        wall,
        {"units": "s", "long_name": "wall time of both rays (free, blocked), retries included"},
    )
    if deformed is not None:  # the unit check of a default run reads the chosen case instead of solving it again
        ds["displacement_mm"] = (
            ("dof",),
            np.asarray(deformed[1], float),
            {"units": "mm", "long_name": "free ray's nodal displacement at the largest pressure (node-interleaved)"},
        )
    ds.attrs.update({"case": case.name, "model": case.model, "h_mm": case.h_mm, "contact": int(case.contact)})
    ds.attrs["iteration_budget"] = "none" if iteration_budget is None else int(iteration_budget)
    if extra:  # what a sweep must match to take the P_B = 0 ray from here (the budget only ends a ray early)
        ds.attrs["actuator_sha256"] = ray_config_sha256(act)
    log.info(
        "%s: free %s deg, blocked %s N m, status %s, %.1f s",
        case.name,
        np.round(ds["bending_angle_deg"].values, 3),
        np.round(ds["bending_moment_nm"].values, 4),
        ds["status"].values.ravel().tolist(),
        wall,
        extra=solved(int(np.count_nonzero(ds["status"].values)), n=int(ds["status"].size)),
    )
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice=config_slice,
        title=f"FE unit fidelity {case.name}: free angle and blocked moment at P_T = 60/180/300 kPa",
    )
    return ds
