"""A unit under an external end moment: direct FEA against `workflow.unit_model` (issue 5 item 4).

CLARIFICATIONS 6: free bending (M = 0) and blocked (angle 0) are the two ends
of a unit's moment-angle curve; FEA runs at prescribed end rotations check the
model between them.  Per pressure pair P = (P_T, P_B) this runs the unit FEA
(`workflow.fem`, case ``free``, ``blocked`` and ``rotation``) and compares the
couple M_fea(theta) needed to hold the end at theta = fraction * theta_f(P)
with the unit model's moment at that angle, the model being built on the free
angle and blocked moment of *the same FEA runs* (so the model is tested, not
a surrogate).

End holds (``end_holds``, see `workflow.fem.held_end_nodes`): ``face`` holds
the whole end face plane (the sweeps' blocked moment), ``backbone`` only its
paper and base layers.  Measured on the 2D unit (h = 1 mm, contact): with
``face`` the couple collapses once the last bottom block, forced to turn with
the face, is pressed into its neighbour (M < 0 from about 0.1-0.25 theta_f,
and the solve stalls beyond about 20 deg total), so a torsional spring cannot
represent it; with ``backbone`` the curve runs from M_b to about 0 at
theta_f and the linear spring is within about 11 % of M_b.

Units: angles in degrees per unit (chamber; the FEA's total / n_chambers),
moments in N m per unit for the full actuator width, pressures in kPa.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Mapping

import numpy as np
import xarray as xr

from workflow import fem
from workflow.unit_model import UnitModel, fit_shape
from workflow.runlog import solved

__all__ = ["DEFAULT_CHECK", "lookup", "model_moment_nm", "run_fea", "compare", "moment_check", "plot_moment_check",
           "write_moment_check"]

log = logging.getLogger(__name__)

#: Points of the check (config ``actuator.moment_check``); about 2.5 min of CPU for 2D at h = 1 mm.
DEFAULT_CHECK = {
    "model": "2d",
    "pairs_kpa": [[180.0, 0.0], [300.0, 0.0], [300.0, 150.0]],
    "fractions": [0.25, 0.5, 1.0],  # end inclination / free angle
    "end_holds": ["backbone", "face"],
}

#: Status of a rotation point that was not run because its free or blocked run failed.
NOT_RUN = 4


def lookup(pt_kpa, pb_kpa, values):
    """A vectorised callable (p_top, p_bottom) -> value at the given pairs exactly, NaN elsewhere.

    Feeds FEA values at a few pressure pairs to `UnitModel` as its free-angle
    or blocked-moment function.
    """
    table = {(round(float(a), 9), round(float(b), 9)): float(v) for a, b, v in zip(pt_kpa, pb_kpa, values)}

    def fn(pt, pb):
        pt, pb = np.broadcast_arrays(np.asarray(pt, float), np.asarray(pb, float))
        out = [table.get((round(float(a), 9), round(float(b), 9)), np.nan) for a, b in zip(pt.ravel(), pb.ravel())]
        return np.asarray(out, float).reshape(pt.shape)

    return fn


def model_moment_nm(model: UnitModel, pt_kpa, pb_kpa, angle_deg) -> np.ndarray:
    """End moment (N m per unit) at which ``model`` gives ``angle_deg`` (deg per unit): its inverse.

    With u = M / k the model reads theta = theta_f - u + (c / theta_s) u (theta_f - u),
    a quadratic a u^2 + b u + (theta - theta_f) = 0 with a = c / theta_s and
    b = 1 - c theta_f / theta_s; the root that tends to the linear spring's
    u = theta_f - theta as c -> 0 is u = 2 (theta_f - theta) / (b + sqrt(b^2 + 4 a (theta_f - theta))).
    NaN where that root does not exist.
    """
    pt, pb, th = np.broadcast_arrays(np.asarray(pt_kpa, float), np.asarray(pb_kpa, float), np.asarray(angle_deg, float))
    thf = model.free_angle_deg(pt, pb)
    k = model.stiffness_nm_per_deg(pt, pb)
    d = thf - th
    if model.shape_c == 0.0:
        return k * d
    a = model.shape_c / model.theta_s
    b = 1.0 - model.shape_c * thf / model.theta_s
    with np.errstate(invalid="ignore"):
        u = 2.0 * d / (b + np.sqrt(b * b + 4.0 * a * d))
    return k * u


def _solve(actuator, dim, mesh, pt, pb, case, **kw):
    """One unit solve with the config's settings; returns (result, wall time s)."""
    t0 = time.perf_counter()
    res = fem.solve_unit_from_config(actuator, dim, pt, pb, case, mesh=mesh, **kw)
    return res, time.perf_counter() - t0


def run_fea(actuator: Mapping, pairs_kpa, fractions, end_holds=("backbone", "face"), dim: int = 2) -> dict:
    """FEA free angle, blocked moments and moments at prescribed end rotations.

    Returns arrays: ``free_angle_deg``, ``free_status`` (point); ``blocked_moment_nm``,
    ``blocked_status`` (hold, point); ``end_angle_deg`` (point, fraction);
    ``moment_fea_nm``, ``backbone_angle_deg``, ``status``, ``wall_time_s``
    (hold, point, fraction).  Angles per unit, deg; moments N m per unit.
    """
    pairs = np.asarray(pairs_kpa, float).reshape(-1, 2)
    fr = np.asarray(fractions, float)
    holds = list(end_holds)
    mesh = fem.unit_mesh_from_config(actuator, dim)
    n = int(mesh.geometry["n_chambers"])
    npt, nh, nf = len(pairs), len(holds), len(fr)
    out = {
        "free_angle_deg": np.full(npt, np.nan), "free_status": np.full(npt, 3, np.int32),
        "blocked_moment_nm": np.full((nh, npt), np.nan), "blocked_status": np.full((nh, npt), NOT_RUN, np.int32),
        "end_angle_deg": np.full((npt, nf), np.nan), "moment_fea_nm": np.full((nh, npt, nf), np.nan),
        "backbone_angle_deg": np.full((nh, npt, nf), np.nan), "status": np.full((nh, npt, nf), NOT_RUN, np.int32),
        "wall_time_s": np.full((nh, npt, nf), np.nan),
    }
    for i, (pt, pb) in enumerate(pairs):
        free, t = _solve(actuator, dim, mesh, pt, pb, "free")
        out["free_status"][i] = free.status
        log.info("P = (%g, %g) kPa: free angle %.3f deg/unit, status %d, %.1f s", pt, pb, free.bending_angle_deg, free.status, t,
                 extra=solved(free.status != 0))
        if free.status:
            continue
        total = free.bending_angle_total_deg
        out["free_angle_deg"][i] = total / n
        out["end_angle_deg"][i] = fr * total / n
        for h, hold in enumerate(holds):
            blk, t = _solve(actuator, dim, mesh, pt, pb, "blocked", end_hold=hold)
            out["blocked_status"][h, i] = blk.status
            out["blocked_moment_nm"][h, i] = blk.bending_moment_nm if blk.status == 0 else np.nan
            log.info("  %s: blocked moment %.5f N m, status %d, %.1f s", hold, blk.bending_moment_nm, blk.status, t,
                     extra=solved(blk.status != 0))
            for j, f in enumerate(fr):
                rot, t = _solve(actuator, dim, mesh, pt, pb, "rotation", end_hold=hold, end_angle_deg=f * total)
                out["status"][h, i, j] = rot.status
                out["wall_time_s"][h, i, j] = t
                if rot.status == 0:  # a stalled ray's last state is not at the prescribed angle
                    out["moment_fea_nm"][h, i, j] = rot.bending_moment_nm
                    out["backbone_angle_deg"][h, i, j] = rot.bending_angle_deg
                log.info("    theta = %.2f theta_f: M = %.5f N m, status %d (%s), %.1f s", f, rot.bending_moment_nm,
                         rot.status, rot.reason, t, extra=solved(rot.status != 0))
    return out


def _model(free_deg, blocked_nm, pairs, shape_c: float, theta_scale_deg: float) -> UnitModel:
    fa = lookup(pairs[:, 0], pairs[:, 1], free_deg)
    mb = lookup(pairs[:, 0], pairs[:, 1], blocked_nm)
    return UnitModel(fa, mb, shape_c=shape_c, theta_scale_deg=theta_scale_deg)


def compare(fea: dict, pairs_kpa, fractions, end_holds, shape_c: float = 0.0, theta_scale_deg: float | None = None
            ) -> xr.Dataset:
    """The check dataset: FEA against the unit model (shape ``shape_c``) built on the same FEA runs.

    ``theta_scale_deg`` (deg per unit) is the model's theta_s; default the
    largest |free angle| of the check.  Also fits shape_c per hold
    (`workflow.unit_model.fit_shape`, angle residuals) for information.
    """
    pairs = np.asarray(pairs_kpa, float).reshape(-1, 2)
    fr = np.asarray(fractions, float)
    holds = list(end_holds)
    ths = float(np.nanmax(np.abs(fea["free_angle_deg"]))) if theta_scale_deg is None else float(theta_scale_deg)
    pt = np.broadcast_to(pairs[:, 0, None], (len(pairs), len(fr)))
    pb = np.broadcast_to(pairs[:, 1, None], (len(pairs), len(fr)))
    shape = (len(holds), len(pairs), len(fr))
    m_model, a_model, m_lin = np.full(shape, np.nan), np.full(shape, np.nan), np.full(shape, np.nan)
    c_fit, rms_fit = np.full(len(holds), np.nan), np.full(len(holds), np.nan)
    for h in range(len(holds)):
        model = _model(fea["free_angle_deg"], fea["blocked_moment_nm"][h], pairs, shape_c, ths)
        m_model[h] = model_moment_nm(model, pt, pb, fea["end_angle_deg"])
        m_lin[h] = model_moment_nm(model.with_shape(0.0), pt, pb, fea["end_angle_deg"])
        a_model[h] = model.angle_deg(pt, pb, np.nan_to_num(fea["moment_fea_nm"][h]))
        ok = np.isfinite(fea["moment_fea_nm"][h])
        inner = ok & (fr[None, :] > 0) & (fr[None, :] < 1)  # the shape term vanishes at both ends
        if inner.any():
            fitted = fit_shape(model, pt[ok], pb[ok], fea["moment_fea_nm"][h][ok], fea["end_angle_deg"][ok])
            c_fit[h] = fitted.shape_c
            r = model_moment_nm(fitted, pt, pb, fea["end_angle_deg"])[ok] - fea["moment_fea_nm"][h][ok]
            mb = np.broadcast_to(fea["blocked_moment_nm"][h][:, None], pt.shape)[ok]
            rms_fit[h] = float(np.sqrt(np.mean((r / np.abs(mb)) ** 2)))
    mb3 = np.broadcast_to(fea["blocked_moment_nm"][:, :, None], shape)
    err = np.where(fea["status"] == 0, m_model - fea["moment_fea_nm"], np.nan)
    err_lin = np.where(fea["status"] == 0, m_lin - fea["moment_fea_nm"], np.nan)
    rel = err / np.abs(mb3)
    d3, d2 = ("end_hold", "point", "fraction"), ("end_hold", "point")
    flags = dict(fem.STATUS_FLAGS)
    flags[NOT_RUN] = "not_run"
    ds = xr.Dataset(
        {
            "free_angle_deg": ("point", fea["free_angle_deg"], {"units": "degree", "long_name": "FEA free bending angle per unit"}),
            "blocked_moment_nm": (d2, fea["blocked_moment_nm"], {"units": "N m", "long_name": "FEA blocked moment per unit (end held at 0)"}),
            "end_angle_deg": (("point", "fraction"), fea["end_angle_deg"],
                              {"units": "degree", "long_name": "prescribed end inclination per unit (fraction * free angle)"}),
            "backbone_angle_deg": (d3, fea["backbone_angle_deg"],
                                   {"units": "degree", "long_name": "FEA backbone angle per unit at the prescribed inclination"}),
            "moment_fea_nm": (d3, fea["moment_fea_nm"],
                              {"units": "N m", "long_name": "FEA couple holding the end at the prescribed inclination"}),
            "moment_model_nm": (d3, m_model, {"units": "N m", "long_name": f"unit-model moment at that angle (shape_c = {shape_c:g})"}),
            "moment_linear_nm": (d3, m_lin, {"units": "N m", "long_name": "linear-spring moment at that angle (shape_c = 0)"}),
            "moment_error_nm": (d3, err, {"units": "N m", "long_name": "model minus FEA moment"}),
            "moment_error_linear_nm": (d3, err_lin, {"units": "N m", "long_name": "linear spring minus FEA moment"}),
            "moment_error_rel": (d3, rel, {"units": "1", "long_name": "model minus FEA moment / |blocked moment|"}),
            "angle_model_deg": (d3, np.where(fea["status"] == 0, a_model, np.nan),
                                {"units": "degree", "long_name": "unit-model angle per unit under the FEA moment"}),
            "angle_error_deg": (d3, np.where(fea["status"] == 0, a_model - fea["end_angle_deg"][None], np.nan),
                                {"units": "degree", "long_name": "model angle minus prescribed angle, per unit"}),
            "shape_c_fit": ("end_hold", c_fit, {"units": "1", "long_name": "least-squares shape_c from these FEA points"}),
            "moment_error_rel_rms_fit": ("end_hold", rms_fit, {"units": "1", "long_name": "rms relative moment error with shape_c_fit"}),
            "status": (d3, fea["status"], {"units": "1", "long_name": "rotation solve status",
                                           "flag_values": np.array(sorted(flags), dtype=np.int32),
                                           "flag_meanings": " ".join(flags[k] for k in sorted(flags))}),
            "free_status": ("point", fea["free_status"], {"units": "1", "long_name": "free solve status (0 = converged)"}),
            "blocked_status": (d2, fea["blocked_status"], {"units": "1", "long_name": "blocked solve status (0 = converged)"}),
            "wall_time_s": (d3, fea["wall_time_s"], {"units": "s", "long_name": "wall time of the rotation solve"}),
        },
        coords={
            "end_hold": ("end_hold", holds, {"long_name": "end nodes held plane (face: whole end face; backbone: paper + base layers)"}),
            "point": ("point", np.arange(len(pairs))),
            "fraction": ("fraction", fr, {"units": "1", "long_name": "prescribed end inclination / free angle"}),
            "p_top_kpa": ("point", pairs[:, 0], {"units": "kPa", "long_name": "top chamber pressure P_T"}),
            "p_bottom_kpa": ("point", pairs[:, 1], {"units": "kPa", "long_name": "bottom chamber pressure P_B"}),
        },
    )
    ds.attrs["shape_c"] = float(shape_c)
    ds.attrs["theta_scale_deg"] = ths
    for h, hold in enumerate(holds):
        e = np.abs(rel[h])
        ds.attrs[f"max_abs_rel_error_{hold}"] = float(np.nanmax(e)) if np.isfinite(e).any() else np.nan
        ds.attrs[f"mean_abs_rel_error_{hold}"] = float(np.nanmean(e)) if np.isfinite(e).any() else np.nan
        ds.attrs[f"failed_rotations_{hold}"] = int(np.sum(fea["status"][h] != 0))
    return ds


def moment_check(actuator: Mapping, check: Mapping | None = None, shape_c: float = 0.0) -> xr.Dataset:
    """Run the check's FEA points (``actuator.moment_check``) and compare with the unit model."""
    c = dict(DEFAULT_CHECK)
    c.update(dict(check or {}))
    dim = int(str(c["model"])[0])
    fea = run_fea(actuator, c["pairs_kpa"], c["fractions"], c["end_holds"], dim)
    ds = compare(fea, c["pairs_kpa"], c["fractions"], c["end_holds"], shape_c=shape_c)
    ds.attrs["model"] = str(c["model"])
    return ds


def plot_moment_check(ds: xr.Dataset, out: str | Path) -> Path:
    """Moment against angle per unit, FEA markers and model lines, per pressure pair and end hold."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    markers = {"backbone": "o", "face": "s"}
    colours = plt.cm.viridis(np.linspace(0, 0.8, ds.sizes["point"]))
    for h, hold in enumerate(ds["end_hold"].values):
        for i in range(ds.sizes["point"]):
            thf = float(ds["free_angle_deg"][i])
            mb = float(ds["blocked_moment_nm"][h, i])
            if not (np.isfinite(thf) and np.isfinite(mb)):
                continue
            th = np.concatenate([[0.0], ds["end_angle_deg"][i].values])  # the blocked run is theta = 0
            m = np.concatenate([[mb], ds["moment_fea_nm"][h, i].values])
            lab = f"P = ({ds.p_top_kpa.values[i]:g}, {ds.p_bottom_kpa.values[i]:g}) kPa, {hold}"
            ls = "-" if hold == "backbone" else ":"
            mk = dict(marker=markers.get(hold, "^"), ls="none", color=colours[i], mfc="none" if hold == "face" else colours[i])
            x = np.linspace(min(0.0, np.nanmin(th / thf)), max(1.0, np.nanmax(th / thf)), 50)
            # linear spring M = M_b (1 - theta / theta_f), absolute and normalised
            axes[0].plot(x * thf, mb * (1 - x), ls, color=colours[i], lw=1)
            axes[0].plot(th, m, label=lab, **mk)
            axes[1].plot(x, 1 - x, ls, color="0.5", lw=1)
            axes[1].plot(th / thf, m / mb, **mk)
    axes[0].set_xlabel("end inclination per unit (deg)")
    axes[0].set_ylabel("end moment per unit (N m)")
    axes[1].set_xlabel("inclination / free angle")
    axes[1].set_ylabel("moment / blocked moment")
    for ax in axes:
        ax.axhline(0.0, color="0.6", lw=0.5)
        ax.grid(alpha=0.3)
    axes[1].set_ylim(-2.0, 1.5)
    axes[0].legend(fontsize=7)
    fig.suptitle("Unit under an end rotation: FEA (markers; open = face hold) vs linear spring (lines)", fontsize=9)
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def write_moment_check(nc_path: str | Path, plot_path: str | Path, actuator: Mapping, unit_model: Mapping | None = None,
                       *, rule: str = "unit_moment_check", config_slice=None) -> xr.Dataset:
    """Run the check with ``actuator.moment_check`` and ``unit_model.shape_c``; write the dataset and plot."""
    from workflow.provenance import write_dataset

    shape_c = float(dict(unit_model or {}).get("shape_c", 0.0))
    ds = moment_check(actuator, actuator.get("moment_check"), shape_c=shape_c)
    write_dataset(ds, nc_path, rule=rule, config_slice=config_slice if config_slice is not None else dict(actuator),
                  title="PNA unit under a prescribed end rotation: FEA couple vs the unit model (issue 5 item 4)",
                  source="workflow.fem (case rotation) and workflow.unit_model on the same FEA free/blocked runs")
    plot_moment_check(ds, plot_path)
    return ds
