"""The whole cascaded actuator: group pressures, stand-alone solve, backbone curve.

The actuator is the unit model's chain with ``sum(units_per_group)`` chambers
(``build_actuator_mesh``): same materials (``material_constants``), follower
pressure per group and side (``cavity_{top,bottom}_{group}``) and penalty
self-contact across every gap (``contact_pairs_from_mesh``).  Stand-alone
(Fig. 22): the hand end (x = 0) is clamped, no finger, no gravity; 3D adds the
symmetry condition u_z = 0 on z = 0 of the half model.

Measurements: the *backbone curve* is the paper layer's mid-line, the mean
position of its nodes per grid column along the actuator (mm); the *tip
angle* is the rotation of its last element column, positive clockwise in the
x-y plane (towards the bottom side = the palm, CONTRACT signs), in degrees.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from workflow.fem._mesh import UnitMesh
from workflow.fem._overlap import overlap_measures
from workflow.fem._solve import DEFAULT_SOLVER, Model, solve_path
from workflow.fem._unit import (
    DEFAULT_CONTACT,
    DEFAULT_FORMULATION,
    contact_penalty,
    material_constants,
    self_contact_pairs,
    solid_assembler,
)
from workflow.fem.finger2d import DeadLoad

__all__ = [
    "group_pressures",
    "tip_load",
    "actuator_model",
    "backbone_curve",
    "tip_angle_deg",
    "unit_bends_deg",
    "jam_angle_deg",
    "StandaloneResult",
    "solve_standalone",
]


def group_pressures(um: UnitMesh, pressures_kpa: Mapping[str, tuple[float, float]], node_offset: int = 0) -> dict:
    """``Model`` pressures {name: (facets, p in MPa)} from {group: (P_T, P_B) in kPa}.

    Groups of the mesh missing from ``pressures_kpa`` get zero pressure.
    ``node_offset`` shifts the facets' node numbers (actuator inside a larger mesh).
    """
    out = {}
    for g in dict.fromkeys(um.chamber_group):
        pt, pb = pressures_kpa.get(g, (0.0, 0.0))
        out[f"{g}_top"] = (um.facets[f"cavity_top_{g}"] + node_offset, 1e-3 * float(pt))
        out[f"{g}_bottom"] = (um.facets[f"cavity_bottom_{g}"] + node_offset, 1e-3 * float(pb))
    return out


def tip_load(um: UnitMesh, force_n: float) -> DeadLoad:
    """A dead transverse force at the free end, shared equally by the nodes of the end face.

    ``force_n`` (N) is the whole actuator's (20 mm wide): the model carries its share, per mm of width in 2D and
    half of it on the 3D half model. Positive along +y, against the bending of the top chambers (they bend the
    actuator towards -y), as a finger's resisting load does. It ramps with the pressures.
    """
    p = um.mesh.p
    end = np.flatnonzero(np.isclose(p[0], p[0].max()))  # on the paper layer's end alone it distorts the layer
    share = float(force_n) / um.geometry["width"] if um.dim == 2 else 0.5 * float(force_n)
    f = np.zeros(p.size)
    f[um.dim * end + 1] = share / end.size
    return DeadLoad(f, ramp=True)


def actuator_model(
    um: UnitMesh,
    pressures_kpa: Mapping[str, tuple[float, float]],
    *,
    material: Mapping | None = None,
    contact_options: Mapping | None = None,
    contact: bool = True,
    formulation: str = DEFAULT_FORMULATION,
    tip_force_n: float = 0.0,
) -> Model:
    """Stand-alone whole actuator: clamped hand end, group pressures (and a tip force, :func:`tip_load`) at load
    factor 1."""
    mat = material_constants(material)
    solid = solid_assembler(um.mesh, um.material, mat, formulation)
    dim = um.dim
    fixed = [(dim * um.nodes["clamp"][:, None] + np.arange(dim)).ravel()]
    if dim == 3:
        fixed.append(dim * um.nodes["symmetry"] + 2)
    copts = {**DEFAULT_CONTACT, **dict(contact_options or {})}
    pairs = self_contact_pairs(um, copts) if contact else []
    return Model(
        solid,
        pressures=group_pressures(um, pressures_kpa),
        contacts=pairs,
        penalty=contact_penalty(mat, copts),
        fixed=np.unique(np.concatenate(fixed)),
        extras=[tip_load(um, tip_force_n)] if tip_force_n else [],
    )


def backbone_curve(x: np.ndarray, p_ref: np.ndarray, backbone_nodes: np.ndarray) -> np.ndarray:
    """Mid-line of the paper layer (ncol, dim): mean current position per reference x column, mm."""
    xr = np.round(p_ref[0, backbone_nodes], 6)
    cols, inv = np.unique(xr, return_inverse=True)
    cnt = np.bincount(inv)
    return np.stack([np.bincount(inv, weights=x[d, backbone_nodes]) / cnt for d in range(x.shape[0])], axis=1)


def tip_angle_deg(curve: np.ndarray) -> float:
    """Rotation of the backbone's last segment from the +x axis, clockwise positive, deg."""
    d = curve[-1] - curve[-2]
    return float(-np.degrees(np.arctan2(d[1], d[0])))


def unit_bends_deg(
    curve: np.ndarray, curve_ref: np.ndarray, n_units: int, depth_mm: float, gap_mm: float, start_mm: float = 0.0
) -> np.ndarray:
    """Bend of each of the ``n_units`` units along a chain of chambers (n,), deg, positive as :func:`tip_angle_deg`.

    Unit k (chamber k, from x = ``start_mm`` + k (depth + gap) at rest, and half of each gap beside it: the paper's
    L_R) turns the backbone by the change of its inclination between the gap centres on either side, the chain's
    ends for the end units; the inclination at a point is interpolated between the backbone segments' own. The
    bends add up to the turn from the first segment to the last. ``curve``/``curve_ref``: :func:`backbone_curve`
    deformed / at rest, mm.
    """
    d = np.diff(curve[:, :2], axis=0)
    incl = -np.degrees(np.unwrap(np.arctan2(d[:, 1], d[:, 0])))
    xm = 0.5 * (curve_ref[1:, 0] + curve_ref[:-1, 0])
    pitch = float(depth_mm) + float(gap_mm)
    inner = float(start_mm) + pitch * np.arange(1, int(n_units)) - 0.5 * float(gap_mm)
    return np.diff(np.interp(np.concatenate([[xm[0]], inner, [xm[-1]]]), xm, incl))


def jam_angle_deg(geometry: Mapping) -> float:
    """Bend per unit at which neighbouring blocks on the concave side meet, if they were rigid, deg.

    Two blocks turning about the paper layer close the gap between their outer corners by the relative rotation
    times the corners' distance from the paper's mid-plane, paper/2 + base layer + block height: they meet at
    gap / that distance (Table 6: 1 / 17.1 rad = 3.35 deg). Beyond it a unit bends only as far as the unpressurised
    blocks squeeze, which the unit model of three chambers hides: two of its three units are end units, whose
    blocks can splay outwards.
    """
    g = dict(geometry)
    return float(np.degrees(g["gap"] / (0.5 * g["paper_width"] + g["bot_layer"] + g["height"])))


@dataclass
class StandaloneResult:
    """Stand-alone actuator at the given group pressures (kPa)."""

    dim: int
    status: int
    reason: str
    load_factor: float
    tip_angle_deg: float
    backbone_mm: np.ndarray  # (ncol, dim) deformed mid-line
    backbone_ref_mm: np.ndarray
    newton_iterations: int
    steps: int
    wall_time_s: float
    ndofs: int
    max_penetration_mm: float
    overlap_depth_mm: float = 0.0  # deepest node inside foreign material over the path
    min_pocket: float = np.nan  # smallest pocket over the path: area mm^2 (2D) / volume mm^3 (3D)
    displacement: np.ndarray | None = field(default=None, repr=False)
    tip_history: np.ndarray | None = field(default=None, repr=False)  # (steps, 2): load factor, tip angle (deg)
    unit_bends_deg: np.ndarray | None = None  # (units,) each unit's bend at the last converged state, deg


def solve_standalone(
    um: UnitMesh,
    pressures_kpa: Mapping[str, tuple[float, float]],
    *,
    material: Mapping | None = None,
    contact_options: Mapping | None = None,
    contact: bool = True,
    solver: Mapping | None = None,
    keep_displacement: bool = False,
    formulation: str = DEFAULT_FORMULATION,
    tip_force_n: float = 0.0,
) -> StandaloneResult:
    """Ramp the group pressures (and ``tip_force_n``, N, :func:`tip_load`) from zero on the clamped actuator; never
    raises for a failed path."""
    t0 = time.perf_counter()
    model = actuator_model(
        um,
        pressures_kpa,
        material=material,
        contact_options=contact_options,
        contact=contact,
        formulation=formulation,
        tip_force_n=tip_force_n,
    )
    opts = dict(DEFAULT_SOLVER)
    opts.update(dict(solver or {}))
    p_ref = um.mesh.p
    bb = um.nodes["backbone"]

    def measure(u, lam, info):
        x = model.positions(u, p_ref)
        return {**overlap_measures(um, x, info), "tip_angle_deg": tip_angle_deg(backbone_curve(x, p_ref, bb))}

    res = solve_path(model, p_ref, opts, measure)
    x = model.positions(res.u, p_ref)
    curve = backbone_curve(x, p_ref, bb)
    pocket = "min_pocket_area_mm2" if um.dim == 2 else "min_pocket_volume_mm3"
    return StandaloneResult(
        dim=um.dim,
        status=res.status,
        reason=res.reason,
        load_factor=res.lam,
        tip_angle_deg=tip_angle_deg(curve),
        backbone_mm=curve,
        backbone_ref_mm=backbone_curve(p_ref, p_ref, bb),
        newton_iterations=res.iterations,
        steps=res.steps,
        wall_time_s=time.perf_counter() - t0,
        ndofs=model.n,
        max_penetration_mm=max([h["max_penetration_mm"] for h in res.history], default=0.0),
        overlap_depth_mm=max([h["overlap_depth_mm"] for h in res.history], default=0.0),
        min_pocket=min([h[pocket] for h in res.history], default=np.nan),
        displacement=res.u if keep_displacement else None,
        tip_history=np.array([[0.0, 0.0]] + [[h["lam"], h["tip_angle_deg"]] for h in res.history]),
        unit_bends_deg=unit_bends_deg(
            curve, backbone_curve(p_ref, p_ref, bb), len(um.chamber_group), um.geometry["depth"], um.geometry["gap"]
        ),
    )
