"""What an FEA check of a plan concluded per exercise: the state after its correction step where that step ran,
else the first solve.

One place for that choice, read by the studies that compare checks (the authors' settings, the layout choice). The
check writes both states (:mod:`.run`, :mod:`.correction`). Pure: dataset in, dataset out.
"""

from __future__ import annotations

import xarray as xr

from workflow.common.constants import JOINTS

__all__ = ["final_outcome"]


def final_outcome(check: xr.Dataset) -> xr.Dataset:
    """Per exercise: ``reached`` (bool; within the check's tolerance with the safety limits held) and ``angle_deg``
    (exercise, joint = MCP, PIP, DIP; degrees), after the correction step where it ran, else the first solve. The
    attribute ``corrected`` says which."""
    corrected = "corrected_angle_deg" in check
    angle = check["corrected_angle_deg"] if corrected else check["angle_deg"]
    reached = check["achieved_corrected"] if corrected else check["achieved"]
    return xr.Dataset(
        {"angle_deg": angle.sel(joint=list(JOINTS)).astype(float), "reached": reached.astype(bool)},
        attrs={"corrected": int(corrected)},
    )
