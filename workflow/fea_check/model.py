"""The planar finger + whole-actuator FE model of a patient, from the plan's finger.

Builds the inputs of :mod:`workflow.fem`'s coupled model from the same objects
the plan uses (:func:`workflow.cascade.patient_finger`, the plan's
``units_per_group``), so the check and the plan differ only in mechanics:

* **Finger section**: the authors' section points (outline and bone, dorsal
  and palmar) mapped onto the patient's segments and depth-scaled exactly as
  :func:`workflow.cascade.finger.build_finger` does for the masses; the bone's centre
  line runs through the joint centres (``Finger.joints_ref``).  The distal
  phalanx closes to zero depth at the tip: its body ends where its depth drops
  to ``tip_min_depth_ratio`` of D3DP (the last ~7 % of the pad, a sliver
  that would only make distorted elements).
* **Layout**: the actuator's chambers are centred on the plan's units (unit
  ``i`` at ``base_x + (i + 1/2) L_R``), its bottom outer face on the flat
  dorsal line.
* **Per mm of actuator width** (plane strain): spring moments, weights and
  strap stiffness of the whole finger/actuator are divided by the actuator
  width W (20 mm), so pressures act on the 2D section as in the unit model
  (whose per-mm results are multiplied by W).  240 kN/m -> 12 N/mm per mm.
* **Weights**: each finger segment's weight is the plan's segment mass times
  g, spread over its cells in proportion to the paper's densities (flesh of
  that segment, bone); the actuator's is the plan's unit mass times the number
  of units, spread over silicone and paper.  So the droop and the moments of
  gravity are the plan's, not those of the 2D section's area.
* **Materials**: flesh E = 24 kPa, nu = 0.4 and bone E = 20 GPa, nu = 0.3 as
  compressible neo-Hooke solids (the paper's linear-elastic flesh would not
  stay objective under the joints' large rotations).

Units: mm, MPa, N inside the FE model; N m, N, deg, kPa at the interfaces.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from workflow import fem
from workflow.cascade.finger import Finger, _read_section_profile
from workflow.cascade.model import actuator_start_mm, unit_section
from workflow.common.constants import GROUPS
from workflow.fem._mesh import build_actuator_mesh
from workflow.fem.coupled import CoupledSetup, cell_areas, couple_meshes, nodal_body_force
from workflow.fem.finger2d import BONE, FLESH, SegmentProfile, build_finger_mesh

__all__ = ["DEFAULT_FEA_CHECK", "lame", "finger_profiles", "spring_callables", "PatientFEA", "build_patient_fea"]

#: Defaults of the config block ``fea_check`` (see config/config.yaml).
DEFAULT_FEA_CHECK: dict[str, Any] = {
    "h_actuator_mm": 1.0,
    "h_finger_mm": 1.5,
    "flesh": {"e_mpa": 0.024, "nu": 0.4},
    "bone": {"e_mpa": 20000.0, "nu": 0.3},
    "finger_penalty_factor": 100.0,
    "slide_stiffness_n_per_mm": 1.0e-6,
    "hand_support": False,
    "strap_hold_along": 1.0,
    "tip_min_depth_ratio": 0.35,
    "penetration_bound_mm": 0.1,
    # the retry that passes the blocks' first corner contact (measured on the mean finger's gravity phase); its small
    # steps keep the 2D predictor: the same gravity states in 36-50 % fewer Newton iterations than without it
    "restarts": ({"contact": {"smoothing_mm": 0.1}, "solver": {"max_step": 0.02}},),
    # gravity starts at this attempt (0: as configured; 1: the first restart): its first attempt stalled on every mesh
    "gravity_first_attempt": 1,
}


def lame(e_mpa: float, nu: float) -> tuple[float, float]:
    """(mu, lambda) in MPa from Young's modulus and Poisson's ratio."""
    return e_mpa / (2 * (1 + nu)), e_mpa * nu / ((1 + nu) * (1 - 2 * nu))


def finger_profiles(
    finger: Finger,
    section_points: str,
    reference_dims_mm: Mapping[str, float],
    tip_min_depth_ratio: float = 0.35,
    n_stations: int = 41,
) -> list[SegmentProfile]:
    """The three segments' sections (mm, finger frame: x from the MCP centre, y dorsal)."""
    prof = _read_section_profile(section_points)
    dims = finger.dimensions_mm
    L = np.array([s.length_m for s in finger.segments]) * 1e3
    xj = np.concatenate([[0.0], np.cumsum(L)])
    s_file = np.array([prof["s_joint"]["MCP"], prof["s_joint"]["PIP"], prof["s_joint"]["DIP"], prof["s_tip"]])
    seg_depth = np.array([dims["D3PP"], dims["D3MP"], dims["D3DP"]])
    ref_depth = np.array([reference_dims_mm["D3PP"], reference_dims_mm["D3MP"], reference_dims_mm["D3DP"]])
    z_ref = float(np.interp(s_file[0], *prof["outline"]["dorsal"].T))  # the flat dorsal line of the file
    y_dorsal = finger.dorsal_y_m * 1e3
    joints = finger.joints_ref * 1e3
    centre = prof["outline"]["centre"]
    out = []
    for k, name in enumerate(("PP", "MP", "DP")):
        t = np.linspace(0.0, 1.0, n_stations)
        s_f = s_file[k] + t * (s_file[k + 1] - s_file[k])
        x = xj[k] + t * L[k]
        sc = seg_depth[k] / ref_depth[k]

        def y(kind, side):
            return y_dorsal - (z_ref - np.interp(s_f, *prof[kind][side].T)) * sc

        if k < 2:
            yc = np.interp(x, [xj[k], xj[k + 1]], [joints[k, 1], joints[k + 1, 1]])
        else:
            yc = joints[2, 1] + (np.interp(s_f, *centre.T) - np.interp(s_file[2], *centre.T)) * sc
        lines = np.array([y("outline", "palmar"), y("bone", "palmar"), yc, y("bone", "dorsal"), y("outline", "dorsal")])
        bone_end = x[-1]
        if k == 2:
            depth = lines[4] - lines[0]
            ok = depth >= tip_min_depth_ratio * seg_depth[k]
            last = int(np.flatnonzero(ok)[-1])
            x, lines = x[: last + 1], lines[:, : last + 1]
            s_bone = float(prof["bone"]["dorsal"][-1, 0])
            bone_end = min(xj[2] + (s_bone - s_file[2]) / (s_file[3] - s_file[2]) * L[2], x[-1])
        out.append(SegmentProfile(name=name, x=x, lines=lines, bone_end_x=float(bone_end)))
    return out


def spring_callables(spring, width_mm: float):
    """(moment(theta rad) -> N mm per mm, stiffness -> N mm per mm per rad) of a ``JointSpring``."""
    f = 1e3 / width_mm

    def moment(th):
        return float(spring.moment_nm(np.degrees(th))) * f

    def stiffness(th):
        return float(spring.stiffness_nm_per_deg(np.degrees(th))) * np.degrees(1.0) * f

    return moment, stiffness


@dataclass
class PatientFEA:
    """A patient's coupled FE setup and what is needed to read its results."""

    setup: CoupledSetup
    finger: Finger
    units_per_group: dict
    width_mm: float
    base_x_mm: float
    notes: str
    #: retries of a stalled solve, each over the previous (config ``fea_check.restarts``): the blocks' first corner
    #: contact stalls the whole actuator as it stalls a unit ray; a wider band with small steps passes it
    restarts: tuple = ()
    #: the attempt gravity starts at (config ``fea_check.gravity_first_attempt``; 0 = as configured)
    gravity_first_attempt: int = DEFAULT_FEA_CHECK["gravity_first_attempt"]


def build_patient_fea(
    finger: Finger,
    units_per_group: Mapping[str, int],
    *,
    actuator_cfg: Mapping,
    cascade_cfg: Mapping,
    reference_dims_mm: Mapping[str, float],
    fea_cfg: Mapping | None = None,
) -> PatientFEA:
    """The coupled FE model of ``finger`` under an actuator of ``units_per_group`` chambers.

    ``actuator_cfg``: the config's ``actuator`` section (geometry, material,
    contact); ``cascade_cfg``: ``cascade`` (densities, strap stiffness,
    gravity, section points, unit geometry); ``reference_dims_mm``: the Table 2
    means the section points belong to; ``fea_cfg``: ``fea_check``.
    """
    fc = dict(DEFAULT_FEA_CHECK)
    fc.update(dict(fea_cfg or {}))
    geom = dict(fem.DEFAULT_GEOMETRY)
    geom.update(dict(actuator_cfg.get("geometry", {})))
    W = float(geom["width"])
    counts = {g: int(units_per_group[g]) for g in GROUPS}
    act = build_actuator_mesh(geom, counts, h=float(fc["h_actuator_mm"]), dim=2, **fem.layer_options(actuator_cfg))
    ref_dims = {k: float(v) for k, v in reference_dims_mm.items()}
    profiles = finger_profiles(finger, cascade_cfg["section_points"], ref_dims, fc["tip_min_depth_ratio"])
    fm = build_finger_mesh(profiles, h=float(fc["h_finger_mm"]))
    lr = geom["depth"] + geom["gap"]
    base_x = actuator_start_mm(counts["CMC"], lr, cascade_cfg.get("layout_shift_mm", 0.0))
    yt = geom["paper_width"] / 2 + geom["bot_layer"] + geom["height"]
    contact = dict(fem.DEFAULT_CONTACT)
    contact.update(dict(actuator_cfg.get("contact", {})))
    contact.pop("enabled", None)
    restarts = tuple(fc["restarts"])
    # the actuator rests where the finger contact's force starts: the penalty law pushes from the far edge of its
    # band, so an actuator laid on the skin would be pushed off it at rest by eps d / 2 per contact pass (43 kPa
    # with the restarts' 0.1 mm band, 4.3 kPa with 0.01 mm), a preload that tensed the straps; lifted by the
    # widest band of every attempt, no attempt starts with a contact force
    rest_gap = max(fem.contact_band(c, 2) for c, _ in fem.cumulative_attempts(contact, {}, restarts))
    cm = couple_meshes(act, (base_x + geom["gap"] / 2, finger.dorsal_y_m * 1e3 + yt + rest_gap), fm)
    # materials
    mat = fem.material_constants(actuator_cfg.get("material"))
    mu_f, la_f = lame(fc["flesh"]["e_mpa"], fc["flesh"]["nu"])
    mat["neo_hooke"] = {FLESH: (mu_f, la_f), BONE: lame(fc["bone"]["e_mpa"], fc["bone"]["nu"])}
    # weights per mm of width, spread by density (see the module docstring)
    g = float(cascade_cfg["gravity_m_s2"])
    d = cascade_cfg["densities"]
    area = cell_areas(cm.mesh)
    rho = np.zeros(area.size)
    target = {}
    flesh = (d["flesh_proximal"], d["flesh_middle"], d["flesh_distal"])
    for k in range(3):
        sel = cm.body == k
        rho[sel] = np.where(cm.material[sel] == BONE, d["bone"], flesh[k])
        target[k] = finger.segments[k].mass_kg * g / W
    sel = cm.body == -1
    rho[sel] = np.where(cm.material[sel] == 1, d["paper"], d["silicone"])
    sec = unit_section(cascade_cfg["unit_geometry_mm"])
    unit_mass = (d["silicone"] * sec["silicone_mm3"] + d["paper"] * sec["paper_mm3"]) * 1e-9
    target[-1] = unit_mass * sum(counts.values()) * g / W
    b = np.zeros(area.size)
    for body, w in target.items():
        sel = cm.body == body
        b[sel] = -rho[sel] * w / float(np.sum(rho[sel] * area[sel]))  # N/mm^3, downward
    gravity = nodal_body_force(cm.mesh, b)  # external nodal forces (N/mm)
    # as the silicone's: eps = factor mu / (1 mm), the same on every finger mesh
    contact["finger_penalty"] = float(fc["finger_penalty_factor"]) * mu_f / 1.0
    setup = CoupledSetup(
        cm=cm,
        mat=mat,
        springs=[spring_callables(s, W) for s in finger.springs],
        strap_k=float(cascade_cfg["strap_stiffness_n_per_m"]) * 1e-3 / W,
        gravity=gravity if g > 0 else None,
        contact=contact,
        slide_k=float(fc["slide_stiffness_n_per_mm"]),
        hand_support=bool(fc["hand_support"]),
        strap_hold_along=float(fc["strap_hold_along"]),
        formulation=actuator_cfg.get("formulation", fem.DEFAULT_FORMULATION),
    )
    notes = (
        f"plane strain per mm of actuator width W = {W:g} mm; finger weights {np.round([target[k] * W for k in range(3)], 5)} N, "
        f"actuator {target[-1] * W:.4g} N; strap {setup.strap_k:g} N/mm per mm; flesh mu {mu_f:.4g} MPa; "
        f"{cm.mesh.p.shape[1] * 2} dofs; actuator {rest_gap:g} mm above the skin (the contact band)"
    )
    return PatientFEA(
        setup=setup,
        finger=finger,
        units_per_group=counts,
        width_mm=W,
        base_x_mm=base_x,
        notes=notes,
        restarts=restarts,
        gravity_first_attempt=int(fc["gravity_first_attempt"]),
    )
