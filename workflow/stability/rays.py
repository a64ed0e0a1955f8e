"""Stability maps: where each method of the workflow fails or degrades.

Five maps, each a function of datasets the workflow already writes, plus two
small FE studies of their own:

1. **Newton failures** over the pressure plane (P_T, P_B), by mesh and
   formulation: the sweeps' per-sample ``status`` and extra 2D rays at other
   element sizes, with and without contact, mixed and plain displacement
   elements (`ray_statuses`, `rays_dataset`).  `fe_samples` puts every source
   into one long table on a ``sample`` dimension; `failure_counts` counts the
   statuses of the *solved* samples (mirrored ones are copies, not solves).
2. **Volumetric locking**: free angle of the 2D unit against K/mu0 for the
   mean-dilatation (mixed) and the plain Q1 displacement formulation
   (`locking_dataset`, `locking_ratio`).
3. **Contact penetration** against a stated bound (`penetration_summary`).
4. **Surrogate queries outside the sampled grid**: `SampledRegion` (convex
   hull of the converged samples plus the unloaded origin, and which sample is
   nearest) flags a query (P_T, P_B) outside the hull, outside the sampled
   range or nearest to a sample that failed; `flag_pressure_table` applies it
   to a cascade plan's pressures.
5. **Response surfaces outside |x| <= 1** (`design_range_table`,
   `scaled_prediction_variance`: how the quadratic CCD model's prediction
   variance grows outside the design sphere) and **exercises with no feasible
   pressures** (`feasibility_table`).

Units: pressures kPa, angles degree, lengths mm, moments N m.  Status codes of
FE samples are the sweep's (`workflow.sweep.STATUS_FLAGS`, 0 = converged).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.sweep import STATUS_FLAGS
from workflow.runlog import solved

__all__ = [
    "STATUS_FLAGS",
    "FORMULATIONS",
    "method_name",
    "ray_statuses",
    "solve_rays",
    "rays_dataset",
    "fe_samples",
    "ray_last_converged_kpa",
    "failure_counts",
    "locking_dataset",
    "locking_ratio",
    "penetration_summary",
    "SampledRegion",
    "flag_pressure_table",
    "coverage_grid",
    "quadratic_terms",
    "scaled_prediction_variance",
    "design_range_table",
    "feasibility_table",
]

log = logging.getLogger(__name__)

#: Element formulations of workflow.fem (``FORMULATIONS`` there): the default enhanced-strain paper layer on
#: mean-dilatation silicone, the silicone enhanced too, mean dilatation only and plain Q1.
FORMULATIONS = ("enhanced_paper", "enhanced", "mixed", "displacement")
#: The locking study's: shear locking of the paper layer (mixed vs enhanced_paper) and volumetric
#: locking of the silicone (displacement vs mixed).
LOCKING_FORMULATIONS = ("enhanced_paper", "mixed", "displacement")


def method_name(source: str, fea: str, h_mm: float, contact: bool, formulation: str = "enhanced_paper") -> str:
    """Label of one FE method, e.g. ``sweep 2D h=1 mm, contact, enhanced_paper``."""
    return f"{source} {fea.upper()} h={h_mm:g} mm, {'contact' if contact else 'no contact'}, {formulation}"


# ---------------------------------------------------------------------------
# 1. Newton failures
# ---------------------------------------------------------------------------
def ray_statuses(scales: Sequence[float], load_factor: float, solver_status: int, *, tol: float = 1e-9) -> np.ndarray:
    """Sweep status of the samples at ``scales`` of a ray whose solve stopped at ``load_factor``.

    ``solver_status`` is workflow.fem's (0 = reached the end, 3 = raised,
    else a stall).  Scales up to the last converged load factor are converged
    (0); the first beyond is ``diverged`` (1), or ``solver_error`` (3) if the
    solver raised; the rest ``not_reached`` (2).
    """
    s = np.asarray(scales, float)
    out = np.zeros(s.size, dtype=np.int32)
    if solver_status == 0:
        return out
    beyond = np.flatnonzero(s > load_factor + tol)
    if beyond.size:
        out[beyond] = 2
        out[beyond[0]] = 3 if solver_status == 3 else 1
    return out


def _history_at(history: Sequence[Mapping[str, Any]], scales: np.ndarray, key: str, tol: float = 1e-9) -> np.ndarray:
    """``key`` of the accepted load step at each scale (NaN where no step landed there)."""
    out = np.full(scales.size, np.nan)
    for rec in history:
        hit = np.isclose(scales, float(rec["lam"]), rtol=0.0, atol=tol)
        out[hit] = float(rec.get(key, np.nan))
    return out


def _running_max_at(history: Sequence[Mapping[str, Any]], scales: np.ndarray, key: str, tol: float = 1e-9) -> np.ndarray:
    """Largest ``key`` over the accepted load steps up to each scale (as the unit check records penetration)."""
    lam = np.array([float(r["lam"]) for r in history])
    val = np.array([float(r.get(key, np.nan)) for r in history])
    out = np.full(scales.size, np.nan)
    for i, s in enumerate(scales):
        upto = lam <= s + tol
        if upto.any() and np.isclose(lam, s, rtol=0.0, atol=tol).any():
            out[i] = np.nanmax(val[upto])
    return out


def solve_rays(solve: Callable[..., Any], variants: Sequence[Mapping[str, Any]], *, p_max_kpa: float,
               n_pressures: int) -> dict[str, np.ndarray]:
    """Free-bending rays of each variant, as flat per-ray and per-sample arrays.

    ``variants``: mappings with ``h_mm``, ``contact``, ``formulation``
    (`FORMULATIONS`) and ``ratios`` (P_B/P_T in [0, 1]; P_T = p_max at the
    ray's end).  ``solve(variant, p_top_kpa, p_bottom_kpa, stops)`` returns a
    result with ``status``, ``reason``, ``load_factor``, ``history`` (one
    record per accepted load step with ``lam``, ``bending_angle_deg``,
    ``max_penetration_mm``), ``newton_iterations`` and ``wall_time_s`` (e.g.
    ``workflow.fem.solve_unit``'s `UnitResult`).  The load steps land on the
    scales s = 1/n .. 1.  A sample's penetration is the largest over the load
    path up to it (contact events between samples count).
    """
    scales = np.arange(1, n_pressures + 1) / n_pressures
    rows: dict[str, list] = {k: [] for k in ("variant", "ratio", "status", "angle", "pen", "overlap", "pocket", "lam",
                                             "solver_status", "reason", "iters", "wall")}
    for v, var in enumerate(variants):
        if var["formulation"] not in FORMULATIONS:
            raise ValueError(f"unknown formulation {var['formulation']!r}: expected one of {FORMULATIONS}")
        for r in var["ratios"]:
            res = solve(var, p_max_kpa, float(r) * p_max_kpa, tuple(scales))
            st = ray_statuses(scales, float(res.load_factor), int(res.status))
            angle = _history_at(res.history, scales, "bending_angle_deg")
            pen = _running_max_at(res.history, scales, "max_penetration_mm")
            overlap = _running_max_at(res.history, scales, "overlap_depth_mm")
            pocket = -_running_max_at([dict(h, m=-h.get("min_pocket_area_mm2", np.nan)) for h in res.history], scales, "m")
            for arr in (angle, pen, overlap, pocket):
                arr[st != 0] = np.nan
            log.info("%s, P_B/P_T = %.2f: status %d (%s), reached %.0f kPa, %d iterations, %.1f s",
                     method_name("rays", "2d", var["h_mm"], var["contact"], var["formulation"]), r, res.status,
                     res.reason or "ok", res.load_factor * p_max_kpa, res.newton_iterations, res.wall_time_s,
                     extra=solved(res.status != 0))
            for key, val in (("variant", v), ("ratio", float(r)), ("status", st), ("angle", angle), ("pen", pen),
                             ("overlap", overlap), ("pocket", pocket),
                             ("lam", float(res.load_factor)), ("solver_status", int(res.status)),
                             ("reason", str(res.reason)), ("iters", int(res.newton_iterations)),
                             ("wall", float(res.wall_time_s))):
                rows[key].append(val)
    out = {k: np.array(val) for k, val in rows.items()}
    out["scale"] = scales
    return out


def rays_dataset(rays: Mapping[str, np.ndarray], variants: Sequence[Mapping[str, Any]], *, p_max_kpa: float) -> xr.Dataset:
    """The extra rays (`solve_rays` output) as a dataset on ``ray`` x ``scale``."""
    v = np.asarray(rays["variant"], int)
    scale = np.asarray(rays["scale"], float)
    ratio = np.asarray(rays["ratio"], float)
    pt = np.outer(np.full(ratio.size, p_max_kpa), scale)
    pb = np.outer(ratio * p_max_kpa, scale)
    flag_vals = np.array(sorted(STATUS_FLAGS), dtype=np.int32)
    ds = xr.Dataset(
        {
            "status": (("ray", "scale"), np.asarray(rays["status"], np.int32).reshape(ratio.size, scale.size),
                       {"long_name": "sample status", "flag_values": flag_vals,
                        "flag_meanings": " ".join(STATUS_FLAGS[int(k)] for k in flag_vals)}),
            "bending_angle_deg": (("ray", "scale"), np.asarray(rays["angle"], float).reshape(ratio.size, scale.size),
                                  {"units": "degree", "long_name": "free bending angle per unit"}),
            "max_penetration_mm": (("ray", "scale"), np.asarray(rays["pen"], float).reshape(ratio.size, scale.size),
                                   {"units": "mm", "long_name": "largest penetration over the load path up to the sample (contact or overlap check)"}),
            "overlap_depth_mm": (("ray", "scale"), np.asarray(rays["overlap"], float).reshape(ratio.size, scale.size),
                                 {"units": "mm", "long_name": "deepest boundary node inside another element up to the sample"}),
            "min_pocket_area_mm2": (("ray", "scale"), np.asarray(rays["pocket"], float).reshape(ratio.size, scale.size),
                                    {"units": "mm2", "long_name": "smallest pocket area up to the sample (36.4 at rest)"}),
            "last_converged_scale": ("ray", np.asarray(rays["lam"], float),
                                     {"units": "1", "long_name": "last converged load factor of the ray"}),
            "solver_status": ("ray", np.asarray(rays["solver_status"], np.int32),
                              {"long_name": "workflow.fem status of the ray (0 converged, 1 step below minimum, "
                                            "2 too many steps, 3 solver error)"}),
            "reason": ("ray", np.asarray(rays["reason"], dtype=object), {"long_name": "why the ray stopped"}),
            "newton_iterations": ("ray", np.asarray(rays["iters"], np.int32), {"units": "1"}),
            "wall_time_s": ("ray", np.asarray(rays["wall"], float), {"units": "s"}),
        },
        coords={
            "ray": np.arange(ratio.size),
            "scale": ("scale", scale, {"units": "1", "long_name": "load scale along the ray"}),
            "ratio": ("ray", ratio, {"units": "1", "long_name": "P_B / P_T of the ray"}),
            "h_mm": ("ray", np.array([variants[i]["h_mm"] for i in v], float), {"units": "mm", "long_name": "element size"}),
            "contact": ("ray", np.array([bool(variants[i]["contact"]) for i in v])),
            "formulation": ("ray", np.array([str(variants[i]["formulation"]) for i in v], dtype=object)),
            "p_top_kpa": (("ray", "scale"), pt, {"units": "kPa"}),
            "p_bottom_kpa": (("ray", "scale"), pb, {"units": "kPa"}),
        },
    )
    ds.attrs.update({"fea": "2d", "case": "free", "p_max_kpa": float(p_max_kpa)})
    return ds


def ray_last_converged_kpa(ray: np.ndarray, p_top: np.ndarray, p_bottom: np.ndarray, status: np.ndarray) -> np.ndarray:
    """Per sample, the larger chamber pressure at its ray's last converged sample (0 if none), kPa."""
    ray = np.asarray(ray)
    load = np.maximum(np.asarray(p_top, float), np.asarray(p_bottom, float))
    ok = np.asarray(status) == 0
    out = np.zeros(load.size)
    for r in np.unique(ray):
        on = ray == r
        out[on] = load[on & ok].max() if np.any(on & ok) else 0.0
    return out


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
    cols: dict[str, list] = {k: [] for k in ("method", "case", "p_top_kpa", "p_bottom_kpa", "status", "mirrored",
                                             "max_penetration_mm", "ray_last_converged_kpa")}

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
            add(name, "free+blocked", ds["p_top_kpa"].values, ds["p_bottom_kpa"].values, ds["status"].values,
                ds["mirrored"].values, pen, ray)
        elif kind == "rays":
            for r in ds["ray"].values:
                d = ds.sel(ray=r)
                name = method_name("rays", "2d", float(d["h_mm"]), bool(d["contact"]), str(d["formulation"].values))
                add(name, "free", d["p_top_kpa"].values, d["p_bottom_kpa"].values, d["status"].values,
                    np.zeros(d.sizes["scale"], bool), d["max_penetration_mm"].values, np.zeros(d.sizes["scale"], int))
        elif kind == "unit_check":
            for model in ds["model"].values:
                h = float(ds.attrs["h_2d_mm"] if str(model) == "2d" else ds.attrs["h_3d_mm"])
                name = method_name("unit check", str(model), h, bool(ds.attrs["contact"]))
                for case in ds["case"].values:
                    d = ds.sel(model=model, case=case)
                    # the unit check's statuses are workflow.fem's: any stall is a divergence here
                    st = np.where(d["status"].values == 0, 0, np.where(d["status"].values == 3, 3, 1))
                    n = d.sizes["p_top_kpa"]
                    add(name, str(case), d["p_top_kpa"].values, np.full(n, float(d["p_bottom_kpa"])), st,
                        np.zeros(n, bool), d["max_penetration_mm"].values, np.zeros(n, int))
        elif kind == "fem_case":  # one fidelity-study case (workflow.fidelity_run.write_fem_case)
            name = method_name("fidelity study", str(ds.attrs["model"]), float(ds.attrs["h_mm"]),
                               bool(int(ds.attrs["contact"])))
            for case in ds["case"].values:
                d = ds.sel(case=case)
                st = np.where(d["status"].values == 0, 0, np.where(d["status"].values == 3, 3, 1))
                n = d.sizes["p_top_kpa"]
                add(name, str(case), d["p_top_kpa"].values, np.full(n, float(d["p_bottom_kpa"])), st,
                    np.zeros(n, bool), d["max_penetration_mm"].values, np.zeros(n, int))
        else:
            raise ValueError(f"unknown source kind {kind!r}")
    n = len(cols["method"])
    flag_vals = np.array(sorted(STATUS_FLAGS), dtype=np.int32)
    return xr.Dataset(
        {
            "method": ("sample", np.array(cols["method"], dtype=object), {"long_name": "FE method (source, model, mesh, contact, formulation)"}),
            "case": ("sample", np.array(cols["case"], dtype=object), {"long_name": "load case(s) the status covers"}),
            "status": ("sample", np.array(cols["status"], np.int32),
                       {"long_name": "sample status", "flag_values": flag_vals,
                        "flag_meanings": " ".join(STATUS_FLAGS[int(k)] for k in flag_vals)}),
            "mirrored": ("sample", np.array(cols["mirrored"], bool), {"long_name": "copied from its (P_B, P_T) twin"}),
            "max_penetration_mm": ("sample", np.array(cols["max_penetration_mm"], float),
                                   {"units": "mm", "long_name": "largest contact penetration (NaN: not recorded)"}),
            "ray_last_converged_kpa": ("sample", np.array(cols["ray_last_converged_kpa"], float),
                                       {"units": "kPa", "long_name": "larger chamber pressure at the last converged sample of the sample's ray"}),
        },
        coords={"sample": np.arange(n),
                "p_top_kpa": ("sample", np.array(cols["p_top_kpa"], float), {"units": "kPa"}),
                "p_bottom_kpa": ("sample", np.array(cols["p_bottom_kpa"], float), {"units": "kPa"})},
    )


def failure_counts(samples: xr.Dataset) -> xr.DataArray:
    """Number of solved (not mirrored) samples per method and status; dims ``fe_method``, ``status_code``.

    (Not ``method``: that is a keyword of xarray's ``sel``.)
    """
    methods = list(dict.fromkeys(samples["method"].values.tolist()))
    codes = sorted(STATUS_FLAGS)
    solved = ~samples["mirrored"].values
    counts = np.zeros((len(methods), len(codes)), dtype=np.int32)
    for i, m in enumerate(methods):
        on = solved & (samples["method"].values == m)
        for j, c in enumerate(codes):
            counts[i, j] = int(np.count_nonzero(on & (samples["status"].values == c)))
    return xr.DataArray(counts, dims=("fe_method", "status_code"),
                        coords={"fe_method": np.array(methods, dtype=str), "status_code": np.array(codes, np.int32),
                                "status_meaning": ("status_code", [STATUS_FLAGS[c] for c in codes])},
                        attrs={"units": "1", "long_name": "solved samples per method and status"})


# ---------------------------------------------------------------------------
# 2. Locking
# ---------------------------------------------------------------------------
def locking_dataset(bulk_ratios: Sequence[float], angle_deg: Mapping[str, Sequence[float]],
                    status: Mapping[str, Sequence[int]], *, p_top_kpa: float, h_mm: float,
                    wall_time_s: Mapping[str, Sequence[float]] | None = None) -> xr.Dataset:
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
        "bending_angle_deg": (("formulation", "bulk_ratio"), ang,
                              {"units": "degree", "long_name": f"free bending angle per unit at P_T = {p_top_kpa:g} kPa"}),
        "status": (("formulation", "bulk_ratio"), st, {"long_name": "workflow.fem status (0 = converged)"}),
    }
    if wall_time_s is not None:
        data["wall_time_s"] = (("formulation", "bulk_ratio"), np.array([np.asarray(wall_time_s[f], float) for f in forms]),
                               {"units": "s"})
    ds = xr.Dataset(data, coords={"formulation": forms,
                                  "bulk_ratio": ("bulk_ratio", k, {"units": "1", "long_name": "K / mu0"})})
    ds["locking_ratio"] = locking_ratio(ds)
    ds["shear_locking_ratio"] = (ds["bending_angle_deg"].sel(formulation="mixed")
                                 / ds["bending_angle_deg"].sel(formulation="enhanced_paper")).drop_vars(
        "formulation", errors="ignore").assign_attrs(
        units="1", long_name="plain Q1 paper layer / enhanced-strain paper layer free angle (1 = no shear locking)")
    ds.attrs.update({"p_top_kpa": float(p_top_kpa), "p_bottom_kpa": 0.0, "h_mm": float(h_mm), "contact": 0})
    return ds


def locking_ratio(ds: xr.Dataset) -> xr.DataArray:
    """Displacement-formulation angle / mixed angle per bulk ratio (1 = no locking, -> 0 = locked)."""
    r = ds["bending_angle_deg"].sel(formulation="displacement") / ds["bending_angle_deg"].sel(formulation="mixed")
    return r.drop_vars("formulation", errors="ignore").assign_attrs(
        units="1", long_name="plain Q1 free angle / mean-dilatation free angle (1 = no locking)")


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
        {"max_penetration_mm": ("fe_method", mx, {"units": "mm", "long_name": "largest contact penetration over the converged samples"}),
         "n_above_bound": ("fe_method", n_above, {"units": "1", "long_name": "converged samples above the penetration bound"}),
         "above_bound": ("sample", above, {"long_name": f"penetration above {bound_mm:g} mm"})},
        coords={"fe_method": np.array(methods, dtype=str)},
        attrs={"penetration_bound_mm": float(bound_mm)},
    )


# ---------------------------------------------------------------------------
# 4. Surrogate queries outside the sampled grid
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class SampledRegion:
    """The part of the (P_T, P_B) plane a surrogate was trained on.

    ``converged_kpa`` (n, 2): converged samples (mirrored included: the
    surrogate is trained on them) plus the unloaded origin (angle and moment 0
    exactly, so the surrogate is anchored there); ``failed_kpa`` (m, 2): samples
    that did not converge.  A query is *inside* when it lies in the convex hull
    of the converged samples (which implies the sampled range); it is *in a
    known failure region* when its nearest sample is a failed one.
    """

    converged_kpa: np.ndarray
    failed_kpa: np.ndarray
    scale_kpa: float = 300.0

    @classmethod
    def from_response(cls, ds: xr.Dataset, *, include_origin: bool = True) -> "SampledRegion":
        """From a ``response_{2d,3d}.nc`` sweep."""
        p = np.column_stack([ds["p_top_kpa"].values, ds["p_bottom_kpa"].values]).astype(float)
        ok = ds["status"].values == 0
        conv = p[ok]
        if include_origin:
            conv = np.vstack([[0.0, 0.0], conv])
        scale = float(np.max(np.abs(p))) if p.size else 1.0
        return cls(conv, p[~ok], scale if scale > 0 else 1.0)

    @property
    def range_kpa(self) -> np.ndarray:
        """[[P_T min, P_T max], [P_B min, P_B max]] of the converged samples."""
        return np.column_stack([self.converged_kpa.min(axis=0), self.converged_kpa.max(axis=0)])

    def in_range(self, p_top_kpa, p_bottom_kpa, tol_kpa: float = 1e-6) -> np.ndarray:
        """Inside the box of the converged samples' ranges."""
        pt, pb = np.broadcast_arrays(np.asarray(p_top_kpa, float), np.asarray(p_bottom_kpa, float))
        r = self.range_kpa
        return ((pt >= r[0, 0] - tol_kpa) & (pt <= r[0, 1] + tol_kpa)
                & (pb >= r[1, 0] - tol_kpa) & (pb <= r[1, 1] + tol_kpa))

    def in_hull(self, p_top_kpa, p_bottom_kpa, tol: float = 1e-9) -> np.ndarray:
        """Inside the convex hull of the converged samples (False everywhere if they span no area)."""
        from scipy.spatial import Delaunay, QhullError

        pt, pb = np.broadcast_arrays(np.asarray(p_top_kpa, float), np.asarray(p_bottom_kpa, float))
        # scaled to O(1) so that the tolerance means the same at any p_max
        pts = np.unique(self.converged_kpa / self.scale_kpa, axis=0)
        if pts.shape[0] < 3:
            return np.zeros(pt.shape, bool)
        try:
            tri = Delaunay(pts)
        except QhullError:  # collinear samples: no area
            return np.zeros(pt.shape, bool)
        q = np.column_stack([pt.ravel(), pb.ravel()]) / self.scale_kpa
        return (tri.find_simplex(q, tol=tol) >= 0).reshape(pt.shape)

    def nearest_failed(self, p_top_kpa, p_bottom_kpa) -> np.ndarray:
        """The nearest sample (converged or failed) to the query is a failed one."""
        pt, pb = np.broadcast_arrays(np.asarray(p_top_kpa, float), np.asarray(p_bottom_kpa, float))
        if self.failed_kpa.size == 0:
            return np.zeros(pt.shape, bool)
        q = np.column_stack([pt.ravel(), pb.ravel()])
        d_ok = np.min(np.linalg.norm(q[:, None, :] - self.converged_kpa[None, :, :], axis=2), axis=1)
        d_bad = np.min(np.linalg.norm(q[:, None, :] - self.failed_kpa[None, :, :], axis=2), axis=1)
        return (d_bad < d_ok).reshape(pt.shape)

    def flags(self, p_top_kpa, p_bottom_kpa) -> dict[str, np.ndarray]:
        """``in_range``, ``in_hull``, ``near_failure`` and ``trusted`` (= in hull and not near a failure)."""
        hull = self.in_hull(p_top_kpa, p_bottom_kpa)
        near = self.nearest_failed(p_top_kpa, p_bottom_kpa)
        return {"in_range": self.in_range(p_top_kpa, p_bottom_kpa), "in_hull": hull, "near_failure": near,
                "trusted": hull & ~near}


def flag_pressure_table(pressure_kpa: xr.DataArray, region: SampledRegion, *, label: str = "") -> tuple[xr.DataArray, list[str]]:
    """Flag each (P_T, P_B) pair of a plan's ``pressure_kpa`` (exercise, group, chamber) against ``region``.

    Returns ``pressure_in_sampled_region`` (exercise, group; True = inside the
    hull of converged samples and not nearest to a failed one) and one
    warning message per flagged pair.
    """
    pt = pressure_kpa.sel(chamber="top").values
    pb = pressure_kpa.sel(chamber="bottom").values
    f = region.flags(pt, pb)
    da = xr.DataArray(f["trusted"], dims=pressure_kpa.sel(chamber="top").dims,
                      coords={d: pressure_kpa[d] for d in pressure_kpa.sel(chamber="top").dims},
                      attrs={"long_name": "planned (P_T, P_B) inside the convex hull of the surrogate's converged FE "
                                          "samples and not nearest to a failed sample"})
    msgs = []
    dims = da.dims
    for idx in zip(*np.nonzero(~f["trusted"])):
        where = ", ".join(f"{d} {da[d].values[i]}" for d, i in zip(dims, idx))
        why = "outside the sampled region" if not f["in_hull"][idx] else "nearest FE sample failed"
        msgs.append(f"{label}{where}: surrogate queried at (P_T, P_B) = ({pt[idx]:.1f}, {pb[idx]:.1f}) kPa, {why}")
    return da, msgs


def coverage_grid(region: SampledRegion, p_max_kpa: float, n: int = 61) -> xr.Dataset:
    """`SampledRegion.flags` on an n x n grid of [0, p_max]^2 (dims ``grid_p_top_kpa``, ``grid_p_bottom_kpa``)."""
    g = np.linspace(0.0, p_max_kpa, n)
    PT, PB = np.meshgrid(g, g, indexing="ij")
    f = region.flags(PT, PB)
    dims = ("grid_p_top_kpa", "grid_p_bottom_kpa")
    return xr.Dataset({k: (dims, v) for k, v in f.items()},
                      coords={dims[0]: (dims[0], g, {"units": "kPa"}), dims[1]: (dims[1], g, {"units": "kPa"})})


# ---------------------------------------------------------------------------
# 5. Response surfaces outside the design sphere; exercises with no feasible pressures
# ---------------------------------------------------------------------------
def quadratic_terms(x: np.ndarray) -> np.ndarray:
    """Columns of the ten-term quadratic model (1, x_i, x_i^2, x_i x_j) of coded levels x (n, 3)."""
    x = np.atleast_2d(np.asarray(x, float))
    d, le, b = x[:, 0], x[:, 1], x[:, 2]
    return np.column_stack([np.ones(len(x)), d, le, b, d**2, le**2, b**2, d * le, d * b, le * b])


def scaled_prediction_variance(design: np.ndarray, x: np.ndarray) -> np.ndarray:
    """N f(x)^T (F^T F)^-1 f(x) of the quadratic model on ``design`` (N runs x 3, coded) at ``x`` (m x 3).

    The variance of a response-surface prediction at x in units of sigma^2/N:
    a property of the design alone, small inside the design sphere and growing
    roughly as |x|^4 outside it.
    """
    F = quadratic_terms(design)
    M = np.linalg.pinv(F.T @ F)
    f = quadratic_terms(x)
    return F.shape[0] * np.einsum("ij,jk,ik->i", f, M, f)


def design_range_table(loads: Mapping[str, xr.Dataset], design: np.ndarray | None = None) -> xr.Dataset:
    """Per patient: coded levels, ||x||, max |x_i|, ``in_design_range`` and (with ``design``) the scaled
    prediction variance of the quadratic model at the patient's levels."""
    names = list(loads)
    dims = ["depth", "length", "breadth"]
    x = np.array([[float(loads[p]["x"].sel(dimension=d)) for d in dims] for p in names]).reshape(len(names), 3)
    norm = np.linalg.norm(x, axis=1)
    mx = np.max(np.abs(x), axis=1)
    data = {
        "x": (("patient", "dimension"), x, {"units": "1", "long_name": "coded levels"}),
        "coded_norm": ("patient", norm, {"units": "1", "long_name": "||x||_2"}),
        "max_abs_coded": ("patient", mx, {"units": "1", "long_name": "max |x_i|"}),
        "in_design_range": ("patient", np.array([bool(loads[p]["in_design_range"]) for p in names]),
                            {"long_name": "||x|| <= 1 and every |x_i| <= 1 (joint_loads.nc)"}),
    }
    if design is not None:
        data["prediction_variance"] = ("patient", scaled_prediction_variance(design, x),
                                       {"units": "1", "long_name": "scaled prediction variance N Var(y_hat)/sigma^2 of the quadratic CCD model"})
    return xr.Dataset(data, coords={"patient": names, "dimension": dims})


def feasibility_table(plans: Mapping[str, xr.Dataset]) -> xr.Dataset:
    """Per patient and exercise: ``achieved`` and ``reason`` from ``cascade_plan.nc``."""
    names = list(plans)
    ex = list(dict.fromkeys(e for p in names for e in plans[p]["exercise"].values.tolist()))
    ach = np.zeros((len(names), len(ex)), bool)
    why = np.full((len(names), len(ex)), "not planned", dtype=object)
    for i, p in enumerate(names):
        for e in plans[p]["exercise"].values:
            j = ex.index(e)
            ach[i, j] = bool(plans[p]["achieved"].sel(exercise=e))
            why[i, j] = str(plans[p]["reason"].sel(exercise=e).values)
    return xr.Dataset({"achieved": (("patient", "exercise"), ach, {"long_name": "exercise reached by the plan"}),
                       "reason": (("patient", "exercise"), why, {"long_name": "why not (empty if reached)"})},
                      coords={"patient": names, "exercise": ex})
