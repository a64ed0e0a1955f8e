"""Entry point of the layout choice: the FEA checks of the chain's best layouts and of the length rule's default read,
one chosen (:mod:`workflow.layout.choice`), the dataset and figure written. Angles deg, pressures kPa."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from workflow.common.constants import GROUPS, JOINTS
from workflow.common.provenance import open_result, write_dataset
from workflow.fea_check.outcome import final_outcome
from workflow.layout.choice import CheckedLayout, choose_layout, why_chosen
from workflow.layout.plots import plot_layouts
from workflow.layout.units import rank_index

__all__ = ["write_layout_choice"]

log = logging.getLogger(__name__)


def _fea_outcome(chk: xr.Dataset, ex: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Per exercise of ``ex`` reached by an FEA check and the joint angles (deg; NaN and not reached where the check
    has no such exercise)."""
    final = final_outcome(chk).reindex(exercise=list(ex))
    return final["reached"].fillna(False).values.astype(bool), final["angle_deg"].values


def write_layout_choice(
    search_nc: str | Path,
    check_ncs: Sequence[str | Path],
    *,
    out_nc: str | Path,
    out_png: str | Path,
    config_slice: Any,
    default_plan_nc: str | Path | None = None,
    default_check_nc: str | Path | None = None,
    rule: str = "layout_choice",
) -> xr.Dataset:
    """Choose among the layouts the FEA checked (:func:`workflow.layout.choice.choose_layout`): the chain's best
    (``check_ncs``, rank 0, 1, ...) and, when ``default_plan_nc`` and ``default_check_nc`` are given, the length
    rule's layout planned on the same chain and checked on the same mesh."""
    search = open_result(search_nc)
    ex = [str(e) for e in search["exercise"].values]
    rows, angles = [], []
    for k, path in enumerate(check_ncs):
        i = rank_index(search, k)
        fea, ang = _fea_outcome(open_result(path), ex)
        rows.append(
            CheckedLayout(
                f"rank {k}",
                tuple(int(v) for v in search["units"].values[i]),
                np.asarray(search["reached"].values[i], dtype=bool),
                fea,
                float(search["mean_pressure_kpa"].values[i]),
                k,
            )
        )
        angles.append(ang)
    if (default_plan_nc is None) != (default_check_nc is None):
        raise ValueError("layout choice: the default layout needs both its plan and its FEA check")
    if default_plan_nc is not None:
        plan = open_result(default_plan_nc)
        units = tuple(int(plan["units_per_group"].sel(group=g)) for g in GROUPS)
        hit = np.flatnonzero((search["units"].values == np.array(units)).all(axis=1))
        fea, ang = _fea_outcome(open_result(default_check_nc), ex)
        rows.append(
            CheckedLayout(
                "default",
                units,
                np.array([bool(plan["achieved"].sel(exercise=e)) for e in ex]),
                fea,
                float(plan["pressure_kpa"].mean()),
                int(search["rank"].values[hit[0]]) if hit.size else int(search.sizes["candidate"]),
            )
        )
        angles.append(ang)
    w = choose_layout(rows)
    why = why_chosen(rows, w, ex, int(search.sizes["candidate"]))
    ds = xr.Dataset(
        {
            "checked_label": ("checked", np.array([r.label for r in rows]), {"long_name": "why it was checked"}),
            "checked_units": (("checked", "group"), np.array([r.units for r in rows], dtype="i4")),
            "checked_chain_rank": (
                "checked",
                np.array([r.chain_rank for r in rows], dtype="i4"),
                {"units": "1", "long_name": "rank on the chain (the number of candidates: not one of them)"},
            ),
            "chain_reached": (("checked", "exercise"), np.array([r.chain_reached for r in rows])),
            "fea_reached": (("checked", "exercise"), np.array([r.fea_reached for r in rows])),
            "fea_angle_deg": (("checked", "exercise", "joint"), np.array(angles), {"units": "degree"}),
            "checked_mean_pressure_kpa": ("checked", np.array([r.mean_pressure_kpa for r in rows]), {"units": "kPa"}),
            "chosen_units": ("group", np.array(rows[w].units, dtype="i4")),
        },
        coords={
            "checked": np.arange(len(rows)),
            "group": search["group"].values,
            "exercise": ex,
            "joint": list(JOINTS),
        },
    )
    kept = search.drop_vars(["pressure_kpa", "pressure"], errors="ignore")
    ds = ds.merge(kept.rename({k: f"search_{k}" for k in kept.data_vars}))
    ds.attrs.update(
        {
            "patient": search.attrs.get("patient", ""),
            "chain": search.attrs.get("chain", ""),
            "chosen": rows[w].label,
            "why": why,
        }
    )
    log.info(
        "patient %s: chosen layout %s: %s",
        ds.attrs["patient"],
        dict(zip(GROUPS, ds["chosen_units"].values.tolist())),
        why,
    )
    write_dataset(ds, out_nc, rule=rule, config_slice=config_slice, title="The layout chosen by the FEA check")
    plot_layouts(ds, out_png)
    return ds
