"""Joint moments of one patient sampled directly from the OpenSim model (no response surface).

The reference model is scaled to the patient's coded levels by the same law
as the CCD runs (:func:`workflow.doe.scale_factors`) and sampled at the
exercises' target angles: what the response surfaces approximate, at the cost
of an OpenSim model build and a few equilibria (about 2 s) instead of a
polynomial (milliseconds).  Used by the fidelity study and, where
the response surfaces are not trusted, by the patient's loads.

Moments in N m (the flexion moment a device applies to hold the joint, as
``moments.nc``), angles in degrees.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import pandas as pd
import xarray as xr

from workflow.doe import ccd as doe
from workflow.musculoskeletal.opensim_backend import sample_finger

from .moments import ACTIVATIONS, JOINTS, response_angles

__all__ = ["patient_scale_factors", "direct_responses", "loads_method"]


def patient_scale_factors(
    x: Mapping[str, float], scaling_cfg: Mapping, anthropometry: Mapping
) -> dict[str, tuple[float, float, float]]:
    """OpenSim scale factors {body: (sX, sY, sZ)} at coded levels ``x`` (the CCD's scaling law)."""
    levels = pd.DataFrame([{k: float(x[k]) for k in doe.FACTORS}])
    scale = doe.scale_factors(
        levels, scaling_cfg, anthropometry["measures"], float(anthropometry.get("coded_unit_sd", 1.0))
    )
    return {str(b): tuple(float(v) for v in scale.sel(run=0, body=b).values) for b in scale["body"].values}


def direct_responses(
    model_osim: str,
    x: Mapping[str, float],
    exercises: Mapping,
    *,
    finger: str,
    scaling_cfg: Mapping,
    anthropometry: Mapping,
) -> dict[tuple[str, str, float], float]:
    """{(kind "P"/"A", joint, angle): moment} at every response angle of the exercises, sampled directly."""

    want = response_angles(exercises)
    angles: Sequence[float] = sorted({a for kind in want.values() for v in kind.values() for a in v})
    s = sample_finger(
        model_osim, patient_scale_factors(x, scaling_cfg, anthropometry), angles, tuple(ACTIVATIONS.values()), (finger,)
    )
    out = {}
    for kind, act in ACTIVATIONS.items():
        for joint in JOINTS:
            for a in want[kind][joint]:
                out[kind, joint, float(a)] = float(
                    np.asarray(s["moment_nm"].sel(finger=finger, joint=joint, angle_deg=a, activation=act))
                )
    return out


def loads_method(
    study: xr.Dataset | None, x: Mapping[str, float], tolerance: float, *, model_available: bool
) -> tuple[str, str]:
    """("rsm" or "opensim_direct", why) for one patient from the musculoskeletal study.

    ``study``: the dataset of :func:`workflow.fidelity.entry.write_msk_study`.
    The response surfaces (the selected form per response) are used where the
    study found their largest error, over its test patients on the same side
    of the design region's boundary as this patient, within ``tolerance``;
    otherwise the patient is sampled directly (when there is a model).
    """
    if study is None:
        return "rsm", "response surfaces (fidelity.auto off)"
    inside = bool(np.linalg.norm([float(v) for v in x.values()]) <= 1 + 1e-9)
    where = "inside" if inside else "outside"
    s = study
    sel = s["inside_design"].values.astype(bool) == inside
    e = s["rel_error"].sel({"method": "msk_rsm_selected"}).values[sel]
    t_rsm = float(np.nanmean(s["wall_time_s"].sel({"method": "msk_rsm_selected"})))
    t_dir = float(np.nanmean(s["wall_time_s"].sel({"method": "msk_opensim"})))
    err = float(np.nanmax(e)) if e.size and np.isfinite(e).any() else np.nan
    if np.isfinite(err) and err <= tolerance:
        return "rsm", (
            f"response surfaces: their largest error at the study's test patients {where} the design "
            f"region is {100 * err:.2f} % <= {100 * tolerance:g} % ({t_rsm * 1e3:.0f} ms vs {t_dir:.1f} s direct)"
        )
    if not model_available:
        return "rsm", (
            f"response surfaces although their error {where} the design region is "
            f"{'unknown' if not np.isfinite(err) else f'{100 * err:.1f} %'}: no OpenSim model to sample directly"
        )
    return "opensim_direct", (
        f"direct OpenSim sampling: the response surfaces' largest error {where} the design "
        f"region is {'unknown' if not np.isfinite(err) else f'{100 * err:.1f} %'} > "
        f"{100 * tolerance:g} % ({t_dir:.1f} s instead of {t_rsm * 1e3:.0f} ms)"
    )
