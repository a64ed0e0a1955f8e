"""Rule entry points of the actuator's FEA (``sweep_shard``, ``unit_check``).

Apart from :mod:`.entry` so that these rules' inputs (the code they run) hold
the sweep and the FE engine only: editing the surrogates or the mapping does not
rerun minutes of FEA.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np
import xarray as xr

from workflow.actuator.fe_solver import make_solver, studied_ray
from workflow.actuator.sweep import run_shard
from workflow.common.provenance import write_dataset
from workflow.common.vtu import write_vtu
from workflow.fem._config import unit_check, unit_mesh_from_config

__all__ = ["write_unit_check", "studied_unit_check", "write_shard"]

log = logging.getLogger(__name__)


def write_unit_check(
    nc_path: str | Path,
    vtu_path: str | Path,
    actuator: Mapping,
    *,
    rule: str = "unit_check",
    config_slice=None,
    model_actuators: Mapping[str, Mapping] | None = None,
    attrs: Mapping | None = None,
    studied: Mapping[str, xr.Dataset] | None = None,
) -> None:
    """Run ``unit_check`` with the config's points and write the dataset and the deformed 3D unit.

    ``model_actuators``: a config per model (``{"2d": ..., "3d": ...}``, e.g.
    the meshes a fidelity study chose), else ``actuator`` for all; ``attrs``
    are added to the dataset.  ``studied``: per model, the FE study's case on
    that same mesh and config (``results/fidelity/fem/<case>.nc``); where it
    reached every point its rays are these rays, so they are taken from it
    instead of being solved again (see :func:`studied_unit_check`).  If the 3D
    model is not requested or its ray fails, the .vtu holds the undeformed 3D
    mesh with zero displacement (and the dataset's status says why).
    """

    uc = dict(actuator.get("unit_check", {}))
    models = tuple(uc.get("models", ("2d", "3d")))
    p_top = uc.get("p_top_kpa", (60.0, 180.0, 300.0))
    if model_actuators:
        parts, source = [], {}
        for m in models:
            act = model_actuators.get(m, actuator)
            known = studied_unit_check(studied.get(m), act, m, p_top) if studied else None
            if known is None:
                known = unit_check(act, (m,), p_top)
                source[f"unit_check_source_{m}"] = "solved here"
            else:
                source[f"unit_check_source_{m}"] = (
                    f"the FE study's case {studied[m].attrs.get('case', '?')}: the same rays, not solved again"
                )
            log.info("unit check %s: %s", m, source[f"unit_check_source_{m}"])
            parts.append(known)
        ds = xr.concat([p[0] for p in parts], dim="model")  # the variables keep their units and names
        ds.attrs = dict(source)
        deformed = next((p[1] for p in parts if p[1] is not None), None)
        actuator = model_actuators.get("3d", actuator)
    else:
        ds, deformed = unit_check(actuator, models, p_top)
    ds.attrs.update({k: str(v) for k, v in dict(attrs or {}).items()})
    write_dataset(
        ds,
        nc_path,
        rule=rule,
        config_slice=config_slice if config_slice is not None else dict(actuator),
        title="PNA unit check: free bending angle and blocked moment at P_T = 60, 180, 300 kPa (P_B = 0)",
        source="workflow.fem (scikit-fem; Q1/P0 silicone, enhanced-strain paper layer, follower pressure, penalty self-contact)",
    )
    if deformed is None:
        mesh = unit_mesh_from_config(actuator, 3)
        deformed = (mesh, np.zeros(mesh.mesh.p.size))
    mesh, u = deformed
    write_vtu(mesh.mesh, u, vtu_path, cell_data={"material": mesh.material})


def studied_unit_check(case: xr.Dataset | None, actuator: Mapping, model: str, p_top_kpa) -> tuple | None:
    """The unit check of ``model`` read from the FE study's case ``case``, or None where it must be solved.

    The study's case (:func:`workflow.fidelity.entry_fem.write_fem_case`) runs this same ``unit_check`` on the
    same mesh, contact and solver, with a Newton budget per ray that only ends a ray early: a case that reached
    every point was not touched by it, so its values, statuses and times are the rays' own (the solver's path
    does not depend on what ran before it).  A case that shares the sweep's P_B = 0 ray also landed its steps on
    the sweep's samples: the same points of a path with more steps (the 3D values at most 5.3e-5 from the check's
    own path at 1e-2 convergence, the 2D ones 7e-10).  Taken only if the case's element size, contact and points are the
    check's and every point converged.  Returns ``(dataset with a model dimension, (mesh, displacement) or
    None)`` as ``unit_check`` does.
    """
    if case is None:
        return None
    h = float(dict(actuator.get("mesh", {})).get(f"h_{model}_mm", np.nan))
    contact = bool(dict(actuator.get("contact", {})).get("enabled", True))
    same = (
        str(case.attrs.get("model")) == model
        and np.isclose(float(case.attrs.get("h_mm", np.nan)), h)
        and bool(int(case.attrs.get("contact", -1))) == contact
        and _same_points(case["p_top_kpa"].values, p_top_kpa)
    )
    if not same or not bool((case["status"] == 0).all()):
        return None
    deformed = None
    if "displacement_mm" in case:
        mesh = unit_mesh_from_config(actuator, int(model[0]))
        u = case["displacement_mm"].values
        if u.size != mesh.mesh.p.size:
            return None
        deformed = (mesh, u)
    elif model == "3d":  # the check's .vtu needs the 3D free ray's displacement
        return None
    paths = [k for k in case.data_vars if str(k).startswith("path_")]  # the sweep's, not the check's
    ds = case.drop_vars(["case_wall_time_s", "displacement_mm", *paths], errors="ignore")
    ds = ds.drop_dims("step", errors="ignore").expand_dims(model=[model])
    ds.attrs = {}
    return ds, deformed


def _same_points(a, b) -> bool:
    """The same pressures (kPa), in any order; lists of different lengths are simply not the same."""
    a, b = np.sort(np.asarray(a, float)), np.sort(np.asarray(b, float))
    return a.shape == b.shape and bool(np.allclose(a, b))


def write_shard(
    out: str | Path,
    *,
    fea: str,
    shard: int,
    sweep_cfg: Mapping[str, Any],
    actuator_cfg: Mapping[str, Any],
    config_slice: Any,
    rule: str = "sweep_shard",
    solver: Callable | None = None,
    attrs: Mapping[str, Any] | None = None,
    studied: xr.Dataset | None = None,
) -> xr.Dataset:
    """Solve shard ``shard`` of FE model ``fea`` and write it (atomically) to ``out``.

    ``sweep_cfg`` is the model's ``sweep`` config (p_max_kpa, n_ratios,
    n_pressures, n_shards); ``solver`` defaults to `make_solver(fea, actuator_cfg)`;
    ``attrs`` (e.g. the fidelity used and why) go into the file and on to the merged response.
    ``studied``: the FE study's case on this mesh; a ray it already solved on
    the same load steps (the P_B = 0 ray, :func:`studied_ray`) is read from it.
    """
    solver = make_solver(fea, actuator_cfg) if solver is None else solver
    read: list[str] = []  # the rays taken from the study (their wall time and Newton iterations are the study's)
    if studied is not None:
        solver = _reading_studied_ray(solver, studied, actuator_cfg, fea, read)
    ds = run_shard(
        solver,
        shard=int(shard),
        p_max_kpa=sweep_cfg["p_max_kpa"],
        n_ratios=sweep_cfg["n_ratios"],
        n_pressures=sweep_cfg["n_pressures"],
        n_shards=sweep_cfg["n_shards"],
    )
    ds.attrs["fea"] = fea
    ds.attrs["shard"] = int(shard)
    if read:
        ds.attrs["rays_read_from_study"] = "; ".join(read)
    mesh = dict(actuator_cfg.get("mesh", {}))
    ds.attrs["h_mm"] = float(mesh.get(f"h_{fea}_mm", 1.0 if fea == "2d" else 2.0))
    ds.attrs["contact"] = int(bool(dict(actuator_cfg.get("contact", {})).get("enabled", True)))
    ds.attrs.update({k: str(v) for k, v in dict(attrs or {}).items()})
    write_dataset(
        ds, out, rule=rule, config_slice=config_slice, title=f"{fea.upper()} unit pressure sweep, shard {int(shard)}"
    )
    return ds


def _reading_studied_ray(
    solve_ray: Callable, case: xr.Dataset, actuator: Mapping, fea: str, read: list[str]
) -> Callable:
    """``solve_ray`` that takes a ray from the FE study's ``case`` where :func:`studied_ray` finds it there, and
    names each ray it took in ``read``."""

    def solve(direction, scales):
        known = studied_ray(case, actuator, fea, direction, scales)
        if known is None:
            return solve_ray(direction, scales)
        name = str(case.attrs.get("case", "?"))
        log.info(
            "ray to (%.1f, %.1f) kPa: the FE study's case %s solved it on these load steps; read, not solved again",
            float(direction[0]),
            float(direction[1]),
            name,
        )
        read.append(f"ray to ({float(direction[0]):g}, {float(direction[1]):g}) kPa from {name}")
        return known

    return solve
