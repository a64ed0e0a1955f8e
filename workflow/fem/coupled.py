"""Whole actuator strapped to the planar finger (paper Fig. 18-21), plane strain.

One mesh holds both bodies: the actuator (``build_actuator_mesh``, shifted so
that its bottom outer face lies on the finger's dorsal skin, in the check one
contact band above it, where the penalty force starts) and the finger
(``build_finger_mesh``).  Materials: silicone (0), paper (1), flesh (2) and
bone (3), the last three compressible neo-Hooke (valid under large rotation).
Couplings:

* frictionless penalty contact between the finger's dorsal skin and the
  actuator's bottom outer face, both ways (each side slave once; skin under a
  gap between two blocks touches both blocks' corners), besides the
  actuator's self-contact across its gaps;
* straps at PIP and DIP: ``StrapSpring`` from the actuator's bottom-face node
  above the joint to the point of the dorsal skin above the joint centre,
  carried by the two adjacent bones (on the bisector of the joint angle);
  a strap resists relative motion in every direction (it wraps the finger),
  so it also holds the actuator along the finger; with ``strap_hold_along``
  below 1 only that share of its stiffness acts along the finger, the
  actuator sliding through it (``SlidingStrap``);
* the sliding support at the hand end of the actuator, as in the plan: the end
  face keeps its height and stays perpendicular to the hand (u_y = 0, one
  shared u_x) and may slide along the hand; a ground spring of negligible
  stiffness on that slide removes the rigid-body mode frictionless contact
  leaves (its force is reported);
* the MCP pin is fixed (the hand); hinge springs at MCP, PIP, DIP;
* gravity as dead loads (``DeadLoad``), first ramped alone, then held while
  the pressures are ramped from zero (``solve_coupled``).

The penalty of the finger-actuator contact is its own (flesh is about 100x
softer than silicone): the finger pairs carry ``penalty_factor`` =
eps_finger / eps_model (``ContactPair``).

2D quantities are per mm of actuator width (N/mm, N mm/mm): the caller
divides whole-finger quantities (spring moments, weights, strap stiffness)
by the actuator width.  Units: mm, MPa, N, rad.

Over 400 lines: the coupled finger-actuator mesh and its model share one node and body numbering.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np
import skfem

from workflow.fem._assembly import SolidAssembler
from workflow.fem._contact import ContactPair, tributary_areas
from workflow.fem._mesh import UnitMesh
from workflow.fem._overlap import overlap_measures
from workflow.fem._solve import DEFAULT_SOLVER, Model, solve_path
from workflow.fem._unit import (
    DEFAULT_CONTACT,
    DEFAULT_FORMULATION,
    contact_band,
    contact_penalty,
    self_contact_pairs,
    solid_assembler,
)
from workflow.fem.actuator import backbone_curve, group_pressures, tip_angle_deg, unit_bends_deg
from workflow.fem.finger2d import (
    BONE,
    FLESH,
    DeadLoad,
    DofSpring,
    FingerMesh,
    HingeSpring,
    RigidRotationUpdate,
    SupportPlane,
    strap,
)

from ..common.constants import JOINTS

__all__ = [
    "CoupledMesh",
    "couple_meshes",
    "cell_areas",
    "nodal_body_force",
    "CoupledSetup",
    "coupled_model",
    "CoupledResult",
    "solve_coupled",
    "segment_rotation_update",
]


@dataclass
class CoupledMesh:
    """Actuator + finger in one node numbering.

    ``body`` per cell: -1 actuator, 0/1/2 the finger segments.  ``act`` is the
    actuator's own ``UnitMesh`` (local coordinates); ``act_nodes`` its node
    numbers here (the first ``n_act``); ``um`` a ``UnitMesh`` view of the merged
    mesh carrying the actuator's facet sets (for pressures and self-contact).
    """

    mesh: skfem.MeshQuad
    material: np.ndarray
    body: np.ndarray
    act: UnitMesh
    offset: np.ndarray
    n_act: int
    finger: FingerMesh
    um: UnitMesh

    def finger_node(self, i: int) -> int:
        return int(i) + self.n_act


def couple_meshes(act: UnitMesh, offset: Sequence[float], finger: FingerMesh) -> CoupledMesh:
    """Merge the actuator (shifted by ``offset`` (2,), mm) and the finger into one mesh."""
    off = np.asarray(offset, float)
    n_act = act.mesh.p.shape[1]
    p = np.concatenate([act.mesh.p + off[:, None], finger.p], axis=1)
    t = np.concatenate([act.mesh.t, finger.t + n_act], axis=1)
    mesh = skfem.MeshQuad(p, t)
    material = np.concatenate([act.material, finger.material])
    body = np.concatenate([np.full(act.mesh.t.shape[1], -1), finger.segment])
    facets = dict(act.facets)
    facets.update({f"finger_{k}": v + n_act for k, v in finger.facets.items()})
    nodes = dict(act.nodes)
    um = UnitMesh(
        mesh=mesh,
        material=material,
        facets=facets,
        nodes=nodes,
        geometry=act.geometry,
        h=act.h,
        contact_surfaces=list(act.contact_surfaces),
        contact_parts=dict(act.contact_parts),
        chamber_group=act.chamber_group,
    )
    return CoupledMesh(mesh=mesh, material=material, body=body, act=act, offset=off, n_act=n_act, finger=finger, um=um)


def cell_areas(mesh: skfem.Mesh) -> np.ndarray:
    """Cell areas (mm^2) by 2x2 Gauss quadrature."""
    basis = skfem.Basis(mesh, skfem.ElementQuad1(), intorder=2)
    return np.asarray(basis.dx).sum(axis=1)


def nodal_body_force(mesh: skfem.Mesh, b_cell: np.ndarray, component: int = 1) -> np.ndarray:
    """Consistent nodal forces (n,) of a cell-wise constant body force ``b_cell`` (N/mm^3) along ``component``."""
    basis = skfem.Basis(mesh, skfem.ElementQuad1(), intorder=2)
    nq = basis.dx.shape[1]

    @skfem.LinearForm
    def form(v, w):
        return w["b"] * v

    fn = form.assemble(basis, b=np.repeat(np.asarray(b_cell, float)[:, None], nq, axis=1))
    dim = mesh.p.shape[0]
    f = np.zeros(dim * mesh.p.shape[1])
    f[component::dim] = fn
    return f


@dataclass
class CoupledSetup:
    """Everything ``coupled_model`` needs besides the pressures.

    ``mat``: ``SolidAssembler`` constants incl. ``neo_hooke`` for FLESH and BONE;
    ``springs``: per joint (moment(theta rad) -> N mm/mm, stiffness -> N mm/mm/rad);
    ``strap_k``: N/mm per mm; ``strap_joints``: joints with a strap; ``gravity``:
    external nodal forces (n,) of all weights (N/mm); ``contact``: the actuator's
    options (``DEFAULT_CONTACT`` keys) plus ``finger_penalty`` (MPa/mm);
    ``slide_k``: stiffness of the regularising spring on the hand-end slide (N/mm).
    """

    cm: CoupledMesh
    mat: dict
    springs: Sequence[tuple[Callable, Callable]]
    strap_k: float
    strap_joints: Sequence[str] = ("PIP", "DIP")
    strap_hold_along: float = 1.0  # share of a strap's stiffness along the finger (1: as across it)
    gravity: np.ndarray | None = None
    contact: dict = field(default_factory=dict)
    slide_k: float = 1e-6
    hand_support: bool = False  # a rigid plane at the dorsal line under the actuator proximal of the MCP joint
    solid: SolidAssembler | None = None
    rigid_update: bool = True
    formulation: str = DEFAULT_FORMULATION  # of the actuator's silicone and paper; flesh and bone plain Q1

    def __post_init__(self):
        if self.solid is None:
            self.solid = solid_assembler(self.cm.mesh, self.cm.material, self.mat, self.formulation)


def _strap_anchor(cm: CoupledMesh, joint_node: int) -> int:
    """The actuator's bottom-face node closest in x to a joint-centre node."""
    p = cm.mesh.p
    cand = np.unique(cm.um.facets["outer_bottom"])
    return int(cand[np.argmin(np.abs(p[0, cand] - p[0, joint_node]))])


def segment_rotation_update(
    cm: CoupledMesh, actuator: bool = False, blend_mm: float | None = None
) -> RigidRotationUpdate:
    """Finite-rotation Newton update of the three finger segments (see ``RigidRotationUpdate``).

    Segment k turns about its proximal joint-centre node (MCP, PIP, DIP), fitted
    over its bone nodes; the pivot itself belongs to the proximal segment.
    With ``actuator``, the actuator's nodes (nearly incompressible silicone and
    stiff paper suffer from the linearised rotation as the bone does) take the
    correction of the segment below them, blended linearly across each joint
    over ``blend_mm`` (default: one unit length, the actuator's x-period), and
    between the clamp and the MCP joint a share of the proximal phalanx's
    rising linearly from 0 at the clamp.  Measured on the mean finger's
    gravity phase (Newton iterations): no update 547, bones 468, bones and
    actuator 693 (the actuator's second-order error along the soft rotation
    about MCP drops 200x, but the iterations do not), so ``actuator`` is off.
    """
    fm = cm.finger
    p = cm.mesh.p
    jx = np.array([p[0, cm.finger_node(fm.nodes[f"joint_{j}"])] for j in JOINTS])
    groups = []
    for k, joint in enumerate(JOINTS):
        pv = cm.finger_node(fm.nodes[f"joint_{joint}"])
        cells = np.flatnonzero(cm.body == k)
        nodes = np.setdiff1d(np.unique(cm.mesh.t[:, cells]), [pv])
        fit = np.setdiff1d(np.unique(cm.mesh.t[:, cells[cm.material[cells] == BONE]]), [pv])
        groups.append((pv, nodes, fit))
    if not actuator:
        return RigidRotationUpdate(groups)
    g = cm.act.geometry
    half = 0.5 * (float(g["depth"]) + float(g["gap"]) if blend_mm is None else float(blend_mm))
    an = np.arange(cm.n_act)
    ax = p[0, an]
    x0 = float(ax.min())
    W = np.zeros((an.size, 3))
    W[:, 0] = np.clip((ax - x0) / max(jx[0] - x0, 1e-9), 0.0, 1.0)
    for k in (1, 2):  # hand over from segment k-1 to k across joint k
        s = np.clip((ax - (jx[k] - half)) / (2 * half), 0.0, 1.0)
        W[:, k] = W[:, k - 1] * s
        W[:, k - 1] = W[:, k - 1] * (1 - s)
    return RigidRotationUpdate(groups, blend=(an, W))


def coupled_model(
    setup: CoupledSetup, pressures_kpa: Mapping[str, tuple[float, float]], gravity_ramp: bool
) -> tuple[Model, dict]:
    """The ``Model`` at the given group pressures (kPa); gravity ramped with lam or held.

    Returns the model and its parts (``hinges``, ``straps``, ``slide``) for measurements.
    """
    cm = setup.cm
    p = cm.mesh.p
    n = 2 * p.shape[1]
    c = dict(DEFAULT_CONTACT)
    c.update(setup.contact)
    fm = cm.finger
    # sliding support: hand-end face of the actuator
    clamp = cm.um.nodes["clamp"]
    fixed = [2 * clamp + 1, [2 * cm.finger_node(fm.nodes["joint_MCP"]) + k for k in (0, 1)]]
    ties = [2 * clamp]
    hinges = {}
    for j, joint in enumerate(JOINTS):
        chord_b = tuple(cm.finger_node(i) for i in fm.chords[j])
        chord_a = None if j == 0 else tuple(cm.finger_node(i) for i in fm.chords[j - 1])
        hinges[joint] = HingeSpring(n, p, chord_a, chord_b, *setup.springs[j])
    straps = {}
    for joint in setup.strap_joints:
        j = JOINTS.index(joint)
        jn = cm.finger_node(fm.nodes[f"joint_{joint}"])
        chords = [tuple(cm.finger_node(i) for i in fm.chords[k]) for k in (j - 1, j) if k >= 0]
        straps[joint] = strap(n, p, _strap_anchor(cm, jn), chords, setup.strap_k, setup.strap_hold_along)
    slide = DofSpring(n, [2 * clamp[0]], setup.slide_k)
    extras = [*hinges.values(), *straps.values(), slide]
    eps = contact_penalty(setup.mat, c)
    hand = None
    if setup.hand_support:
        # the back of the hand: the dorsal line proximal of the MCP joint, under the units that lie over it
        mcp = p[:, cm.finger_node(fm.nodes["joint_MCP"])]
        skin = np.unique(cm.um.facets["finger_dorsal"])
        y0 = float(p[1, skin[np.argmin(p[0, skin])]])
        nodes, area = tributary_areas(p, cm.um.facets["outer_bottom"])
        over = p[0, nodes] < mcp[0] - 1e-9
        hand = SupportPlane(n, nodes[over], area[over], y0, eps, contact_band(c, 2))
        extras.append(hand)
    if setup.gravity is not None:
        extras.append(DeadLoad(setup.gravity, ramp=gravity_ramp))
    pairs = self_contact_pairs(cm.um, c)
    skin, bottom = cm.um.facets["finger_dorsal"], cm.um.facets["outer_bottom"]
    fac = float(c["finger_penalty"]) / eps  # own penalty (see the module docstring)
    # the skin under a gap between two blocks touches both blocks' corners (sum_extensions)
    finger_pairs = [
        ContactPair(p, a, b, c["search_mm"], c["extend"], contact_band(c, 2), penalty_factor=fac, sum_extensions=True)
        for a, b in ((skin, bottom), (bottom, skin))
    ]
    model = Model(
        setup.solid,
        pressures=group_pressures(cm.act, pressures_kpa) if pressures_kpa else {},
        contacts=pairs + finger_pairs,
        penalty=eps,
        fixed=np.unique(np.concatenate([np.ravel(f) for f in fixed])),
        ties=ties,
        extras=extras,
        updaters=[segment_rotation_update(cm)] if setup.rigid_update else [],
    )
    return model, {"hinges": hinges, "straps": straps, "slide": slide, "finger_pairs": finger_pairs, "hand": hand}


@dataclass
class CoupledResult:
    """One check: gravity phase then pressure phase.

    Angles deg (flexion positive), forces N/mm and moments N mm/mm (per mm
    of actuator width); ``status`` / ``load_factor`` of the phase that ended
    (``phase`` = "gravity" or "pressure"), the measurements at the last
    converged state.
    """

    status: int
    reason: str
    phase: str
    load_factor: float
    joint_angles_deg: np.ndarray
    droop_angles_deg: np.ndarray
    spring_moments: np.ndarray
    gravity_moments: np.ndarray
    strap_forces: dict
    max_strap_force: dict
    max_spring_moments: np.ndarray
    slide_force: float
    max_penetration_mm: float
    tip_angle_deg: float
    backbone_mm: np.ndarray
    newton_iterations: int
    steps: int
    wall_time_s: float
    ndofs: int
    overlap_depth_mm: float = 0.0  # deepest actuator node inside foreign material over both phases
    min_pocket_area_mm2: float = np.nan  # smallest pocket of the actuator over both phases
    # displacement (mm) of the actuator's hand end along the hand, distal positive: the rail travel the pose needs
    slide_mm: float = 0.0
    unit_bends_deg: np.ndarray | None = None  # (units,) each actuator unit's bend, hand end first, deg
    history: list = field(default_factory=list)
    u: np.ndarray | None = field(default=None, repr=False)
    state: np.ndarray | None = field(default=None, repr=False)  # u and the enhanced parameters
    contact: dict = field(default_factory=dict)  # the contact settings the state is an equilibrium of


def _gravity_moments(setup: CoupledSetup, x: np.ndarray, lam_g: float) -> np.ndarray:
    """Flexion moment (N mm/mm) of the finger's weight distal to each joint, about the joint."""
    if setup.gravity is None:
        return np.zeros(3)
    cm, fm = setup.cm, setup.cm.finger
    fy = lam_g * setup.gravity[1::2]
    out = np.zeros(3)
    for j, joint in enumerate(JOINTS):
        cells = np.flatnonzero(cm.body >= j)
        nodes = np.unique(cm.mesh.t[:, cells])
        nodes = nodes[nodes >= cm.n_act]
        xj = x[:, cm.finger_node(fm.nodes[f"joint_{joint}"])]
        # a downward force F_y = -w at lever dx flexes (clockwise): moment -F_y dx
        out[j] = float(np.sum(-fy[nodes] * (x[0, nodes] - xj[0])))
    return out


def _measure(setup, model, parts, p_ref, lam_g):
    cm = setup.cm
    # the finger's segments overlap at their pinned joints by design: only the actuator's nodes and cells count
    finger = (np.arange(cm.mesh.p.shape[1]) >= cm.n_act, cm.body >= 0)

    def measure(u, lam, info):
        x = model.positions(u, p_ref)
        checks = overlap_measures(cm.um, x, info, ignore=finger)
        th = np.array([parts["hinges"][j].angle(x) for j in JOINTS])
        return {
            "joint_angles_deg": np.degrees(th),
            "spring_moments": np.array([setup.springs[j][0](th[j]) for j in range(3)]),
            "strap_forces": {k: s.force(x) for k, s in parts["straps"].items()},
            "gravity_moments": _gravity_moments(setup, x, lam if lam_g is None else lam_g),
            "penetration_mm": checks["max_penetration_mm"],
            "overlap_depth_mm": checks["overlap_depth_mm"],
            "min_pocket_area_mm2": checks["min_pocket_area_mm2"],
        }

    return measure


def solve_coupled(
    setup: CoupledSetup,
    pressures_kpa: Mapping[str, tuple[float, float]],
    *,
    solver: Mapping | None = None,
    u_gravity: np.ndarray | None = None,
) -> CoupledResult:
    """Gravity first (ramped alone), then the group pressures ramped from zero with gravity held.

    ``u_gravity``: a converged gravity state (``CoupledResult.state``) to start the pressure phase from
    (skips the gravity phase; the droop angles are then measured on it).  With every pressure zero the pressure
    phase is that state itself.
    Never raises for a failed path: the last converged state is measured.
    """
    t0 = time.perf_counter()
    cm = setup.cm
    p_ref = cm.mesh.p
    opts = dict(DEFAULT_SOLVER)
    opts.update(dict(solver or {}))
    iters = steps = 0
    history = []
    status, reason, phase, lam = 0, "", "gravity", 1.0
    if u_gravity is None:
        mg, parts = coupled_model(setup, {}, gravity_ramp=True)
        rg = solve_path(mg, p_ref, opts, _measure(setup, mg, parts, p_ref, None))
        iters, steps = rg.iterations, rg.steps
        history += [dict(h, phase="gravity") for h in rg.history]
        u = rg.state
        status, reason, lam = rg.status, rg.reason, rg.lam
    else:
        u = np.asarray(u_gravity, float)
    model, parts = coupled_model(setup, pressures_kpa, gravity_ramp=False)
    x = model.positions(u, p_ref)
    droop = np.degrees([parts["hinges"][j].angle(x) for j in JOINTS])
    if status == 0:
        phase = "pressure"
        # at zero pressure the converged gravity state is the pressure phase's equilibrium already (the same model
        # at full weight): its path would only converge it again at every load step (49 steps in the gravity solve)
        if any(float(p) != 0.0 for pair in pressures_kpa.values() for p in pair):
            rp = solve_path(model, p_ref, opts, _measure(setup, model, parts, p_ref, 1.0), u0=u)
            iters, steps = iters + rp.iterations, steps + rp.steps
            history += [dict(h, phase="pressure") for h in rp.history]
            u, status, reason, lam = rp.state, rp.status, rp.reason, rp.lam
    x = model.positions(u, p_ref)
    th = np.array([parts["hinges"][j].angle(x) for j in JOINTS])
    lam_g = 1.0 if phase == "pressure" else lam
    strap = {k: s.force(x) for k, s in parts["straps"].items()}
    hist_str = [h["strap_forces"] for h in history]
    max_strap = {k: max([abs(hs[k]) for hs in hist_str] + [abs(strap[k])]) for k in strap}
    sm = np.array([setup.springs[j][0](th[j]) for j in range(3)])
    max_sm = np.max(np.abs(np.array([h["spring_moments"] for h in history] + [sm])), axis=0)
    pen = max([h["penetration_mm"] for h in history], default=0.0)
    overlap = max([h["overlap_depth_mm"] for h in history], default=0.0)
    pocket = min([h["min_pocket_area_mm2"] for h in history], default=np.nan)
    curve = backbone_curve(x, p_ref, cm.um.nodes["backbone"])
    return CoupledResult(
        status=status,
        reason=reason,
        phase=phase,
        load_factor=lam,
        joint_angles_deg=np.degrees(th),
        droop_angles_deg=droop,
        spring_moments=sm,
        gravity_moments=_gravity_moments(setup, x, lam_g),
        strap_forces=strap,
        max_strap_force=max_strap,
        max_spring_moments=max_sm,
        slide_force=float(parts["slide"].force(u)[0]),
        slide_mm=float(u[parts["slide"].dofs[0]]),
        max_penetration_mm=pen,
        overlap_depth_mm=overlap,
        min_pocket_area_mm2=pocket,
        tip_angle_deg=tip_angle_deg(curve),
        backbone_mm=curve,
        unit_bends_deg=unit_bends_deg(
            curve,
            backbone_curve(p_ref, p_ref, cm.um.nodes["backbone"]),
            len(cm.act.chamber_group),
            cm.act.geometry["depth"],
            cm.act.geometry["gap"],
            start_mm=float(cm.offset[0]),
        ),
        newton_iterations=iters,
        steps=steps,
        wall_time_s=time.perf_counter() - t0,
        ndofs=model.n,
        history=history,
        u=u[: model.n].copy(),
        state=u,
        contact=dict(setup.contact or {}),
    )


__all__ += ["FLESH", "BONE"]
