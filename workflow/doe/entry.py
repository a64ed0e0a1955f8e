"""Rule entry points of the DOE stage: the design, the scale factors per run, their check against Tables 3-4.

Each function reads its inputs from paths, calls the pure science in
:mod:`workflow.doe.ccd`, and writes one dataset
with provenance.  The Snakemake ``script:`` adapters call exactly one of them;
tests call them directly.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Mapping

import pandas as pd
import xarray as xr

from workflow.common.provenance import open_result, write_dataset
from workflow.doe import ccd as doe

__all__ = ["design_from_ccd", "write_ccd", "write_scaling", "write_scaling_validation"]

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
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice={"design": dict(design_cfg)},
        title="Central composite design of finger depth, length and breadth (coded levels)",
    )
    log.info("wrote %d CCD runs to %s", ds.sizes["run"], out)
    return ds


def write_scaling(
    ccd: str | Path, out: str | Path, scaling: Mapping, anthropometry: Mapping, *, rule: str = "scaling"
) -> xr.Dataset:
    design = design_from_ccd(ccd)
    u = anthropometry.get("coded_unit_sd", 1.0)
    scale = doe.scale_factors(design, scaling, anthropometry["measures"], u)
    ds = doe.scaling_dataset(design, scale)
    ds.attrs["coded_unit_sd"] = u
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice={"scaling": scaling, "anthropometry": anthropometry},
        title="OpenSim scale factors per CCD run, body and axis",
    )
    return ds


def write_scaling_validation(
    scaling_nc: str | Path, table_csv: str | Path, out: str | Path, *, rule: str = "validate_scaling"
) -> xr.Dataset:
    with open_result(scaling_nc) as s:
        scale = s["scale"].load()
        design = pd.DataFrame({"marker": s["marker"].values.astype(str)}, index=s["run"].values)
    table = pd.read_csv(table_csv)
    ds = doe.compare_with_table(scale, design, table)
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice={"reference": str(table_csv)},
        title="Scale factors against Tables 3-4 of Chung & Venter 2024",
    )
    log.info(
        "largest |ours - Tables 3-4| = %.4f (%.4f without the paper's inconsistent MP_Z cell)",
        ds.attrs["max_abs_error"],
        ds.attrs["max_abs_error_excluding_paper_inconsistency"],
    )
    return ds
