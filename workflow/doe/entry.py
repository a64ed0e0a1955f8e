"""File-level entry points of the DOE and musculoskeletal stages.

Each function reads its inputs from paths, calls the pure science in
:mod:`workflow.doe` and :mod:`workflow.musculoskeletal`, and writes one dataset
with provenance.  The Snakemake ``script:`` adapters call exactly one of them;
tests call them directly.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd
import xarray as xr

from . import doe
from .musculoskeletal import moments as msm
from .musculoskeletal import patient_loads, rsm, table_backend
from .provenance import open_result, write_dataset

__all__ = [
    "design_from_ccd",
    "write_ccd",
    "write_scaling",
    "write_scaling_validation",
    "write_moments_from_table",
    "write_selected_moments",
    "write_rsm",
    "write_joint_loads",
]

log = logging.getLogger(__name__)


def design_from_ccd(path: str | Path) -> pd.DataFrame:
    """Read ``ccd.nc`` back as the design frame (index ``run``)."""
    with open_result(path) as ds:
        df = pd.DataFrame({f: ds[f].values for f in doe.FACTORS}, index=pd.Index(ds["run"].values, name="run"))
        df.insert(0, "marker", ds["marker"].values.astype(str))
    return df


def write_ccd(out: str | Path, design_cfg: Mapping[str, float], *, rule: str = "ccd") -> xr.Dataset:
    design = doe.ccd_design(design_cfg.get("corner", 0.7071), design_cfg.get("axial", 1.0))
    ds = doe.ccd_dataset(design)
    write_dataset(ds, out, rule=rule, config_slice={"design": dict(design_cfg)},
                  title="Central composite design of finger depth, length and breadth (coded levels)")
    log.info("wrote %d CCD runs to %s", ds.sizes["run"], out)
    return ds


def write_scaling(ccd: str | Path, out: str | Path, scaling: Mapping, anthropometry: Mapping, *, rule: str = "scaling") -> xr.Dataset:
    design = design_from_ccd(ccd)
    u = anthropometry.get("coded_unit_sd", 1.0)
    scale = doe.scale_factors(design, scaling, anthropometry["measures"], u)
    ds = doe.scaling_dataset(design, scale)
    ds.attrs["coded_unit_sd"] = u
    write_dataset(ds, out, rule=rule, config_slice={"scaling": scaling, "anthropometry": anthropometry},
                  title="OpenSim scale factors per CCD run, body and axis")
    return ds


def write_scaling_validation(scaling_nc: str | Path, table_csv: str | Path, out: str | Path, *, rule: str = "validate_scaling") -> xr.Dataset:
    with open_result(scaling_nc) as s:
        scale = s["scale"].load()
        design = pd.DataFrame({"marker": s["marker"].values.astype(str)}, index=s["run"].values)
    table = pd.read_csv(table_csv)
    ds = doe.compare_with_table(scale, design, table)
    write_dataset(ds, out, rule=rule, config_slice={"reference": str(table_csv)},
                  title="Scale factors against Tables 3-4 of Chung & Venter 2024")
    log.info("largest |ours - Tables 3-4| = %.4f (%.4f without the paper's inconsistent MP_Z cell)",
             ds.attrs["max_abs_error"], ds.attrs["max_abs_error_excluding_paper_inconsistency"])
    return ds


def write_moments_from_table(ccd: str | Path, table: str | Path, out: str | Path, *, rule: str = "joint_moments_table") -> xr.Dataset:
    design = design_from_ccd(ccd)
    ds = table_backend.moments_from_export(table_backend.read_export(table), design)
    ds.attrs["backend"] = "table"
    ds.attrs["table_path"] = str(table)
    write_dataset(ds, out, rule=rule, config_slice={"table_path": str(table)},
                  title="Joint moments at the CCD runs (OpenSim export, table backend)",
                  source=f"OpenSim export read from {table}")
    return ds


def write_selected_moments(source: str | Path, out: str | Path, backend: str, *, rule: str = "joint_moments") -> xr.Dataset:
    """Publish the chosen backend's samples as ``moments.nc`` (same layout, new provenance)."""
    with open_result(source) as src:
        ds = src.load()
    ds.attrs = {"backend": backend, "backend_file": str(source), "backend_git_commit": src.attrs.get("git_commit", "")}
    write_dataset(ds, out, rule=rule, config_slice={"backend": backend},
                  title=f"Joint moments at the CCD runs ({backend} backend)")
    return ds


def write_rsm(ccd: str | Path, moments_nc: str | Path, out: str | Path, exercises: Mapping, alpha: float,
              *, rule: str = "rsm", plot: str | Path | None = None) -> xr.Dataset:
    design = design_from_ccd(ccd)
    with open_result(moments_nc) as m:
        responses = msm.responses_from_moments(m.load(), exercises)
    if not responses:
        raise ValueError(f"{moments_nc}: no response has data at every run for the exercises' target angles")
    ds = rsm.rsm_dataset(rsm.fit_all(design, responses), alpha=alpha)
    ds["observed"] = (("response", "run"), np.array([responses[r] for r in ds["response"].values]),
                      {"units": "N m", "long_name": "joint moment at the CCD runs"})
    ds = ds.assign_coords(run=design.index.to_numpy())
    write_dataset(ds, out, rule=rule, config_slice={"exercises": exercises, "alpha": alpha},
                  title="Response surfaces of joint moments over coded finger dimensions, with ANOVA")
    for finger in sorted({r.split("_")[0] for r in ds["response"].values}):
        sel = ds.sel(response=[r for r in ds["response"].values if r.startswith(finger)])
        q = sel["r2"].sel(form="quadratic")
        log.info("%s: quadratic R^2 %.4f..%.4f, overall p <= %.3g", finger, float(q.min()), float(q.max()),
                 float(sel["p_value"].sel(form="quadratic").max()))
    if plot is not None:
        from .plots import plot_rsm_r2
        plot_rsm_r2(ds, plot)
    return ds


def write_joint_loads(patient_name: str, patient: Mapping, ccd: str | Path, moments_nc: str | Path, rsm_nc: str | Path,
                      out: str | Path, exercises: Mapping, anthropometry: Mapping, prediction_alpha: float,
                      config_slice: Any, *, rule: str = "patient_loads", plot: str | Path | None = None,
                      msk_study: str | Path | None = None, model_osim: str | Path | None = None,
                      tolerance: float = 0.05, scaling: Mapping | None = None) -> xr.Dataset:
    """Rule ``patient_loads``.  With ``msk_study`` (``fidelity.auto``) the loads come from the response
    surfaces or from direct OpenSim sampling of the patient, whichever the study says meets ``tolerance``
    (:func:`workflow.musculoskeletal.direct.loads_method`); the choice and why are in the attrs."""
    from .musculoskeletal.direct import loads_method

    design = design_from_ccd(ccd)
    x = patient_loads.patient_levels(patient, anthropometry["measures"], anthropometry.get("coded_unit_sd", 1.0))
    study = open_result(msk_study) if msk_study else None
    method, why = loads_method(study, x, tolerance, model_available=model_osim is not None)
    direct = None
    if method == "opensim_direct":
        from .musculoskeletal.direct import direct_responses

        log.warning("patient %s: %s", patient_name, why)
        direct = direct_responses(str(model_osim), x, exercises, finger=str(patient.get("finger", "F3")),
                                  scaling_cfg=scaling, anthropometry=anthropometry)
    else:
        log.info("patient %s: %s", patient_name, why)
    with open_result(moments_nc) as m, open_result(rsm_nc) as r:
        ds = patient_loads.joint_loads(
            patient, m.load(), r.load(), design, exercises, anthropometry["measures"],
            anthropometry.get("coded_unit_sd", 1.0), prediction_alpha, name=patient_name, direct=direct,
        )
    ds.attrs.update({"fidelity": method, "fidelity_reason": why})
    write_dataset(ds, out, rule=rule, config_slice=config_slice,
                  title=f"Joint loads and safety limits of patient {patient_name}")
    if plot is not None:
        from .plots import plot_joint_loads
        plot_joint_loads(ds, plot)
    return ds
