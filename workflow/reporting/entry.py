"""Rule entry points of the report's tables: read a dataset, build its table, write the HTML page."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import pandas as pd

from workflow.common.html import write_html
from workflow.common.provenance import open_result
from workflow.reporting.tables import TABLES

__all__ = ["write_table", "fidelity_choices_table"]


def write_table(name: str, dataset: str | Path, out: str | Path, title_suffix: str = "") -> Path:
    """Table ``name`` of `TABLES` from the netCDF file ``dataset`` to the HTML page ``out``."""
    title, parts, note_attrs = TABLES[name]
    with open_result(dataset) as ds:
        ds = ds.load()
    notes = [f"{a}: {ds.attrs[a]}" for a in note_attrs if a in ds.attrs]
    notes.append(
        f"source: {Path(dataset).as_posix()} (git {ds.attrs.get('git_commit', '?')}, "
        f"created {ds.attrs.get('created_utc', '?')})"
    )
    return write_html(out, title + title_suffix, [(cap, fn(ds)) for cap, fn in parts], notes)


def fidelity_choices_table(
    unit_check: str | Path,
    cv: str | Path,
    responses: Sequence[str | Path],
    loads: Sequence[str | Path],
    fea_check: str | Path | None = None,
) -> pd.DataFrame:
    """Which fidelity each stage used and why, read from the outputs' own attrs (``fidelity``, ``fidelity_reason``)."""
    rows = []

    def attrs(path):
        with open_result(path) as d:
            return dict(d.attrs)

    a = attrs(unit_check)
    for m in ("2d", "3d"):
        if f"fidelity_{m}" in a:
            rows.append(
                {
                    "stage": f"unit check, {m.upper()}",
                    "used": a[f"fidelity_{m}"],
                    "why": a.get(f"fidelity_reason_{m}", ""),
                }
            )
    for p in responses:
        a = attrs(p)
        rows.append(
            {
                "stage": f"sweep {a.get('fea', '?').upper()}",
                "used": a.get("fidelity", f"h = {a.get('h_mm', '?')} mm"),
                "why": a.get("fidelity_reason", ""),
            }
        )
    with open_result(cv) as c:
        for f in c["fea"].values:
            rows.append(
                {
                    "stage": f"surrogate {str(f).upper()}",
                    "used": str(c["chosen"].sel(fea=f).values),
                    "why": str(c["choice_reason"].sel(fea=f).values)
                    if "choice_reason" in c
                    else c.attrs.get("selection_rule", ""),
                }
            )
    for p in loads:
        a = attrs(p)
        rows.append(
            {
                "stage": f"joint loads, patient {a.get('patient', Path(p).parent.name)}",
                "used": a.get("fidelity", "rsm"),
                "why": a.get("fidelity_reason", ""),
            }
        )
    if fea_check:
        a = attrs(fea_check)
        rows.append(
            {
                "stage": f"FEA check, patient {a.get('patient', '?')}",
                "used": a.get("fidelity", ""),
                "why": a.get("fidelity_reason", ""),
            }
        )
    return pd.DataFrame(rows).set_index("stage")
