"""The FE solve behind one sweep ray: the unit's free and blocked paths along a
pressure direction, turned into the sweep's samples (:mod:`.sweep`).

Pressures kPa, angles deg per unit, moments N m per unit.
"""

from __future__ import annotations

import logging
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from workflow import fem
from workflow.common.rays import ray_config_sha256
from workflow.common.runlog import solved

__all__ = ["samples_from_paths", "make_solver", "studied_ray"]

log = logging.getLogger(__name__)


def _get(obj: Any, key: str, default: Any = None) -> Any:
    return obj.get(key, default) if isinstance(obj, Mapping) else getattr(obj, key, default)


def samples_from_paths(
    direction: Sequence[float], scales: np.ndarray, free: Any, blocked: Any, *, lam_tol: float = 1e-9
) -> dict[str, np.ndarray]:
    """Samples at ``scales`` from a free and a blocked continuation solve along one ray.

    ``free`` and ``blocked`` are path results (objects or mappings) with
    ``status`` (0 = reached load factor 1), ``wall_time_s`` and ``history``: one
    record per accepted load step with ``lam`` (load factor), ``iterations``
    and the measured ``bending_angle_deg`` (free) / ``bending_moment_nm``
    (blocked), e.g. `workflow.fem.UnitResult`.

    A scale equal to an accepted load factor (within ``lam_tol``) takes that
    step's value; otherwise the value is interpolated linearly in the load
    factor between the accepted steps around it, with the unloaded state
    (lam = 0: straight, no moment; true without gravity) below the first step.
    Ask the solver to land on the scales to avoid interpolating.  Scales beyond
    the last accepted step of either case are not converged: the first gets
    status ``diverged``, the rest ``not_reached``.  Newton iterations are those
    of the steps since the previous sample (both cases); the ray's wall time is
    shared among the samples in proportion to them.
    """
    scales = np.asarray(scales, float)
    out_vals = {}
    reached = np.ones(scales.size, dtype=bool)
    iters = np.zeros(scales.size)
    n_interp = 0
    for case, key in ((free, "bending_angle_deg"), (blocked, "bending_moment_nm")):
        hist = list(_get(case, "history", []) or [])
        lam = np.array([0.0] + [float(h["lam"]) for h in hist])
        val = np.array([0.0] + [float(h[key]) for h in hist])
        its = np.array([0.0] + [float(h.get("iterations", 0)) for h in hist])
        lam_last = lam[-1] if _get(case, "status", 0) != 0 else max(lam[-1], 1.0)
        reached &= scales <= lam_last + lam_tol
        v = np.interp(scales, lam, val)
        exact = np.isclose(scales[:, None], lam[None, 1:], rtol=0, atol=lam_tol).any(axis=1)
        n_interp += int(np.count_nonzero(~exact & reached))
        cum = np.cumsum(its)
        idx = np.searchsorted(lam, scales - lam_tol)  # first step at or after each scale
        idx = np.minimum(idx, lam.size - 1)
        at = cum[idx]
        iters += np.diff(np.r_[0.0, at])
        out_vals[key] = v
    if n_interp:
        log.warning("ray %s: %d sample values interpolated between load steps", tuple(direction), n_interp)
    checks = {}
    for key, worst in (
        ("max_penetration_mm", np.max),
        ("overlap_depth_mm", np.max),
        ("min_pocket_area_mm2", np.min),
        ("min_pocket_volume_mm3", np.min),
    ):
        rec = [
            (float(h["lam"]), float(h[key]))
            for case in (free, blocked)
            for h in (_get(case, "history", []) or [])
            if key in h
        ]
        if not rec:
            continue
        lam_k, val_k = np.array(rec).T
        checks[key] = np.array(
            [worst(val_k[lam_k <= s + lam_tol]) if np.any(lam_k <= s + lam_tol) else np.nan for s in scales]
        )
    status = np.zeros(scales.size, dtype=int)
    not_reached = np.flatnonzero(~reached)
    if not_reached.size:
        status[not_reached] = 2
        status[not_reached[0]] = 1
    for key in out_vals:
        out_vals[key][~reached] = np.nan
    wall = float(_get(free, "wall_time_s", 0.0)) + float(_get(blocked, "wall_time_s", 0.0))
    share = iters / iters.sum() if iters.sum() > 0 else np.full(scales.size, 1.0 / scales.size)
    return {
        "p_top_kpa": scales * float(direction[0]),
        "p_bottom_kpa": scales * float(direction[1]),
        "bending_angle_deg": out_vals["bending_angle_deg"],
        "bending_moment_nm": out_vals["bending_moment_nm"],
        "status": status,
        "newton_iterations": iters.astype(int),
        "wall_time_s": wall * share,
        **checks,
    }


def _mirror_blocked(free: Any, direction: Sequence[float]) -> dict:
    """The blocked case of a ray with P_T = P_B on a top/bottom mirror-symmetric unit, without solving it.

    The load is symmetric, so the held state is too and the couple that holds it is zero at every load step the
    free case reached (``free``'s history and status; no Newton iterations, no time).  The free case's own angle is
    zero by the same symmetry: a warning says so if it is not, to round-off.
    """
    hist = list(_get(free, "history", []) or [])
    worst = max((abs(float(h.get("bending_angle_deg", 0.0))) for h in hist), default=0.0)
    if worst > 1e-6:
        log.warning("ray %s: free angle %.3g deg where the mirror symmetry makes it zero", tuple(direction), worst)
    log.info(
        "ray to (%.1f, %.1f) kPa, blocked: zero moment by the unit's top/bottom mirror symmetry (P_T = P_B), not "
        "solved; the free case's largest |angle| %.1e deg",
        float(direction[0]),
        float(direction[1]),
        worst,
    )
    return {
        "status": int(_get(free, "status", 0)),
        "wall_time_s": 0.0,
        "history": [{"lam": float(h["lam"]), "bending_moment_nm": 0.0, "iterations": 0} for h in hist],
    }


def studied_ray(
    case: Any, actuator: Mapping[str, Any], fea: str, direction: Sequence[float], scales: np.ndarray
) -> dict[str, np.ndarray] | None:
    """The samples of the sweep ray ``direction`` at ``scales`` from the FE study's case ``case``, or None where
    it must be solved.

    A case that shares the sweep's P_B = 0 ray (``workflow.fidelity.entry_fem.write_fem_case`` with a sweep)
    solved it on the same mesh and config with its load steps landing on the same load factors, and keeps both
    paths (``path_*``): the solver's path depends on nothing else (each path starts from its own analysis), so
    :func:`samples_from_paths` on them gives what solving the ray here gives.  Taken only when the model, the
    element size, the contact switch, the config (:func:`workflow.common.rays.ray_config_sha256`), the direction
    and the load factors (to the bit) are the ray's, both paths reached their load, and the ray's own Newton budget
    (``actuator.iteration_budget``, None: none) is none or at least the case's (a ray that converged within the
    case's budget converges alike within a larger one, not within a smaller).
    """
    if case is None or "path_status" not in case or "actuator_sha256" not in case.attrs:
        return None
    budget, case_budget = actuator.get("iteration_budget"), str(case.attrs.get("iteration_budget", "none"))
    same = (
        str(case.attrs.get("model")) == fea
        and str(case.attrs["actuator_sha256"]) == ray_config_sha256(actuator)
        and float(direction[1]) == 0.0
        and float(direction[0]) == float(case["p_top_kpa"].max())
        and np.array_equal(np.atleast_1d(np.asarray(case.attrs.get("path_stops", []), float)), scales)
        and bool((case["path_status"] == 0).all())
        and (budget is None or (case_budget != "none" and int(budget) >= int(case_budget)))
    )
    if not same:
        return None
    steps = [str(k) for k in case.data_vars if str(k).startswith("path_") and "step" in case[k].dims]
    paths = {}
    for c in ("free", "blocked"):
        keep = np.isfinite(case["path_lam"].sel(case=c).values)
        cols = {k[len("path_") :]: case[k].sel(case=c).values[keep] for k in steps}
        paths[c] = {
            "status": int(case["path_status"].sel(case=c)),
            "wall_time_s": float(case["path_wall_time_s"].sel(case=c)),
            "history": [{k: float(v[j]) for k, v in cols.items()} for j in range(int(keep.sum()))],
        }
    return samples_from_paths(direction, scales, paths["free"], paths["blocked"])


def make_solver(fea: str, actuator_config: Mapping[str, Any]) -> Callable[[Sequence[float], np.ndarray], Any]:
    """The ray solver of FE model ``fea`` ('2d' or '3d') for the sweep.

    Returns ``solve_ray(direction, scales)``: the free and the blocked case of
    :func:`workflow.fem.solve_unit` along (P_T, P_B) = s * direction, with load
    steps landing exactly on ``scales`` (so the samples are solutions, not
    interpolations), turned into the fields of `SAMPLE_FIELDS` by
    :func:`samples_from_paths`.  The mesh is built once per job.
    """

    if fea not in ("2d", "3d"):
        raise ValueError(f"unknown FE model {fea!r}: expected '2d' or '3d'")
    dim = 2 if fea == "2d" else 3
    mesh = fem.unit_mesh_from_config(actuator_config, dim)
    symmetric = fem.top_bottom_symmetric(mesh)

    def solve_ray(direction: Sequence[float], scales: np.ndarray) -> dict[str, np.ndarray]:
        p_top, p_bottom = (float(v) for v in direction)
        stops = tuple(float(v) for v in np.asarray(scales, float))
        paths = {}
        for case in ("free", "blocked"):
            if case == "blocked" and symmetric and p_top == p_bottom:
                paths[case] = _mirror_blocked(paths["free"], direction)
                continue
            r = fem.solve_unit_from_config(actuator_config, dim, p_top, p_bottom, case, mesh=mesh, stops=stops)
            # a 3D ray takes minutes per case: say so as each case ends
            log.info(
                "ray to (%.1f, %.1f) kPa, %s: %s at load factor %.3f, %d steps, %d Newton iterations, %.1f s",
                p_top,
                p_bottom,
                case,
                r.reason or "converged",
                r.load_factor,
                r.steps,
                r.newton_iterations,
                r.wall_time_s,
                extra=solved(r.status != 0),
            )
            paths[case] = r
        return samples_from_paths(direction, scales, paths["free"], paths["blocked"])

    return solve_ray
