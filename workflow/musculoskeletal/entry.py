"""Rule entry points of the musculoskeletal stage: the moments from the
authors' export or the OpenSim backend, the response surfaces with ANOVA, a
patient's joint loads and safety limits, the backend's validation.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd
import xarray as xr

from workflow.common.provenance import open_result, write_dataset
from workflow.doe.entry import design_from_ccd
from workflow.musculoskeletal import moments as msm
from workflow.musculoskeletal import patient_loads, rsm, table_backend
from workflow.musculoskeletal.direct import direct_responses, loads_method
from workflow.musculoskeletal.plots import plot_joint_loads, plot_missing_reference, plot_rsm_r2, plot_validation
from workflow.musculoskeletal.validation import DIMENSIONS, compare, read_reference, summary

__all__ = ["write_moments_from_table", "write_selected_moments", "write_rsm", "write_joint_loads", "write_validation"]

log = logging.getLogger(__name__)


def write_moments_from_table(
    ccd: str | Path, table: str | Path, out: str | Path, *, rule: str = "joint_moments_table"
) -> xr.Dataset:
    design = design_from_ccd(ccd)
    ds = table_backend.moments_from_export(table_backend.read_export(table), design)
    ds.attrs["backend"] = "table"
    ds.attrs["table_path"] = str(table)
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice={"table_path": str(table)},
        title="Joint moments at the CCD runs (OpenSim export, table backend)",
        source=f"OpenSim export read from {table}",
    )
    return ds


def write_selected_moments(
    source: str | Path, out: str | Path, backend: str, *, rule: str = "joint_moments"
) -> xr.Dataset:
    """Publish the chosen backend's samples as ``moments.nc`` (same layout, new provenance)."""
    with open_result(source) as src:
        ds = src.load()
    ds.attrs = {"backend": backend, "backend_file": str(source), "backend_git_commit": src.attrs.get("git_commit", "")}
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice={"backend": backend},
        title=f"Joint moments at the CCD runs ({backend} backend)",
    )
    return ds


def write_rsm(
    ccd: str | Path,
    moments_nc: str | Path,
    out: str | Path,
    exercises: Mapping,
    alpha: float,
    *,
    rule: str = "rsm",
    plot: str | Path | None = None,
) -> xr.Dataset:
    design = design_from_ccd(ccd)
    with open_result(moments_nc) as m:
        responses = msm.responses_from_moments(m.load(), exercises)
    if not responses:
        raise ValueError(f"{moments_nc}: no response has data at every run for the exercises' target angles")
    ds = rsm.rsm_dataset(rsm.fit_all(design, responses), alpha=alpha)
    ds["observed"] = (
        ("response", "run"),
        np.array([responses[r] for r in ds["response"].values]),
        {"units": "N m", "long_name": "joint moment at the CCD runs"},
    )
    ds = ds.assign_coords(run=design.index.to_numpy())
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice={"exercises": exercises, "alpha": alpha},
        title="Response surfaces of joint moments over coded finger dimensions, with ANOVA",
    )
    for finger in sorted({r.split("_")[0] for r in ds["response"].values}):
        sel = ds.sel(response=[r for r in ds["response"].values if r.startswith(finger)])
        q = sel["r2"].sel(form="quadratic")
        log.info(
            "%s: quadratic R^2 %.4f..%.4f, overall p <= %.3g",
            finger,
            float(q.min()),
            float(q.max()),
            float(sel["p_value"].sel(form="quadratic").max()),
        )
    if plot is not None:
        plot_rsm_r2(ds, plot)
    return ds


def write_joint_loads(
    patient_name: str,
    patient: Mapping,
    ccd: str | Path,
    moments_nc: str | Path,
    rsm_nc: str | Path,
    out: str | Path,
    exercises: Mapping,
    anthropometry: Mapping,
    prediction_alpha: float,
    config_slice: Any,
    *,
    rule: str = "patient_loads",
    plot: str | Path | None = None,
    msk_study: str | Path | None = None,
    model_osim: str | Path | None = None,
    tolerance: float = 0.05,
    scaling: Mapping | None = None,
) -> xr.Dataset:
    """Rule ``patient_loads``.  With ``msk_study`` (``fidelity.auto``) the loads come from the response
    surfaces or from direct OpenSim sampling of the patient, whichever the study says meets ``tolerance``
    (:func:`workflow.musculoskeletal.direct.loads_method`); the choice and why are in the attrs."""

    design = design_from_ccd(ccd)
    x = patient_loads.patient_levels(patient, anthropometry["measures"], anthropometry.get("coded_unit_sd", 1.0))
    study = open_result(msk_study) if msk_study else None
    method, why = loads_method(study, x, tolerance, model_available=model_osim is not None)
    direct = None
    if method == "opensim_direct":
        log.warning("patient %s: %s", patient_name, why)
        direct = direct_responses(
            str(model_osim),
            x,
            exercises,
            finger=str(patient.get("finger", "F3")),
            scaling_cfg=scaling,
            anthropometry=anthropometry,
        )
    else:
        log.info("patient %s: %s", patient_name, why)
    with open_result(moments_nc) as m, open_result(rsm_nc) as r:
        ds = patient_loads.joint_loads(
            patient,
            m.load(),
            r.load(),
            design,
            exercises,
            anthropometry["measures"],
            anthropometry.get("coded_unit_sd", 1.0),
            prediction_alpha,
            name=patient_name,
            direct=direct,
        )
    ds.attrs.update({"fidelity": method, "fidelity_reason": why})
    write_dataset(
        ds, out, rule=rule, config_slice=config_slice, title=f"Joint loads and safety limits of patient {patient_name}"
    )
    if plot is not None:
        plot_joint_loads(ds, plot)
    return ds


def write_validation(
    moments_nc: str | Path,
    ccd_nc: str | Path,
    reference_csv: str | Path,
    out_nc: str | Path,
    out_png: str | Path,
    *,
    rule: str,
    config_slice: Any,
) -> xr.Dataset:
    """Rule ``opensim_validate``: write ``musculoskeletal.nc`` and its plot.

    When the reference export is absent the dataset has an empty ``response``
    dimension and the attribute ``reference_missing = 1``, and the plot says so.
    """

    with open_result(moments_nc) as m:
        ours = m.load()
    with open_result(ccd_nc) as c:
        design = pd.DataFrame({d: c[d].values for d in DIMENSIONS}, index=c["run"].values)
    ref = read_reference(reference_csv)
    if ref is None:
        log.warning("reference export %s absent: writing an empty validation", reference_csv)
        ds = xr.Dataset(
            {
                v: (("response", "run"), np.empty((0, len(design))))
                for v in ("ours", "reference", "abs_error", "rel_error")
            },
            coords={"response": [], "run": list(design.index)},
        )
        for v, u in (("ours", "N m"), ("reference", "N m"), ("abs_error", "N m"), ("rel_error", "1")):
            ds[v].attrs = {"units": u, "long_name": v.replace("_", " ")}
        ds.attrs["reference_missing"] = 1
        plot_missing_reference(reference_csv, out_png)
    else:
        ds = compare(ours, design, ref)
        ds.attrs["reference_missing"] = 0
        plot_validation(ds, out_png)
        summ = summary(ds)
        for line in summ.splitlines():
            log.info(line)
    write_dataset(
        ds,
        out_nc,
        rule=rule,
        config_slice=config_slice,
        title="OpenSim backend against the authors' ARMS export",
        source=f"ours: {moments_nc}; reference: {reference_csv}",
    )
    return ds
