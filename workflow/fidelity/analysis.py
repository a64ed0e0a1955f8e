"""Speed against accuracy, and the cheapest fidelity that meets a tolerance.

Pure functions on small tables; the FE solves, surrogate fits and OpenSim
samples that feed them are run by :mod:`workflow.fidelity.entry`.

Vocabulary
----------
* A *method* is one fidelity of one stage: an FE unit model at one element
  size with or without contact (``fem_2d_h1_contact``), a surrogate
  (``surrogate_3d_rbf``), a plan made with one surrogate (``plan_3d_knn``),
  the finger-actuator FEA check at one mesh (``check_h2``) or the
  reduced-order chain standing in for it (``check_chain_3d``), a response
  surface or direct OpenSim sampling (``msk_rsm_quadratic``, ``msk_opensim``).
* A *quantity* is what is compared across methods: the unit's free angle and
  blocked moment at P_T = 60, 180, 300 kPa (P_B = 0), the planned pressures of
  an exercise, the joint angles the check reaches, a joint moment at a target
  angle.
* The *reference* of a quantity is the finest method that produced it (the
  finest converged mesh; see each builder).  ``error`` is relative
  (``|m - ref| / |ref|``) for the unit quantities and the moments, in kPa (RMS
  over the eight chamber pressures) for plans and in degrees (largest over the
  three joints) for the check; a method has no error on its own reference
  point (NaN) unless it is the reference itself (0).
* *Pareto*: a method is on the front of a quantity when no other method is
  both at least as fast and at least as accurate, and better in one.

Units: wall time s, pressures kPa, angles deg, moments N m.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
import xarray as xr

__all__ = [
    "METHOD_GROUPS",
    "group_errors",
    "UNIT_QUANTITIES",
    "unit_quantities",
    "relative_errors",
    "Richardson",
    "richardson",
    "pareto_front",
    "speed_accuracy_dataset",
]

#: The unit quantities of the FE and surrogate methods (P_B = 0).
UNIT_QUANTITIES = tuple(f"{q}_{p}" for q in ("angle", "moment") for p in (60, 180, 300))


def unit_quantities(
    angle_deg: Sequence[float], moment_nm: Sequence[float], p_top_kpa: Sequence[float]
) -> dict[str, float]:
    """{``angle_60``: ..., ``moment_300``: ...} from values at the study pressures (NaN where not reached)."""
    out = {q: np.nan for q in UNIT_QUANTITIES}
    for a, m, p in zip(angle_deg, moment_nm, p_top_kpa):
        out[f"angle_{int(round(p))}"] = float(a)
        out[f"moment_{int(round(p))}"] = float(m)
    return out


@dataclass(frozen=True)
class Richardson:
    """Extrapolation from three meshes: limit, observed order, grid convergence index of the finest.

    ``asymptotic`` is False when the three values do not converge monotonically
    (oscillating differences, or differences that grow under refinement) or the
    order falls outside [0.5, 6]: the limit is then the finest value and the GCI NaN.
    """

    limit: float
    order: float
    gci_fine: float
    asymptotic: bool


def richardson(h: Sequence[float], f: Sequence[float], fs: float = 1.25) -> Richardson:
    """Generalised Richardson extrapolation (Celik et al. 2008, J. Fluids Eng. 130, 078001).

    ``h``: three element sizes (any order), ``f``: the values on them.  With
    h1 < h2 < h3, r21 = h2/h1, r32 = h3/h2, e21 = f2 - f1, e32 = f3 - f2 and
    s = sign(e32/e21), the observed order p solves
    p = |ln|e32/e21| + ln((r21^p - s)/(r32^p - s))| / ln r21 (fixed point); then
    f_ext = (r21^p f1 - f2)/(r21^p - 1) and GCI_fine = fs |e21/f1| / (r21^p - 1).

    The absolute value in Celik's formula also maps differences that grow under refinement (divergence: with
    equal ratios, |e21| > |e32|) onto a positive order; such a p does not satisfy the un-signed equation
    e32/e21 = r21^p (r32^p - s) / (r21^p - s), so it is checked and the triple declared not asymptotic, with the
    order negated (with equal ratios exactly the negative order of growing differences).
    """
    order = np.argsort(np.asarray(h, float))
    (h1, h2, h3), (f1, f2, f3) = np.asarray(h, float)[order], np.asarray(f, float)[order]
    if not np.all(np.isfinite([f1, f2, f3])):
        return Richardson(np.nan, np.nan, np.nan, False)
    e21, e32 = f2 - f1, f3 - f2
    if e21 == 0.0:
        return Richardson(float(f1), np.inf, 0.0, True)
    r21, r32 = h2 / h1, h3 / h2
    ratio = e32 / e21
    s = np.sign(ratio)
    if s <= 0:  # oscillating: no observed order
        return Richardson(float(f1), np.nan, np.nan, False)
    p = abs(np.log(abs(ratio))) / np.log(r21)
    for _ in range(100):
        q = np.log((r21**p - s) / (r32**p - s))
        p_new = abs(np.log(abs(ratio)) + q) / np.log(r21)
        if abs(p_new - p) < 1e-12:
            p = p_new
            break
        p = p_new
    if np.log(abs(ratio)) + np.log((r21**p - s) / (r32**p - s)) < 0:  # the root of the absolute value only
        return Richardson(float(f1), -float(p), np.nan, False)
    if not (0.5 <= p <= 6.0):
        return Richardson(float(f1), float(p), np.nan, False)
    rp = r21**p
    return Richardson(float((rp * f1 - f2) / (rp - 1.0)), float(p), float(fs * abs(e21 / f1) / (rp - 1.0)), True)


def relative_errors(values: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """|v - ref| / |ref| elementwise (NaN where either is NaN or ref is 0)."""
    v, r = np.asarray(values, float), np.asarray(reference, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        e = np.abs(v - r) / np.abs(r)
    return np.where(np.isfinite(e), e, np.nan)


def pareto_front(wall_time_s: np.ndarray, error: np.ndarray) -> np.ndarray:
    """Boolean mask of the methods no other method dominates (time and error both <=, one <).

    Methods with a NaN error are never on the front.
    """
    t, e = np.asarray(wall_time_s, float), np.asarray(error, float)
    ok = np.isfinite(t) & np.isfinite(e)
    front = np.zeros(t.size, bool)
    for i in np.flatnonzero(ok):
        dom = ok & (t <= t[i]) & (e <= e[i]) & ((t < t[i]) | (e < e[i]))
        front[i] = not dom.any()
    return front


def speed_accuracy_dataset(
    methods: Sequence[str],
    quantities: Sequence[str],
    wall_time_s: Sequence[float],
    error: np.ndarray,
    *,
    family: Sequence[str],
    error_units: Mapping[str, str],
    reference: Mapping[str, str],
    value: np.ndarray | None = None,
    setup_time_s: Sequence[float] | None = None,
    front_group: Sequence[str] | None = None,
    notes: Mapping[str, str] | None = None,
) -> xr.Dataset:
    """The contract's ``speed_accuracy.nc``: ``wall_time_s`` (method), ``error`` and ``pareto`` (method, quantity).

    ``error_units`` / ``reference``: per quantity, the error's unit and the
    reference method's name; ``value`` (method, quantity) the compared values;
    ``setup_time_s`` (method) a one-off cost behind a method's query time (a
    surrogate's sweep and fit); ``front_group`` (method): methods compete for
    a Pareto front only within their group (2D and 3D models answer the same
    quantity against different references, so each has its own front).
    """
    err = np.asarray(error, float)
    t = np.asarray(wall_time_s, float)
    grp = np.asarray(list(front_group) if front_group is not None else [""] * t.size, dtype=object)
    par = np.zeros(err.shape, bool)
    for g in dict.fromkeys(grp.tolist()):
        rows = grp == g
        for j in range(err.shape[1]):
            par[rows, j] = pareto_front(t[rows], err[rows, j])
    ds = xr.Dataset(
        {
            "wall_time_s": ("method", t, {"units": "s", "long_name": "wall time of the method for its quantities"}),
            "error": (
                ("method", "quantity"),
                err,
                {"units": "see error_units", "long_name": "error against the quantity's reference"},
            ),
            "pareto": (
                ("method", "quantity"),
                par,
                {"units": "1", "long_name": "on the speed-accuracy Pareto front of the quantity"},
            ),
            "family": (
                "method",
                np.array(list(family), dtype=object),
                {"units": "1", "long_name": "stage and kind of the method"},
            ),
            "front_group": ("method", grp, {"units": "1", "long_name": "methods that share a Pareto front"}),
            "error_units": (
                "quantity",
                np.array([error_units[q] for q in quantities], dtype=object),
                {"units": "1", "long_name": "unit of the error (1 = relative)"},
            ),
            "reference_method": (
                "quantity",
                np.array([reference.get(q, "") for q in quantities], dtype=object),
                {"units": "1", "long_name": "method taken as the reference"},
            ),
        },
        coords={"method": list(methods), "quantity": list(quantities)},
    )
    if value is not None:
        ds["value"] = (
            ("method", "quantity"),
            np.asarray(value, float),
            {"units": "mixed", "long_name": "the compared value (deg, N m, kPa RMS, deg)"},
        )
    if setup_time_s is not None:
        ds["setup_time_s"] = (
            "method",
            np.asarray(setup_time_s, float),
            {"units": "s", "long_name": "one-off cost behind the method (e.g. a surrogate's sweep and fit)"},
        )
    ds.attrs.update({k: str(v) for k, v in dict(notes or {}).items()})
    return ds


#: Quantity groups of the speed-accuracy study (one plot panel, one report column each): title, quantity prefix, error label.
METHOD_GROUPS = (
    ("unit free angle (60/180/300 kPa)", "angle_", "largest relative error"),
    ("unit blocked moment (60/180/300 kPa)", "moment_", "largest relative error"),
    ("surrogates on held-out FE samples (5-fold CV)", "cv_", "largest RMSE / std"),
    ("planned pressures (TGE1-5)", "plan_", "largest RMS difference (kPa)"),
    ("FEA check joint angles", "check_", "largest joint error (deg)"),
    ("joint moments (test patients in the design region)", "msk_", "largest relative error"),
)


def group_errors(ds: xr.Dataset, prefix: str) -> xr.DataArray:
    """Per method, the largest error over the quantities starting with ``prefix`` (NaN if it has none)."""
    q = [str(x) for x in ds["quantity"].values if str(x).startswith(prefix)]
    if not q:
        return xr.full_like(ds["wall_time_s"], np.nan)
    e = ds["error"].sel(quantity=q)
    return e.max("quantity", skipna=True).where(e.notnull().any("quantity"))
