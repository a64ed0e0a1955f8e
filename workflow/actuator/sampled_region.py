"""The region of the (P_T, P_B) plane a sweep sampled with converged solves.

A surrogate beyond it extrapolates: planned pressures outside it, or nearest a
failed sample, are flagged (:func:`flag_pressure_table`).  Pressures kPa.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr

__all__ = ["SampledRegion", "flag_pressure_table", "coverage_grid"]


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
        return (
            (pt >= r[0, 0] - tol_kpa)
            & (pt <= r[0, 1] + tol_kpa)
            & (pb >= r[1, 0] - tol_kpa)
            & (pb <= r[1, 1] + tol_kpa)
        )

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
        return {
            "in_range": self.in_range(p_top_kpa, p_bottom_kpa),
            "in_hull": hull,
            "near_failure": near,
            "trusted": hull & ~near,
        }


def flag_pressure_table(
    pressure_kpa: xr.DataArray, region: SampledRegion, *, label: str = ""
) -> tuple[xr.DataArray, list[str]]:
    """Flag each (P_T, P_B) pair of a plan's ``pressure_kpa`` (exercise, group, chamber) against ``region``.

    Returns ``pressure_in_sampled_region`` (exercise, group; True = inside the
    hull of converged samples and not nearest to a failed one) and one
    warning message per flagged pair.
    """
    pt = pressure_kpa.sel(chamber="top").values
    pb = pressure_kpa.sel(chamber="bottom").values
    f = region.flags(pt, pb)
    da = xr.DataArray(
        f["trusted"],
        dims=pressure_kpa.sel(chamber="top").dims,
        coords={d: pressure_kpa[d] for d in pressure_kpa.sel(chamber="top").dims},
        attrs={
            "long_name": "planned (P_T, P_B) inside the convex hull of the surrogate's converged FE "
            "samples and not nearest to a failed sample"
        },
    )
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
    return xr.Dataset(
        {k: (dims, v) for k, v in f.items()},
        coords={dims[0]: (dims[0], g, {"units": "kPa"}), dims[1]: (dims[1], g, {"units": "kPa"})},
    )
