"""Entry point of the authors' settings study: read the variants' FEA checks, write the joined dataset, its table
(HTML, for the report) and its figure."""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from pathlib import Path

import pandas as pd

from workflow.authors_study.plots import plot_study
from workflow.authors_study.summary import study_dataset
from workflow.common.html import write_html
from workflow.common.provenance import open_result, write_dataset

__all__ = ["study_table", "write_authors_study"]

log = logging.getLogger(__name__)


def study_table(ds) -> pd.DataFrame:
    """One row per variant and exercise: angles reached, reached, load factor, largest strap force and moment share."""
    rows = []
    for v in ds["variant"].values:
        for e in ds["exercise"].values:
            s = ds.sel(variant=v, exercise=e)
            rows.append(
                {
                    "variant": str(v),
                    "exercise": str(e),
                    "MCP / PIP / DIP (deg)": " / ".join(f"{a:.1f}" for a in s["angle_deg"].values),
                    "target (deg)": " / ".join(f"{a:.0f}" for a in s["target_angle_deg"].values),
                    "reached": bool(s["reached"]),
                    "load factor": float(s["load_factor"]),
                    "largest strap force (N)": float(s["max_strap_force_n"]),
                    "largest moment / limit": float(s["moment_share_of_limit"]),
                    "why not reached (first solve)": str(s["reason"].item()),
                }
            )
    return pd.DataFrame(rows).set_index(["variant", "exercise"])


def write_authors_study(
    check_ncs: Mapping[str, str | Path],
    changes: Mapping[str, Sequence[str]],
    *,
    patient: str,
    out_nc: str | Path,
    out_png: str | Path,
    out_html: str | Path,
    config_slice,
    rule: str = "authors_study_table",
):
    """Join ``check_ncs`` (variant -> fea_check.nc) into ``out_nc`` with a table and a figure."""
    checks = {v: open_result(p) for v, p in check_ncs.items()}
    ds = study_dataset(checks, changes)
    ds.attrs["patient"] = patient
    for v in ds["variant"].values:
        s = ds.sel(variant=v)
        log.info(
            "%s: reached %s; %s",
            v,
            ", ".join(str(e) for e in s["exercise"].values[s["reached"].values]) or "none",
            s["changes"].item() or "our default model",
        )
    write_dataset(
        ds,
        out_nc,
        rule=rule,
        config_slice=config_slice,
        title="The FEA check with the authors' 2D settings one at a time",
        source="settings of the authors' 2D generator, github.com/sbcglacier/Africomp (Chung & Venter 2024)",
    )
    changes_df = pd.DataFrame(
        {"variant": [str(v) for v in ds["variant"].values], "config keys changed": list(ds["changes"].values)}
    ).set_index("variant")
    write_html(
        out_html,
        f"The authors' settings one at a time: the FEA check of patient {patient}",
        [("What each variant changes", changes_df), ("Per variant and exercise", study_table(ds))],
        notes=[
            "Each variant is our default model with one setting of the authors' published 2D generator switched; "
            "'all' switches every one. Angles after the correction step where it ran; reached = every joint within "
            "the tolerance and every actuator moment within its active limit."
        ],
    )
    plot_study(ds, out_png, title=f"Authors' settings one at a time, patient {patient}")
    return ds
