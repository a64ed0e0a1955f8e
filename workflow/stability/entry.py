"""Rule entry point of the stability maps (the two FE studies are :mod:`.entry_fem`).

The science is in `workflow.stability` (pure functions: rays, samples, design) and the figures in
`workflow.stability.plots`; this module reads and writes files.  Units: kPa, degree, mm, N m.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd
import xarray as xr

from workflow.actuator import sampled_region
from workflow.common.fidelity_choice import FemCase
from workflow.common.html import write_html
from workflow.common.provenance import open_result, write_dataset
from workflow.stability import design as DR
from workflow.stability import plots as P
from workflow.stability import samples as SM

__all__ = ["write_stability", "summary_table"]

log = logging.getLogger(__name__)


def _sweep_with_mesh(path: str | Path, fea: str, actuator: Mapping[str, Any]) -> xr.Dataset:
    """The sweep with its mesh and contact: its own attrs (the fidelity it was solved with), else the config's."""
    ds = open_result(path)
    mesh = dict(actuator.get("mesh", {}))
    ds.attrs["fea"] = fea
    ds.attrs.setdefault("h_mm", float(mesh.get(f"h_{fea}_mm", 1.0 if fea == "2d" else 2.0)))
    ds.attrs["contact"] = bool(int(ds.attrs.get("contact", dict(actuator.get("contact", {})).get("enabled", True))))
    return ds


def _unit_check_mesh(uc: xr.Dataset, actuator: Mapping[str, Any]) -> xr.Dataset:
    """The unit check with its meshes: from its fidelity attrs (``fidelity_2d`` = a case name), else the config's."""

    mesh = dict(actuator.get("mesh", {}))
    contact = bool(dict(actuator.get("contact", {})).get("enabled", True))
    for m, default in (("2d", 1.0), ("3d", 2.0)):
        h = float(mesh.get(f"h_{m}_mm", default))
        name = str(uc.attrs.get(f"fidelity_{m}", ""))
        if name.startswith("fem_"):
            case = FemCase.parse(name)
            h, contact = case.h_mm, case.contact
        uc.attrs[f"h_{m}_mm"] = h
    uc.attrs["contact"] = contact
    return uc


def summary_table(ds: xr.Dataset) -> pd.DataFrame:
    """One row per finding of the maps (map, item, finding), for the report."""
    rows = []
    fc = ds["failure_count"]
    bound = float(ds.attrs["penetration_bound_mm"])
    for m in fc["fe_method"].values:
        c = fc.sel(fe_method=m).values
        pen = float(ds["max_penetration_by_method"].sel(fe_method=m))
        text = f"{c[0]}/{c.sum()} solved samples converged (diverged {c[1]}, not reached {c[2]}, solver error {c[3]})"
        if np.isfinite(pen):
            text += (
                f"; largest penetration {pen:.4f} mm ({'above' if pen > bound else 'within'} the {bound:g} mm bound)"
            )
        rows.append(("Newton failures, penetration", str(m), text))
    for k, r in zip(ds["bulk_ratio"].values, ds["locking_ratio"].values):
        a = {str(f): float(ds["locking_angle_deg"].sel(bulk_ratio=k, formulation=f)) for f in ds["formulation"].values}
        rows.append(
            (
                "locking",
                f"K/mu0 = {k:g}",
                "free angle "
                + ", ".join(f"{f} {v:.3f} deg" for f, v in a.items())
                + f": volumetric ratio {r:.4f}"
                + (
                    f", shear ratio {float(ds['locking_shear_ratio'].sel(bulk_ratio=k)):.4f}"
                    if "locking_shear_ratio" in ds
                    else ""
                ),
            )
        )
    for fea in ds["fea"].values:
        on = ds["query_fea"].values == fea
        bad = int(np.count_nonzero(~ds["query_trusted"].values[on]))
        rows.append(
            (
                "surrogate coverage",
                f"{fea} sweep",
                f"{float(ds['covered_fraction'].sel(fea=fea)):.1%} of [0, p_max]^2 inside the hull and not near "
                f"a failure; {bad} of {int(on.sum())} planned (P_T, P_B) pairs flagged",
            )
        )
    for p in ds["patient"].values:
        d = ds.sel(patient=p)
        missed = [str(e) for e, a in zip(d["exercise"].values, d["achieved"].values) if not a]
        rows.append(
            (
                "design range, feasibility",
                str(p),
                f"||x|| = {float(d['coded_norm']):.2f}, max |x_i| = {float(d['max_abs_coded']):.2f}, "
                f"in design range: {'yes' if bool(d['in_design_range']) else 'NO'}; prediction variance "
                f"{float(d['prediction_variance']):.1f}; not reached: {', '.join(missed) or 'none'}",
            )
        )
    return pd.DataFrame(rows, columns=["map", "item", "finding"])


def write_stability(
    out: str | Path,
    *,
    responses: Mapping[str, str | Path],
    unit_check: str | Path | None,
    rays: str | Path,
    locking: str | Path,
    ccd: str | Path,
    loads: Mapping[str, str | Path],
    plans: Mapping[str, str | Path],
    actuator: Mapping[str, Any],
    stab_cfg: Mapping[str, Any],
    cascade_surrogate: str,
    config_slice: Any,
    plots: Mapping[str, str | Path] | None = None,
    table_html: str | Path | None = None,
    rule: str = "stability_maps",
    fem_cases: Sequence[str | Path] | None = None,
) -> xr.Dataset:
    """Gather the five maps into ``stability.nc`` (and the plots and the summary table)."""
    sweeps = {fea: _sweep_with_mesh(p, fea, actuator) for fea, p in responses.items()}
    sources: list[tuple[str, xr.Dataset]] = [("sweep", sweeps[f]) for f in sweeps]
    uc = None
    if unit_check is not None:
        uc = _unit_check_mesh(open_result(unit_check), actuator)
        sources.append(("unit_check", uc))
    # the fidelity study's FE cases: every mesh and contact switch to 300 kPa, free and blocked
    sources += [("fem_case", open_result(f)) for f in (fem_cases or ())]
    rays_ds = open_result(rays)
    sources.append(("rays", rays_ds))
    samples = SM.fe_samples(sources)
    counts = SM.failure_counts(samples)
    bound = float(stab_cfg["penetration_bound_mm"])
    pen = SM.penetration_summary(samples, bound)
    lock = open_result(locking)

    # surrogate coverage and the cascade's queries (its planned pairs)
    regions = {fea: sampled_region.SampledRegion.from_response(ds) for fea, ds in sweeps.items()}
    p_max = max(float(ds.attrs.get("p_max_kpa", 300.0)) for ds in sweeps.values())
    grids = [
        sampled_region.coverage_grid(regions[f], p_max, int(stab_cfg["coverage_grid"])).expand_dims(fea=[f])
        for f in regions
    ]
    cover = xr.concat(grids, dim="fea")
    plan_ds = {p: open_result(f) for p, f in plans.items()}
    q = {k: [] for k in ("patient", "exercise", "group", "pt", "pb", "fea", "in_hull", "near", "trusted")}
    for p, d in plan_ds.items():
        pr = d["pressure_kpa"]
        for e in pr["exercise"].values:
            for g in pr["group"].values:
                pt, pb = (
                    float(pr.sel(exercise=e, group=g, chamber="top")),
                    float(pr.sel(exercise=e, group=g, chamber="bottom")),
                )
                f = regions[cascade_surrogate].flags(pt, pb)
                for k, v in (
                    ("patient", p),
                    ("exercise", str(e)),
                    ("group", str(g)),
                    ("pt", pt),
                    ("pb", pb),
                    ("fea", cascade_surrogate),
                    ("in_hull", bool(f["in_hull"])),
                    ("near", bool(f["near_failure"])),
                    ("trusted", bool(f["trusted"])),
                ):
                    q[k].append(v)
                if not f["trusted"]:
                    log.warning(
                        "patient %s %s %s: planned (P_T, P_B) = (%.1f, %.1f) kPa lies %s of the %s surrogate",
                        p,
                        e,
                        g,
                        pt,
                        pb,
                        "outside the sampled region" if not f["in_hull"] else "nearest a failed sample",
                        cascade_surrogate,
                    )

    loads_ds = {p: open_result(f) for p, f in loads.items()}
    with open_result(ccd) as c:
        design = np.column_stack([c[d].values for d in ("depth", "length", "breadth")])
    dr = DR.design_range_table(loads_ds, design)
    feas = DR.feasibility_table(plan_ds)
    # prediction variance along the diagonal direction (worst case of a CCD) and an axis, |x| = 0..2
    radius = np.linspace(0.0, 2.0, 81)
    dirs = {"axial": np.array([1.0, 0.0, 0.0]), "diagonal": np.ones(3) / np.sqrt(3.0)}
    spv = np.array([DR.scaled_prediction_variance(design, radius[:, None] * u[None, :]) for u in dirs.values()])

    ds = xr.merge(
        [
            samples,
            counts.rename("failure_count").to_dataset(),
            pen.rename({"max_penetration_mm": "max_penetration_by_method"}),
            lock.rename(
                {
                    "status": "locking_status",
                    "bending_angle_deg": "locking_angle_deg",
                    "shear_locking_ratio": "locking_shear_ratio",
                    **({"wall_time_s": "locking_wall_time_s"} if "wall_time_s" in lock else {}),
                }
            ).drop_attrs(),
            cover.rename({k: f"coverage_{k}" for k in ("in_range", "in_hull", "near_failure", "trusted")}),
            dr,
            feas,
        ],
        compat="override",
        join="outer",
        combine_attrs="drop",
    )
    ds["covered_fraction"] = (
        "fea",
        np.array([float(cover["trusted"].sel(fea=f).mean()) for f in cover["fea"].values]),
        {"units": "1", "long_name": "fraction of [0, p_max]^2 inside the hull and not near a failure"},
    )
    nq = len(q["patient"])
    ds = ds.assign_coords(query=np.arange(nq))
    for k, name, dtype, attrs in (
        ("patient", "query_patient", object, {}),
        ("exercise", "query_exercise", object, {}),
        ("group", "query_group", object, {}),
        ("fea", "query_fea", object, {}),
        ("pt", "query_p_top_kpa", float, {"units": "kPa", "long_name": "planned top pressure"}),
        ("pb", "query_p_bottom_kpa", float, {"units": "kPa", "long_name": "planned bottom pressure"}),
        ("in_hull", "query_in_hull", bool, {"long_name": "inside the hull of the converged samples"}),
        ("near", "query_near_failure", bool, {"long_name": "nearest sample failed"}),
        ("trusted", "query_trusted", bool, {"long_name": "inside the hull and not nearest a failed sample"}),
    ):
        ds[name] = ("query", np.array(q[k], dtype=dtype), attrs)
    ds = ds.assign_coords(
        radius=("radius", radius, {"units": "1", "long_name": "||x|| in coded units"}), direction=list(dirs)
    )
    ds["prediction_variance_radial"] = (
        ("direction", "radius"),
        spv,
        {"units": "1", "long_name": "scaled prediction variance of the quadratic CCD model"},
    )
    ds.attrs.update(
        {
            "penetration_bound_mm": bound,
            "cascade_surrogate": cascade_surrogate,
            "locking_p_top_kpa": float(lock.attrs["p_top_kpa"]),
            "locking_h_mm": float(lock.attrs["h_mm"]),
            "ccd_corner_norm": float(np.max(np.linalg.norm(design, axis=1))),
        }
    )
    for k in ("locking_status", "locking_angle_deg"):
        ds[k].attrs.update(lock[k.replace("locking_", "")].attrs if k.replace("locking_", "") in lock else {})
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice=config_slice,
        title="Stability maps: where each method of the workflow fails or degrades",
    )
    log.info("failures per method:\n%s", counts.to_pandas().to_string())
    log.info(
        "largest penetration per method (bound %g mm): %s",
        bound,
        {str(m): round(float(v), 5) for m, v in zip(pen["fe_method"].values, pen["max_penetration_mm"].values)},
    )
    if plots:
        P.plot_failures(ds, plots["failures"])
        P.plot_locking(ds, plots["locking"])
        P.plot_penetration(ds, plots["penetration"])
        P.plot_coverage(ds, sweeps, plots["coverage"])
        P.plot_design_feasibility(ds, design, plots["design"])
    if table_html:
        write_html(
            table_html,
            "Stability maps: summary",
            [("", summary_table(ds).set_index(["map", "item"]))],
            [
                f"penetration bound {bound:g} mm; surrogate of the cascade: {cascade_surrogate}; "
                f"locking study: 2D unit, h = {lock.attrs['h_mm']:g} mm, P_T = {lock.attrs['p_top_kpa']:g} kPa"
            ],
        )
    return ds
