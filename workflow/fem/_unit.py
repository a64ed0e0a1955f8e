"""The three-chamber unit model: free bending angle and blocked moment.

Boundary conditions: the left end face (x = 0) is clamped.
*free*: the right end is free; the bending angle is the rotation of the
strain-limiting backbone at the right end, from the direction of the paper
layer's last element column (mean position of its paper nodes at x = L minus
that at the previous grid column).  *blocked*: every held node of the right
end face (``end_hold``, below; default all of them) shares one axial displacement (the face stays plane and perpendicular to the
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

*rotation*: the right end face is held
plane at a prescribed total inclination ``end_angle_deg`` (relative to the
clamp, positive = the sense of P_T bending) while free to slide axially and
sideways, the generalisation of *blocked* (inclination 0).  Implementation:
the end face keeps exactly the blocked tie (one shared x displacement, y/z
free) and the *clamp* is turned rigidly by end_angle_deg against the P_T
sense (counter-clockwise) about the paper layer's mid-point at x = 0
(prescribed displacements).  Pressure, contact and
the hyperelastic solid are frame-invariant, so this is the end face held at
+end_angle_deg in the clamp's frame, exactly and for any angle, and the couple
is measured on the end face as in *blocked*.  Rejected alternative: tying the
end face's x-dofs with offsets tan(theta) (Y - Y_ref) or sin(theta) (Y - Y_ref)
with y free holds the face only approximately (its y-stretch changes the
actual inclination) and degenerates as the face approaches 90 deg, which the
2D unit reaches (about 87 deg total free at 300 kPa).  Caveat: the prescribed
displacement ramps linearly with the load factor, so an intermediate state has
the clamp face turned by atan2(lam sin t, 1 - lam + lam cos t) and shortened
by up to cos(t/2); only the final state (lam = 1) is the rotation asked for.
An applied end moment was not used: a couple on a deforming face needs a
follower load (a dead couple loses its arm as the face turns) and the solve
is force-controlled near the free angle, where the unit is softest.

``end_hold`` (blocked and rotation) chooses the end nodes held plane:
``face`` (``DEFAULT_END_HOLD``) the whole end face, ``backbone`` only the paper
and base layers (|y| <= 2.1 mm), the blocks' end walls being as free as in
case *free*.  The default is chosen by evidence (``workflow.actuator.moment_check``):
against the middle unit of a chain of five chambers under end moments (2D,
h = 1 mm, 60-180 kPa), the spring theta_f (1 - M / M_b) with the face hold's
blocked moment has that unit's compliance within 1-9 %, the backbone hold's is
2.4-5.9 times too compliant, and its blocked ray stalls where the held layers
meet the free end wall (a singular corner; 117 kPa at h = 1 mm).  The paper
(Fig. 10) summed sum Fx (y - y_SL) + sum Fy L_R over the reactions at the end
of the middle chamber; with the end free to slide there is no net force, so
both terms reduce to our couple about any point.

Over 400 lines: the unit's load cases (free, blocked, end holds) share its mesh sets, constraints and reported quantities.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Mapping

import numpy as np

from workflow.fem._assembly import PAPER, SILICONE

from ._assembly import SolidAssembler
from ._contact import contact_pairs_from_mesh
from ._mesh import UnitMesh, build_unit_mesh
from ._overlap import overlap_measures
from ._solve import DEFAULT_SOLVER, Model, solve_path

__all__ = [
    "DEFAULT_MATERIAL",
    "DEFAULT_CONTACT",
    "CASES",
    "END_HOLDS",
    "material_constants",
    "UnitResult",
    "solve_unit",
    "unit_model",
    "held_end_nodes",
    "clamp_rotation",
    "clamp_inclination_deg",
    "contact_band",
    "contact_penalty",
    "DEFAULT_END_HOLD",
    "FORMULATIONS",
    "DEFAULT_FORMULATION",
    "solid_assembler",
]

#: Table 5 Mooney-Rivlin constants of Smooth-Sil 950 (MPa; C10 = 260,567.62, C01 = 97,549.81,
#: C20 = 57,500.69 Pa, mu0 = 0.716 MPa), bulk modulus ratio K/mu0, paper layer (section 2.3).
DEFAULT_MATERIAL = {
    "c10_mpa": 0.26056762,
    "c01_mpa": 0.09754981,
    "c20_mpa": 0.05750069,
    "bulk_ratio": 1000.0,  # K = bulk_ratio * mu0, mu0 = 2 (c10 + c01)
    "paper_e_mpa": 1200.0,
    "paper_nu": 0.2,
}

#: Penalty self-contact: eps = penalty_factor * mu0 / penalty_length_mm (MPa/mm), the same on every
#: mesh (a contact pressure p_c gives a penetration p_c / eps: mu0 gives 0.01 mm); search distance, mm.
DEFAULT_CONTACT = {
    "penalty_factor": 100.0,
    "penalty_length_mm": 1.0,
    "search_mm": 1.0,
    "extend": 0.5,
    # regularisation band of the penalty law, per model: in 3D 0.02 mm takes a third off a free ray's Newton
    # iterations at 1.4 mm (more at 1 mm) and moves the free angle by under 0.12 %; in 2D it gains 6 % and stops the
    # 0.25 mm free ray earlier (docs/fea.md, "One band per model")
    "smoothing_mm": {"2d": 0.01, "3d": 0.02},
    "friction": 0.0,  # Coulomb coefficient between silicone surfaces (0: frictionless, as the paper's Marc model)
    "friction_penalty_factor": 0.1,  # tangential penalty = this x the normal one (sticking slaves slip by t_T / eps_t)
    "smooth_normals": True,  # master normals interpolated between nodal normals (continuous across nodes and edges)
}


def contact_band(contact: Mapping, dim: int) -> float:
    """The penalty law's regularisation band (mm) of a ``dim``-D model.

    ``contact["smoothing_mm"]`` is one band for every model or one per model (``{"2d": ..., "3d": ...}``).
    """
    band = contact.get("smoothing_mm", DEFAULT_CONTACT["smoothing_mm"])
    if isinstance(band, Mapping):
        key = f"{dim}d"
        if key not in band:
            raise ValueError(f"contact smoothing_mm {dict(band)} has no band for the {key} model")
        band = band[key]
    return float(band)


def self_contact_pairs(um: UnitMesh, contact_options: Mapping | None = None) -> list:
    """The self-contact of every gap and pocket of ``um`` with ``contact_options`` over ``DEFAULT_CONTACT``."""
    c = {**DEFAULT_CONTACT, **dict(contact_options or {})}
    return contact_pairs_from_mesh(
        um,
        c["search_mm"],
        c["extend"],
        contact_band(c, um.dim),
        smooth_normals=c["smooth_normals"],
        friction=c["friction"],
        friction_penalty_factor=c["friction_penalty_factor"],
    )


def contact_penalty(mat: Mapping, contact: Mapping) -> float:
    """Silicone self-contact penalty eps = penalty_factor mu0 / penalty_length_mm (MPa/mm), mesh-independent."""
    c = dict(DEFAULT_CONTACT)
    c.update(dict(contact))
    return float(c["penalty_factor"]) * mat["mu0"] / float(c["penalty_length_mm"])


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
    full actuator width, pressures in kPa, lengths in mm.  ``end_angle_deg``
    is the held end's total inclination reached (case ``rotation``; 0 for
    ``blocked``, NaN for ``free``); the bending angles are the backbone's.
    ``history`` holds one dict per accepted load step (same keys as the
    scalars), so a sweep along a ray gets every step as a sample.
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
    end_angle_deg: float = 0.0
    attempt: int = 0  # restart that produced it (solve_unit_from_config; 0 = as configured)
    contact_smoothing_mm: float = np.nan  # contact regularisation band used (mm)
    history: list = field(default_factory=list)
    displacement: np.ndarray | None = field(default=None, repr=False)

    @property
    def converged(self) -> bool:
        return self.status == 0

    def as_dict(self) -> dict:
        d = asdict(self)
        d.pop("displacement")
        return d


CASES = ("free", "blocked", "rotation")
END_HOLDS = ("face", "backbone")
#: The blocked moment's end hold used by every caller (see the module docstring).
DEFAULT_END_HOLD = "face"
#: Element formulations -> (mean dilatation in the silicone, material ids with enhanced strains):
#: ``enhanced_paper``: mean-dilatation silicone, enhanced (incompatible-mode) paper layer;
#: ``enhanced``: both enhanced; ``mixed``: mean dilatation only (the paper layer shear-locks in
#: bending); ``displacement``: plain Q1 (also locks volumetrically).  The last two for studies.
FORMULATIONS = {
    "enhanced_paper": (True, (PAPER,)),
    "enhanced": (True, (SILICONE, PAPER)),
    "mixed": (True, ()),
    "displacement": (False, ()),
}
DEFAULT_FORMULATION = "enhanced_paper"


def solid_assembler(mesh, material: np.ndarray, mat: Mapping, formulation: str = DEFAULT_FORMULATION) -> SolidAssembler:
    """The ``SolidAssembler`` of an actuator body (silicone 0, paper 1, others plain) in ``formulation``."""
    if formulation not in FORMULATIONS:
        raise ValueError(f"formulation must be one of {tuple(FORMULATIONS)}, not {formulation!r}")
    mixed, enhanced = FORMULATIONS[formulation]
    return SolidAssembler(mesh, material, dict(mat), mixed=mixed, enhanced=enhanced)


def held_end_nodes(um: UnitMesh, end_hold: str = DEFAULT_END_HOLD) -> np.ndarray:
    """Right-end nodes held plane by cases ``blocked``/``rotation``.

    ``face``: the whole end face (the blocks' end walls too).  ``backbone``:
    only the paper and base layers, |y| <= paper_width/2 + bot_layer (mm), so
    the blocks' end walls are as free as in case ``free``.
    """
    if end_hold not in END_HOLDS:
        raise ValueError(f"end_hold must be one of {END_HOLDS}, not {end_hold!r}")
    end = um.nodes["end"]
    if end_hold == "face":
        return end
    g = um.geometry
    yb = 0.5 * g["paper_width"] + g["bot_layer"]
    return end[np.abs(um.mesh.p[1, end]) <= yb + 1e-9]


def clamp_rotation(um: UnitMesh, angle_deg: float) -> dict:
    """Prescribed clamp displacements (mm) that turn the x = 0 face rigidly by ``angle_deg``.

    Positive = counter-clockwise in the x-y plane (the opposite sense of P_T
    bending), about the paper layer's mid-point (0, 0); z is left out (held).
    Returns ``{dof: value}`` for the clamp's x and y dofs.
    """
    t = np.radians(float(angle_deg))
    dim = um.dim
    clamp = um.nodes["clamp"]
    X, Y = um.mesh.p[0, clamp], um.mesh.p[1, clamp]
    ux = (np.cos(t) - 1.0) * X - np.sin(t) * Y
    uy = np.sin(t) * X + (np.cos(t) - 1.0) * Y
    out = {int(dim * n): float(v) for n, v in zip(clamp, ux)}
    out.update({int(dim * n + 1): float(v) for n, v in zip(clamp, uy)})
    return out


def unit_model(
    um: UnitMesh,
    p_top_kpa: float,
    p_bottom_kpa: float,
    case: str = "free",
    contact: bool = True,
    material: Mapping | None = None,
    contact_options: Mapping | None = None,
    formulation: str = DEFAULT_FORMULATION,
    end_angle_deg: float = 0.0,
    end_hold: str = DEFAULT_END_HOLD,
) -> Model:
    """The ``Model`` of the unit (pressures in MPa at load factor 1).

    ``end_angle_deg`` (deg, total over the unit, + = P_T sense) is used by
    case ``rotation`` only (see the module docstring).
    """
    if case not in CASES:
        raise ValueError(f"case must be one of {CASES}, not {case!r}")
    mat = material_constants(material)
    solid = solid_assembler(um.mesh, um.material, mat, formulation)
    dim = um.dim
    # counter-clockwise clamp = the end face turned clockwise (P_T sense) relative to it
    prescribed = clamp_rotation(um, end_angle_deg) if case == "rotation" else {}
    fixed = [dim * um.nodes["clamp"][:, None] + np.arange(dim)]
    if dim == 3:
        fixed.append(dim * um.nodes["symmetry"] + 2)
    fixed = np.unique(np.concatenate([f.ravel() for f in fixed]))
    fixed = np.setdiff1d(fixed, np.fromiter(prescribed, dtype=np.int64, count=len(prescribed)))
    ties = [dim * held_end_nodes(um, end_hold)] if case in ("blocked", "rotation") else []
    pressures = {
        "top": (um.facets["cavity_top"], 1e-3 * float(p_top_kpa)),
        "bottom": (um.facets["cavity_bottom"], 1e-3 * float(p_bottom_kpa)),
    }
    copts = {**DEFAULT_CONTACT, **dict(contact_options or {})}
    pairs = self_contact_pairs(um, copts) if contact else []
    return Model(
        solid,
        pressures=pressures,
        contacts=pairs,
        penalty=contact_penalty(mat, copts),
        fixed=fixed,
        prescribed=prescribed,
        ties=ties,
    )


def clamp_inclination_deg(end_angle_deg: float, lam: float) -> float:
    """Inclination (deg) of the clamp face at load factor ``lam`` when lam = 1 turns it by ``end_angle_deg``.

    The prescribed displacement is linear in lam, so the face (a straight
    line) is turned by atan2(lam sin t, 1 - lam + lam cos t), not lam t.
    """
    t = np.radians(float(end_angle_deg))
    return float(np.degrees(np.arctan2(lam * np.sin(t), 1.0 - lam + lam * np.cos(t))))


def _measure_factory(
    um: UnitMesh,
    model: Model,
    case: str,
    p_top_kpa: float,
    p_bottom_kpa: float,
    end_angle_deg: float = 0.0,
    end_hold: str = DEFAULT_END_HOLD,
):
    p_ref = um.mesh.p
    dim = um.dim
    n = int(um.geometry["n_chambers"])
    width_factor = um.geometry["width"] if dim == 2 else 2.0
    end = held_end_nodes(um, end_hold)

    def measure(u, lam, info):
        x = model.positions(u, p_ref)
        a = x[:, um.nodes["backbone_end"]].mean(axis=1)
        b = x[:, um.nodes["backbone_prev"]].mean(axis=1)
        # the clamp of case rotation is turned by -end_angle: angles are relative to it
        end_angle = (
            clamp_inclination_deg(end_angle_deg, lam) if case == "rotation" else (0.0 if case == "blocked" else np.nan)
        )
        total = -np.degrees(np.arctan2(a[1] - b[1], a[0] - b[0])) + (end_angle if case == "rotation" else 0.0)
        moment = np.nan
        if case in ("blocked", "rotation") and info.get("r") is not None:
            r = info["r"].reshape(-1, dim)[end]
            xe = x[:, end]
            c = xe.mean(axis=1)
            m_mm = np.sum((xe[0] - c[0]) * r[:, 1] - (xe[1] - c[1]) * r[:, 0])
            moment = float(m_mm * width_factor * 1e-3)  # N mm (per mm) -> N m, full width
        return {
            "p_top_kpa": lam * p_top_kpa,
            "p_bottom_kpa": lam * p_bottom_kpa,
            "bending_angle_total_deg": float(total),
            "bending_angle_deg": float(total / n),
            "bending_moment_nm": moment,
            "end_angle_deg": end_angle,
            **overlap_measures(um, x, info),
        }

    return measure


def solve_unit(
    mesh_or_params,
    p_top_kpa: float,
    p_bottom_kpa: float,
    case: str = "free",
    contact: bool = True,
    *,
    material: Mapping | None = None,
    contact_options: Mapping | None = None,
    solver: Mapping | None = None,
    formulation: str = DEFAULT_FORMULATION,
    keep_displacement: bool = False,
    stops=(),
    end_angle_deg: float = 0.0,
    end_hold: str = DEFAULT_END_HOLD,
) -> UnitResult:
    """Solve the unit model from zero to (p_top_kpa, p_bottom_kpa) and measure it.

    Parameters
    ----------
    mesh_or_params : UnitMesh or mapping
        A mesh from ``build_unit_mesh`` or a mapping with ``dim``, ``h`` (mm),
        optional ``geometry``, ``paper_layers`` and ``base_layers``.
    p_top_kpa, p_bottom_kpa : float
        Top and bottom chamber pressures at the end of the ray, kPa.
    case : {"free", "blocked", "rotation"}
        Free bending (angle), rotation held at zero at the right end (moment)
        or held at ``end_angle_deg`` (moment; only the final state, lam = 1,
        is that rotation: see the module docstring).
    contact : bool
        Penalty self-contact across the gaps.
    material, contact_options, solver : mapping, optional
        Overrides of ``DEFAULT_MATERIAL``, ``DEFAULT_CONTACT``, ``DEFAULT_SOLVER``.
    formulation : str
        Element technology (``FORMULATIONS``); ``mixed`` and ``displacement`` lock, for studies.
    keep_displacement : bool
        Keep the final nodal displacement (mm, node-interleaved) in the result.
    stops : sequence of float
        Fractions s in (0, 1] of the ray that the load steps must hit exactly
        (e.g. 60/300 and 180/300), so that ``history`` has samples there.
    end_angle_deg : float
        Case ``rotation``: total inclination of the right end face relative to
        the clamp, deg, positive in the sense of P_T bending.
    end_hold : {"face", "backbone"}
        Cases ``blocked``/``rotation``: hold the whole end face plane or only
        its paper and base layers (see `held_end_nodes`).

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
        um = build_unit_mesh(
            prm.get("geometry"),
            h=prm["h"],
            dim=prm["dim"],
            paper_layers=prm.get("paper_layers"),
            base_layers=prm.get("base_layers"),
        )
    model = unit_model(
        um, p_top_kpa, p_bottom_kpa, case, contact, material, contact_options, formulation, end_angle_deg, end_hold
    )
    measure = _measure_factory(um, model, case, p_top_kpa, p_bottom_kpa, end_angle_deg, end_hold)
    opts = dict(DEFAULT_SOLVER)
    opts.update(dict(solver or {}))
    res = solve_path(model, um.mesh.p, opts, measure, stops=tuple(stops))
    last = (
        res.history[-1]
        if res.history
        else {
            "bending_angle_total_deg": 0.0,
            "bending_angle_deg": 0.0,
            "bending_moment_nm": 0.0 if case == "blocked" else np.nan,
            "end_angle_deg": 0.0 if case == "blocked" else np.nan,
            "max_penetration_mm": 0.0,
        }
    )
    pen = max([h["max_penetration_mm"] for h in res.history], default=0.0)
    return UnitResult(
        dim=um.dim,
        case=case,
        contact=bool(contact),
        p_top_kpa=float(p_top_kpa),
        p_bottom_kpa=float(p_bottom_kpa),
        status=res.status,
        reason=res.reason,
        load_factor=res.lam,
        bending_angle_deg=last["bending_angle_deg"],
        bending_angle_total_deg=last["bending_angle_total_deg"],
        bending_moment_nm=last["bending_moment_nm"],
        max_penetration_mm=pen,
        newton_iterations=res.iterations,
        steps=res.steps,
        cutbacks=res.cutbacks,
        wall_time_s=time.perf_counter() - t0,
        assembly_time_s=res.timing["assembly_s"],
        solve_time_s=res.timing["solve_s"],
        ndofs=model.n,
        end_angle_deg=last["end_angle_deg"],
        history=res.history,
        displacement=res.u if keep_displacement else None,
    )
