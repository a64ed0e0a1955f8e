"""Failure, locking and penetration tables from every FE sample the workflow
solved (sweeps, unit check, FE study, extra rays).

Status codes are the sweep's (:data:`workflow.common.constants.SWEEP_SAMPLE_STATUS`,
0 = converged).  Units: kPa, deg, mm.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.common.constants import SWEEP_SAMPLE_STATUS
from workflow.stability.rays import LOCKING_FORMULATIONS, method_name, ray_last_converged_kpa

__all__ = ["fe_samples", "failure_counts", "locking_dataset", "locking_ratio", "penetration_summary"]


def _add_unit_cases(add, name: str, ds: xr.Dataset) -> None:
    """Add a unit check's (or FE-study case's) rays, one per case; their statuses are workflow.fem's, so any stall
    counts as a divergence here."""
    for case in ds["case"].values:
        d = ds.sel(case=case)
        st = np.where(d["status"].values == 0, 0, np.where(d["status"].values == 3, 3, 1))
        n = d.sizes["p_top_kpa"]
        pb = np.full(n, float(d["p_bottom_kpa"]))
        add(
            name,
            str(case),
            d["p_top_kpa"].values,
            pb,
            st,
            np.zeros(n, bool),
            d["max_penetration_mm"].values,
            np.zeros(n, int),
        )


def fe_samples(sources: Sequence[tuple[str, xr.Dataset]]) -> xr.Dataset:
    """Every FE sample of every method in one long table on ``sample``.

    ``sources``: (kind, dataset) with kind ``sweep`` (a ``response_{fea}.nc``,
    attrs ``fea``, ``h_mm``, ``contact`` set by the caller), ``rays``
    (`rays_dataset`) or ``unit_check`` (``unit_check.nc``, attrs ``h_2d_mm``,
    ``h_3d_mm``, ``contact``).  Variables: ``method``, ``case`` (``free``,
    ``blocked`` or ``free+blocked``), ``p_top_kpa``, ``p_bottom_kpa``,
    (kind ``fem_case``: one case file of the fidelity study, attrs ``model``,
    ``h_mm``, ``contact``),
    ``status``, ``mirrored``, ``max_penetration_mm`` (NaN where the source
    does not record it), ``ray_last_converged_kpa``.
    """
    cols: dict[str, list] = {
        k: []
        for k in (
            "method",
            "case",
            "p_top_kpa",
            "p_bottom_kpa",
            "status",
            "mirrored",
            "max_penetration_mm",
            "ray_last_converged_kpa",
        )
    }

    def add(method, case, pt, pb, st, mir, pen, ray):
        n = np.size(pt)
        pt, pb, st = np.ravel(pt), np.ravel(pb), np.ravel(st)
        cols["method"] += [method] * n
        cols["case"] += [case] * n if isinstance(case, str) else list(case)
        cols["p_top_kpa"] += list(pt)
        cols["p_bottom_kpa"] += list(pb)
        cols["status"] += list(st.astype(int))
        cols["mirrored"] += list(np.ravel(mir).astype(bool))
        cols["max_penetration_mm"] += list(np.ravel(pen).astype(float))
        cols["ray_last_converged_kpa"] += list(ray_last_converged_kpa(np.ravel(ray), pt, pb, st))

    for kind, ds in sources:
        if kind == "sweep":
            name = method_name("sweep", ds.attrs["fea"], float(ds.attrs["h_mm"]), bool(ds.attrs["contact"]))
            n = ds.sizes["point"]
            pen = ds["max_penetration_mm"].values if "max_penetration_mm" in ds else np.full(n, np.nan)
            # a mirrored sample belongs to its twin's ray, mirrored: keep rays apart by the mirror flag
            ray = ds["ray"].values * 2 + ds["mirrored"].values.astype(int) if "ray" in ds else np.arange(n)
            add(
                name,
                "free+blocked",
                ds["p_top_kpa"].values,
                ds["p_bottom_kpa"].values,
                ds["status"].values,
                ds["mirrored"].values,
                pen,
                ray,
            )
        elif kind == "rays":
            for r in ds["ray"].values:
                d = ds.sel(ray=r)
                name = method_name("rays", "2d", float(d["h_mm"]), bool(d["contact"]), str(d["formulation"].values))
                add(
                    name,
                    "free",
                    d["p_top_kpa"].values,
                    d["p_bottom_kpa"].values,
                    d["status"].values,
                    np.zeros(d.sizes["scale"], bool),
                    d["max_penetration_mm"].values,
                    np.zeros(d.sizes["scale"], int),
                )
        elif kind == "unit_check":
            for model in ds["model"].values:
                h = float(ds.attrs["h_2d_mm"] if str(model) == "2d" else ds.attrs["h_3d_mm"])
                name = method_name("unit check", str(model), h, bool(ds.attrs["contact"]))
                _add_unit_cases(add, name, ds.sel(model=model))
        elif kind == "fem_case":  # one fidelity-study case (workflow.fidelity.entry_fem.write_fem_case)
            name = method_name(
                "fidelity study", str(ds.attrs["model"]), float(ds.attrs["h_mm"]), bool(int(ds.attrs["contact"]))
            )
            _add_unit_cases(add, name, ds)
        else:
            raise ValueError(f"unknown source kind {kind!r}")
    n = len(cols["method"])
    flag_vals = np.array(sorted(SWEEP_SAMPLE_STATUS), dtype=np.int32)
    return xr.Dataset(
        {
            "method": (
                "sample",
                np.array(cols["method"], dtype=object),
                {"long_name": "FE method (source, model, mesh, contact, formulation)"},
            ),
            "case": ("sample", np.array(cols["case"], dtype=object), {"long_name": "load case(s) the status covers"}),
            "status": (
                "sample",
                np.array(cols["status"], np.int32),
                {
                    "long_name": "sample status",
                    "flag_values": flag_vals,
                    "flag_meanings": " ".join(SWEEP_SAMPLE_STATUS[int(k)] for k in flag_vals),
                },
            ),
            "mirrored": ("sample", np.array(cols["mirrored"], bool), {"long_name": "copied from its (P_B, P_T) twin"}),
            "max_penetration_mm": (
                "sample",
                np.array(cols["max_penetration_mm"], float),
                {"units": "mm", "long_name": "largest contact penetration (NaN: not recorded)"},
            ),
            "ray_last_converged_kpa": (
                "sample",
                np.array(cols["ray_last_converged_kpa"], float),
                {
                    "units": "kPa",
                    "long_name": "larger chamber pressure at the last converged sample of the sample's ray",
                },
            ),
        },
        coords={
            "sample": np.arange(n),
            "p_top_kpa": ("sample", np.array(cols["p_top_kpa"], float), {"units": "kPa"}),
            "p_bottom_kpa": ("sample", np.array(cols["p_bottom_kpa"], float), {"units": "kPa"}),
        },
    )


def failure_counts(samples: xr.Dataset) -> xr.DataArray:
    """Number of solved (not mirrored) samples per method and status; dims ``fe_method``, ``status_code``.

    (Not ``method``: that is a keyword of xarray's ``sel``.)
    """
    methods = list(dict.fromkeys(samples["method"].values.tolist()))
    codes = sorted(SWEEP_SAMPLE_STATUS)
    solved = ~samples["mirrored"].values
    counts = np.zeros((len(methods), len(codes)), dtype=np.int32)
    for i, m in enumerate(methods):
        on = solved & (samples["method"].values == m)
        for j, c in enumerate(codes):
            counts[i, j] = int(np.count_nonzero(on & (samples["status"].values == c)))
    return xr.DataArray(
        counts,
        dims=("fe_method", "status_code"),
        coords={
            "fe_method": np.array(methods, dtype=str),
            "status_code": np.array(codes, np.int32),
            "status_meaning": ("status_code", [SWEEP_SAMPLE_STATUS[c] for c in codes]),
        },
        attrs={"units": "1", "long_name": "solved samples per method and status"},
    )


# ---------------------------------------------------------------------------
# 2. Locking
# ---------------------------------------------------------------------------
def locking_dataset(
    bulk_ratios: Sequence[float],
    angle_deg: Mapping[str, Sequence[float]],
    status: Mapping[str, Sequence[int]],
    *,
    p_top_kpa: float,
    h_mm: float,
    wall_time_s: Mapping[str, Sequence[float]] | None = None,
) -> xr.Dataset:
    """Free angle per unit (deg) on ``formulation`` x ``bulk_ratio`` (K/mu0), with the locking ratio.

    ``angle_deg`` / ``status`` map each of `LOCKING_FORMULATIONS` to one value
    per bulk ratio (status: workflow.fem's, 0 = converged; the angle of a
    failed solve is NaN).
    """
    k = np.asarray(bulk_ratios, float)
    forms = list(LOCKING_FORMULATIONS)
    ang = np.array([np.asarray(angle_deg[f], float) for f in forms])
    st = np.array([np.asarray(status[f], np.int32) for f in forms])
    ang = np.where(st == 0, ang, np.nan)
    data = {
        "bending_angle_deg": (
            ("formulation", "bulk_ratio"),
            ang,
            {"units": "degree", "long_name": f"free bending angle per unit at P_T = {p_top_kpa:g} kPa"},
        ),
        "status": (("formulation", "bulk_ratio"), st, {"long_name": "workflow.fem status (0 = converged)"}),
    }
    if wall_time_s is not None:
        data["wall_time_s"] = (
            ("formulation", "bulk_ratio"),
            np.array([np.asarray(wall_time_s[f], float) for f in forms]),
            {"units": "s"},
        )
    ds = xr.Dataset(
        data, coords={"formulation": forms, "bulk_ratio": ("bulk_ratio", k, {"units": "1", "long_name": "K / mu0"})}
    )
    ds["locking_ratio"] = locking_ratio(ds)
    ds["shear_locking_ratio"] = (
        (ds["bending_angle_deg"].sel(formulation="mixed") / ds["bending_angle_deg"].sel(formulation="enhanced_paper"))
        .drop_vars("formulation", errors="ignore")
        .assign_attrs(
            units="1", long_name="plain Q1 paper layer / enhanced-strain paper layer free angle (1 = no shear locking)"
        )
    )
    ds.attrs.update({"p_top_kpa": float(p_top_kpa), "p_bottom_kpa": 0.0, "h_mm": float(h_mm), "contact": 0})
    return ds


def locking_ratio(ds: xr.Dataset) -> xr.DataArray:
    """Displacement-formulation angle / mixed angle per bulk ratio (1 = no locking, -> 0 = locked)."""
    r = ds["bending_angle_deg"].sel(formulation="displacement") / ds["bending_angle_deg"].sel(formulation="mixed")
    return r.drop_vars("formulation", errors="ignore").assign_attrs(
        units="1", long_name="plain Q1 free angle / mean-dilatation free angle (1 = no locking)"
    )


# ---------------------------------------------------------------------------
# 3. Contact penetration
# ---------------------------------------------------------------------------
def penetration_summary(samples: xr.Dataset, bound_mm: float) -> xr.Dataset:
    """Largest penetration per method (converged samples with a record) and the samples above ``bound_mm``.

    Returns ``max_penetration_mm`` (fe_method; NaN if the method records
    none), ``n_above_bound`` (fe_method) and ``above_bound`` (sample).
    """
    methods = list(dict.fromkeys(samples["method"].values.tolist()))
    pen = samples["max_penetration_mm"].values
    ok = (samples["status"].values == 0) & np.isfinite(pen)
    above = ok & (pen > bound_mm)
    mx = np.full(len(methods), np.nan)
    n_above = np.zeros(len(methods), np.int32)
    for i, m in enumerate(methods):
        on = ok & (samples["method"].values == m)
        if on.any():
            mx[i] = float(pen[on].max())
        n_above[i] = int(np.count_nonzero(above & (samples["method"].values == m)))
    return xr.Dataset(
        {
            "max_penetration_mm": (
                "fe_method",
                mx,
                {"units": "mm", "long_name": "largest contact penetration over the converged samples"},
            ),
            "n_above_bound": (
                "fe_method",
                n_above,
                {"units": "1", "long_name": "converged samples above the penetration bound"},
            ),
            "above_bound": ("sample", above, {"long_name": f"penetration above {bound_mm:g} mm"}),
        },
        coords={"fe_method": np.array(methods, dtype=str)},
        attrs={"penetration_bound_mm": float(bound_mm)},
    )
