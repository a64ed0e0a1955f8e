"""Rule entry points of the fidelity stage's file-level steps (its FE, OpenSim and FEA-check studies have
modules of their own: :mod:`.entry_fem`, :mod:`.entry_msk`, :mod:`.entry_check`).

* :func:`write_fem_choice` -- the FE unit cases (:mod:`workflow.fidelity.entry_fem`) against the finest converged one of
  their model, and the cheapest case per model within the tolerance (what the
  sweeps and the unit check then use when ``fidelity.auto`` is on);
* :func:`write_speed_accuracy` -- everything on one (method, quantity) table
  with the Pareto fronts and the chart.

Units: s, kPa, deg, N m, mm.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.actuator.surrogates import fit_surrogate
from workflow.actuator.unit_model import UnitModel
from workflow.cascade.patient import patient_cascade, patient_finger, plan_limit, plan_options
from workflow.cascade.planning import plan_patient
from workflow.common import fidelity_choice
from workflow.common.fidelity_choice import NOT_SOLVED, P_STUDY
from workflow.common.provenance import open_result, write_dataset
from workflow.fidelity import analysis as FD
from workflow.fidelity.plots import plot_speed_accuracy
from workflow.fidelity.tables import _model_cases, _reference_values, fem_table

__all__ = ["write_fem_choice", "write_speed_accuracy"]

log = logging.getLogger(__name__)


def write_fem_choice(
    case_files: Sequence[str | Path],
    out: str | Path,
    *,
    tolerance: float | Mapping[str, float],
    config_slice: Any,
    rule: str = "fidelity_fem_choice",
) -> xr.Dataset:
    """Rule ``fidelity_fem_choice``: the table and, per model, the cheapest case within ``tolerance``.

    ``tolerance``: one relative bound, or ``{"angle": ..., "moment": ...}``
    for the free-angle and blocked-moment quantities.  A case's error is its
    largest over the quantities, each divided by its bound (so <= 1 means
    within); it must have reached every point.  The reference itself has error 0.
    """
    table = fem_table([open_result(f) for f in case_files])
    tol = tolerance if isinstance(tolerance, Mapping) else {"angle": float(tolerance), "moment": float(tolerance)}
    bound = xr.DataArray(
        [float(tol[str(q).split("_")[0]]) for q in table["quantity"].values],
        dims="quantity",
        coords={"quantity": table["quantity"].values},
    )
    models = sorted(set(table["model"].values.tolist()))
    chosen, reason, h, contact, met = [], [], [], [], []
    for model in models:
        sel = _model_cases(table, model)
        names = [str(n) for n in sel["case"].values]
        worst = (sel["error"] / bound).max("quantity", skipna=True).values
        # contact is part of the physics: cases without it are comparisons, never a choice
        conv = sel["converged"].values.astype(bool) & sel["contact"].values.astype(bool)
        try:
            ch = fidelity_choice.cheapest_within(
                f"fem_{model}", names, sel["wall_time_s"].values, worst, 1.0, converged=conv, unit="x the tolerance"
            )
        except ValueError:
            # no case with contact reached every point: the finest with contact is used (its sweeps
            # record each failed sample's status), and the choice says so
            withc = [n for n, c in zip(names, sel["contact"].values) if bool(c)] or names
            fine = min(withc, key=lambda n: fidelity_choice.FemCase.parse(n).h_mm)
            ch = fidelity_choice.Choice(
                f"fem_{model}",
                fine,
                f"{fine}: no case with contact reached every study point; the finest with contact taken",
                float("nan"),
                float(sel["wall_time_s"].sel(case=fine)),
                False,
            )
            log.warning("FE %s: no case with contact reached every study point; %s taken", model, fine)
        case = fidelity_choice.FemCase.parse(ch.method)
        e = sel["error"].sel(case=ch.method)
        ea = float(e.sel(quantity=[q for q in e["quantity"].values if str(q).startswith("angle")]).max())
        em = float(e.sel(quantity=[q for q in e["quantity"].values if str(q).startswith("moment")]).max())
        chosen.append(ch.method)
        reason.append(
            f"{ch.reason}; its largest errors: free angle {100 * ea:.1f} % (tolerance "
            f"{100 * tol['angle']:g} %), blocked moment {100 * em:.1f} % (tolerance {100 * tol['moment']:g} %)"
        )
        h.append(case.h_mm)
        contact.append(case.contact)
        met.append(ch.met_tolerance)
        log.info("FE %s: %s", model, reason[-1])
    ds = table.assign(
        chosen_case=(
            "model_choice",
            np.array(chosen, dtype=object),
            {"units": "1", "long_name": "FE case the sweeps and the unit check use"},
        ),
        chosen_h_mm=("model_choice", np.array(h), {"units": "mm", "long_name": "chosen element size"}),
        chosen_contact=("model_choice", np.array(contact), {"units": "1", "long_name": "chosen contact switch"}),
        choice_reason=("model_choice", np.array(reason, dtype=object), {"units": "1", "long_name": "why this case"}),
        tolerance_met=(
            "model_choice",
            np.array(met),
            {"units": "1", "long_name": "the chosen case is within the tolerance"},
        ),
    ).assign_coords(model_choice=models)
    ds.attrs["tolerance_angle"] = float(tol["angle"])
    ds.attrs["tolerance_moment"] = float(tol["moment"])
    ds.attrs["rule_of_choice"] = (
        "cheapest converged case whose relative errors of the unit's free angle and blocked "
        "moment at P_T = 60/180/300 kPa are within their tolerances (error / tolerance <= 1)"
    )
    write_dataset(
        ds,
        out,
        rule=rule,
        config_slice=config_slice,
        title="FE unit fidelities: speed and error per element size and contact, and the choice",
    )
    return ds


def write_speed_accuracy(
    out_nc: str | Path,
    out_png: str | Path | None,
    *,
    fem_nc: str,
    responses: Mapping[str, str],
    cv_nc: str,
    msk_nc: str | None,
    check_nc: str | None,
    plan_inputs: Mapping | None,
    surrogates_cfg: Mapping,
    config_slice: Any,
    rule: str = "speed_accuracy",
) -> xr.Dataset:
    """Rule ``speed_accuracy``: every fidelity on one (method, quantity) table, Pareto fronts, chart.

    Quantities and references (see :mod:`workflow.fidelity.analysis`): the unit's six
    (reference: the finest converged FE case with contact of the same model;
    surrogates are compared with it too, so their error includes the mesh
    error of the sweep they learnt from); ``cv_angle`` / ``cv_moment``
    (surrogates: mean CV RMSE / std on held-out FE samples, since the unit
    points lie on a sweep ray, where interpolators are exact); ``plan_TGEn``
    (RMS over the eight pressures, kPa, against the plan made with the
    regressor of the best CV score); ``check_{exercise}`` of the check study's exercises
    (deg, largest over the joints, against the finest converged mesh); the
    joint moments (relative, against direct
    OpenSim sampling, over the test patients inside the design region).
    """
    fem = open_result(fem_nc)
    cv = open_result(cv_nc)
    methods, family, wall, setup = [], [], [], []
    quantities: list[str] = list(FD.UNIT_QUANTITIES)
    units = {q: "1" for q in quantities}
    refs = {q: "" for q in quantities}
    cells: dict[tuple[str, str], tuple[float, float]] = {}  # (method, quantity) -> (value, error)

    for i, case in enumerate(fem["case"].values):
        m = str(case)
        methods.append(m)
        family.append(f"fem_{fem['model'].values[i]}")
        wall.append(float(fem["wall_time_s"].values[i]))
        setup.append(0.0)
        for j, q in enumerate(FD.UNIT_QUANTITIES):
            cells[m, q] = (float(fem["value"].values[i, j]), float(fem["error"].values[i, j]))
    for q in FD.UNIT_QUANTITIES:
        r = {str(x) for x in fem["reference_case"].sel(quantity=q).values if str(x)}
        refs[q] = ", ".join(sorted(r))

    rows = _surrogate_rows(responses, fem, surrogates_cfg, cv)
    # held-out accuracy: the study points lie on a sweep ray, where interpolators are exact
    for t in ("angle", "moment"):
        quantities.append(f"cv_{t}")
        units[f"cv_{t}"] = "1"
        refs[f"cv_{t}"] = "the held-out FE samples of the surrogate's own sweep"
    for name, fam, qv, q_t, s_t, ref, _ in rows:
        methods.append(name)
        family.append(fam)
        wall.append(q_t)
        setup.append(s_t)
        for q in FD.UNIT_QUANTITIES:
            cells[name, q] = (qv[q], float(FD.relative_errors(qv[q], ref.get(q, np.nan))))
        fea, reg = name.split("_", 2)[1], name.split("_", 2)[2]
        for t in ("angle", "moment"):
            c = cv.sel(fea=fea, regressor=reg, target=t)
            nrmse = float((c["rmse"] / c["target_std"]).mean("fold"))
            cells[name, f"cv_{t}"] = (float(c["rmse"].mean("fold")), nrmse)

    if plan_inputs:
        pi = plan_inputs
        loads = open_result(pi["joint_loads"])
        finger, _ = patient_finger(
            pi["patient"],
            loads,
            open_result(pi["moments"]),
            open_result(pi["ccd"]),
            cascade_cfg=pi["cascade"],
            anthropometry=pi["anthropometry"],
        )
        c = pi["cascade"]
        targets = {str(e): loads["target_angle_deg"].sel(exercise=e).values for e in loads["exercise"].values}
        plan_fea = c.get("surrogate", "3d")
        cand = [r for r in rows if r[1] == f"surrogate_{plan_fea}"]
        # reference plan: the regressor with the best held-out (CV) score
        best = min(cand, key=lambda r: cells[r[0], "cv_angle"][1] + cells[r[0], "cv_moment"][1])
        plans = {}
        for name, _, _, _, s_t, _, s in cand:
            unit = UnitModel.from_surrogate(s, **pi["unit_model"])
            ro = patient_cascade(finger, unit, c)
            opts = plan_options(c, loads["active_limit_nm"].values, plan_limit(c, unit))  # no plan beyond the samples
            t0 = time.perf_counter()
            plans[name] = {p.exercise: p.pressures_kpa for p in plan_patient(ro, targets, **opts)}
            t_plan = (time.perf_counter() - t0) / len(targets)  # one evaluation = one exercise's plan
            pm = name.replace("surrogate_", "plan_")
            methods.append(pm)
            family.append("plan")
            wall.append(t_plan)
            setup.append(s_t)
        for e in targets:
            q = f"plan_{e}"
            quantities.append(q)
            units[q] = "kPa"
            refs[q] = best[0].replace("surrogate_", "plan_")
            for name in plans:
                d = plans[name][e] - plans[best[0]][e]
                cells[name.replace("surrogate_", "plan_"), q] = (
                    float(np.sqrt(np.mean(plans[name][e] ** 2))),
                    float(np.sqrt(np.mean(d**2))),
                )

    if check_nc:
        chk = open_result(check_nc)
        # a mesh the coarsest-first search left out has no time or error to chart
        chk = chk.isel(h_mm=~np.all(chk["status"].values == NOT_SOLVED, axis=1))
        hs = chk["h_mm"].values
        for e in chk["exercise"].values:
            c = chk.sel(exercise=e)
            ok = c["status"].values == 0
            r = int(np.flatnonzero(ok)[np.argmin(hs[ok])]) if ok.any() else None
            q = f"check_{e}"
            quantities.append(q)
            units[q] = "degree"
            refs[q] = f"check_h{hs[r]:g}" if r is not None else ""
            ref_ang = c["angle_deg"].values[r] if r is not None else np.full(3, np.nan)
            for i, h in enumerate(hs):
                cells[f"check_h{h:g}", q] = (
                    float(c["angle_deg"].values[i, 0]),
                    float(np.max(np.abs(c["angle_deg"].values[i] - ref_ang))) if ok[i] else np.nan,
                )
            for k, ch in enumerate(chk["chain"].values):
                cells[str(ch), q] = (
                    float(c["chain_angle_deg"].values[k, 0]),
                    float(np.max(np.abs(c["chain_angle_deg"].values[k] - ref_ang))),
                )
        for i, h in enumerate(hs):  # one evaluation = one exercise's check
            methods.append(f"check_h{h:g}")
            family.append("check")
            wall.append(float(np.nanmean(chk["wall_time_s"].values[i])))
            setup.append(0.0)
        for k, ch in enumerate(chk["chain"].values):
            methods.append(str(ch))
            family.append("check")
            wall.append(float(np.mean(chk["chain_wall_time_s"].values[k])))
            setup.append(0.0)

    if msk_nc:
        msk = open_result(msk_nc)
        inside = msk["inside_design"].values.astype(bool)
        for q in msk["quantity"].values:
            quantities.append(f"msk_{q}")
            units[f"msk_{q}"] = "1"
            refs[f"msk_{q}"] = "msk_opensim"
        for m in msk["method"].values:
            methods.append(str(m))
            family.append("musculoskeletal")
            # the median over the test patients: the first direct sample also loads the model
            wall.append(float(msk["wall_time_s"].sel({"method": m}).median()))
            setup.append(float(msk["setup_time_s"].sel({"method": m})) if "setup_time_s" in msk else 0.0)
            for q in msk["quantity"].values:
                e = msk["rel_error"].sel({"method": m, "quantity": q}).values[inside]
                v = msk["moment_nm"].sel({"method": m, "quantity": q}).values[inside]
                cells[str(m), f"msk_{q}"] = (
                    float(np.mean(v)) if v.size else np.nan,
                    float(np.nanmax(e)) if e.size and np.isfinite(e).any() else np.nan,
                )

    err = np.full((len(methods), len(quantities)), np.nan)
    val = np.full_like(err, np.nan)
    for i, m in enumerate(methods):
        for j, q in enumerate(quantities):
            if (m, q) in cells:
                val[i, j], err[i, j] = cells[m, q]
    # 2D and 3D unit models each against their own reference: one front per model, one per other stage
    group = [f.split("_")[-1] if f.startswith(("fem_", "surrogate_")) else f for f in family]
    ds = FD.speed_accuracy_dataset(
        methods,
        quantities,
        wall,
        err,
        family=family,
        error_units=units,
        reference=refs,
        value=val,
        setup_time_s=setup,
        front_group=group,
    )
    write_dataset(
        ds,
        out_nc,
        rule=rule,
        config_slice=config_slice,
        title="Speed against accuracy of every fidelity the workflow offers",
    )
    if out_png:
        plot_speed_accuracy(ds, out_png)
    return ds


def _surrogate_rows(responses: Mapping[str, str], fem: xr.Dataset, surrogates_cfg: Mapping, cv: xr.Dataset):
    """Every regressor of each sweep, fitted on all its samples, at the unit study points."""

    rows = []
    for fea, path in responses.items():
        resp = open_result(path)
        sweep_time = float(resp["wall_time_s"].sum())
        ref = _reference_values(fem, fea)
        for reg in [str(r) for r in cv["regressor"].values]:
            t0 = time.perf_counter()
            s = fit_surrogate(
                resp, reg, fea=fea, k=int(surrogates_cfg["k"]), random_state=int(surrogates_cfg["random_state"])
            )
            fit_t = time.perf_counter() - t0
            p = np.array(P_STUDY)
            t1 = time.perf_counter()
            a, m = s.angle_deg(p, 0.0 * p), s.moment_nm(p, 0.0 * p)
            q_t = time.perf_counter() - t1
            rows.append(
                (
                    f"surrogate_{fea}_{reg}",
                    f"surrogate_{fea}",
                    FD.unit_quantities(a, m, p),
                    q_t,
                    sweep_time + fit_t,
                    ref,
                    s,
                )
            )
    return rows
