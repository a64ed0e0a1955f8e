"""The unit under an external end moment, checked against a unit inside a longer chain.

Free bending (M = 0) and blocked (angle 0) are the two ends of a unit's
moment-angle curve; `workflow.actuator.unit_model` joins them with a torsional spring
theta(M) = theta_f - M theta_f / M_b.  Which blocked moment M_b belongs in it
depends on how the three-chamber unit model's free end is held at zero
rotation (``end_hold``, `workflow.fem.held_end_nodes`): ``face`` holds the whole
end face plane (the blocks' end walls with the backbone), ``backbone`` only
the paper and base layers.

The reference is what the reduced-order model stands for: one unit inside a
longer actuator.  A chain of ``chain_units`` chambers (default 5), cut at gap
centres so that its ends are the backbone alone (`build_unit_mesh(...,
end_gaps=True)`), is solved free and with its end held at prescribed
rotations (fractions of its own free angle, 0 = blocked); in each state the
end couple M is the moment every unit of the chain carries, and the middle
unit's rotation theta_mid (backbone angle between the centres of its two gaps)
is its response.  Per hold the spring built on the three-chamber unit's free
angle and that hold's blocked moment predicts theta_mid(M); the hold whose
compliance theta_f / M_b matches the chain's (the least-squares slope of
theta_mid against M) best, and whose predictions are closest, is the one the
workflow uses (``actuator.end_hold``).

Units: angles in degrees per unit (chamber), moments in N m per unit for the
full actuator width, pressures in kPa.
"""

from __future__ import annotations

import logging
import time
from typing import Mapping

import numpy as np
import xarray as xr

from workflow import fem
from workflow.actuator.unit_model import UnitModel
from workflow.common.constants import SOLVER_STATUS
from workflow.fem.actuator import backbone_curve, unit_bends_deg

__all__ = [
    "DEFAULT_CHECK",
    "lookup",
    "model_moment_nm",
    "unit_rotations_deg",
    "chain_mesh",
    "run_fea",
    "compare",
    "moment_check",
    "NOT_RUN",
]

log = logging.getLogger(__name__)

#: Points of the check (config ``actuator.moment_check``).
DEFAULT_CHECK = {
    "model": "2d",
    "pairs_kpa": [[60.0, 0.0], [180.0, 0.0], [300.0, 150.0]],
    "fractions": [0.0, 0.25, 0.5, 0.75],  # chain end inclination / its free angle (0 = blocked)
    "end_holds": ["face", "backbone"],
    "chain_units": 5,
}

#: Status of a point that was not run because the free run it depends on failed.
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


def chain_mesh(unit, chain_units: int = 5, **layers):
    """The reference chain of ``chain_units`` chambers, cut at gap centres (its ends are the backbone alone), on the
    unit's geometry and element size; ``layers``: `workflow.fem.layer_options`."""
    geom = dict(unit.geometry, n_chambers=int(chain_units))
    return fem.build_unit_mesh(geom, h=unit.h, dim=unit.dim, end_gaps=True, refine=unit.refine, **layers)


def unit_rotations_deg(um, u: np.ndarray) -> np.ndarray:
    """Backbone rotation of each unit (deg, positive = P_T sense) between the centres of its gaps.

    The first and last units run from the chain's ends (:func:`workflow.fem.actuator.unit_bends_deg`).  ``u``:
    nodal displacements (mm) of the mesh ``um``.
    """
    p = um.mesh.p
    x = p + np.asarray(u)[: p.size].reshape(-1, um.dim).T
    g = um.geometry
    paper = np.flatnonzero(np.abs(p[1]) <= 0.5 * g["paper_width"] + 1e-9)
    cur, ref = backbone_curve(x, p, paper), backbone_curve(p, p, paper)
    return unit_bends_deg(cur, ref, int(g["n_chambers"]), g["depth"], g["gap"])


def _solve(actuator, dim, mesh, pt, pb, case, **kw):
    """One solve with the config's settings; returns (result, wall time s)."""
    t0 = time.perf_counter()
    res = fem.solve_unit_from_config(actuator, dim, pt, pb, case, mesh=mesh, **kw)
    return res, time.perf_counter() - t0


def run_fea(
    actuator: Mapping, pairs_kpa, fractions, end_holds=("face", "backbone"), dim: int = 2, chain_units: int = 5
) -> dict:
    """The three-chamber unit (free, blocked per hold) and the chain (free, end rotations) per pressure pair.

    Returns arrays: ``free_angle_deg``, ``free_status`` (point); ``blocked_moment_nm``,
    ``blocked_status``, ``blocked_load_factor`` (hold, point); ``chain_free_deg``
    (point, the chain's total free angle per unit); ``chain_moment_nm``,
    ``chain_mid_angle_deg``, ``chain_status`` (point, state: free, then each
    fraction); ``wall_time_s`` (point).  Angles per unit, deg; moments N m per unit.
    """
    pairs = np.asarray(pairs_kpa, float).reshape(-1, 2)
    fr = np.asarray(fractions, float)
    holds = list(end_holds)
    unit = fem.unit_mesh_from_config(actuator, dim)
    chain = chain_mesh(unit, chain_units, **fem.layer_options(actuator))
    n = int(unit.geometry["n_chambers"])
    mid = int(chain_units) // 2
    npt, nh, ns = len(pairs), len(holds), 1 + len(fr)
    out = {
        "free_angle_deg": np.full(npt, np.nan),
        "free_status": np.full(npt, NOT_RUN, np.int32),
        "blocked_moment_nm": np.full((nh, npt), np.nan),
        "blocked_status": np.full((nh, npt), NOT_RUN, np.int32),
        "blocked_load_factor": np.full((nh, npt), np.nan),
        "chain_free_deg": np.full(npt, np.nan),
        "chain_moment_nm": np.full((npt, ns), np.nan),
        "chain_mid_angle_deg": np.full((npt, ns), np.nan),
        "chain_status": np.full((npt, ns), NOT_RUN, np.int32),
        "wall_time_s": np.zeros(npt),
    }
    for i, (pt, pb) in enumerate(pairs):
        free, t = _solve(actuator, dim, unit, pt, pb, "free")
        out["wall_time_s"][i] += t
        out["free_status"][i] = free.status
        out["free_angle_deg"][i] = free.bending_angle_total_deg / n if free.status == 0 else np.nan
        log.info(
            "P = (%g, %g) kPa: unit free angle %.3f deg/unit, status %d, %.1f s",
            pt,
            pb,
            free.bending_angle_total_deg / n,
            free.status,
            t,
        )
        for k, hold in enumerate(holds):
            blk, t = _solve(actuator, dim, unit, pt, pb, "blocked", end_hold=hold)
            out["wall_time_s"][i] += t
            out["blocked_status"][k, i], out["blocked_load_factor"][k, i] = blk.status, blk.load_factor
            out["blocked_moment_nm"][k, i] = blk.bending_moment_nm if blk.status == 0 else np.nan
            log.info(
                "  %s hold: blocked moment %.5f N m, status %d at %.3f of the load, %.1f s",
                hold,
                blk.bending_moment_nm,
                blk.status,
                blk.load_factor,
                t,
            )
        cf, t = _solve(actuator, dim, chain, pt, pb, "free", keep_displacement=True)
        out["wall_time_s"][i] += t
        out["chain_status"][i, 0] = cf.status
        if cf.status:
            continue
        total = cf.bending_angle_total_deg
        out["chain_free_deg"][i] = total / chain_units
        out["chain_moment_nm"][i, 0] = 0.0
        out["chain_mid_angle_deg"][i, 0] = unit_rotations_deg(chain, cf.displacement)[mid]
        for j, f in enumerate(fr, start=1):
            case = "blocked" if f == 0 else "rotation"
            r, t = _solve(
                actuator, dim, chain, pt, pb, case, end_hold="face", end_angle_deg=f * total, keep_displacement=True
            )
            out["wall_time_s"][i] += t
            out["chain_status"][i, j] = r.status
            if r.status == 0:  # a stalled ray's last state is not at the prescribed angle
                out["chain_moment_nm"][i, j] = r.bending_moment_nm
                out["chain_mid_angle_deg"][i, j] = unit_rotations_deg(chain, r.displacement)[mid]
            log.info(
                "  chain of %d at %.2f of its free angle: M = %.5f N m, middle unit %.3f deg, status %d, %.1f s",
                chain_units,
                f,
                r.bending_moment_nm,
                out["chain_mid_angle_deg"][i, j],
                r.status,
                t,
            )
    return out


def compare(fea: dict, pairs_kpa, fractions, end_holds) -> xr.Dataset:
    """The check dataset: the chain's middle unit against each hold's spring, and the evidence per hold."""
    pairs = np.asarray(pairs_kpa, float).reshape(-1, 2)
    fr = np.asarray(fractions, float)
    holds = list(end_holds)
    npt, nh = len(pairs), len(holds)
    M, th = fea["chain_moment_nm"], fea["chain_mid_angle_deg"]
    ok = (fea["chain_status"] == 0) & np.isfinite(M) & np.isfinite(th)
    # the chain's interior unit: least-squares line theta_mid = a - c M per pair
    c_chain, a_chain = np.full(npt, np.nan), np.full(npt, np.nan)
    for i in range(npt):
        if ok[i].sum() >= 2:
            slope, icpt = np.polyfit(M[i, ok[i]], th[i, ok[i]], 1)
            c_chain[i], a_chain[i] = -slope, icpt
    thf = fea["free_angle_deg"]
    c_hold = thf[None, :] / fea["blocked_moment_nm"]  # deg per N m
    pred = thf[None, :, None] - c_hold[:, :, None] * M[None]
    err = np.where(ok[None], pred - th[None], np.nan)
    rms = np.sqrt(np.nanmean(err**2, axis=2)) if np.isfinite(err).any() else np.full((nh, npt), np.nan)
    ratio = c_hold / c_chain[None, :]
    with np.errstate(invalid="ignore"):
        score = np.array(
            [np.nanmean(np.abs(np.log(ratio[k]))) if np.isfinite(ratio[k]).any() else np.inf for k in range(nh)]
        )
    best = holds[int(np.argmin(score))] if np.isfinite(score).any() else ""
    states = ["free"] + [f"{f:g}" for f in fr]
    flags = dict(SOLVER_STATUS)
    flags[NOT_RUN] = "not_run"
    flag_attrs = {
        "flag_values": np.array(sorted(flags), dtype=np.int32),
        "flag_meanings": " ".join(flags[k] for k in sorted(flags)),
    }
    d2, d3 = ("end_hold", "point"), ("end_hold", "point", "state")
    ds = xr.Dataset(
        {
            "free_angle_deg": (
                "point",
                thf,
                {"units": "degree", "long_name": "three-chamber unit: free bending angle per unit"},
            ),
            "blocked_moment_nm": (
                d2,
                fea["blocked_moment_nm"],
                {"units": "N m", "long_name": "three-chamber unit: blocked moment per hold"},
            ),
            "blocked_status": (
                d2,
                fea["blocked_status"],
                {"units": "1", "long_name": "blocked solve status", **flag_attrs},
            ),
            "blocked_load_factor": (
                d2,
                fea["blocked_load_factor"],
                {"units": "1", "long_name": "last converged load factor of the blocked solve"},
            ),
            "hold_compliance_deg_per_nm": (
                d2,
                c_hold,
                {"units": "degree/(N m)", "long_name": "spring compliance theta_f / M_b of the hold"},
            ),
            "chain_free_angle_deg": (
                "point",
                fea["chain_free_deg"],
                {"units": "degree", "long_name": "chain: total free angle / units"},
            ),
            "chain_moment_nm": (
                ("point", "state"),
                M,
                {"units": "N m", "long_name": "chain: end couple (carried by every unit)"},
            ),
            "chain_mid_angle_deg": (
                ("point", "state"),
                th,
                {"units": "degree", "long_name": "chain: middle unit's rotation"},
            ),
            "chain_status": (
                ("point", "state"),
                fea["chain_status"],
                {"units": "1", "long_name": "chain solve status", **flag_attrs},
            ),
            "chain_compliance_deg_per_nm": (
                "point",
                c_chain,
                {"units": "degree/(N m)", "long_name": "chain: middle unit's compliance -d theta/dM (least squares)"},
            ),
            "chain_free_mid_fit_deg": (
                "point",
                a_chain,
                {"units": "degree", "long_name": "chain: middle unit's rotation at M = 0 (least-squares line)"},
            ),
            "compliance_ratio": (
                d2,
                ratio,
                {
                    "units": "1",
                    "long_name": "hold compliance / chain compliance (1 = the hold's spring has the interior unit's stiffness)",
                },
            ),
            "angle_pred_deg": (
                d3,
                pred,
                {"units": "degree", "long_name": "hold's spring: middle unit's rotation under the chain's couple"},
            ),
            "angle_error_deg": (
                d3,
                err,
                {"units": "degree", "long_name": "spring prediction minus the chain's middle unit"},
            ),
            "angle_error_rms_deg": (
                d2,
                rms,
                {"units": "degree", "long_name": "rms prediction error over the chain's states"},
            ),
            "evidence_score": (
                "end_hold",
                score,
                {"units": "1", "long_name": "mean |ln(compliance ratio)| over the pairs (0 = exact)"},
            ),
            "wall_time_s": ("point", fea["wall_time_s"], {"units": "s", "long_name": "wall time of the pair's solves"}),
        },
        coords={
            "end_hold": (
                "end_hold",
                holds,
                {"long_name": "end nodes held plane (face: whole end face; backbone: paper + base layers)"},
            ),
            "point": ("point", np.arange(npt)),
            "state": (
                "state",
                states,
                {"long_name": "chain state: free, or its end held at this fraction of its free angle"},
            ),
            "p_top_kpa": ("point", pairs[:, 0], {"units": "kPa", "long_name": "top chamber pressure P_T"}),
            "p_bottom_kpa": ("point", pairs[:, 1], {"units": "kPa", "long_name": "bottom chamber pressure P_B"}),
        },
    )
    ds.attrs["best_end_hold"] = best
    for k, hold in enumerate(holds):
        ds.attrs[f"evidence_score_{hold}"] = float(score[k])
        ds.attrs[f"failed_blocked_{hold}"] = int(np.sum(fea["blocked_status"][k] != 0))
    return ds


def moment_check(actuator: Mapping, check: Mapping | None = None) -> xr.Dataset:
    """Run the check's FEA points (``actuator.moment_check``) and compare each hold with the chain."""
    c = dict(DEFAULT_CHECK)
    c.update(dict(check or {}))
    dim = int(str(c["model"])[0])
    fea = run_fea(actuator, c["pairs_kpa"], c["fractions"], c["end_holds"], dim, int(c["chain_units"]))
    ds = compare(fea, c["pairs_kpa"], c["fractions"], c["end_holds"])
    ds.attrs.update(
        {
            "model": str(c["model"]),
            "chain_units": int(c["chain_units"]),
            "end_hold_in_use": str(actuator.get("end_hold", fem.DEFAULT_END_HOLD)),
        }
    )
    log.info(
        "end holds against the chain's middle unit (mean |ln compliance ratio|): %s; best: %s",
        ", ".join(f"{h} {ds.attrs[f'evidence_score_{h}']:.3f}" for h in c["end_holds"]),
        ds.attrs["best_end_hold"],
    )
    if ds.attrs["best_end_hold"] and ds.attrs["best_end_hold"] != ds.attrs["end_hold_in_use"]:
        log.warning(
            "actuator.end_hold = %s, but the chain check favours %s",
            ds.attrs["end_hold_in_use"],
            ds.attrs["best_end_hold"],
        )
    return ds
