"""The fidelity study's choices as the stages read them.

An FE case's name and config (:class:`FemCase`), the cheapest method within a
tolerance (:func:`cheapest_within`), and the two readers the rules use: the
unit mesh the FE study chose (:func:`apply_fem_choice`) and the FEA check's
mesh (:func:`check_choice`), and the order in which the check's mesh study solves its meshes and where it may
stop (:func:`search_meshes`).  Pure functions on configs and small datasets.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.common.rays import shared_stops

__all__ = [
    "NOT_SOLVED",
    "mesh_order",
    "search_meshes",
    "valid_checks",
    "within_reference",
    "FemCase",
    "fem_cases",
    "case_actuator",
    "Choice",
    "cheapest_within",
    "apply_fem_choice",
    "check_choice",
    "P_STUDY",
    "shares_sweep_ray",
    "case_sweep",
]


@dataclass(frozen=True)
class FemCase:
    """One FE unit fidelity: model (``2d``/``3d``), element size (mm), self-contact."""

    model: str
    h_mm: float
    contact: bool

    @property
    def name(self) -> str:
        return f"fem_{self.model}_h{self.h_mm:g}_{'contact' if self.contact else 'nocontact'}"

    @classmethod
    def parse(cls, name: str) -> "FemCase":
        m = re.fullmatch(r"fem_(2d|3d)_h([0-9.]+)_(contact|nocontact)", name)
        if m is None:
            raise ValueError(f"not an FE case name: {name!r} (expected e.g. fem_2d_h1_contact)")
        return cls(m.group(1), float(m.group(2)), m.group(3) == "contact")


def fem_cases(spec: Sequence[Mapping]) -> list[FemCase]:
    """Cases of the config list ``[{model, h_mm: [...], contact}, ...]``, each once, in order."""
    out: list[FemCase] = []
    for s in spec:
        for h in s["h_mm"]:
            c = FemCase(str(s["model"]), float(h), bool(s["contact"]))
            if c not in out:
                out.append(c)
    return out


def shares_sweep_ray(case: FemCase, cases: Sequence[FemCase]) -> bool:
    """Whether the case's rays also land on the sweep's P_B = 0 samples, so that a sweep on its mesh takes that
    ray from the study instead of solving it again.

    Every case with contact but the finest of its model (sweeps always run with contact).  The finest keeps the
    study's own points: it is the study's reference, a fine ray's fate at a contact event hangs on where its steps
    land (the 2D 0.25 mm free ray with the sweep's ten stops stops at 150 kPa instead of past 180 kPa, whose
    Richardson point it carries), and it is chosen only when no coarser mesh is within the tolerance.
    """
    if not case.contact:
        return False
    finest = min(c.h_mm for c in cases if c.model == case.model and c.contact)
    return case.h_mm > finest


def case_sweep(case: FemCase, cases: Sequence[FemCase], sweep: Mapping, p_top_kpa: Sequence[float], auto: bool) -> dict:
    """The part of the model's ``sweep`` config (``p_max_kpa``, ``n_pressures``) the FE case ``case`` lands its
    steps on, or {} where no sweep can read its P_B = 0 ray from the case (``auto``: ``fidelity.auto``, without which
    the sweeps take the config's mesh and never read the study): the case must share the ray
    (:func:`shares_sweep_ray`) and the study points ``p_top_kpa`` (kPa) be samples of it
    (:func:`workflow.common.rays.shared_stops`).  A case given {} does not rerun when the sweep changes."""
    if not auto or not shares_sweep_ray(case, cases):
        return {}
    part = {k: sweep[k] for k in ("p_max_kpa", "n_pressures")}
    return part if shared_stops(p_top_kpa, part) else {}


def case_actuator(actuator: Mapping, case: FemCase, iteration_budget: int | None = None) -> dict:
    """The ``actuator`` config with the case's element size and contact switch (and the study's Newton budget)."""
    mesh = dict(actuator.get("mesh", {}), **{f"h_{case.model}_mm": float(case.h_mm)})
    contact = dict(actuator.get("contact", {}), enabled=bool(case.contact))
    out = dict(actuator, mesh=mesh, contact=contact)
    if iteration_budget is not None:
        out["iteration_budget"] = int(iteration_budget)
    return out


@dataclass
class Choice:
    """The fidelity picked for one stage, and why."""

    stage: str
    method: str
    reason: str
    error: float
    wall_time_s: float
    met_tolerance: bool


def cheapest_within(
    stage: str,
    methods: Sequence[str],
    wall_time_s: Sequence[float],
    error: Sequence[float],
    tolerance: float,
    *,
    converged: Sequence[bool] | None = None,
    unit: str = "",
) -> Choice:
    """The cheapest converged method whose error (its largest over the stage's quantities) is within ``tolerance``.

    If none is, the most accurate converged one, said so.  ``error`` NaN
    counts as unknown: such a method is only taken when it is the reference
    (error 0 is expected there) -- callers pass 0 for the reference.
    """
    t = np.asarray(wall_time_s, float)
    e = np.asarray(error, float)
    ok = np.ones(t.size, bool) if converged is None else np.asarray(converged, bool)
    within = ok & np.isfinite(e) & (e <= tolerance)
    u = f" {unit}" if unit and unit != "1" else ""
    fmt = (lambda x: f"{x:.3g}{u}") if u else (lambda x: f"{100 * x:.2f} %")
    if within.any():
        i = int(np.flatnonzero(within)[np.argmin(t[within])])
        faster = ok & (t < t[i])
        why = f"{methods[i]}: the cheapest ({t[i]:.3g} s) within {fmt(tolerance)} (its error {fmt(e[i])})" + (
            f"; faster but outside: {', '.join(f'{methods[k]} {fmt(e[k])}' for k in np.flatnonzero(faster))}"
            if faster.any()
            else ""
        )
        return Choice(stage, methods[i], why, float(e[i]), float(t[i]), True)
    cand = ok & np.isfinite(e)
    if not cand.any():
        raise ValueError(f"{stage}: no converged method with a known error to choose from")
    i = int(np.flatnonzero(cand)[np.argmin(e[cand])])
    return Choice(
        stage,
        methods[i],
        f"{methods[i]}: no method within {fmt(tolerance)}; the most accurate "
        f"converged one taken (error {fmt(e[i])}, {t[i]:.3g} s)",
        float(e[i]),
        float(t[i]),
        False,
    )


def apply_fem_choice(actuator: Mapping, choice: xr.Dataset | None, model: str) -> tuple[dict, dict]:
    """(``actuator`` config with the chosen mesh and contact for ``model``, the fidelity attrs to record).

    ``choice``: the FE study's choice (``results/fidelity/fem.nc``); without it
    (``fidelity.auto`` off) the config's own mesh is used and said so.
    """
    act = dict(actuator)
    if choice is None:
        h_cfg = dict(act.get("mesh", {})).get(f"h_{model}_mm")
        return act, {
            "fidelity": "config",
            "fidelity_reason": f"actuator.mesh.h_{model}_mm = {h_cfg} (fidelity.auto off)",
        }
    if model not in [str(m) for m in choice["model_choice"].values]:
        h_cfg = dict(act.get("mesh", {})).get(f"h_{model}_mm")
        return act, {
            "fidelity": "config",
            "fidelity_reason": f"actuator.mesh.h_{model}_mm = {h_cfg} (no {model} case in fidelity.fem_cases)",
        }
    row = choice.sel(model_choice=model)
    case = FemCase(model, float(row["chosen_h_mm"]), bool(row["chosen_contact"]))
    return case_actuator(act, case), {"fidelity": case.name, "fidelity_reason": str(row["choice_reason"].values)}


#: ``status`` of a mesh the study left out (search ``coarsest_first``: a coarser mesh met the tolerance first).
NOT_SOLVED = -1


def mesh_order(n: int, search: str) -> list[int]:
    """Order in which the check's mesh study solves its ``n`` meshes, indexed coarsest (0) to finest (n - 1).

    ``"all"``: coarsest to finest.  ``"coarsest_first"``: the finest first (every
    other mesh is measured against it), then the rest from the coarsest up, so
    that the study can stop at the first that meets the tolerance: on a run
    whose coarsest mesh qualifies, two meshes are solved instead of ``n``.
    """
    if search == "all":
        return list(range(n))
    if search == "coarsest_first":
        return [n - 1] + list(range(n - 1))
    raise ValueError(f"fidelity.check.search: {search!r} is neither 'all' nor 'coarsest_first'")


def search_meshes(
    n: int,
    n_exercises: int,
    solve_mesh: Callable[[int], tuple[np.ndarray, np.ndarray, np.ndarray]],
    search: str,
    *,
    tolerance_deg: float,
    penetration_bound_mm: float = np.inf,
):
    """Run the check's mesh study in :func:`mesh_order`; with ``coarsest_first`` stop at the first mesh that
    :func:`within_reference` accepts against the finest.

    ``solve_mesh(i)`` -> (angles (exercise, joint) deg, statuses (exercise,), penetrations (exercise,) mm) of mesh i
    (0 coarsest).  Returns (angles (mesh, exercise, joint), statuses, penetrations, stop) where the meshes left out
    keep :data:`NOT_SOLVED` and NaN and ``stop`` is (the accepted mesh, its largest angle difference in deg, the
    meshes left out) or None when every mesh was solved.  Where the finest fails, no mesh is accepted early and all
    are solved (the choice then measures against the finest that converged).
    """
    ang = np.full((n, n_exercises, 3), np.nan)
    status = np.full((n, n_exercises), NOT_SOLVED, dtype="i1")
    pen = np.full((n, n_exercises), np.nan)
    order = mesh_order(n, search)
    for n_done, i in enumerate(order, start=1):
        ang[i], status[i], pen[i] = solve_mesh(i)
        if search == "coarsest_first" and 1 < n_done < len(order):
            err = within_reference(ang, status, pen, i, n - 1, tolerance_deg, penetration_bound_mm)
            if err is not None:
                return ang, status, pen, (i, err, order[n_done:])
    return ang, status, pen, None


def valid_checks(status: np.ndarray, pen: np.ndarray, penetration_bound_mm: float) -> np.ndarray:
    """Per mesh (rows of ``status`` and ``pen``, (mesh, exercise)): every exercise converged and no contact penetration
    beyond the bound -- a mesh whose contact penetrates further is no valid check, however close its angles."""
    return np.all(status == 0, axis=1) & ~np.any(pen > penetration_bound_mm, axis=1)


def within_reference(
    ang: np.ndarray,
    status: np.ndarray,
    pen: np.ndarray,
    i: int,
    ref: int,
    tolerance_deg: float,
    penetration_bound_mm: float,
) -> float | None:
    """Largest |angle difference| (deg) of mesh ``i`` from mesh ``ref`` if mesh i qualifies as the check's mesh:
    every exercise converged at both, i's penetration within the bound and the difference within the tolerance;
    None otherwise.  ``ang`` (mesh, exercise, joint), ``status`` and ``pen`` (mesh, exercise)."""
    if np.any(status[ref] != 0) or not valid_checks(status[i : i + 1], pen[i : i + 1], penetration_bound_mm)[0]:
        return None
    err = float(np.max(np.abs(ang[i] - ang[ref])))
    return err if err <= tolerance_deg else None


def check_choice(
    study: xr.Dataset | None, tolerance_deg: float, h_config_mm: float, penetration_bound_mm: float = np.inf
) -> tuple[float, str]:
    """(element size, why) for the FEA check: the cheapest mesh whose joint angles (every exercise of the
    study) are within ``tolerance_deg`` of the finest converged one's (the config's without a study),
    among the meshes whose contact penetration stays within ``penetration_bound_mm``.

    ``study``: the dataset of :func:`workflow.fidelity.entry.write_check_study`.
    """
    if study is None:
        return float(h_config_mm), f"fea_check.h_actuator_mm = {h_config_mm:g} (fidelity.auto off)"
    c = study
    hs = c["h_mm"].values
    ang = c["angle_deg"].values  # (h, exercise, joint)
    pen_all = c["max_penetration_mm"].values if "max_penetration_mm" in c else np.zeros(c["status"].shape)
    ok = valid_checks(c["status"].values, pen_all, penetration_bound_mm)
    w = c["wall_time_s"].values
    solved_any = np.isfinite(w).any(axis=1)  # a mesh the study left out (NOT_SOLVED) has no time
    wall = np.full(hs.size, np.nan)
    wall[solved_any] = np.nanmean(w[solved_any], axis=1)
    ex = ", ".join(str(e) for e in c["exercise"].values)
    if not ok.any():
        return float(h_config_mm), f"fea_check.h_actuator_mm = {h_config_mm:g}: no mesh of the check study qualified"
    r = int(np.flatnonzero(ok)[np.argmin(hs[ok])])
    err = np.where(ok, np.max(np.abs(ang - ang[r]), axis=(1, 2)), np.nan)
    ch = cheapest_within("fea_check", [f"check_h{h:g}" for h in hs], wall, err, tolerance_deg, converged=ok, unit="deg")
    pen = "" if not np.isfinite(penetration_bound_mm) else f", penetration <= {penetration_bound_mm:g} mm"
    left = hs[np.all(c["status"].values == NOT_SOLVED, axis=1)]
    if left.size:
        pen += f"; h = {', '.join(f'{h:g}' for h in left)} mm not solved: a coarser mesh qualified first"
    return float(
        hs[[f"check_h{h:g}" for h in hs].index(ch.method)]
    ), f"{ch.reason} (study: {ex}, finest h = {hs[r]:g} mm{pen})"


#: The study points: P_T in kPa at P_B = 0.
P_STUDY = (60.0, 180.0, 300.0)
