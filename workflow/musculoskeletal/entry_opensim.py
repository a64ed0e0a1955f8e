"""Rule entry points of the OpenSim backend (``opensim_model``,
``opensim_sample``, ``opensim_merge``): write the reference model, one sampled
CCD run, the merged moments.

Apart from :mod:`.entry` so that the OpenSim sampling (minutes) does not rerun
when the response surfaces' code changes.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Sequence

import xarray as xr

from workflow.common.provenance import open_result, write_dataset
from workflow.common.runlog import solved
from workflow.musculoskeletal import opensim_model as om
from workflow.musculoskeletal.opensim_backend import (
    angle_grid,
    merge_runs,
    reference_scale_factors,
    sample_run,
    scale_factors_of_run,
)

__all__ = ["write_reference_model", "write_run", "write_merged"]

log = logging.getLogger(__name__)


def _scaling_table(scaling_nc: str | Path) -> xr.Dataset:

    with open_result(scaling_nc) as s:
        return s.load()


def write_reference_model(
    parameters: str | Path,
    scaling_nc: str | Path,
    out: str | Path,
    *,
    fingers: Sequence[str],
    reference_marker: str = "Original",
) -> Path:
    """Rule ``opensim_model``: the reference ``.osim`` (mean finger / the reference run's factors)."""
    params = om.load_parameters(parameters)
    ref = reference_scale_factors(_scaling_table(scaling_nc), reference_marker)
    path = om.write_model(params, out, fingers, ref)
    log.info("wrote %s (fingers %s, reference factors %s)", path, list(fingers), ref)
    return path


def write_run(
    model_path: str | Path,
    scaling_nc: str | Path,
    run: int,
    out: str | Path,
    *,
    fingers: Sequence[str],
    angle_step_deg: float,
    activations: Sequence[float],
    include_gravity: bool,
    rule: str,
    config_slice: Any,
) -> xr.Dataset:
    """Rule ``opensim_sample``: one CCD run's moment-angle curves -> ``run{run}.nc``."""

    scaling = _scaling_table(scaling_nc)
    factors = scale_factors_of_run(scaling, int(run))
    ds = sample_run(model_path, factors, int(run), fingers, angle_grid(angle_step_deg), activations, include_gravity)
    marker = str(scaling["marker"].sel(run=int(run)).values)
    ds = ds.assign_coords(marker=marker)
    # The reference model carries the parameter file's content: hash it with the config slice.
    config_slice = {"config": config_slice, "reference_model_sha256": _sha256(model_path)}
    n_fail = int((ds["status"] == 1).sum())
    log.info(
        "run %s (%s): %d samples in %.2f s, %d failed equilibria",
        run,
        marker,
        int((ds["status"] == 0).sum()),
        float(ds["wall_time_s"]),
        n_fail,
        extra=solved(n_fail, n=int((ds["status"] == 0).sum()) + n_fail),
    )
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice=config_slice,
        title=f"OpenSim finger moments, CCD run {run} ({marker})",
        source="finger-rehab-workflow generated OpenSim finger model (opensim backend)",
    )
    return ds


def _sha256(path: str | Path) -> str:
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def write_merged(run_files: Sequence[str | Path], out: str | Path, *, rule: str, config_slice: Any) -> xr.Dataset:
    """Rule ``opensim_merge``: the per-run files -> ``moments_opensim.nc`` (``moments.nc`` layout)."""

    parts = []
    for f in run_files:
        with open_result(f) as d:
            parts.append(d.load())
    ds = merge_runs(parts)
    # Encodings read from the per-run files (e.g. a 2-character string width for
    # the marker "DM") must not constrain the merged file.
    for v in ds.variables.values():
        v.encoding = {}
    ds.attrs["backend"] = "opensim"
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice=config_slice,
        title="Joint moments at the CCD runs (OpenSim backend, generated finger model)",
        source="finger-rehab-workflow generated OpenSim finger model (opensim backend)",
    )
    return ds
