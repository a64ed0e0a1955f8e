"""Rule entry points of the actuator stage's file-level steps: merge the sweep
shards, cross-validate and fit the surrogates, map Table 8 to 2D, run the
end-moment check.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import xarray as xr

from workflow import fem
from workflow.actuator.mapping import map_pairs, mapping_dataset, read_planned_pressures, read_unit_moments
from workflow.actuator.moment_check import chain_mesh, moment_check
from workflow.actuator.plots import (
    plot_mapping,
    plot_moment_check,
    plot_response,
    plot_surrogate_cv,
    plot_unit_stiffness,
)
from workflow.actuator.pressure_limit import PressureLimit, smallest
from workflow.actuator.stiffness import (
    DEFAULT_STIFFNESS,
    SOLVES,
    StiffnessTable,
    compare_model,
    heldout_errors,
    rotation_stiffness,
    stiffness_dataset,
)
from workflow.actuator.surrogates import Surrogate, fit_surrogate, load_surrogate, save_surrogate, surrogate_cv
from workflow.actuator.sweep import merge_shards
from workflow.actuator.unit_model import load_unit_model
from workflow.common.constants import GROUPS
from workflow.common.provenance import open_result, write_dataset

__all__ = [
    "write_response",
    "write_surrogate_cv",
    "write_surrogate",
    "write_mapping",
    "write_moment_check",
    "write_unit_stiffness",
]

log = logging.getLogger(__name__)


def write_response(
    shards: Sequence[str | Path],
    out: str | Path,
    *,
    fea: str,
    sweep_cfg: Mapping[str, Any],
    config_slice: Any,
    rule: str = "sweep_merge",
) -> xr.Dataset:
    """Merge the shard files of FE model ``fea`` into ``response_{fea}.nc`` (CONTRACT.md)."""
    ds = merge_shards(shards, n_ratios=sweep_cfg["n_ratios"], n_pressures=sweep_cfg["n_pressures"])
    solved = ~ds["mirrored"].values
    n_ok = int(np.count_nonzero(ds["converged"].values[solved]))
    wall = float(ds["wall_time_s"].sum())
    log.info(
        "%s sweep: %d points (%d solved, %d converged, %d mirrored), %.1f s of solver time",
        fea,
        ds.sizes["point"],
        int(solved.sum()),
        n_ok,
        int((~solved).sum()),
        wall,
    )
    ds.attrs.update(
        {
            "fea": fea,
            "p_max_kpa": float(sweep_cfg["p_max_kpa"]),
            "n_ratios": int(sweep_cfg["n_ratios"]),
            "n_pressures": int(sweep_cfg["n_pressures"]),
            "solver_wall_time_s": wall,
        }
    )
    first = shards[0] if isinstance(shards[0], xr.Dataset) else open_result(shards[0])
    # the mesh the shards were solved on, and why
    ds.attrs.update({k: v for k, v in first.attrs.items() if k in ("h_mm", "contact") or k.startswith("fidelity")})
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice=config_slice,
        title=f"{fea.upper()} unit response over (P_T, P_B): free angle and blocked moment per unit",
    )
    return ds


def write_surrogate_cv(
    response_2d: str | Path,
    response_3d: str | Path,
    out: str | Path,
    *,
    k: int,
    folds: int,
    random_state: int,
    regressors: Sequence[str],
    config_slice,
    rule: str = "surrogate_cv",
    plot: str | Path | None = None,
    tolerance: float | None = None,
) -> xr.Dataset:
    """CV of the regressors on both sweeps -> ``surrogate_cv.nc`` (and the CV chart)."""
    responses = {fea: open_result(p) for fea, p in (("2d", response_2d), ("3d", response_3d))}
    ds = surrogate_cv(
        responses, regressors=regressors, k=k, folds=folds, random_state=random_state, tolerance=tolerance
    )
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice=config_slice,
        title="Cross-validation of surrogates of the unit's angle and moment over (P_T, P_B)",
    )
    if plot is not None:
        plot_surrogate_cv(ds, plot)
    return ds


def write_surrogate(
    response: str | Path,
    cv: str | Path,
    out: str | Path,
    *,
    fea: str,
    k: int,
    random_state: int,
    plot: str | Path | None = None,
) -> Surrogate:
    """Fit the regressor the CV chose for ``fea`` on all its samples; save it (and the Fig. 11-like plot)."""
    resp = open_result(response)
    with open_result(cv) as c:
        chosen = str(c["chosen"].sel(fea=fea).values)
        why = str(c["choice_reason"].sel(fea=fea).values) if "choice_reason" in c else ""
    s = fit_surrogate(resp, chosen, fea=fea, k=k, random_state=random_state)
    s.meta.update({"fidelity": chosen, "fidelity_reason": why})
    log.info("%s: fitted %s on %d samples (%s)", fea, chosen, s.n_samples, why)
    save_surrogate(s, out)
    if plot is not None:
        plot_response(resp, s, plot, fea=fea)
    return s


def write_mapping(
    planned_csv: str | Path,
    surrogate_3d: str | Path,
    surrogate_2d: str | Path,
    out: str | Path,
    *,
    config_slice,
    rule: str = "mapping_2d3d",
    plot: str | Path | None = None,
    material_limit=None,
    unit_moments_csv: str | Path | None = None,
    unit_model: Mapping | None = None,
) -> xr.Dataset:
    """Map Table 8 with the fitted 3D and 2D surrogates -> ``mapping_2d3d.nc`` (and the Fig. 17-like plot).

    The 2D grid's edge is the smaller of the 2D surrogate's training range (its
    sweep's p_max) and the silicone's limit ``material_limit``
    (:func:`workflow.actuator.pressure_limit.material_limit`): no 2D pair beyond either.
    With ``unit_moments_csv`` (Table 7: the moment per unit of each group and exercise, N m) the pairs are also
    mapped under those moments with the unit models (``*_loaded`` variables; `workflow.actuator.mapping`).
    """

    s3, s2 = load_surrogate(surrogate_3d), load_surrogate(surrogate_2d)
    limit = smallest(material_limit, PressureLimit(float(s2.p_max_kpa), "the range the 2D surrogate's sweep sampled"))
    ds = mapping_dataset(
        read_planned_pressures(planned_csv),
        s3.angle_deg,
        s2.angle_deg,
        p_max_2d_kpa=limit.kpa,
        p_max_3d_kpa=s3.p_max_kpa,
    )
    if unit_moments_csv is not None:
        ds = ds.merge(
            _loaded_map(ds, unit_moments_csv, surrogate_3d, surrogate_2d, unit_model, limit.kpa, s3.p_max_kpa)
        )
    ds.attrs["surrogate_3d"] = s3.regressor
    ds.attrs["surrogate_2d"] = s2.regressor
    ds.attrs["p_limit_source"] = limit.source
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice=config_slice,
        title="2D pressures of the same ratio and free angle as the planned 3D pressures (Table 8)",
    )
    if plot is not None:
        plot_mapping(ds, plot)
    return ds


def _loaded_map(ds, unit_moments_csv, surrogate_3d, surrogate_2d, unit_model, p_max_2d_kpa, p_max_3d_kpa):
    """The Table 8 pairs of ``ds`` mapped under Table 7's unit moments (variables ``*_loaded``)."""
    ex = [str(e) for e in ds["exercise"].values]
    m = read_unit_moments(unit_moments_csv, ex)  # (exercise, group)
    u3 = load_unit_model(surrogate_3d, **dict(unit_model or {}))
    u2 = load_unit_model(surrogate_2d, **dict(unit_model or {}))
    p3 = ds["pressure_3d_kpa"].values
    r = map_pairs(
        p3[..., 0],
        p3[..., 1],
        u3.angle_deg,
        u2.angle_deg,
        p_max_2d_kpa=p_max_2d_kpa,
        p_max_3d_kpa=p_max_3d_kpa,
        m_ext_nm=m,
    )
    dims2 = ("exercise", "group")
    return xr.Dataset(
        {
            "unit_moment_nm": (dims2, m, {"units": "N m", "long_name": "moment per unit (Table 7)"}),
            "pressure_2d_loaded_kpa": (
                (*dims2, "chamber"),
                np.stack([r["p_top_2d_kpa"], r["p_bottom_2d_kpa"]], axis=-1),
                {"units": "kPa", "long_name": "2D chamber pressure of the same ratio giving the 3D angle under M"},
            ),
            "scale_loaded": (dims2, r["scale"], {"units": "1", "long_name": "scale s under the unit moment"}),
            "angle_3d_loaded_deg": (
                dims2,
                r["angle_3d_deg"],
                {"units": "degree", "long_name": "3D unit angle under the unit moment"},
            ),
            "status_loaded": (dims2, r["status"], {"units": "1", "long_name": "mapping status under the unit moment"}),
        },
        coords={"exercise": ex, "group": list(GROUPS), "chamber": list(ds["chamber"].values)},
    )


def write_moment_check(
    nc_path: str | Path,
    plot_path: str | Path,
    actuator: Mapping,
    unit_model: Mapping | None = None,
    *,
    rule: str = "unit_moment_check",
    config_slice=None,
) -> xr.Dataset:
    """Run the check with ``actuator.moment_check``; write the dataset and plot."""

    ds = moment_check(actuator, actuator.get("moment_check"))
    write_dataset(
        ds,
        nc_path,
        rule=rule,
        config_slice=config_slice if config_slice is not None else dict(actuator),
        title="PNA unit under an end moment: the unit model's spring per end hold vs a unit inside a chain",
        source="workflow.fem (three-chamber unit: free, blocked; chain cut at gap centres: free, end rotations)",
    )
    plot_moment_check(ds, plot_path)
    return ds


def write_unit_stiffness(
    nc_path: str | Path,
    plot_path: str | Path,
    actuator: Mapping,
    surrogate_2d: str | Path | None = None,
    unit_model: Mapping | None = None,
    *,
    rule: str = "unit_stiffness",
    config_slice=None,
) -> xr.Dataset:
    """Run the stiffness study of ``actuator.stiffness`` on the 2D chain; compare the 2D unit model; write both."""
    st = {**DEFAULT_STIFFNESS, **dict(actuator.get("stiffness") or {})}
    unit = fem.unit_mesh_from_config(actuator, 2)
    chain = chain_mesh(unit, int(st["chain_units"]), **fem.layer_options(actuator))
    log.info(
        "unit stiffness: %d pressure pairs (%d held out) x 4 solves on a 2D chain of %d (h = %g mm, %d dofs)",
        len(st["pairs_kpa"]) + len(st.get("heldout_kpa") or []),
        len(st.get("heldout_kpa") or []),
        int(st["chain_units"]),
        unit.h,
        chain.mesh.p.size,
    )
    pairs, held = list(st["pairs_kpa"]), list(st.get("heldout_kpa") or [])
    delta = float(st["delta_deg"])
    res = rotation_stiffness(chain, pairs + held, delta_deg=delta, actuator=actuator)
    fit = np.arange(len(pairs) + len(held)) < len(pairs)
    P, k = res["pairs_kpa"], res["k_nm_per_deg"]
    model = load_unit_model(surrogate_2d, **dict(unit_model or {})) if surrogate_2d is not None else None
    # the moment scale of the errors: the unit's largest blocked moment over the sweep's pressures (one side at
    # 0 to p_max); without a surrogate the chain's largest over the fit pairs (near the diagonal it is small, so
    # the shares are then large: the log says which scale)
    if model is not None:
        p = np.linspace(0.0, model.p_max_kpa, 31)
        m_max = float(np.nanmax(np.abs(np.r_[model.blocked_moment_nm(p, 0.0), model.blocked_moment_nm(0.0, p)])))
        scale = "the 2D unit's largest blocked moment"
    else:
        blocked = [name for name, _, _ in SOLVES].index("blocked")
        m_max = float(np.nanmax(np.abs(res["moment_nm"][fit, blocked])))
        scale = "the chain's largest blocked moment over the fit pairs (no surrogate)"
    log.info("unit stiffness: moment errors as a share of %s, %.4g N m", scale, m_max)
    try:
        table = StiffnessTable(P[fit, 0], P[fit, 1], k[fit])
    except ValueError as exc:  # too few pairs with a finite k: the study stands without its table
        log.warning("unit stiffness: no stiffness table (%s)", exc)
        table, errs = None, None
    else:
        errs = heldout_errors(table, P[:, 0], P[:, 1], k, delta, m_max)
        for (pt, pb), e, r in zip(P[~fit], errs["moment_error_share"][~fit], errs["rel_error"][~fit]):
            log.info(
                "stiffness table at held-out (%g, %g) kPa: k %+.1f %% off, moment error %.2f %% of M_b,max",
                pt,
                pb,
                100 * r,
                100 * e,
            )
    cmp = cmp_table = None
    if model is not None:
        cmp = compare_model(res, model)
        if table is not None:
            cmp_table = compare_model(res, replace(model, measured_stiffness=table, measured_window_deg=delta))
    ds = stiffness_dataset(
        res,
        delta_deg=delta,
        h_mm=float(unit.h),
        chain_units=int(st["chain_units"]),
        model=cmp,
        fit=fit,
        table=errs,
        m_blocked_max_nm=m_max,
        model_with_table=cmp_table,
    )
    write_dataset(
        ds,
        nc_path,
        rule=rule,
        config_slice=config_slice if config_slice is not None else dict(actuator),
        title="Bending stiffness of a PNA unit inside a chain vs both chamber pressures (FEA) and the unit model's",
        source="workflow.fem (2D chain cut at gap centres: free, blocked, end rotations +-delta per unit)",
    )
    plot_unit_stiffness(ds, plot_path)
    return ds
