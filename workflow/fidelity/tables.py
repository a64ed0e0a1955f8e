"""The fidelity study's tables: the FE cases side by side, the musculoskeletal
quantities compared, the reference value of each quantity.

Units: wall time s, angles deg, moments N m, pressures kPa.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.common import fidelity_choice
from workflow.common.constants import JOINTS
from workflow.fidelity import analysis as FD
from workflow.musculoskeletal.moments import ACTIVATIONS, response_angles, response_name

__all__ = ["fem_table"]


# --------------------------------------------------------------------------
# FE unit: one case, the table, the choice
# --------------------------------------------------------------------------
def fem_table(cases: Sequence[xr.Dataset]) -> xr.Dataset:
    """The cases on one table (case, quantity) with errors against each model's converged value.

    Reference per model and quantity: the generalised Richardson extrapolation
    (`workflow.fidelity.richardson`) from the three finest meshes *with
    contact* that reached that point, when they converge monotonically with an
    observed order in [0.5, 6]; otherwise the finest of them (contact is part
    of the physics; cases without it are compared with it).  ``error`` =
    relative error; NaN where the case did not reach the point or, without an
    extrapolation, is finer than the reference.
    """
    names = [str(c.attrs["case"]) for c in cases]
    parsed = [fidelity_choice.FemCase.parse(n) for n in names]
    vals = np.full((len(cases), len(FD.UNIT_QUANTITIES)), np.nan)
    for i, c in enumerate(cases):
        q = FD.unit_quantities(c["bending_angle_deg"].values, c["bending_moment_nm"].values, c["p_top_kpa"].values)
        vals[i] = [q[k] for k in FD.UNIT_QUANTITIES]
    err = np.full_like(vals, np.nan)
    ref_name = np.full(vals.shape, "", dtype=object)
    ref_val, order, gci = np.full(vals.shape, np.nan), np.full(vals.shape, np.nan), np.full(vals.shape, np.nan)
    for model in sorted({c.model for c in parsed}):
        rows = [i for i, c in enumerate(parsed) if c.model == model]
        for j in range(vals.shape[1]):
            cands = sorted(
                [i for i in rows if parsed[i].contact and np.isfinite(vals[i, j])], key=lambda i: parsed[i].h_mm
            )
            if not cands:
                continue
            r = cands[0]
            rich = FD.richardson([parsed[i].h_mm for i in cands[:3]], vals[cands[:3], j]) if len(cands) >= 3 else None
            extrapolated = rich is not None and rich.asymptotic
            ref = rich.limit if extrapolated else vals[r, j]
            label = (
                ("richardson(" + ", ".join(f"{parsed[i].h_mm:g}" for i in cands[:3]) + " mm)")
                if extrapolated
                else names[r]
            )
            for i in rows:
                ref_name[i, j], ref_val[i, j] = label, ref
                if rich is not None:
                    order[i, j], gci[i, j] = rich.order, rich.gci_fine
                if i == r and not extrapolated:
                    err[i, j] = 0.0
                elif not extrapolated and parsed[i].contact and parsed[i].h_mm <= parsed[r].h_mm:
                    continue  # a finer case the reference could not be compared with
                else:
                    err[i, j] = FD.relative_errors(vals[i, j], ref)
    wall = np.array([float(c["case_wall_time_s"]) for c in cases])
    conv = np.array([bool(np.all(c["status"].values == 0)) for c in cases])
    return xr.Dataset(
        {
            "value": (
                ("case", "quantity"),
                vals,
                {
                    "units": "deg or N m",
                    "long_name": "free angle per unit (angle_*) / blocked moment per unit (moment_*), P_B = 0",
                },
            ),
            "error": (
                ("case", "quantity"),
                err,
                {"units": "1", "long_name": "relative error against the model's finest converged case with contact"},
            ),
            "reference_case": (
                ("case", "quantity"),
                ref_name,
                {
                    "units": "1",
                    "long_name": "reference: Richardson extrapolation from three meshes, or the finest case",
                },
            ),
            "reference_value": (
                ("case", "quantity"),
                ref_val,
                {"units": "deg or N m", "long_name": "reference value of the model and quantity"},
            ),
            "observed_order": (
                ("case", "quantity"),
                order,
                {"units": "1", "long_name": "observed order of convergence of the three finest meshes with contact"},
            ),
            "gci_fine": (
                ("case", "quantity"),
                gci,
                {
                    "units": "1",
                    "long_name": "grid convergence index of the finest mesh (Celik et al. 2008, safety factor 1.25)",
                },
            ),
            "wall_time_s": ("case", wall, {"units": "s", "long_name": "wall time of the case (free and blocked rays)"}),
            "converged": ("case", conv, {"units": "1", "long_name": "every study point reached in both rays"}),
            "model": (
                "case",
                np.array([c.model for c in parsed], dtype=object),
                {"units": "1", "long_name": "2d or 3d"},
            ),
            "h_mm": ("case", np.array([c.h_mm for c in parsed]), {"units": "mm", "long_name": "element size"}),
            "contact": (
                "case",
                np.array([c.contact for c in parsed]),
                {"units": "1", "long_name": "self-contact across the gaps"},
            ),
        },
        coords={"case": names, "quantity": list(FD.UNIT_QUANTITIES)},
    )


# --------------------------------------------------------------------------
# Musculoskeletal: response surfaces against direct OpenSim sampling
# --------------------------------------------------------------------------
def _msk_quantities(
    exercises: Mapping[str, Mapping[str, float]], finger: str
) -> list[tuple[str, str, str, str, float]]:
    """(quantity, response name, kind P/A, joint, angle) for every passive target and active limit."""

    out = []
    angles = response_angles(exercises)
    for kind in ("P", "A"):
        for joint in JOINTS:
            for a in angles[kind][joint]:
                out.append(
                    (
                        f"{'passive' if kind == 'P' else 'active'}_{joint}_{a:g}",
                        response_name(finger, ACTIVATIONS[kind], joint, a),
                        kind,
                        joint,
                        float(a),
                    )
                )
    return out


# --------------------------------------------------------------------------
# Everything on one table
# --------------------------------------------------------------------------
def _model_cases(table: xr.Dataset, model: str) -> xr.Dataset:
    """The FE table's rows of one model (2d / 3d)."""
    return table.isel(case=np.flatnonzero(table["model"].values == model))


def _reference_values(fem: xr.Dataset, model: str) -> dict[str, float]:
    """Per unit quantity, the value of the model's reference case (the one with error 0)."""
    sel = _model_cases(fem, model)
    out = {}
    for q in FD.UNIT_QUANTITIES:
        r = np.flatnonzero(sel["error"].sel(quantity=q).values == 0.0)
        out[q] = float(sel["value"].sel(quantity=q).values[r[0]]) if r.size else np.nan
    return out
