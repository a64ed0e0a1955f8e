"""The three-chamber unit model: free bending angle and blocked moment.

Boundary conditions (CLARIFICATIONS 1): the left end face (x = 0) is clamped.
*free*: the right end is free; the bending angle is the rotation of the
strain-limiting backbone at the right end, from the direction of the paper
layer's last element column (mean position of its paper nodes at x = L minus
that at the previous grid column).  *blocked*: every node of the right end face
shares one axial displacement (the face stays plane and perpendicular to the
undeformed axis, i.e. its rotation is held at zero) while it may slide
axially and sideways as a whole, so the constraint forces have no resultant
and form a pure couple M = sum_i (x_i r_yi - y_i r_xi) over the face.  The
paper (Fig. 10) instead summed sum Fx (y - y_SL) + sum Fy L_R over the
reactions at the end of the middle chamber; without a net force both are the
same couple, ours needs no choice of reference point.

Signs (CONTRACT): P_T only gives a positive angle (the end turns clockwise in
the x-y plane, away from the top chambers) and a positive moment.  Per unit:
angle / n_chambers; the blocked moment is the same in every chamber and is
not divided.  Full width: 2D values per mm x ``width``; 3D half model x 2.
3D adds the symmetry condition u_z = 0 on z = 0.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Mapping

import numpy as np

from ._assembly import SolidAssembler
from ._contact import contact_pairs_from_mesh
from ._mesh import UnitMesh, build_unit_mesh
from ._solve import DEFAULT_SOLVER, Model, solve_path

__all__ = ["DEFAULT_MATERIAL", "DEFAULT_CONTACT", "material_constants", "UnitResult", "solve_unit", "unit_model"]

#: Table 5 Mooney-Rivlin constants (MPa), bulk modulus ratio K/mu0, paper layer.
DEFAULT_MATERIAL = {
    "c10_mpa": 0.2605676,
    "c01_mpa": 0.2975498,
    "c20_mpa": 0.15750069,
    "bulk_ratio": 1000.0,  # K = bulk_ratio * mu0, mu0 = 2 (c10 + c01)
    "paper_e_mpa": 1200.0,
    "paper_nu": 0.2,
}

#: Penalty contact: eps = penalty_factor * mu0 / h (MPa/mm); search distance, mm.
DEFAULT_CONTACT = {"penalty_factor": 100.0, "search_mm": 1.0, "two_pass": True, "extend": 0.5, "smoothing_mm": 0.01}


def material_constants(material: Mapping | None = None) -> dict:
    """Constants for ``SolidAssembler`` (MPa) from the config's material section."""
    m = dict(DEFAULT_MATERIAL)
    m.update(dict(material or {}))
    mu0 = 2.0 * (m["c10_mpa"] + m["c01_mpa"])
    E, nu = m["paper_e_mpa"], m["paper_nu"]
    return {
        "c10": m["c10_mpa"],
        "c01": m["c01_mpa"],
        "c20": m["c20_mpa"],
        "mu0": mu0,
        "bulk": m["bulk_ratio"] * mu0,
        "paper_mu": E / (2.0 * (1.0 + nu)),
        "paper_lambda": E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
    }


@dataclass
class UnitResult:
    """One unit-model solve along the ray p = s (p_top, p_bottom), s in (0, 1].

    Angles in degrees (per unit = total / n_chambers), moments in N m for the
    full actuator width, pressures in kPa, lengths in mm.  ``history`` holds
    one dict per accepted load step (same keys as the scalars), so a sweep
    along a ray gets every step as a sample.
    """

    dim: int
    case: str
    contact: bool
    p_top_kpa: float
    p_bottom_kpa: float
    status: int
    reason: str
    load_factor: float
    bending_angle_deg: float
    bending_angle_total_deg: float
    bending_moment_nm: float
    max_penetration_mm: float
    newton_iterations: int
    steps: int
    cutbacks: int
    wall_time_s: float
    assembly_time_s: float
    solve_time_s: float
    ndofs: int
    history: list = field(default_factory=list)
    displacement: np.ndarray | None = field(default=None, repr=False)

    @property
    def converged(self) -> bool:
        return self.status == 0

    def as_dict(self) -> dict:
        d = asdict(self)
        d.pop("displacement")
        return d


def unit_model(um: UnitMesh, p_top_kpa: float, p_bottom_kpa: float, case: str = "free", contact: bool = True,
               material: Mapping | None = None, contact_options: Mapping | None = None, mixed: bool = True) -> Model:
    """The ``Model`` of the unit (pressures in MPa at load factor 1)."""
    if case not in ("free", "blocked"):
        raise ValueError(f"case must be 'free' or 'blocked', not {case!r}")
    mat = material_constants(material)
    solid = SolidAssembler(um.mesh, um.material, mat, mixed=mixed)
    dim = um.dim
    fixed = [dim * um.nodes["clamp"][:, None] + np.arange(dim)]
    if dim == 3:
        fixed.append(dim * um.nodes["symmetry"] + 2)
    fixed = np.unique(np.concatenate([f.ravel() for f in fixed]))
    ties = [dim * um.nodes["end"]] if case == "blocked" else []
    pressures = {
        "top": (um.facets["cavity_top"], 1e-3 * float(p_top_kpa)),
        "bottom": (um.facets["cavity_bottom"], 1e-3 * float(p_bottom_kpa)),
    }
    copts = dict(DEFAULT_CONTACT)
    copts.update(dict(contact_options or {}))
    pairs = contact_pairs_from_mesh(um, copts["search_mm"], copts["two_pass"], copts["extend"], copts["smoothing_mm"]) if contact else []
    eps = copts["penalty_factor"] * mat["mu0"] / um.h
    return Model(solid, pressures=pressures, contacts=pairs, penalty=eps, fixed=fixed, ties=ties)


def _measure_factory(um: UnitMesh, model: Model, case: str, p_top_kpa: float, p_bottom_kpa: float):
    p_ref = um.mesh.p
    dim = um.dim
    n = int(um.geometry["n_chambers"])
    width_factor = um.geometry["width"] if dim == 2 else 2.0
    end = um.nodes["end"]

    def measure(u, lam, info):
        x = model.positions(u, p_ref)
        a = x[:, um.nodes["backbone_end"]].mean(axis=1)
        b = x[:, um.nodes["backbone_prev"]].mean(axis=1)
        total = -np.degrees(np.arctan2(a[1] - b[1], a[0] - b[0]))
        moment = np.nan
        if case == "blocked" and info.get("r") is not None:
            r = info["r"].reshape(-1, dim)[end]
            xe = x[:, end]
            c = xe.mean(axis=1)
            m_mm = np.sum((xe[0] - c[0]) * r[:, 1] - (xe[1] - c[1]) * r[:, 0])
            moment = float(m_mm * width_factor * 1e-3)  # N mm (per mm) -> N m, full width
        gmin = info.get("gmin", np.inf)
        return {
            "p_top_kpa": lam * p_top_kpa,
            "p_bottom_kpa": lam * p_bottom_kpa,
            "bending_angle_total_deg": float(total),
            "bending_angle_deg": float(total / n),
            "bending_moment_nm": moment,
            "max_penetration_mm": float(max(0.0, -gmin)) if np.isfinite(gmin) else 0.0,
        }

    return measure


def solve_unit(mesh_or_params, p_top_kpa: float, p_bottom_kpa: float, case: str = "free", contact: bool = True, *,
               material: Mapping | None = None, contact_options: Mapping | None = None,
               solver: Mapping | None = None, mixed: bool = True, keep_displacement: bool = False,
               stops=()) -> UnitResult:
    """Solve the unit model from zero to (p_top_kpa, p_bottom_kpa) and measure it.

    Parameters
    ----------
    mesh_or_params : UnitMesh or mapping
        A mesh from ``build_unit_mesh`` or a mapping with ``dim``, ``h`` (mm),
        optional ``geometry`` and ``paper_layers``.
    p_top_kpa, p_bottom_kpa : float
        Top and bottom chamber pressures at the end of the ray, kPa.
    case : {"free", "blocked"}
        Free bending (angle) or rotation held at the right end (moment).
    contact : bool
        Penalty self-contact across the gaps.
    material, contact_options, solver : mapping, optional
        Overrides of ``DEFAULT_MATERIAL``, ``DEFAULT_CONTACT``, ``DEFAULT_SOLVER``.
    mixed : bool
        False = plain Q1 displacement elements (lock; for tests only).
    keep_displacement : bool
        Keep the final nodal displacement (mm, node-interleaved) in the result.
    stops : sequence of float
        Fractions s in (0, 1] of the ray that the load steps must hit exactly
        (e.g. 60/300 and 180/300), so that ``history`` has samples there.

    Returns
    -------
    UnitResult
        Never raises for a failed solve: see ``status``/``reason``/``load_factor``.
    """
    t0 = time.perf_counter()
    if isinstance(mesh_or_params, UnitMesh):
        um = mesh_or_params
    else:
        prm = dict(mesh_or_params)
        um = build_unit_mesh(prm.get("geometry"), h=prm["h"], dim=prm["dim"], paper_layers=prm.get("paper_layers", 1))
    model = unit_model(um, p_top_kpa, p_bottom_kpa, case, contact, material, contact_options, mixed)
    measure = _measure_factory(um, model, case, p_top_kpa, p_bottom_kpa)
    opts = dict(DEFAULT_SOLVER)
    opts.update(dict(solver or {}))
    res = solve_path(model, um.mesh.p, opts, measure, stops=tuple(stops))
    last = res.history[-1] if res.history else {
        "bending_angle_total_deg": 0.0, "bending_angle_deg": 0.0, "bending_moment_nm": 0.0 if case == "blocked" else np.nan,
        "max_penetration_mm": 0.0}
    pen = max([h["max_penetration_mm"] for h in res.history], default=0.0)
    return UnitResult(
        dim=um.dim, case=case, contact=bool(contact), p_top_kpa=float(p_top_kpa), p_bottom_kpa=float(p_bottom_kpa),
        status=res.status, reason=res.reason, load_factor=res.lam,
        bending_angle_deg=last["bending_angle_deg"], bending_angle_total_deg=last["bending_angle_total_deg"],
        bending_moment_nm=last["bending_moment_nm"], max_penetration_mm=pen,
        newton_iterations=res.iterations, steps=res.steps, cutbacks=res.cutbacks,
        wall_time_s=time.perf_counter() - t0, assembly_time_s=res.timing["assembly_s"], solve_time_s=res.timing["solve_s"],
        ndofs=model.n, history=res.history, displacement=res.u if keep_displacement else None,
    )
