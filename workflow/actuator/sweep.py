"""Pressure-grid sweeps of the actuator unit: ray design, shards, merge.

The (P_T, P_B) plane over 0..p_max is sampled along *rays* of constant ratio
r = P_B / P_T.  A ray is one continuation solve from zero pressure to its end
point (P_T, P_B) = (p_max, r p_max); its load steps at the scales ``s`` in (0, 1]
are the samples, so a ray costs about one solve, whatever its sample count.

Symmetry: the unit is symmetric about its strain-limiting layer, so swapping
P_T and P_B negates the bending angle and the blocked moment.  Only rays with
P_B <= P_T (0 <= r <= 1) are solved; every solved point off the diagonal gets a
*mirrored* twin (P_B, P_T) with negated angle and moment.  The diagonal ray
(r = 1) is solved (it checks the symmetry: its angle must be ~0) and not
mirrored.

Work is split into shards (independent Snakemake jobs, one or more rays
each); each shard is written as its own netCDF file, atomically, so that an
interrupted sweep rerun recomputes only the missing shards.  `merge_shards`
gathers them into ``response_{2d,3d}.nc`` (CONTRACT.md).

The solver is injected: any callable

    solve_ray(direction, scales) -> mapping or tuple of 1-D arrays
        (p_top_kpa, p_bottom_kpa, bending_angle_deg, bending_moment_nm,
         status, newton_iterations, wall_time_s)

with ``direction = (p_top_kpa, p_bottom_kpa)`` at s = 1 and one sample per
requested scale, in order.  ``status`` uses `SWEEP_SAMPLE_STATUS` (0 = converged);
angles are the free bending angle per unit (deg), moments the blocked moment
per unit (N m), both over the actuator's full width.
If the callable accepts a ``progress`` keyword it is passed a function
``progress(n_done)`` to call after each sample it finishes, for the log.
"""

from __future__ import annotations

import inspect
import logging
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np
import xarray as xr

from workflow.common.constants import SWEEP_SAMPLE_STATUS
from workflow.common.provenance import open_result
from workflow.common.rays import sweep_scales

__all__ = ["SAMPLE_FIELDS", "ray_design", "shard_rays", "n_points_total", "run_shard", "merge_shards", "CHECK_FIELDS"]

log = logging.getLogger(__name__)


#: Fields a ray solve returns, in this order when it returns a tuple.
SAMPLE_FIELDS = (
    "p_top_kpa",
    "p_bottom_kpa",
    "bending_angle_deg",
    "bending_moment_nm",
    "status",
    "newton_iterations",
    "wall_time_s",
)

#: Per-sample checks of the deformed unit (``workflow.fem.overlap_measures``), over the load path up to the
#: sample, both cases; NaN when the solver does not report them.  The pocket size is an area in 2D and a
#: volume in 3D, so a sweep carries one of the last two.
CHECK_FIELDS = ("max_penetration_mm", "overlap_depth_mm", "min_pocket_area_mm2", "min_pocket_volume_mm3")

_VAR_ATTRS = {
    "max_penetration_mm": {
        "units": "mm",
        "long_name": "largest penetration up to the sample (contact pairs or the overlap check)",
    },
    "overlap_depth_mm": {
        "units": "mm",
        "long_name": "deepest boundary node inside another element up to the sample (0: none)",
    },
    "min_pocket_area_mm2": {
        "units": "mm2",
        "long_name": "smallest pocket area of the unit up to the sample (2D; 36.4 at rest)",
    },
    "min_pocket_volume_mm3": {
        "units": "mm3",
        "long_name": "smallest pocket volume of the unit up to the sample (3D; 509.6 at rest)",
    },
    "bending_angle_deg": {
        "units": "degree",
        "long_name": "free bending angle per unit (backbone end rotation / 3), positive towards the palm",
    },
    "bending_moment_nm": {
        "units": "N m",
        "long_name": "blocked bending moment per unit, full actuator width, positive = flexion",
    },
    "newton_iterations": {"units": "1", "long_name": "Newton iterations spent on this sample (0 if mirrored)"},
    "wall_time_s": {"units": "s", "long_name": "wall time spent on this sample (0 if mirrored)"},
    "converged": {"units": "1", "long_name": "sample converged (status == 0)"},
    "mirrored": {"units": "1", "long_name": "sample obtained from its (P_B, P_T) twin by the top/bottom symmetry"},
    "ray": {"units": "1", "long_name": "index of the solved ray the sample comes from"},
    "ratio": {"units": "1", "long_name": "pressure ratio P_B/P_T of the solved ray (before mirroring)"},
    "scale": {"units": "1", "long_name": "load scale s along the ray (pressures = s * ray end point)"},
    "source_point": {"units": "1", "long_name": "point index of the solved twin of a mirrored sample (-1 if solved)"},
}


def ray_design(p_max_kpa: float, n_ratios: int, n_pressures: int) -> dict[str, np.ndarray]:
    """Rays to solve: ratios P_B/P_T evenly spaced over [0, 1], scales over (0, 1].

    Parameters
    ----------
    p_max_kpa : top pressure at the end of every ray, kPa.
    n_ratios : number of solved rays (>= 2: r = 0 and r = 1 are always included).
    n_pressures : samples per ray, at s = 1/n, 2/n, ..., 1 (evenly spaced in pressure).

    Returns
    -------
    dict with ``ratio`` (n_ratios,), ``direction_kpa`` (n_ratios, 2) = (P_T, P_B)
    at s = 1, and ``scales`` (n_pressures,).
    """
    if n_ratios < 2 or n_pressures < 1:
        raise ValueError("need n_ratios >= 2 and n_pressures >= 1")
    if p_max_kpa <= 0:
        raise ValueError("p_max_kpa must be positive")
    ratio = np.linspace(0.0, 1.0, n_ratios)
    direction = np.column_stack([np.full(n_ratios, float(p_max_kpa)), ratio * p_max_kpa])
    scales = sweep_scales(n_pressures)
    return {"ratio": ratio, "direction_kpa": direction, "scales": scales}


def shard_rays(n_ratios: int, n_shards: int) -> list[np.ndarray]:
    """Ray indices of each shard, dealt round-robin so shards mix cheap and costly rays.

    Every ray lands in exactly one shard; ``n_shards`` is capped at ``n_ratios``.
    """
    if n_shards < 1:
        raise ValueError("n_shards must be >= 1")
    n_shards = min(n_shards, n_ratios)
    return [np.arange(i, n_ratios, n_shards) for i in range(n_shards)]


def n_points_total(n_ratios: int, n_pressures: int) -> int:
    """Points in a merged sweep: solved rays plus mirrors of the off-diagonal ones."""
    return (2 * n_ratios - 1) * n_pressures


def _accepts(fn: Callable, name: str) -> bool:
    try:
        params = inspect.signature(fn).parameters
    except (TypeError, ValueError):
        return False
    return name in params or any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())


def _as_samples(result: Any, n: int) -> dict[str, np.ndarray]:
    if isinstance(result, Mapping):
        fields = {k: np.asarray(result[k]) for k in SAMPLE_FIELDS}
    else:
        fields = dict(zip(SAMPLE_FIELDS, (np.asarray(v) for v in result), strict=True))
    for k in CHECK_FIELDS:
        if isinstance(result, Mapping) and k in result:
            fields[k] = np.asarray(result[k], float)
    for k, v in fields.items():
        if v.shape != (n,):
            raise ValueError(f"solver returned {k} with shape {v.shape}, expected ({n},)")
    bad = set(np.unique(fields["status"]).tolist()) - set(SWEEP_SAMPLE_STATUS)
    if bad:
        raise ValueError(
            f"solver returned status codes {sorted(bad)} outside SWEEP_SAMPLE_STATUS {SWEEP_SAMPLE_STATUS}"
        )
    return fields


def _failed_ray(direction: np.ndarray, scales: np.ndarray, wall: float) -> dict[str, np.ndarray]:
    n = scales.size
    return {
        "p_top_kpa": scales * direction[0],
        "p_bottom_kpa": scales * direction[1],
        "bending_angle_deg": np.full(n, np.nan),
        "bending_moment_nm": np.full(n, np.nan),
        "status": np.full(n, 3),
        "newton_iterations": np.zeros(n, dtype=int),
        "wall_time_s": np.full(n, wall / n),
    }


def run_shard(
    solve_ray: Callable,
    *,
    shard: int,
    p_max_kpa: float,
    n_ratios: int,
    n_pressures: int,
    n_shards: int,
    logger: logging.Logger | None = None,
) -> xr.Dataset:
    """Solve the rays of one shard; return its samples as a Dataset on ``point``.

    A ray whose solver raises is kept with status ``solver_error`` (NaN values),
    so one bad ray never stops a sweep.  Logs, per sample when the solver
    reports progress and otherwise per ray, "points done of total" and the
    seconds per point so far.
    """
    logger = logger or log
    design = ray_design(p_max_kpa, n_ratios, n_pressures)
    rays = shard_rays(n_ratios, n_shards)[shard]
    scales = design["scales"]
    total = rays.size * scales.size
    t0 = time.perf_counter()
    done_before = 0
    blocks: list[dict[str, np.ndarray]] = []

    def report(n_done: int) -> None:
        elapsed = time.perf_counter() - t0
        logger.info(
            "shard %d: points done %d of %d, %.3g s per point, elapsed %.1f s",
            shard,
            n_done,
            total,
            elapsed / max(n_done, 1),
            elapsed,
        )

    for j in rays:
        direction = design["direction_kpa"][j]
        logger.info(
            "shard %d: ray %d (P_B/P_T = %.3f, end point %.1f/%.1f kPa), %d samples",
            shard,
            j,
            design["ratio"][j],
            direction[0],
            direction[1],
            scales.size,
        )
        kwargs = {}
        if _accepts(solve_ray, "progress"):
            base = done_before
            kwargs["progress"] = lambda k, base=base: report(base + int(k))
        t_ray = time.perf_counter()
        try:
            samples = _as_samples(solve_ray(tuple(direction), scales.copy(), **kwargs), scales.size)
        except Exception:  # a failed ray is data (status 3), never a crashed sweep
            logger.exception("shard %d: ray %d failed; recorded with status solver_error", shard, j)
            samples = _failed_ray(direction, scales, time.perf_counter() - t_ray)
        samples["ray"] = np.full(scales.size, j)
        samples["ratio"] = np.full(scales.size, design["ratio"][j])
        samples["scale"] = scales.copy()
        blocks.append(samples)
        done_before += scales.size
        report(done_before)
        n_bad = int(np.count_nonzero(samples["status"] != 0))
        if n_bad:
            logger.warning("shard %d: ray %d has %d of %d samples not converged", shard, j, n_bad, scales.size)

    keys = list(dict.fromkeys(k for b in blocks for k in b))  # a failed ray has no checks: NaN there
    cat = {k: np.concatenate([b.get(k, np.full(b["status"].size, np.nan)) for b in blocks]) for k in keys}
    return _points_dataset(cat, mirrored=np.zeros(total, dtype=bool), source=np.full(total, -1))


def _points_dataset(d: Mapping[str, np.ndarray], *, mirrored: np.ndarray, source: np.ndarray) -> xr.Dataset:
    status = np.asarray(d["status"], dtype=np.int32)
    n = status.size
    ds = xr.Dataset(
        {
            "bending_angle_deg": ("point", np.asarray(d["bending_angle_deg"], dtype=float)),
            "bending_moment_nm": ("point", np.asarray(d["bending_moment_nm"], dtype=float)),
            "status": ("point", status),
            "converged": ("point", status == 0),
            "mirrored": ("point", np.asarray(mirrored, dtype=bool)),
            "newton_iterations": ("point", np.asarray(d["newton_iterations"], dtype=np.int32)),
            "wall_time_s": ("point", np.asarray(d["wall_time_s"], dtype=float)),
            "ray": ("point", np.asarray(d["ray"], dtype=np.int32)),
            "ratio": ("point", np.asarray(d["ratio"], dtype=float)),
            "scale": ("point", np.asarray(d["scale"], dtype=float)),
            "source_point": ("point", np.asarray(source, dtype=np.int32)),
            **{k: ("point", np.asarray(d[k], dtype=float)) for k in CHECK_FIELDS if k in d},
        },
        coords={
            "point": np.arange(n, dtype=np.int32),
            "p_top_kpa": (
                "point",
                np.asarray(d["p_top_kpa"], dtype=float),
                {"units": "kPa", "long_name": "top chamber pressure P_T"},
            ),
            "p_bottom_kpa": (
                "point",
                np.asarray(d["p_bottom_kpa"], dtype=float),
                {"units": "kPa", "long_name": "bottom chamber pressure P_B"},
            ),
        },
    )
    for name, attrs in _VAR_ATTRS.items():
        if name in ds:
            ds[name].attrs.update(attrs)
    ds["status"].attrs.update(
        {
            "long_name": "solver status of the sample",
            "units": "1",
            "flag_values": np.array(sorted(SWEEP_SAMPLE_STATUS), dtype=np.int32),
            "flag_meanings": " ".join(SWEEP_SAMPLE_STATUS[k] for k in sorted(SWEEP_SAMPLE_STATUS)),
        }
    )
    ds["point"].attrs.update({"long_name": "sample index", "units": "1"})
    return ds


def merge_shards(shards: Iterable[xr.Dataset | str | Path], *, n_ratios: int, n_pressures: int) -> xr.Dataset:
    """Gather shard datasets (or paths) into the sweep's response dataset.

    Checks that every ray of the design is present exactly once with all its
    samples (a missing shard is a workflow error, not data), orders points by
    (ray, scale), then appends the mirrored twins of every off-diagonal point
    (P_B < P_T).  Failed points are kept, with their status; a mirror inherits
    its twin's status.
    """
    parts = [open_result(s) if isinstance(s, (str, Path)) else s for s in shards]
    if not parts:
        raise ValueError("no shards to merge")
    keys = [*SAMPLE_FIELDS, "ray", "ratio", "scale"]
    keys += [k for k in CHECK_FIELDS if all(k in p for p in parts)]  # a twin's checks hold for its mirror too
    d = {k: np.concatenate([p[k].values for p in parts]) for k in keys}
    rays, counts = np.unique(d["ray"], return_counts=True)
    if not np.array_equal(rays, np.arange(n_ratios)) or np.any(counts != n_pressures):
        raise ValueError(
            f"shards hold rays {rays.tolist()} with counts {counts.tolist()}; expected rays 0..{n_ratios - 1} "
            f"with {n_pressures} samples each (missing or duplicated shard?)"
        )
    order = np.lexsort((d["scale"], d["ray"]))
    d = {k: v[order] for k, v in d.items()}
    n = order.size
    # Mirror every point strictly below the diagonal; the r = 1 ray is its own mirror.
    twin = np.flatnonzero(d["ratio"] < 1.0)  # by the design, not by comparing returned floats
    m = {k: v[twin].copy() for k, v in d.items()}
    m["p_top_kpa"], m["p_bottom_kpa"] = d["p_bottom_kpa"][twin], d["p_top_kpa"][twin]
    m["bending_angle_deg"] = -d["bending_angle_deg"][twin]
    m["bending_moment_nm"] = -d["bending_moment_nm"][twin]
    m["newton_iterations"] = np.zeros(twin.size, dtype=int)
    m["wall_time_s"] = np.zeros(twin.size)
    full = {k: np.concatenate([d[k], m[k]]) for k in keys}
    mirrored = np.r_[np.zeros(n, dtype=bool), np.ones(twin.size, dtype=bool)]
    source = np.r_[np.full(n, -1), twin]
    return _points_dataset(full, mirrored=mirrored, source=source)
