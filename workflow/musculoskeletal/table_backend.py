"""Joint moments from an OpenSim export in the authors' CSV layout.

Columns ``Depth, Length, Breadth, num`` (coded CCD levels and run number) and one
column per response ``F{n}_{P|A}_{JOINT}_{ANGLE}`` in N m (see
``resources/README.md``).  Trailing empty rows are ignored.  Rows are matched
to our CCD runs by their coded levels, not by position.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

from .moments import RESPONSE_RE, empty_moments, parse_response

__all__ = ["read_export", "moments_from_export"]


def read_export(path: str | Path) -> pd.DataFrame:
    """Read the export; raises FileNotFoundError / ValueError with the path named."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(
            f"joint-moment table {path} not found: set musculoskeletal.table_path to an OpenSim "
            "export in the authors' format, or use musculoskeletal.backend: opensim"
        )
    df = pd.read_csv(path).dropna(how="all")
    missing = {"Depth", "Length", "Breadth"} - set(df.columns)
    if missing:
        raise ValueError(f"{path}: missing columns {sorted(missing)}")
    if not any(RESPONSE_RE.match(c) for c in df.columns):
        raise ValueError(f"{path}: no response columns like F3_P_MCP_90")
    return df


def moments_from_export(df: pd.DataFrame, design: pd.DataFrame, tol: float = 1e-3) -> xr.Dataset:
    """Fill the ``moments.nc`` layout from the export for the runs of ``design``.

    ``design`` is the CCD (index ``run``, columns depth, length, breadth).  Each
    run takes the export row with the same coded levels (to ``tol``).
    """
    cols = [c for c in df.columns if RESPONSE_RE.match(c)]
    parsed = {c: parse_response(c) for c in cols}
    ds = empty_moments(design.index, {a for (_, _, _, a) in parsed.values()})
    levels = df[["Depth", "Length", "Breadth"]].to_numpy(float)
    for run, row in design.iterrows():
        d = np.abs(levels - row[["depth", "length", "breadth"]].to_numpy(float)).max(axis=1)
        hits = np.flatnonzero(d < tol)
        if len(hits) != 1:
            raise ValueError(f"run {run} ({row['marker']}): {len(hits)} export rows match its coded levels")
        for c, (finger, act, joint, angle) in parsed.items():
            ds["moment_nm"].loc[dict(run=run, finger=finger, joint=joint, angle_deg=angle, activation=act)] = float(
                df.iloc[hits[0]][c]
            )
    return ds
