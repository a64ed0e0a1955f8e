"""From the config's ``actuator`` section to ``solve_unit`` calls and the unit-check dataset."""

from __future__ import annotations

import logging
from typing import Mapping

import numpy as np
import xarray as xr

from workflow.common.constants import SOLVER_STATUS
from workflow.common.runlog import solved

from ._mesh import build_unit_mesh
from ._restarts import first_converged, separate_attempts
from ._unit import DEFAULT_END_HOLD, DEFAULT_FORMULATION, UnitResult, contact_band, solve_unit

__all__ = ["DEFAULT_RESTARTS", "layer_options", "unit_mesh_from_config", "solve_unit_from_config", "unit_check"]

log = logging.getLogger(__name__)


def layer_options(actuator: Mapping) -> dict:
    """``paper_layers`` / ``base_layers`` of ``actuator.mesh`` (None = the mesh rule's default)."""
    mesh = dict(actuator.get("mesh", {}))
    return {"paper_layers": mesh.get("paper_layers"), "base_layers": mesh.get("base_layers")}


def unit_mesh_from_config(actuator: Mapping, dim: int):
    """The unit mesh of the config (``actuator.geometry``, ``actuator.mesh.h_{2d,3d}_mm``)."""
    mesh = dict(actuator.get("mesh", {}))
    h = mesh.get("h_2d_mm", 1.0) if dim == 2 else mesh.get("h_3d_mm", 2.0)
    return build_unit_mesh(actuator.get("geometry"), h=h, dim=dim, **layer_options(actuator))


#: Restarts from zero load of a ray that stalls, tried in order (overrides of ``actuator``): a wider
#: contact regularisation band (0.05, 0.1 mm instead of 0.01 mm in 2D and 0.02 mm in 3D) or smaller steps
#: without predictor often pass a contact event (blocks meeting corner to corner) where the first try cycled. The band
#: moves the free angle by under 1 % (2D, h = 1 and 2 mm, 60-300 kPa), below the fidelity tolerance.
DEFAULT_RESTARTS = (
    {"contact": {"smoothing_mm": 0.05}},
    {"contact": {"smoothing_mm": 0.1}},
    {"solver": {"predictor": False, "max_step": 0.02}},
)


def solve_unit_from_config(
    actuator: Mapping, dim: int, p_top_kpa: float, p_bottom_kpa: float, case: str = "free", mesh=None, **kwargs
) -> UnitResult:
    """``solve_unit`` with geometry, mesh size, material, contact and solver from ``actuator``.

    ``mesh`` (a ``UnitMesh``) can be passed to reuse one across calls. A ray
    that stalls is solved again from zero with each of ``actuator.restarts``
    (default ``DEFAULT_RESTARTS``) until one reaches the end; the result says
    which (``attempt``, 0 = as configured, and ``contact_smoothing_mm``) and
    its ``wall_time_s`` counts every attempt up to it. If none does, the
    attempt that got furthest is returned.  ``actuator.iteration_budget``
    (Newton iterations of the ray, all attempts together; None = no limit)
    ends a ray that cannot pass a contact event instead of letting its
    restarts run for an hour: it is then a failed solve (status 2) like any other.
    """
    um = mesh if mesh is not None else unit_mesh_from_config(actuator, dim)
    kwargs.setdefault("end_hold", actuator.get("end_hold", DEFAULT_END_HOLD))
    kwargs.setdefault("formulation", actuator.get("formulation", DEFAULT_FORMULATION))
    restarts = list(actuator.get("restarts", DEFAULT_RESTARTS))  # restarts: [] for none
    attempts = separate_attempts(actuator.get("contact", {}), actuator.get("solver", {}), restarts)
    # without contact a contact-only restart repeats the same solve: skipped, the others keep their numbers
    index = [
        k for k, (c, _) in enumerate(attempts) if k == 0 or c.get("enabled", True) or set(restarts[k - 1]) - {"contact"}
    ]
    spent = 0.0
    budget = actuator.get("iteration_budget")
    budget = None if budget is None else int(budget)
    used = 0

    def solve(contact_opts: dict, solver: dict) -> UnitResult:
        nonlocal spent, used
        opts = dict(contact_opts)
        enabled = opts.pop("enabled", True)
        if budget is not None:
            own = solver.get("max_iterations")
            solver = dict(solver, max_iterations=budget - used if own is None else min(own, budget - used))
        res = solve_unit(
            um,
            p_top_kpa,
            p_bottom_kpa,
            case,
            enabled,
            material=actuator.get("material"),
            contact_options=opts,
            solver=solver,
            **kwargs,
        )
        res.contact_smoothing_mm = contact_band(opts, dim)
        spent += res.wall_time_s
        used += res.newton_iterations
        return res

    label = f"{dim}d {case} to ({p_top_kpa:g}, {p_bottom_kpa:g}) kPa"
    left = None if budget is None else (lambda: used < budget)
    res, k = first_converged([attempts[k] for k in index], solve, label=label, budget_left=left)
    attempt = index[k]
    res.attempt = attempt
    res.wall_time_s = spent  # the cost of the result includes every attempt
    return res


#: The load path of a ray kept per step by ``unit_check(..., keep_paths=True)`` (what a sweep's samples are made
#: of), with units.
PATH_KEYS = {
    "lam": "1",
    "iterations": "1",
    "bending_angle_deg": "degree",
    "bending_moment_nm": "N m",
    "max_penetration_mm": "mm",
    "overlap_depth_mm": "mm",
    "min_pocket_area_mm2": "mm2",
    "min_pocket_volume_mm3": "mm3",
}


def unit_check(
    actuator: Mapping, models=("2d", "3d"), p_top_kpa=(60.0, 180.0, 300.0), extra_stops=(), keep_paths: bool = False
):
    """Free angle and blocked moment of the unit at P_T = p_top_kpa, P_B = 0 (Fig. 12 points).

    One ray per (model, case) from 0 to max(p_top_kpa) whose load steps hit
    every point exactly, and every load factor of ``extra_stops`` (fractions of
    max(p_top_kpa) in (0, 1], e.g. the scales of a sweep's P_B = 0 ray, so that the
    sweep can take that ray from here: a point within 1e-9 of one of them lands on
    its value, so the steps are the sweep ray's to the last bit); ``wall_time_s``
    is the time from zero load to the point.
    ``keep_paths``: the dataset also holds each ray's accepted steps
    (``path_*`` on a ``step`` dimension, NaN-padded; :data:`PATH_KEYS`), its
    ``path_status`` and ``path_wall_time_s`` (restarts included).
    Returns ``(dataset, deformed 3D mesh and displacement at the largest
    pressure or None)``.
    """
    p_top_kpa = np.asarray(sorted(p_top_kpa), dtype=float)
    pmax = float(p_top_kpa[-1])
    extra = [float(v) for v in np.asarray(extra_stops, dtype=float).ravel()]
    if any(not 0.0 < v <= 1.0 for v in extra):
        raise ValueError(f"extra stops are load factors in (0, 1], got {extra}")
    own = [float(v) for v in p_top_kpa / pmax if not any(abs(v - e) <= 1e-9 for e in extra)]
    stops = tuple(sorted(set(extra + own)))
    cases = ("free", "blocked")
    shape = (len(models), len(p_top_kpa), len(cases))
    angle = np.full(shape, np.nan)
    angle_total = np.full(shape, np.nan)
    moment = np.full(shape, np.nan)
    pen = np.full(shape, np.nan)
    overlap = np.full(shape, np.nan)
    pocket = {2: np.full(shape, np.nan), 3: np.full(shape, np.nan)}
    wall = np.full(shape, np.nan)
    status = np.full(shape, 3, dtype=np.int32)
    iters = np.zeros(shape, dtype=np.int32)
    deformed = None
    paths = {}  # (model index, case index) -> the path result
    for i, model in enumerate(models):
        dim = int(model[0])
        mesh = unit_mesh_from_config(actuator, dim)
        for k, case in enumerate(cases):
            res = solve_unit_from_config(
                actuator, dim, pmax, 0.0, case, mesh=mesh, stops=stops, keep_displacement=(dim == 3 and case == "free")
            )
            paths[i, k] = res
            log.info(
                "%s %s to P_T=%g kPa: status %d (%s), %d iterations, %.1f s",
                model,
                case,
                pmax,
                res.status,
                res.reason,
                res.newton_iterations,
                res.wall_time_s,
                extra=solved(res.status != 0),
            )
            for j, p in enumerate(p_top_kpa):
                hit = [h for h in res.history if abs(h["p_top_kpa"] - p) < 1e-6 * pmax]
                if not hit:  # the ray failed before this pressure
                    status[i, j, k] = res.status
                    continue
                h = hit[0]
                status[i, j, k] = 0
                iters[i, j, k] = sum(x["iterations"] for x in res.history if x["lam"] <= h["lam"])
                wall[i, j, k] = h["wall_time_s"]
                upto = [x for x in res.history if x["lam"] <= h["lam"]]
                pen[i, j, k] = max(x["max_penetration_mm"] for x in upto)
                overlap[i, j, k] = max(x["overlap_depth_mm"] for x in upto)
                key = "min_pocket_area_mm2" if dim == 2 else "min_pocket_volume_mm3"
                pocket[dim][i, j, k] = min(x[key] for x in upto)
                angle[i, j, k] = h["bending_angle_deg"]
                angle_total[i, j, k] = h["bending_angle_total_deg"]
                moment[i, j, k] = h["bending_moment_nm"]
                log.info(
                    "  P_T=%g kPa: angle %.3f deg/unit, moment %.4f N m",
                    p,
                    h["bending_angle_deg"],
                    h["bending_moment_nm"],
                )
            if res.displacement is not None and res.status == 0:
                deformed = (mesh, res.displacement)
    dims3 = ("model", "p_top_kpa", "case")
    ds = xr.Dataset(
        {
            "bending_angle_deg": (
                ("model", "p_top_kpa"),
                angle[:, :, 0],
                {"units": "degree", "long_name": "free bending angle per unit (chamber), P_B = 0"},
            ),
            "bending_angle_total_deg": (
                ("model", "p_top_kpa"),
                angle_total[:, :, 0],
                {"units": "degree", "long_name": "free bending angle of the three-chamber unit model"},
            ),
            "bending_moment_nm": (
                ("model", "p_top_kpa"),
                moment[:, :, 1],
                {"units": "N m", "long_name": "blocked moment per unit, full actuator width"},
            ),
            "max_penetration_mm": (
                dims3,
                pen,
                {"units": "mm", "long_name": "largest penetration over the load path (contact or overlap check)"},
            ),
            "overlap_depth_mm": (
                dims3,
                overlap,
                {"units": "mm", "long_name": "deepest boundary node inside another element over the load path"},
            ),
            "min_pocket_area_mm2": (
                dims3,
                pocket[2],
                {"units": "mm2", "long_name": "smallest pocket area over the load path (2D; 36.4 at rest)"},
            ),
            "min_pocket_volume_mm3": (
                dims3,
                pocket[3],
                {"units": "mm3", "long_name": "smallest pocket volume over the load path (3D; 509.6 at rest)"},
            ),
            "wall_time_s": (dims3, wall, {"units": "s", "long_name": "wall time of the solve from zero load"}),
            "newton_iterations": (dims3, iters, {"units": "1", "long_name": "Newton iterations over the load path"}),
            "status": (
                dims3,
                status,
                {
                    "units": "1",
                    "long_name": "solver status",
                    "flag_values": np.array(list(SOLVER_STATUS), dtype=np.int32),
                    "flag_meanings": " ".join(SOLVER_STATUS.values()),
                },
            ),
        },
        coords={
            "model": ("model", list(models)),
            "p_top_kpa": ("p_top_kpa", p_top_kpa, {"units": "kPa", "long_name": "top chamber pressure"}),
            "case": ("case", list(cases)),
            "p_bottom_kpa": ((), 0.0, {"units": "kPa", "long_name": "bottom chamber pressure"}),
        },
    )
    if keep_paths:
        ds = ds.assign(_path_variables(paths, len(models), len(cases)))
        ds.attrs["path_stops"] = np.asarray(stops)  # load factors of the rays' end pressure, max(p_top_kpa)
    return ds, deformed


def _path_variables(paths: Mapping, n_models: int, n_cases: int) -> dict:
    """The rays' accepted steps as ``path_*`` variables on (model, case, step), NaN past a ray's last step."""
    n_steps = max((len(r.history) for r in paths.values()), default=0)
    dims = ("model", "case", "step")
    out = {}
    for key, units in PATH_KEYS.items():
        if not any(key in h for r in paths.values() for h in r.history):
            continue
        arr = np.full((n_models, n_cases, n_steps), np.nan)
        for (i, k), r in paths.items():
            arr[i, k, : len(r.history)] = [h.get(key, np.nan) for h in r.history]
        out[f"path_{key}"] = (dims, arr, {"units": units, "long_name": f"{key} at each accepted load step of the ray"})
    out["path_status"] = (
        ("model", "case"),
        np.array([[paths[i, k].status for k in range(n_cases)] for i in range(n_models)], np.int32),
        {"units": "1", "long_name": "solver status of the ray (0: reached its largest pressure)"},
    )
    out["path_wall_time_s"] = (
        ("model", "case"),
        np.array([[paths[i, k].wall_time_s for k in range(n_cases)] for i in range(n_models)]),
        {"units": "s", "long_name": "wall time of the ray, restarts included"},
    )
    return out
