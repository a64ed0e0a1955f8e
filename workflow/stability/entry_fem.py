"""Rule entry points of the stability stage's FE studies (``stability_rays``, ``stability_locking``):
extra rays of the 2D unit by mesh, contact and formulation, and the locking
study against K/mu0.

Apart from :mod:`.entry` so that redrawing the maps does not rerun this FEA.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any, Mapping

import xarray as xr

from workflow import fem
from workflow.common.provenance import write_dataset
from workflow.common.runlog import solved
from workflow.stability import rays as S
from workflow.stability import samples as SM

__all__ = ["fe_ray_solver", "write_rays", "write_locking"]

log = logging.getLogger(__name__)


def fe_ray_solver(actuator: Mapping[str, Any]):
    """``solve(variant, p_top, p_bottom, stops)`` on workflow.fem's 2D unit, one mesh per element size.

    Geometry, material (K/mu0 included), contact options and step control come
    from the config's ``actuator`` section; the variant sets ``h_mm``,
    ``contact`` and ``formulation``.
    """

    meshes: dict[float, Any] = {}
    contact_opts = {k: v for k, v in dict(actuator.get("contact", {})).items() if k != "enabled"}

    def solve(variant, p_top, p_bottom, stops):
        h = float(variant["h_mm"])
        if h not in meshes:
            meshes[h] = fem.build_unit_mesh(actuator.get("geometry"), h=h, dim=2, **fem.layer_options(actuator))
        return fem.solve_unit(
            meshes[h],
            p_top,
            p_bottom,
            "free",
            bool(variant["contact"]),
            material=actuator.get("material"),
            contact_options=contact_opts,
            solver=actuator.get("solver"),
            formulation=variant["formulation"],
            stops=stops,
        )

    return solve


def write_rays(
    out: str | Path,
    *,
    rays_cfg: Mapping[str, Any],
    actuator: Mapping[str, Any],
    config_slice: Any,
    rule: str = "stability_rays",
    solve=None,
) -> xr.Dataset:
    """Extra 2D free-bending rays by mesh, contact and formulation -> ``rays_2d.nc``."""
    solve = fe_ray_solver(actuator) if solve is None else solve
    variants = list(rays_cfg["variants"])
    t0 = time.perf_counter()
    rays = S.solve_rays(
        solve, variants, p_max_kpa=float(rays_cfg["p_max_kpa"]), n_pressures=int(rays_cfg["n_pressures"])
    )
    ds = S.rays_dataset(rays, variants, p_max_kpa=float(rays_cfg["p_max_kpa"]))
    log.info(
        "%d rays, %d of %d samples converged, %.1f s",
        ds.sizes["ray"],
        int((ds["status"] == 0).sum()),
        ds["status"].size,
        time.perf_counter() - t0,
    )
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice=config_slice,
        title="Extra 2D free-bending rays of the unit by element size, contact and formulation",
    )
    return ds


def write_locking(
    out: str | Path,
    *,
    locking_cfg: Mapping[str, Any],
    actuator: Mapping[str, Any],
    config_slice: Any,
    rule: str = "stability_locking",
    solve=None,
) -> xr.Dataset:
    """Free angle vs K/mu0 per element formulation (``stability.LOCKING_FORMULATIONS``) -> ``locking.nc``.

    ``solve(bulk_ratio, formulation)`` defaults to workflow.fem's 2D unit at
    ``locking_cfg`` (``h_mm``, ``p_top_kpa``, ``contact``); it returns a result
    with ``status``, ``bending_angle_deg`` and ``wall_time_s``.
    """
    c = locking_cfg
    if solve is None:
        mesh = fem.build_unit_mesh(actuator.get("geometry"), h=float(c["h_mm"]), dim=2)

        def solve(k, formulation):
            mat = dict(actuator.get("material", {}), bulk_ratio=float(k))
            return fem.solve_unit(
                mesh,
                float(c["p_top_kpa"]),
                0.0,
                "free",
                bool(c["contact"]),
                material=mat,
                solver=actuator.get("solver"),
                formulation=formulation,
            )

    ks = [float(k) for k in c["bulk_ratios"]]
    ang: dict[str, list] = {f: [] for f in S.LOCKING_FORMULATIONS}
    st: dict[str, list] = {f: [] for f in S.LOCKING_FORMULATIONS}
    wall: dict[str, list] = {f: [] for f in S.LOCKING_FORMULATIONS}
    for f in S.LOCKING_FORMULATIONS:
        for k in ks:
            r = solve(k, f)
            ang[f].append(float(r.bending_angle_deg))
            st[f].append(int(r.status))
            wall[f].append(float(r.wall_time_s))
            log.info(
                "%s, K/mu0 = %g: angle %.4f deg per unit, status %d, %.2f s",
                f,
                k,
                r.bending_angle_deg,
                r.status,
                r.wall_time_s,
                extra=solved(r.status != 0),
            )
    ds = SM.locking_dataset(ks, ang, st, p_top_kpa=float(c["p_top_kpa"]), h_mm=float(c["h_mm"]), wall_time_s=wall)
    ds.attrs["contact"] = int(bool(c["contact"]))
    log.info(
        "volumetric locking ratio (plain Q1 / mean dilatation) per K/mu0: %s; shear locking ratio (plain / "
        "enhanced paper layer): %s",
        {k: round(float(r), 4) for k, r in zip(ks, ds["locking_ratio"].values)},
        {k: round(float(r), 4) for k, r in zip(ks, ds["shear_locking_ratio"].values)},
    )
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice=config_slice,
        title="Locking: free angle vs K/mu0, enhanced-strain paper layer, mean-dilatation and plain Q1 elements",
    )
    return ds
