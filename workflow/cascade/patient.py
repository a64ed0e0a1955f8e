"""A patient's finger and cascade from the config: the finger's dimensions,
masses and joint springs (from the joint loads), the units per group, and the
planning options (the pressure limit, the active safety limits).
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from workflow.actuator.jam import JamModel
from workflow.actuator.pressure_limit import PressureLimit, smallest
from workflow.cascade import finger as F
from workflow.cascade.finger import Finger
from workflow.cascade.model import CascadeModel, build_cascade
from workflow.common.constants import JOINTS

__all__ = [
    "chain_note",
    "jam_model",
    "linear_springs",
    "patient_finger",
    "patient_cascade",
    "plan_limit",
    "plan_options",
]


def patient_finger(
    patient: Mapping[str, Any], loads, moments, ccd, *, cascade_cfg: Mapping[str, Any], anthropometry: Mapping[str, Any]
) -> tuple[Finger, str]:
    """The patient's finger model as the plan builds it, and a note on its springs' source.

    ``loads``, ``moments``, ``ccd``: the datasets of ``joint_loads.nc``,
    ``moments.nc`` and ``ccd.nc``; ``cascade_cfg`` the config's ``cascade``
    section (densities, gravity, section points).  Shared by the planning
    and the FEA check, so both see the same finger.
    """

    c = cascade_cfg
    finger_name = str(patient.get("finger", "F3"))
    coded = {d: float(v) for d, v in zip(loads["dimension"].values, loads["x"].values)}
    measures = anthropometry["measures"]
    dims = F.patient_dimensions_mm(
        measures, coded, float(anthropometry.get("coded_unit_sd", 1.0)), patient.get("measurements_mm")
    )
    # Shape of the passive curves: the design centre's, where a backend sampled more than the targets.
    centre = ccd["run"].values[[str(m) == "Original" for m in ccd["marker"].values]]
    curve = None
    if centre.size and finger_name in moments["finger"].values:
        mm = moments["moment_nm"].sel(run=centre[0], finger=finger_name)
        mm = mm.sel(activation=mm["activation"].values[np.argmin(mm["activation"].values)])
        curve = (moments["angle_deg"].values, mm.transpose("joint", "angle_deg").sel(joint=list(JOINTS)).values)
    springs, spring_note = F.springs_from_loads(
        loads["target_angle_deg"].sel(joint=list(JOINTS)).values,
        loads["passive_moment_nm"].sel(joint=list(JOINTS)).values,
        *(curve if curve is not None else (None, None)),
    )
    if c.get("joint_springs", "curve") == "linear":
        # the authors' 2D model (its published generator): k = M(target) / target per joint, straight through zero
        # (MCP 90, PIP 100, DIP 80 deg: each joint's largest target over the exercises)
        springs = list(linear_springs(loads))
        spring_note += "; linear springs through the passive moment at each target angle (cascade.joint_springs)"
    d = dict(c["densities"])
    if patient.get("model", "human") == "dummy":
        # The paper's test finger (Table 10): solid PLA of the same shape; its
        # springs stand in for the passive joint moments, so those stay.
        d.update({k: d.get("pla", 1240.0) for k in ("flesh_proximal", "flesh_middle", "flesh_distal", "bone")})
        spring_note += f"; dummy finger: PLA {d['flesh_proximal']:g} kg/m^3 throughout"
    fing = F.build_finger(
        dims,
        springs,
        {k: d[k] for k in ("flesh_proximal", "flesh_middle", "flesh_distal", "bone")},
        gravity_m_s2=c["gravity_m_s2"],
        section_points=c.get("section_points"),
        reference_dims_mm={k: float(v["mean"]) for k, v in measures.items()},
    )
    return fing, spring_note


def linear_springs(loads) -> tuple[F.JointSpring, ...]:
    """Per joint (MCP, PIP, DIP) a straight spring k = M / theta through the passive moment M (N m) at the joint's
    largest target angle theta (deg) over the exercises of ``loads`` (a ``joint_loads.nc`` dataset)."""
    th = np.atleast_2d(loads["target_angle_deg"].sel(joint=list(JOINTS)).values.T)  # (joint, exercise)
    m = np.atleast_2d(loads["passive_moment_nm"].sel(joint=list(JOINTS)).values.T)
    out = []
    for j, joint in enumerate(JOINTS):
        i = int(np.nanargmax(th[j]))
        if not th[j, i] > 0:
            raise ValueError(f"linear joint springs: no flexed target for {joint}")
        out.append(F.JointSpring.linear(float(m[j, i]) / float(th[j, i])))
    return tuple(out)


def patient_cascade(
    finger: Finger, unit: Any, cascade_cfg: Mapping[str, Any], units_per_group: Mapping[str, int] | None = None
) -> CascadeModel:
    """The actuator laid on ``finger`` as the config's ``cascade`` section says (densities, unit counts, straps).

    ``units_per_group`` (e.g. a plan's) overrides the config's counts.  Shared
    by the planning and the FEA check's correction step.
    """
    c, d = cascade_cfg, cascade_cfg["densities"]
    return build_cascade(
        finger,
        unit,
        actuator_dims_mm=c["unit_geometry_mm"],
        silicone_density=d["silicone"],
        paper_density=d["paper"],
        cmc_length_fraction=c["cmc_length_fraction"],
        tip_units=c["tip_units"],
        units_per_group=units_per_group or c.get("units_per_group") or None,
        layout_shift_mm=float(c.get("layout_shift_mm", 0.0)),
        strap_stiffness_n_per_m=c["strap_stiffness_n_per_m"],
        jam=jam_model(c),
    )


def chain_note(model: CascadeModel, base: str = "the paper's chain (no calibration)") -> str:
    """What the chain is, for a dataset's attrs and the log: ``base`` and, with one, the jam model's settings."""
    j = model.jam
    if j is None:
        return base
    return (
        f"{base}; units inside the actuator jam at {j.jam_deg:.2f} deg, slope {j.slope:g} past it, free-end decay "
        f"{j.decay_units:g} units (cascade.jam)"
    )


def jam_model(cascade_cfg: Mapping[str, Any]) -> JamModel | None:
    """The config's ``cascade.jam`` as a :class:`JamModel` on the unit's Table 6 geometry, or None where it is off."""
    j = cascade_cfg.get("jam") or {}
    if not j.get("use", True):  # the schema's default
        return None
    keys = {"slope": "slope", "decay_units": "free_end_decay_units"}  # unset: the schema's defaults, as JamModel's
    return JamModel.from_geometry(
        cascade_cfg["unit_geometry_mm"], **{k: float(j[c]) for k, c in keys.items() if c in j}
    )


def plan_limit(cascade_cfg: Mapping[str, Any], unit: Any = None, material: Any = None):
    """The bound (:class:`workflow.actuator.pressure_limit.PressureLimit`, kPa) of every planned pressure.

    The smallest of ``cascade.p_max_kpa``, the silicone's limit ``material``
    and the range the unit's surrogate was sampled on (``unit.p_max_kpa``):
    a plan never stands on an extrapolated unit response.
    """

    sampled = getattr(unit, "p_max_kpa", None)
    return smallest(
        PressureLimit(float(cascade_cfg["p_max_kpa"]), "cascade.p_max_kpa"),
        material,
        None if sampled is None else PressureLimit(float(sampled), "the range the unit surrogate's sweep sampled"),
    )


def plan_options(
    cascade_cfg: Mapping[str, Any], active_limits_nm: Sequence[float] | None, limit: Any = None
) -> dict[str, Any]:
    """Keywords of :func:`plan_exercise` from the config's ``cascade`` section and the patient's active limits (N m).

    ``limit`` (a :func:`plan_limit`) tightens ``cascade.p_max_kpa``.  One
    definition for the plan, the FEA check's correction step and the
    speed-accuracy study's plans, so all three plan alike.
    """
    c = cascade_cfg
    p_max = min(float(c["p_max_kpa"]), np.inf if limit is None else float(limit.kpa))
    return {
        "tol_deg": float(c["tolerance_deg"]),
        "p_max_kpa": p_max,
        "tie_cmc_mcp": bool(c["tie_cmc_mcp"]),
        "margin_deg": float(c["margin_deg"]),
        "planner": str(c.get("planner", "paper")),
        "stiffness_margin": float(c.get("stiffness_margin", 1.0)),
        "active_limits_nm": None if active_limits_nm is None else np.abs(np.asarray(active_limits_nm, float)),
    }
