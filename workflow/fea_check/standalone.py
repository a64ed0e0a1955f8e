"""Stand-alone whole actuators at the plan's pressures, 2D against 3D (paper Fig. 22).

The actuator of the plan (``units_per_group``), hand end clamped, no finger,
no gravity, each exercise's pressures ramped from zero, in up to three models:

* ``2d_mapped``: plane strain at the 2D pressures of the 2D-to-3D mapping
  (:func:`workflow.fea_check.applied.pressures_2d`), the pressures the FEA check uses;
* ``2d_plan``: plane strain at the planned (3D) pressures unchanged (the
  paper's "limited bending" comparison the other way round);
* ``3d_plan``: the 3D half model at the planned pressures, on the coarsest
  mesh that converges: the element sizes ``h_3d_mm`` are tried coarse to fine
  per exercise until one reaches the full pressures (``h_used_mm``).

Compared by the backbone curve (paper-layer mid-line, resampled at common
stations along the undeformed actuator) and the tip angle.  A model that does
not reach the full pressures is kept with its last converged load factor.
The workflow solves each exercise in a job of its own (the 3D solves take
minutes each, so two run at once) and joins them with :func:`merge_exercises`.
Lengths mm, angles deg, pressures kPa.
"""

from __future__ import annotations

import logging
from typing import Mapping, Sequence

import numpy as np
import xarray as xr

from workflow import fem
from workflow.common.constants import CHAMBERS, CHECK_MAPPING_STATUS, GROUPS, SOLVER_STATUS
from workflow.common.runlog import solved
from workflow.fea_check.check import unit_bends_dataset
from workflow.fem._mesh import build_actuator_mesh
from workflow.fem.actuator import solve_standalone

__all__ = ["MODELS", "compare_models", "merge_exercises", "resample_backbone", "standalone_dataset"]

log = logging.getLogger(__name__)
MODELS = ("2d_mapped", "2d_plan", "3d_plan")


def resample_backbone(curve: np.ndarray, ref: np.ndarray, stations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Deformed (x, y) of the backbone at reference positions ``stations`` (mm along the undeformed actuator)."""
    return np.interp(stations, ref[:, 0], curve[:, 0]), np.interp(stations, ref[:, 0], curve[:, 1])


def standalone_dataset(
    plan: xr.Dataset,
    *,
    exercises: Sequence[str],
    models: Sequence[str],
    actuator_cfg: Mapping,
    h_2d_mm: float,
    h_3d_mm: float | Sequence[float],
    solver: Mapping,
    p2: np.ndarray,
    flag: np.ndarray,
    restarts: Sequence[Mapping] = (),
    n_stations: int = 41,
) -> xr.Dataset:
    """Solve every (exercise, model) and collect curves and tip angles.

    ``h_3d_mm``: one element size or several, tried coarse to fine per
    exercise until the 3D solve reaches the full pressures; on each, a solve
    that stalls is tried again with each of ``restarts`` applied over the
    previous ones (as the finger-actuator check, ``fea_check.restarts``).
    """
    h3_list = sorted(np.atleast_1d(np.asarray(h_3d_mm, float)).tolist(), reverse=True)
    geom = dict(fem.DEFAULT_GEOMETRY)
    geom.update(dict(actuator_cfg.get("geometry", {})))
    upg = {g: int(v) for g, v in zip(plan["group"].values, plan["units_per_group"].values)}
    n = sum(upg.values())
    length = n * geom["depth"] + (n - 1) * geom["gap"]
    stations = np.linspace(0.0, length, n_stations)
    p_plan = plan["pressure_kpa"].sel(exercise=list(exercises), group=list(GROUPS), chamber=list(CHAMBERS)).values
    shape = (len(exercises), len(models))
    bx = np.full(shape + (n_stations,), np.nan)
    by = np.full_like(bx, np.nan)
    tip, lam, wall = np.full(shape, np.nan), np.zeros(shape), np.zeros(shape)
    bends = np.full(shape + (n,), np.nan)
    status = np.full(shape, -1, dtype="i1")
    its, ndofs = np.zeros(shape, dtype="i4"), np.zeros(shape, dtype="i4")
    h_used = np.full(shape, np.nan)
    attempt = np.zeros(shape, dtype="i1")
    meshes = {}
    mat = actuator_cfg.get("material")
    contact = {k: v for k, v in dict(actuator_cfg.get("contact", {})).items() if k != "enabled"}
    layers = fem.layer_options(actuator_cfg)
    formulation = actuator_cfg.get("formulation", fem.DEFAULT_FORMULATION)
    pen, overlap = np.full(shape, np.nan), np.full(shape, np.nan)
    pocket = {2: np.full(shape, np.nan), 3: np.full(shape, np.nan)}

    def mesh(dim, h):
        if (dim, h) not in meshes:
            meshes[dim, h] = build_actuator_mesh(geom, upg, h=h, dim=dim, **layers)
        return meshes[dim, h]

    for j, m in enumerate(models):
        dim = 3 if m.startswith("3d") else 2
        for i, ex in enumerate(exercises):
            pk = p2[i] if m == "2d_mapped" else p_plan[i]
            press = {g: (float(pk[k, 0]), float(pk[k, 1])) for k, g in enumerate(GROUPS)}
            t_case = 0.0
            for h in h3_list if dim == 3 else [float(h_2d_mm)]:
                spent = []

                def solve(contact_opts, opts, um=mesh(dim, h), press=press):
                    res = solve_standalone(
                        um, press, material=mat, contact_options=contact_opts, solver=opts, formulation=formulation
                    )
                    spent.append(res.wall_time_s)
                    return res

                label = f"{ex} {m} (h = {h:g} mm)"
                r, k = fem.first_converged(fem.cumulative_attempts(contact, solver, restarts), solve, label=label)
                t_case += sum(spent)
                log.info(
                    "%s %s (h = %g mm, %d dofs): tip %.1f deg, status %d at %.3f, %d its, %.1f s",
                    ex,
                    m,
                    h,
                    r.ndofs,
                    r.tip_angle_deg,
                    r.status,
                    r.load_factor,
                    r.newton_iterations,
                    r.wall_time_s,
                    extra=solved(r.status != 0),
                )
                if r.status == 0:
                    break
            bx[i, j], by[i, j] = resample_backbone(r.backbone_mm, r.backbone_ref_mm, stations)
            tip[i, j], lam[i, j], status[i, j] = r.tip_angle_deg, r.load_factor, r.status
            bends[i, j] = r.unit_bends_deg
            its[i, j], wall[i, j], ndofs[i, j], h_used[i, j] = r.newton_iterations, t_case, r.ndofs, h
            attempt[i, j] = k
            pen[i, j], overlap[i, j], pocket[dim][i, j] = r.max_penetration_mm, r.overlap_depth_mm, r.min_pocket
    flag_vals = np.array(sorted(SOLVER_STATUS), dtype="i1")
    map_vals = np.array(sorted(CHECK_MAPPING_STATUS), dtype="i1")
    ds = xr.Dataset(
        {
            "backbone_x_mm": (
                ("exercise", "model", "station"),
                bx,
                {"units": "mm", "long_name": "deformed backbone x (hand end at 0)"},
            ),
            "backbone_y_mm": (
                ("exercise", "model", "station"),
                by,
                {"units": "mm", "long_name": "deformed backbone y (paper layer at 0)"},
            ),
            "tip_angle_deg": (
                ("exercise", "model"),
                tip,
                {"units": "degree", "long_name": "backbone rotation at the tip (positive towards the bottom side)"},
            ),
            "converged": (
                ("exercise", "model"),
                (status == 0) & (lam >= 1 - 1e-9),
                {"units": "1", "long_name": "pressures reached in full"},
            ),
            "load_factor": (
                ("exercise", "model"),
                lam,
                {"units": "1", "long_name": "last converged fraction of the pressures"},
            ),
            "status": (
                ("exercise", "model"),
                status,
                {
                    "units": "1",
                    "long_name": "solver status",
                    "flag_values": flag_vals,
                    "flag_meanings": " ".join(SOLVER_STATUS[int(v)] for v in flag_vals),
                },
            ),
            "newton_iterations": (("exercise", "model"), its, {"units": "1", "long_name": "Newton iterations"}),
            "wall_time_s": (
                ("exercise", "model"),
                wall,
                {"units": "s", "long_name": "wall time of the solves (incl. coarser meshes that failed)"},
            ),
            "ndofs": (("exercise", "model"), ndofs, {"units": "1", "long_name": "degrees of freedom of the mesh kept"}),
            "max_penetration_mm": (
                ("exercise", "model"),
                pen,
                {"units": "mm", "long_name": "largest penetration over the path (contact or overlap check)"},
            ),
            "overlap_depth_mm": (
                ("exercise", "model"),
                overlap,
                {"units": "mm", "long_name": "deepest boundary node inside another element over the path"},
            ),
            "min_pocket_area_mm2": (
                ("exercise", "model"),
                pocket[2],
                {"units": "mm2", "long_name": "smallest pocket area over the path (2D models)"},
            ),
            "min_pocket_volume_mm3": (
                ("exercise", "model"),
                pocket[3],
                {"units": "mm3", "long_name": "smallest pocket volume over the path (3D models)"},
            ),
            "attempt": (
                ("exercise", "model"),
                attempt,
                {
                    "units": "1",
                    "long_name": "solve kept: 0 as configured, k the k-th of fea_check.restarts over the others",
                },
            ),
            "h_used_mm": (
                ("exercise", "model"),
                h_used,
                {
                    "units": "mm",
                    "long_name": "element size kept (3D: the coarsest that converged, else the finest tried)",
                },
            ),
            "pressure_plan_kpa": (
                ("exercise", "group", "chamber"),
                p_plan,
                {"units": "kPa", "long_name": "planned (3D) pressure"},
            ),
            "pressure_2d_kpa": (
                ("exercise", "group", "chamber"),
                p2,
                {"units": "kPa", "long_name": "2D pressure of the mapping"},
            ),
            "mapping_status": (
                ("exercise", "group"),
                flag.astype("i1"),
                {
                    "units": "1",
                    "long_name": "how the 2D pressure pair was obtained",
                    "flag_values": map_vals,
                    "flag_meanings": " ".join(CHECK_MAPPING_STATUS[int(v)] for v in map_vals),
                },
            ),
        },
        coords={
            "exercise": list(exercises),
            "model": list(models),
            "station": stations,
            "group": list(GROUPS),
            "chamber": list(CHAMBERS),
        },
    )
    groups = [g for g, k in upg.items() for _ in range(k)]
    ds = ds.merge(unit_bends_dataset(bends, groups=groups, geometry=geom, dims=("exercise", "model")))
    ds["station"].attrs = {"units": "mm", "long_name": "position along the undeformed backbone from the hand end"}
    ds.attrs.update({"h_2d_mm": float(h_2d_mm), "h_3d_mm_tried": str(h3_list), "units_per_group": str(upg)})
    return compare_models(ds)


#: Variables that compare two models of one exercise (recomputed when exercises are joined).
_COMPARISONS = ("profile_rms_mm", "tip_angle_diff_deg")


def compare_models(ds: xr.Dataset) -> xr.Dataset:
    """Add the mapped 2D model against the 3D one, per exercise: RMS distance of the backbones, tip angle difference."""
    ds = ds.drop_vars([v for v in _COMPARISONS if v in ds])
    models = list(ds["model"].values)
    if "2d_mapped" in models and "3d_plan" in models:
        d = np.hypot(
            ds["backbone_x_mm"].sel(model="2d_mapped") - ds["backbone_x_mm"].sel(model="3d_plan"),
            ds["backbone_y_mm"].sel(model="2d_mapped") - ds["backbone_y_mm"].sel(model="3d_plan"),
        )
        ds["profile_rms_mm"] = (
            ("exercise",),
            np.sqrt((d**2).mean("station")).values,
            {"units": "mm", "long_name": "RMS distance of the 2d_mapped and 3d_plan backbone curves"},
        )
        ds["tip_angle_diff_deg"] = (
            ("exercise",),
            (ds["tip_angle_deg"].sel(model="2d_mapped") - ds["tip_angle_deg"].sel(model="3d_plan")).values,
            {"units": "degree", "long_name": "tip angle 2d_mapped minus 3d_plan"},
        )
    return ds


def merge_exercises(parts: Sequence[xr.Dataset]) -> xr.Dataset:
    """One dataset of the exercises solved apart (each part from :func:`standalone_dataset` on one or more).

    The parts must share the actuator, the models and the stations; the exercises keep the parts' order.
    """
    if not parts:
        raise ValueError("no stand-alone results to merge")
    first = parts[0]
    for part in parts[1:]:
        for coord in ("model", "station", "unit", "group", "chamber"):
            if not np.array_equal(part[coord].values, first[coord].values):
                raise ValueError(f"stand-alone parts differ in {coord!r}: solved on different settings")
    stripped = [part.drop_vars([v for v in _COMPARISONS if v in part]) for part in parts]
    # variables without an exercise (the units' groups, the jam angle) are the actuator's: kept once
    ds = xr.concat(stripped, dim="exercise", data_vars="minimal", combine_attrs="override")
    return compare_models(ds)
