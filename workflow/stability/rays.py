"""Extra FE rays of the 2D unit by mesh, contact and formulation: where Newton fails over the pressure plane.

The sweeps' per-sample ``status`` and these rays (`ray_statuses`, `rays_dataset`) feed the stability maps; the
tables built from every FE sample are :mod:`.samples`, the design-region checks :mod:`.design` and the
surrogates' sampled region :mod:`workflow.actuator.sampled_region`.

Units: pressures kPa, angles degree, lengths mm, moments N m.  Status codes of
FE samples are the sweep's (`workflow.common.constants.SWEEP_SAMPLE_STATUS`, 0 = converged).
"""

from __future__ import annotations

import logging
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.common.constants import SWEEP_SAMPLE_STATUS
from workflow.common.runlog import solved

__all__ = [
    "FORMULATIONS",
    "method_name",
    "ray_statuses",
    "solve_rays",
    "rays_dataset",
    "ray_last_converged_kpa",
    "LOCKING_FORMULATIONS",
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


def _running_max_at(
    history: Sequence[Mapping[str, Any]], scales: np.ndarray, key: str, tol: float = 1e-9
) -> np.ndarray:
    """Largest ``key`` over the accepted load steps up to each scale (as the unit check records penetration)."""
    lam = np.array([float(r["lam"]) for r in history])
    val = np.array([float(r.get(key, np.nan)) for r in history])
    out = np.full(scales.size, np.nan)
    for i, s in enumerate(scales):
        upto = lam <= s + tol
        if upto.any() and np.isclose(lam, s, rtol=0.0, atol=tol).any():
            out[i] = np.nanmax(val[upto])
    return out


def solve_rays(
    solve: Callable[..., Any], variants: Sequence[Mapping[str, Any]], *, p_max_kpa: float, n_pressures: int
) -> dict[str, np.ndarray]:
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
    rows: dict[str, list] = {
        k: []
        for k in (
            "variant",
            "ratio",
            "status",
            "angle",
            "pen",
            "overlap",
            "pocket",
            "lam",
            "solver_status",
            "reason",
            "iters",
            "wall",
        )
    }
    for v, var in enumerate(variants):
        if var["formulation"] not in FORMULATIONS:
            raise ValueError(f"unknown formulation {var['formulation']!r}: expected one of {FORMULATIONS}")
        for r in var["ratios"]:
            res = solve(var, p_max_kpa, float(r) * p_max_kpa, tuple(scales))
            st = ray_statuses(scales, float(res.load_factor), int(res.status))
            angle = _history_at(res.history, scales, "bending_angle_deg")
            pen = _running_max_at(res.history, scales, "max_penetration_mm")
            overlap = _running_max_at(res.history, scales, "overlap_depth_mm")
            pocket = -_running_max_at(
                [dict(h, m=-h.get("min_pocket_area_mm2", np.nan)) for h in res.history], scales, "m"
            )
            for arr in (angle, pen, overlap, pocket):
                arr[st != 0] = np.nan
            log.info(
                "%s, P_B/P_T = %.2f: status %d (%s), reached %.0f kPa, %d iterations, %.1f s",
                method_name("rays", "2d", var["h_mm"], var["contact"], var["formulation"]),
                r,
                res.status,
                res.reason or "ok",
                res.load_factor * p_max_kpa,
                res.newton_iterations,
                res.wall_time_s,
                extra=solved(res.status != 0),
            )
            for key, val in (
                ("variant", v),
                ("ratio", float(r)),
                ("status", st),
                ("angle", angle),
                ("pen", pen),
                ("overlap", overlap),
                ("pocket", pocket),
                ("lam", float(res.load_factor)),
                ("solver_status", int(res.status)),
                ("reason", str(res.reason)),
                ("iters", int(res.newton_iterations)),
                ("wall", float(res.wall_time_s)),
            ):
                rows[key].append(val)
    out = {k: np.array(val) for k, val in rows.items()}
    out["scale"] = scales
    return out


def rays_dataset(
    rays: Mapping[str, np.ndarray], variants: Sequence[Mapping[str, Any]], *, p_max_kpa: float
) -> xr.Dataset:
    """The extra rays (`solve_rays` output) as a dataset on ``ray`` x ``scale``."""
    v = np.asarray(rays["variant"], int)
    scale = np.asarray(rays["scale"], float)
    ratio = np.asarray(rays["ratio"], float)
    pt = np.outer(np.full(ratio.size, p_max_kpa), scale)
    pb = np.outer(ratio * p_max_kpa, scale)
    flag_vals = np.array(sorted(SWEEP_SAMPLE_STATUS), dtype=np.int32)
    ds = xr.Dataset(
        {
            "status": (
                ("ray", "scale"),
                np.asarray(rays["status"], np.int32).reshape(ratio.size, scale.size),
                {
                    "long_name": "sample status",
                    "flag_values": flag_vals,
                    "flag_meanings": " ".join(SWEEP_SAMPLE_STATUS[int(k)] for k in flag_vals),
                },
            ),
            "bending_angle_deg": (
                ("ray", "scale"),
                np.asarray(rays["angle"], float).reshape(ratio.size, scale.size),
                {"units": "degree", "long_name": "free bending angle per unit"},
            ),
            "max_penetration_mm": (
                ("ray", "scale"),
                np.asarray(rays["pen"], float).reshape(ratio.size, scale.size),
                {
                    "units": "mm",
                    "long_name": "largest penetration over the load path up to the sample (contact or overlap check)",
                },
            ),
            "overlap_depth_mm": (
                ("ray", "scale"),
                np.asarray(rays["overlap"], float).reshape(ratio.size, scale.size),
                {"units": "mm", "long_name": "deepest boundary node inside another element up to the sample"},
            ),
            "min_pocket_area_mm2": (
                ("ray", "scale"),
                np.asarray(rays["pocket"], float).reshape(ratio.size, scale.size),
                {"units": "mm2", "long_name": "smallest pocket area up to the sample (36.4 at rest)"},
            ),
            "last_converged_scale": (
                "ray",
                np.asarray(rays["lam"], float),
                {"units": "1", "long_name": "last converged load factor of the ray"},
            ),
            "solver_status": (
                "ray",
                np.asarray(rays["solver_status"], np.int32),
                {
                    "long_name": "workflow.fem status of the ray (0 converged, 1 step below minimum, "
                    "2 too many steps, 3 solver error)"
                },
            ),
            "reason": ("ray", np.asarray(rays["reason"], dtype=object), {"long_name": "why the ray stopped"}),
            "newton_iterations": ("ray", np.asarray(rays["iters"], np.int32), {"units": "1"}),
            "wall_time_s": ("ray", np.asarray(rays["wall"], float), {"units": "s"}),
        },
        coords={
            "ray": np.arange(ratio.size),
            "scale": ("scale", scale, {"units": "1", "long_name": "load scale along the ray"}),
            "ratio": ("ray", ratio, {"units": "1", "long_name": "P_B / P_T of the ray"}),
            "h_mm": (
                "ray",
                np.array([variants[i]["h_mm"] for i in v], float),
                {"units": "mm", "long_name": "element size"},
            ),
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
