"""Rule entry point of the musculoskeletal fidelity study (``fidelity_msk``):
the response surfaces against direct OpenSim sampling at test patients.

Apart from :mod:`.entry`: it samples OpenSim (minutes), which should not rerun
when the speed-accuracy tables change.  Moments N m, wall times s.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.common.provenance import open_result, write_dataset
from workflow.common.runlog import solved
from workflow.doe import ccd as doe
from workflow.doe.entry import design_from_ccd
from workflow.fidelity.tables import _msk_quantities
from workflow.musculoskeletal import rsm
from workflow.musculoskeletal.direct import direct_responses
from workflow.musculoskeletal.moments import responses_from_moments

__all__ = ["write_msk_study"]

log = logging.getLogger(__name__)


def write_msk_study(
    out: str | Path,
    *,
    ccd_nc: str,
    moments_nc: str,
    rsm_nc: str,
    model_osim: str | None,
    points: Sequence[Mapping[str, float]],
    exercises: Mapping,
    scaling_cfg: Mapping,
    anthropometry: Mapping,
    finger: str,
    config_slice: Any,
    rule: str = "fidelity_msk",
) -> xr.Dataset:
    """Rule ``fidelity_msk``: each RSM form, and the selected one per response, against direct sampling.

    At test patients given by coded levels, inside and outside the design
    region.  Direct sampling (:mod:`workflow.musculoskeletal.direct`) is the
    reference.  Without a model (``table`` backend) only the RSM forms are
    timed and no error can be given (said so in the dataset and the log).
    Errors compare magnitudes (the active moments' sign is a backend convention).
    """

    design = design_from_ccd(ccd_nc)
    responses = responses_from_moments(open_result(moments_nc), exercises)
    rsm_ds = open_result(rsm_nc)
    quants = [q for q in _msk_quantities(exercises, finger) if q[1] in responses]
    forms = [str(f) for f in rsm_ds["form"].values]
    selected = {q[1]: forms[int(np.argmax(rsm_ds["selected"].sel(response=q[1]).values))] for q in quants}
    pts = [{k: float(p[k]) for k in doe.FACTORS} for p in points]
    norm = np.array([np.linalg.norm([p[k] for k in doe.FACTORS]) for p in pts])
    methods = [f"msk_rsm_{f}" for f in forms] + ["msk_rsm_selected", "msk_opensim"]
    vals = np.full((len(methods), len(pts), len(quants)), np.nan)
    wall = np.full((len(methods), len(pts)), np.nan)
    setup = np.zeros(len(methods))
    for m, form in enumerate(forms + ["selected"]):
        t0 = time.perf_counter()  # the surfaces are fitted once (the rsm rule's job), then queried per patient
        fits = [
            rsm.fit_response(design, responses[resp], selected[resp] if form == "selected" else form)
            for _, resp, *_rest in quants
        ]
        setup[m] = time.perf_counter() - t0
        for i, x in enumerate(pts):
            t0 = time.perf_counter()
            vals[m, i] = [rsm.predict(f, x)[0] for f in fits]
            wall[m, i] = time.perf_counter() - t0
    note = "direct OpenSim sampling at each test patient (reference)"
    if model_osim:
        for i, x in enumerate(pts):
            t0 = time.perf_counter()
            d = direct_responses(
                model_osim, x, exercises, finger=finger, scaling_cfg=scaling_cfg, anthropometry=anthropometry
            )
            vals[-1, i] = [d[kind, joint, a] for _, _, kind, joint, a in quants]
            wall[-1, i] = time.perf_counter() - t0
            log.info(
                "direct OpenSim at %s: %d responses, %.2f s",
                x,
                len(quants),
                wall[-1, i],
                extra=solved(int(np.sum(~np.isfinite(vals[-1, i]))), n=len(quants)),
            )
    else:
        note = "no OpenSim model (table backend): direct sampling not available, errors unknown"
        log.warning("fidelity_msk: %s", note)
    with np.errstate(invalid="ignore", divide="ignore"):
        err = np.abs(np.abs(vals) - np.abs(vals[-1][None])) / np.abs(vals[-1][None])
    inside = norm <= 1 + 1e-9
    ds = xr.Dataset(
        {
            "moment_nm": (
                ("method", "point", "quantity"),
                vals,
                {"units": "N m", "long_name": "joint moment at the target angle"},
            ),
            "rel_error": (
                ("method", "point", "quantity"),
                err,
                {"units": "1", "long_name": "relative error of the magnitude against direct sampling"},
            ),
            "wall_time_s": (
                ("method", "point"),
                wall,
                {
                    "units": "s",
                    "long_name": "time to give one patient's moments (RSM: predict with intervals; OpenSim: scale + sample)",
                },
            ),
            "setup_time_s": (
                "method",
                setup,
                {
                    "units": "s",
                    "long_name": "one-off cost (RSM: fitting the surfaces; OpenSim: 0, the model build is the CCD's)",
                },
            ),
            "coded": (
                ("point", "dimension"),
                np.array([[p[k] for k in doe.FACTORS] for p in pts]),
                {"units": "1", "long_name": "coded levels of the test patient"},
            ),
            "coded_norm": ("point", norm, {"units": "1", "long_name": "||x|| of the test patient"}),
            "inside_design": ("point", inside, {"units": "1", "long_name": "||x|| <= 1"}),
        },
        coords={
            "method": methods,
            "point": np.arange(len(pts)),
            "quantity": [q[0] for q in quants],
            "dimension": list(doe.FACTORS),
        },
    )
    ds.attrs.update({"finger": finger, "reference": "msk_opensim", "note": note})
    for m in methods[:-1]:
        e = ds["rel_error"].sel({"method": m})
        log.info(
            "%s: largest relative error inside %.3g, outside %.3g",
            m,
            float(e.where(ds["inside_design"]).max()),
            float(e.where(~ds["inside_design"]).max()),
        )
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice=config_slice,
        title="Response surfaces against direct OpenSim sampling at test patients",
    )
    return ds
