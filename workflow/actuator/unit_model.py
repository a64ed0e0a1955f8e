"""A unit's bending angle under an external end moment (the inverse queries are :mod:`.unit_inverse`).

Model.  At pressures P = (P_T, P_B) a unit (one chamber)
has two measured ends of its moment-angle curve: the free bending angle
theta_f(P) (no end moment) and the blocked moment M_b(P) (the end couple that
holds its angle at zero).  Between them the unit is modelled as a torsional
spring with stiffness k(P) = M_b(P) / theta_f(P), in N m per degree:

    theta(P, M) = theta_f(P) - M / k(P)  +  c * (M / k) * (theta_f - M / k) / theta_s

* ``M`` (N m, per unit) is the moment the unit delivers to its load, i.e. the
  load's resisting moment at the unit's end, positive in the flexion sense
  (the sign of M_b when only the top chambers are pressurised).  So M = 0
  gives the free angle and M = M_b gives zero angle: the two ends are exact for
  every c.  A positive M reduces a flexion angle; a negative (assisting) M
  increases it.
* ``c`` (dimensionless, default 0 = linear spring) is a shape correction that
  bends the curve between its ends while keeping both ends fixed;
  ``theta_s`` (deg) is a fixed angle scale (the largest free angle of the
  sweep) that keeps the term regular where theta_f -> 0.  ``c`` is meant to be
  calibrated with `fit_shape` against FEA runs at prescribed end moments, and
  the model checked with `verify`.  Until such runs exist,
  c = 0.
* Outside 0 <= M/M_b <= 1 the model is an extrapolation of the spring.
* Near P_T = P_B both theta_f and M_b vanish and their ratio is ill-conditioned.
  There k is taken at the nearby pair (p_m + h, p_m - h) with p_m = (P_T + P_B)/2
  and h = ``offset_kpa``/2 (by symmetry k(P_T, P_B) = k(P_B, P_T), so this is a
  first-order estimate of the limit), whenever |theta_f| < ``theta_floor_deg`` or
  the ratio is not positive; h is doubled (up to 32 times) while the offset pair
  itself has |theta_f| below the floor (a flat stretch of a KNN surrogate).
* With a measured stiffness (``measured_stiffness``, e.g. a
  `workflow.actuator.stiffness.StiffnessTable` from FEA of a unit inside a chain
  at end rotations about its blocked state), k is that measurement wherever
  |theta_f| < ``measured_window_deg`` / 2 (the window is the rotation it was
  measured over) and it is defined, blended geometrically into the secant up
  to the window's edge: near the diagonal the secant is 0/0 and the offset
  estimate a guess, while the measurement is the tangent the unit has there.

Inverse queries find the first sign change of angle - target on a grid and
refine it by bisection, vectorised over rays/directions.  On a piecewise-constant
surrogate (KNN) the angle may jump over the target: the answer is then the jump,
within one step of the staircase.

Vectorised: every function broadcasts its array arguments.  The cascade
planner calls `UnitModel.angle_deg`, `free_angle_deg` and `blocked_moment_nm`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from workflow.actuator.surrogates import load_surrogate

__all__ = ["UnitModel", "load_unit_model", "fit_shape", "verify", "verification_points", "verification_dataset"]


ArrayFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class UnitModel:
    """Angle of one unit (deg) as a function of (P_T, P_B) in kPa and end moment in N m.

    ``free_angle`` and ``blocked_moment`` are vectorised callables of
    (p_top_kpa, p_bottom_kpa), e.g. a fitted `workflow.actuator.surrogates.Surrogate`'s
    ``angle_deg`` and ``moment_nm``.
    """

    free_angle: ArrayFn
    blocked_moment: ArrayFn
    p_max_kpa: float = 300.0
    shape_c: float = 0.0
    theta_scale_deg: float | None = None
    theta_floor_deg: float = 0.05
    offset_kpa: float = 10.0
    measured_stiffness: ArrayFn | None = None
    measured_window_deg: float = 3.0

    @classmethod
    def from_surrogate(cls, surrogate, **kwargs) -> "UnitModel":
        """Unit model on a fitted surrogate (its training range sets p_max)."""
        kwargs.setdefault("p_max_kpa", surrogate.p_max_kpa)
        return cls(surrogate.angle_deg, surrogate.moment_nm, **kwargs)

    # -- the two ends -----------------------------------------------------
    def free_angle_deg(self, p_top_kpa, p_bottom_kpa) -> np.ndarray:
        """Free bending angle per unit (M = 0), deg."""
        pt, pb = np.broadcast_arrays(np.asarray(p_top_kpa, float), np.asarray(p_bottom_kpa, float))
        return np.asarray(self.free_angle(pt, pb), float).reshape(pt.shape)

    def blocked_moment_nm(self, p_top_kpa, p_bottom_kpa) -> np.ndarray:
        """Blocked moment per unit (angle held at 0), N m."""
        pt, pb = np.broadcast_arrays(np.asarray(p_top_kpa, float), np.asarray(p_bottom_kpa, float))
        return np.asarray(self.blocked_moment(pt, pb), float).reshape(pt.shape)

    def stiffness_nm_per_deg(self, p_top_kpa, p_bottom_kpa) -> np.ndarray:
        """Spring stiffness k = M_b / theta_f, N m per degree (limit estimate near P_T = P_B).

        With ``measured_stiffness``, the measurement where |theta_f| < ``measured_window_deg`` / 2, the secant
        beyond the window and a geometric blend between: there the zero angle falls at M = k theta_f instead of M_b
        (within the window the two differ by the secant's error)."""
        pt, pb = np.broadcast_arrays(np.asarray(p_top_kpa, float), np.asarray(p_bottom_kpa, float))
        th = self.free_angle_deg(pt, pb)
        mb = self.blocked_moment_nm(pt, pb)
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.asarray(mb / th, float).copy()
        ill = ~((np.abs(th) >= self.theta_floor_deg) & (k > 0) & np.isfinite(k))
        k[ill] = np.nan
        if self.measured_stiffness is not None:
            # the measurement inside half the window, the secant outside it, blended geometrically between (no jump
            # in k at the window's edge for an inverse to mistake for a crossing); the measurement alone where the
            # secant is ill-conditioned
            win = self.measured_window_deg
            near = np.abs(th) < win
            km = np.full(k.shape, np.nan)
            km[near] = np.asarray(self.measured_stiffness(pt[near], pb[near]), float)
            use = near & np.isfinite(km) & (km > 0)
            w = np.clip(2.0 * (1.0 - np.abs(th) / win), 0.0, 1.0)
            w = np.where(np.isfinite(k), w, 1.0)
            with np.errstate(divide="ignore", invalid="ignore"):
                blend = np.exp(w * np.log(km) + (1.0 - w) * np.log(np.where(np.isfinite(k), k, 1.0)))
            k[use] = blend[use]
        # Offset estimate; doubled (up to 5 times) where a flat stretch of the
        # surrogate (e.g. KNN) still gives no usable ratio.
        for attempt in range(6):
            ill = ~np.isfinite(k)
            if not np.any(ill):
                break
            pm = 0.5 * (pt[ill] + pb[ill])
            h = 0.5 * self.offset_kpa * 2**attempt
            hi, lo = pm + h, np.maximum(pm - h, 0.0)
            with np.errstate(divide="ignore", invalid="ignore"):
                th_off = self.free_angle_deg(hi, lo)
                k_off = self.blocked_moment_nm(hi, lo) / th_off
            k[ill] = np.where((k_off > 0) & (np.abs(th_off) >= self.theta_floor_deg), k_off, np.nan)
        return k if k.ndim else k[()]

    @property
    def theta_s(self) -> float:
        """Angle scale of the shape term, deg: given, or the largest |free angle| on P_B = 0."""
        if self.theta_scale_deg is not None:
            return float(self.theta_scale_deg)
        p = np.linspace(0.0, self.p_max_kpa, 61)
        return float(np.nanmax(np.abs(self.free_angle_deg(p, 0.0))))

    # -- the model --------------------------------------------------------
    def angle_deg(self, p_top_kpa, p_bottom_kpa, m_ext_nm=0.0) -> np.ndarray:
        """Bending angle per unit, deg, under the end moment ``m_ext_nm`` (N m, per unit)."""
        pt, pb, m = np.broadcast_arrays(
            np.asarray(p_top_kpa, float), np.asarray(p_bottom_kpa, float), np.asarray(m_ext_nm, float)
        )
        th = self.free_angle_deg(pt, pb)
        u = np.zeros_like(th)  # M / k, deg
        nz = m != 0  # at M = 0 the angle is the free angle, k not needed
        if np.any(nz):
            u[nz] = m[nz] / self.stiffness_nm_per_deg(pt[nz], pb[nz])
        out = th - u
        if self.shape_c:
            out = out + self.shape_c * u * (th - u) / self.theta_s
        return out

    def with_shape(self, c: float) -> "UnitModel":
        """The same model with shape correction ``c`` (theta_s frozen at its current value)."""
        return replace(self, shape_c=float(c), theta_scale_deg=self.theta_s)


def load_unit_model(path: str | Path, **kwargs) -> UnitModel:
    """Unit model on a surrogate saved by `workflow.actuator.surrogates.save_surrogate`."""

    return UnitModel.from_surrogate(load_surrogate(path), **kwargs)


# -- calibration hook (FEA runs at prescribed end moments) -------------------
def fit_shape(model: UnitModel, p_top_kpa, p_bottom_kpa, m_ext_nm, angle_fea_deg) -> UnitModel:
    """Least-squares shape correction c from FEA angles at prescribed end moments.

    The model is linear in c, so c = sum(r b) / sum(b^2) with r the residual of
    the linear spring and b = (M/k)(theta_f - M/k)/theta_s.  c is clipped to
    (-0.99, 0.99), where the curve stays monotonic between its ends.
    """
    base = replace(model, shape_c=0.0, theta_scale_deg=model.theta_s)
    pt, pb, m, a = (
        np.ravel(np.asarray(x, float)) for x in np.broadcast_arrays(p_top_kpa, p_bottom_kpa, m_ext_nm, angle_fea_deg)
    )
    th = base.free_angle_deg(pt, pb)
    u = m / base.stiffness_nm_per_deg(pt, pb)
    b = u * (th - u) / base.theta_s
    r = a - (th - u)
    ok = np.isfinite(b) & np.isfinite(r)
    if not np.any(b[ok] != 0):
        raise ValueError("the FEA runs do not constrain the shape (need 0 < M < M_b at some point)")
    c = float(np.sum(r[ok] * b[ok]) / np.sum(b[ok] ** 2))
    return base.with_shape(float(np.clip(c, -0.99, 0.99)))


def verify(model: UnitModel, p_top_kpa, p_bottom_kpa, m_ext_nm, angle_fea_deg) -> dict[str, np.ndarray | float]:
    """Model against direct FEA angles at prescribed end moments: predictions and errors (deg)."""
    pred = model.angle_deg(p_top_kpa, p_bottom_kpa, m_ext_nm)
    err = pred - np.asarray(angle_fea_deg, float)
    return {
        "predicted_deg": pred,
        "error_deg": err,
        "max_abs_error_deg": float(np.nanmax(np.abs(err))),
        "rmse_deg": float(np.sqrt(np.nanmean(err**2))),
    }


def verification_points(
    model: UnitModel, p_top_kpa, p_bottom_kpa, fractions=(0.25, 0.5, 0.75)
) -> dict[str, np.ndarray]:
    """End moments at which to check the model by FEA: the given fractions of each pair's blocked moment.

    Returns flat arrays ``p_top_kpa``, ``p_bottom_kpa``, ``fraction``, ``m_ext_nm``
    (pairs x fractions) and the model's ``predicted_deg`` there.
    """
    pt, pb = (np.ravel(x) for x in np.broadcast_arrays(np.asarray(p_top_kpa, float), np.asarray(p_bottom_kpa, float)))
    f = np.asarray(fractions, float)
    PT, F = np.meshgrid(pt, f, indexing="ij")
    PB = np.meshgrid(pb, f, indexing="ij")[0]
    m = F * model.blocked_moment_nm(PT, PB)
    return {
        "p_top_kpa": PT.ravel(),
        "p_bottom_kpa": PB.ravel(),
        "fraction": F.ravel(),
        "m_ext_nm": m.ravel(),
        "predicted_deg": model.angle_deg(PT, PB, m).ravel(),
    }


def verification_dataset(model: UnitModel, p_top_kpa, p_bottom_kpa, m_ext_nm, angle_fea_deg, status=None):
    """Model against FEA runs at prescribed end moments, as an xarray Dataset on ``check``.

    ``status`` (0 = converged) marks FEA runs to leave out of the error
    summary (attrs ``max_abs_error_deg``, ``rmse_deg``).
    """
    import xarray as xr

    pt, pb, m, a = (
        np.ravel(np.asarray(x, float)) for x in np.broadcast_arrays(p_top_kpa, p_bottom_kpa, m_ext_nm, angle_fea_deg)
    )
    st = np.zeros(pt.size, dtype=np.int32) if status is None else np.ravel(np.asarray(status, dtype=np.int32))
    pred = model.angle_deg(pt, pb, m)
    err = np.where(st == 0, pred - a, np.nan)
    ds = xr.Dataset(
        {
            "m_ext_nm": (
                "check",
                m,
                {"units": "N m", "long_name": "prescribed end moment per unit (resisting, + = flexion)"},
            ),
            "angle_fea_deg": ("check", a, {"units": "degree", "long_name": "FEA angle per unit under the end moment"}),
            "angle_model_deg": ("check", pred, {"units": "degree", "long_name": "unit-model angle per unit"}),
            "error_deg": ("check", err, {"units": "degree", "long_name": "model minus FEA (NaN where FEA failed)"}),
            "fea_status": ("check", st, {"units": "1", "long_name": "FEA status (0 = converged)"}),
        },
        coords={
            "check": np.arange(pt.size),
            "p_top_kpa": ("check", pt, {"units": "kPa", "long_name": "top chamber pressure P_T"}),
            "p_bottom_kpa": ("check", pb, {"units": "kPa", "long_name": "bottom chamber pressure P_B"}),
        },
    )
    ok = np.isfinite(err)
    ds.attrs["max_abs_error_deg"] = float(np.max(np.abs(err[ok]))) if ok.any() else np.nan
    ds.attrs["rmse_deg"] = float(np.sqrt(np.mean(err[ok] ** 2))) if ok.any() else np.nan
    ds.attrs["shape_c"] = float(model.shape_c)
    return ds
