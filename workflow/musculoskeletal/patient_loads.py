"""Per-patient joint loads from the response surfaces.

For each exercise and joint: the passive moment at the target angle (0 at a
0 deg target by definition) with its prediction interval;
per joint the active safety limit = the magnitude of the active moment at the
joint's largest target angle.  All moments in N m, positive = flexion.
"""

from __future__ import annotations

import logging
from typing import Mapping

import numpy as np
import pandas as pd
import xarray as xr

from workflow.doe import ccd as doe

from . import rsm
from .moments import JOINTS, parse_response, response_angles, response_name, responses_from_moments

__all__ = ["patient_levels", "joint_loads"]

log = logging.getLogger(__name__)


def patient_levels(patient: Mapping, anthropometry: Mapping, coded_unit_sd: float) -> dict[str, float]:
    """Coded levels of a patient given as ``coded`` levels or ``measurements_mm``."""
    if "coded" in patient:
        return {f: float(patient["coded"][f]) for f in doe.FACTORS}
    return doe.coded_levels(patient["measurements_mm"], anthropometry, coded_unit_sd)


def joint_loads(
    patient: Mapping,
    moments: xr.Dataset,
    rsm_ds: xr.Dataset,
    design: pd.DataFrame,
    exercises: Mapping[str, Mapping[str, float]],
    anthropometry: Mapping,
    coded_unit_sd: float = 1.0,
    prediction_alpha: float = 0.05,
    name: str = "patient",
    direct: Mapping[tuple[str, str, float], float] | None = None,
) -> xr.Dataset:
    """The contract's ``joint_loads.nc`` for one patient.

    The response surfaces are refitted from ``moments`` (15 points, cheap and
    exact) in the form ``rsm_ds`` selected for each response.  ``direct``
    ({(kind "P"/"A", joint, angle): N m}, from
    :func:`workflow.musculoskeletal.direct.direct_responses`) replaces them by
    the patient's own sampled moments: the prediction interval is then the
    value itself and ``rsm_form`` says ``opensim_direct``.
    """
    finger = patient.get("finger", "F3")
    x = patient_levels(patient, anthropometry, coded_unit_sd)
    flags = doe.design_region_flags(x)
    if not flags["in_sphere"]:
        log.warning(
            "patient %s: coded levels %s lie outside the design region (||x|| = %.3f > 1); "
            "the response surfaces extrapolate",
            name,
            {k: round(v, 3) for k, v in x.items()},
            float(np.linalg.norm(list(x.values()))),
        )
    responses = responses_from_moments(moments, exercises)
    ex_names = list(exercises)
    shape = (len(ex_names), len(JOINTS))
    mean, lo, hi = np.full(shape, np.nan), np.full(shape, np.nan), np.full(shape, np.nan)
    form_used = np.full(shape, "", dtype=object)

    def _predict(resp: str):
        if direct is not None:
            _, act, joint, angle = parse_response(resp)
            key = ("P" if act < 0.5 else "A", joint, float(angle))
            if key in direct:
                v = float(direct[key])
                return (v, v, v), "opensim_direct"
        if resp not in responses:
            return (np.nan, np.nan, np.nan), "missing"
        form = str(rsm_ds["form"].values[int(np.argmax(rsm_ds["selected"].sel(response=resp).values))])
        res = rsm.fit_response(design, responses[resp], form)
        return rsm.predict(res, x, prediction_alpha), form

    for i, ex in enumerate(ex_names):
        for j, joint in enumerate(JOINTS):
            angle = float(exercises[ex][joint.lower()])
            if angle == 0:
                mean[i, j] = lo[i, j] = hi[i, j] = 0.0
                form_used[i, j] = "zero_by_definition"
                continue
            (m, l, h), form = _predict(response_name(finger, 0.01, joint, angle))
            if form == "missing":
                log.warning(
                    "patient %s: no passive response %s for %s", name, response_name(finger, 0.01, joint, angle), ex
                )
            mean[i, j], lo[i, j], hi[i, j], form_used[i, j] = m, l, h, form
    limit, limit_lo, limit_angle = np.full(3, np.nan), np.full(3, np.nan), np.full(3, np.nan)
    for j, joint in enumerate(JOINTS):
        angles = response_angles(exercises)["A"][joint]
        if not angles:
            continue
        limit_angle[j] = angles[0]
        (m, l, h), form = _predict(response_name(finger, 1.0, joint, angles[0]))
        # A limit is a magnitude: a backend may report the active moment with the
        # sign of the device's hold (negative when the flexors win), the authors'
        # export as a positive number. The conservative bound is the smaller magnitude
        # within the prediction interval (0 if the interval straddles zero).
        limit[j] = abs(m)
        limit_lo[j] = 0.0 if l <= 0 <= h else min(abs(l), abs(h))
    ds = xr.Dataset(
        {
            "x": ("dimension", [x[f] for f in doe.FACTORS], {"units": "1", "long_name": "coded finger dimension"}),
            "passive_moment_nm": (
                ("exercise", "joint"),
                mean,
                {"units": "N m", "long_name": "predicted passive joint moment at the target angle"},
            ),
            "passive_moment_lo_nm": (
                ("exercise", "joint"),
                lo,
                {
                    "units": "N m",
                    "long_name": f"lower {100 * (1 - prediction_alpha):g} % prediction bound of the passive moment",
                },
            ),
            "passive_moment_hi_nm": (
                ("exercise", "joint"),
                hi,
                {
                    "units": "N m",
                    "long_name": f"upper {100 * (1 - prediction_alpha):g} % prediction bound of the passive moment",
                },
            ),
            "rsm_form": (("exercise", "joint"), form_used.astype(str), {"long_name": "response-surface form used"}),
            "active_limit_nm": (
                "joint",
                limit,
                {
                    "units": "N m",
                    "long_name": "active safety limit: magnitude of the active moment at the joint's largest target angle",
                },
            ),
            "active_limit_lo_nm": (
                "joint",
                limit_lo,
                {
                    "units": "N m",
                    "long_name": "smallest magnitude of the active moment within its prediction interval (conservative limit)",
                },
            ),
            "active_limit_angle_deg": (
                "joint",
                limit_angle,
                {"units": "degree", "long_name": "angle at which the active limit is read"},
            ),
            "target_angle_deg": (
                ("exercise", "joint"),
                np.array([[float(exercises[e][j.lower()]) for j in JOINTS] for e in ex_names]),
                {"units": "degree", "long_name": "target joint angle (Table 1)"},
            ),
            "in_design_range": (
                (),
                flags["in_sphere"] and flags["in_box"],
                {"long_name": "coded levels inside the CCD sphere (||x|| <= 1, |x_i| <= 1)"},
            ),
        },
        coords={"exercise": ex_names, "joint": list(JOINTS), "dimension": list(doe.FACTORS)},
    )
    ds.attrs.update({"patient": name, "finger": finger, "coded_norm": float(np.linalg.norm(list(x.values())))})
    return ds
