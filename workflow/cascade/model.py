"""Cascade of reduced-order actuator units on a finger: the forward model and its equilibrium.

Model (planar, the finger's sagittal plane; frame and signs of :mod:`workflow.cascade.finger`)
-------------------------------------------------------------------------------------
The paper's reduced-order setup (section 3.1, Fig. 15-16, Tables 7-8), made a
static equilibrium that can be solved for any pressures:

* **Actuator**: ``N`` units of backbone length ``L_R = depth + gap`` (7.8 mm,
  Table 6) in four groups LA_CMC, LA_MCP, LA_PIP, LA_DIP, each with its
  own top/bottom pressures.  Unit count rule (our reading of Fig. 16):
  ``n_CMC = round(cmc_length_fraction * L3MC / L_R)`` (over the hand, default
  half the metacarpal), ``n_MCP = round(L3PP / L_R)``,
  ``n_PIP = round(L3MP / L_R)``, ``n_DIP = round(L3DP / L_R) + tip_units`` (the
  paper's extra length beyond the tip).
* **Joint-rotation spans** (the groups' roles in Fig. 18): the rotation across
  the MCP joint is taken up by the LA_CMC and LA_MCP units in series, across PIP
  by LA_PIP, across DIP by LA_DIP.  The straps keep each span on the finger, so
  the span's total bend equals the joint angle (plus the strap's give), and all
  units of a span carry the same bending moment ``m_X``: the moment the actuator
  applies about joint X.  A unit's angle is the unit model's
  ``angle_deg(P_T, P_B, m_X)`` (free angle at ``m = 0``, zero at the blocked
  moment).
* **Straps** at PIP and DIP (240 kN/m) transmit ``m_X`` as a force with the
  joint's dorsal moment arm ``a_X`` (the joint centre's depth below the dorsal
  line: 8.43 and 5.67 mm for the mean finger, the paper's dummy-finger arms):
  strap force ``m_X / a_X`` and give ``m_X / (k a_X^2)`` of extra span rotation.
  The MCP span is held by the sliding support at the hand end (no give).
* **Jam** (optional, :mod:`workflow.actuator.jam`): a unit inside the actuator bends as the unit model only up to
  the angle where its unpressurised blocks meet their neighbours', little past it, and as the unit model again near
  the free end; the chain then uses each group's mean bend (:func:`group_bends_deg`).
* **Calibration** (optional, :mod:`workflow.cascade.calibration`): a joint turns by ``g_X`` times its span's
  units' bend less ``c_X m_X`` beyond the straps' give; ``g = 1``, ``c = 0`` is the paper's chain.
* **Equilibrium** of the finger+actuator section at each joint:
  ``spring_X(theta_X) = G_X(theta) + m_X``, where ``G_X`` is the flexion
  moment of gravity about X of the phalanges and of the actuator units distal
  to X (each unit's weight on the backbone, carried by the body under it in the
  straight pose; units beyond the tip by the distal phalanx).  Substituting
  ``m_X`` gives three equations in the three joint angles, solved with
  ``scipy.optimize.root`` (Powell hybrid, then Levenberg-Marquardt, then
  continuation in pressure).  Failure is a status in the result, never an
  exception.

Planning on this model is :mod:`workflow.cascade.planning`.

The unit response object is injected: anything with vectorised
``angle_deg(p_top_kpa, p_bottom_kpa, m_ext_nm)``, ``free_angle_deg(p_top, p_bottom)``
and ``blocked_moment_nm(p_top, p_bottom)`` (per unit; positive = flexion).

Units: SI inside (m, N, rad); pressures kPa, angles deg, moments N m, forces N
at the interfaces.

Over 400 lines: the cascade's forward model and its equilibrium solve (with its fallbacks) are one idea.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Mapping, Protocol, Sequence

import numpy as np
from scipy.optimize import root

from workflow.actuator.jam import free_end_weights
from workflow.cascade.finger import Finger, gravity_moments_nm
from workflow.common.constants import GROUPS, JOINTS, PRESSURE_NAMES

__all__ = [
    "SPANS",
    "UnitResponse",
    "unit_counts",
    "unit_section",
    "actuator_start_mm",
    "CascadeModel",
    "build_cascade",
    "actuator_gravity_moments_nm",
    "Equilibrium",
    "solve_equilibrium",
    "group_bends_deg",
    "pressures_vector",
    "pressures_table",
]

#: Groups whose units take up the rotation of each joint (in series).
SPANS = {"MCP": ("CMC", "MCP"), "PIP": ("PIP",), "DIP": ("DIP",)}


class UnitResponse(Protocol):
    """What the cascade needs from the actuator surrogate."""

    def angle_deg(self, p_top_kpa, p_bottom_kpa, m_ext_nm): ...

    def free_angle_deg(self, p_top_kpa, p_bottom_kpa): ...

    def blocked_moment_nm(self, p_top_kpa, p_bottom_kpa): ...


# --------------------------------------------------------------------------
# Layout
# --------------------------------------------------------------------------
def unit_counts(
    segment_lengths_mm: Sequence[float], unit_length_mm: float, cmc_units: int = 3, tip_units: int = 1
) -> dict[str, int]:
    """Units per group from the phalanx lengths (L3PP, L3MP, L3DP), mm.

    ``n_MCP = round(L3PP/L_R)``, ``n_PIP = round(L3MP/L_R)``,
    ``n_DIP = round(L3DP/L_R) + tip_units``, ``n_CMC = cmc_units``; at least one
    unit per group.
    """
    lpp, lmp, ldp = (float(v) for v in segment_lengths_mm)
    return {
        "CMC": max(1, int(cmc_units)),
        "MCP": max(1, int(round(lpp / unit_length_mm))),
        "PIP": max(1, int(round(lmp / unit_length_mm))),
        "DIP": max(1, int(round(ldp / unit_length_mm)) + int(tip_units)),
    }


def unit_section(dims_mm: Mapping[str, float]) -> dict[str, float]:
    """Volumes (mm^3) of one unit and its bottom-side thickness (mm).

    Per side: base layer ``bot_layer`` over the unit length
    ``depth + gap``, one block ``depth x width x height`` with an air pocket
    ``ch_depth x ch_width x ch_height``; both sides plus the paper layer.  The
    silicone between blocks above the base layer is left out (the gap is open).
    """
    d = dims_mm
    lr = d["depth"] + d["gap"]
    side = (
        d["bot_layer"] * d["width"] * lr
        + d["depth"] * d["width"] * d["height"]
        - d["ch_depth"] * d["ch_width"] * d["ch_height"]
    )
    return {
        "unit_length_mm": lr,
        "silicone_mm3": 2.0 * side,
        "paper_mm3": d["paper_width"] * d["width"] * lr,
        "bottom_side_mm": d["bot_layer"] + d["height"] + 0.5 * d["paper_width"],
    }


@dataclass
class CascadeModel:
    """Finger + actuator, ready for :func:`solve_equilibrium`.

    ``unit_group`` (N,) index into :data:`GROUPS`; ``unit_ref`` (N, 2) unit
    centres on the backbone in the straight pose (m) and ``unit_body`` (N,) the
    body carrying each (-1 hand, 0 PP, 1 MP, 2 DP); ``strap_arm_m`` (3,) the
    moment arm of the strap at each joint (``nan`` at MCP: no strap, the
    sliding support holds the span).  Masses kg, stiffness N/m.
    """

    finger: Finger
    unit: Any
    unit_group: np.ndarray
    unit_ref: np.ndarray
    unit_body: np.ndarray
    unit_length_m: float
    backbone_offset_m: float
    unit_mass_kg: float
    base_x_m: float
    strap_stiffness_n_per_m: float
    strap_arm_m: np.ndarray
    gravity_m_s2: float
    n_per_group: dict[str, int] = field(default_factory=dict)
    #: per joint's span: the share of its units' bend that turns the joint, and extra rotation per N m of span moment
    #: beyond the straps' give (rad / N m); 1 and 0 as the paper's chain has them, fitted to the FEA by
    #: :mod:`workflow.cascade.calibration`
    span_gain: np.ndarray = field(default_factory=lambda: np.ones(3))
    span_compliance_rad_per_nm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    #: a unit inside the actuator (:class:`workflow.actuator.jam.JamModel`); None: every unit bends as the unit model
    jam: Any = None

    @property
    def n_units(self) -> int:
        return int(self.unit_group.size)

    # Derived once per model (the root finders call the span bends hundreds of times); ``replace`` builds a new model,
    # so a changed layout or jam model never sees a stale value.
    @cached_property
    def end_weights(self) -> np.ndarray:
        """(N,) each unit's free-end weight of the jam model (0 without one)."""
        return np.zeros(self.n_units) if self.jam is None else free_end_weights(self.n_units, self.jam.decay_units)

    @cached_property
    def group_end_share(self) -> np.ndarray:
        """(4,) the mean free-end weight of each group's units."""
        w = self.end_weights
        return np.array([w[self.unit_group == g].mean() if np.any(self.unit_group == g) else 0.0 for g in range(4)])

    def bends_deg(self, theta_deg, end_weight) -> np.ndarray:
        """Bend (deg) of units whose unit-model bend is ``theta_deg`` and free-end weight ``end_weight``: the jam
        model's, or ``theta_deg`` itself without one (broadcast). Every caller of the unit model's angle goes here."""
        th = np.asarray(theta_deg, float)
        return th if self.jam is None else self.jam.bend_deg(th, end_weight)

    def span_counts(self) -> np.ndarray:
        """(joint, group) number of units of each group in each joint's span."""
        out = np.zeros((3, 4))
        for j, joint in enumerate(JOINTS):
            for g in SPANS[joint]:
                out[j, GROUPS.index(g)] = self.n_per_group[g]
        return out


def actuator_start_mm(n_cmc: int, unit_length_mm: float, layout_shift_mm: float = 0.0) -> float:
    """Where the actuator's proximal end lies along the straight finger, mm from the MCP joint (distal positive):
    the CMC group ends at the MCP joint, then the whole actuator moves by ``layout_shift_mm``. The chain and the FEA
    check lay the actuator by this one rule."""
    return -int(n_cmc) * float(unit_length_mm) + float(layout_shift_mm)


def build_cascade(
    finger: Finger,
    unit: Any,
    *,
    actuator_dims_mm: Mapping[str, float],
    silicone_density: float = 1240.0,
    paper_density: float = 800.0,
    cmc_units: int | None = None,
    cmc_length_fraction: float = 0.5,
    tip_units: int = 1,
    units_per_group: Mapping[str, int] | None = None,
    strap_stiffness_n_per_m: float = 240e3,
    gravity_m_s2: float | None = None,
    actuator_weight: bool = True,
    layout_shift_mm: float = 0.0,
    jam: Any = None,
) -> CascadeModel:
    """Lay the actuator on the straight finger (see the module docstring).

    ``actuator_dims_mm``: Table 6 names (depth, gap, width, height, ch_depth,
    ch_width, ch_height, bot_layer, paper_width).  ``cmc_units`` defaults to
    ``round(cmc_length_fraction * L3MC / L_R)`` (the hand part the actuator
    covers; L3MC from the finger's dimensions, 76.8 mm if absent);
    ``units_per_group`` overrides the rule group by group.  ``gravity_m_s2``
    defaults to the finger's.  ``actuator_weight=False`` makes the actuator
    massless.  ``layout_shift_mm`` moves the whole actuator along the finger
    (mm, distal positive) from where the CMC group ends at the MCP joint; the
    spans stay group-wise (the MCP joint turns with the CMC and MCP groups).  ``jam``: a
    :class:`workflow.actuator.jam.JamModel` for the units inside the actuator (None: the unit model throughout).
    """
    sec = unit_section(actuator_dims_mm)
    lr = sec["unit_length_mm"] * 1e-3
    lengths_mm = [s.length_m * 1e3 for s in finger.segments]
    if cmc_units is None:
        l_mc = float(finger.dimensions_mm.get("L3MC", 76.8))
        cmc_units = int(round(cmc_length_fraction * l_mc / sec["unit_length_mm"]))
    counts = unit_counts(lengths_mm, sec["unit_length_mm"], cmc_units, tip_units)
    for g, v in (units_per_group or {}).items():
        if g not in GROUPS or int(v) < 1:
            raise ValueError(f"units_per_group: bad entry {g}: {v}")
        counts[g] = int(v)
    groups = np.concatenate([np.full(counts[g], i) for i, g in enumerate(GROUPS)])
    n = groups.size
    base_x = actuator_start_mm(counts["CMC"], sec["unit_length_mm"], layout_shift_mm) * 1e-3
    x = base_x + (np.arange(n) + 0.5) * lr
    y_b = finger.dorsal_y_m + sec["bottom_side_mm"] * 1e-3
    jx = finger.joints_ref[:, 0]
    body = np.where(x < jx[0], -1, np.minimum(np.searchsorted(jx, x, side="right") - 1, 2))
    mass = (silicone_density * sec["silicone_mm3"] + paper_density * sec["paper_mm3"]) * 1e-9
    arms = finger.dorsal_y_m - finger.joints_ref[:, 1]
    return CascadeModel(
        finger=finger,
        unit=unit,
        unit_group=groups,
        unit_ref=np.column_stack([x, np.full(n, y_b)]),
        unit_body=body,
        unit_length_m=lr,
        backbone_offset_m=sec["bottom_side_mm"] * 1e-3,
        unit_mass_kg=mass if actuator_weight else 0.0,
        base_x_m=base_x,
        strap_stiffness_n_per_m=float(strap_stiffness_n_per_m),
        strap_arm_m=np.array([np.nan, arms[1], arms[2]]),
        gravity_m_s2=finger.gravity_m_s2 if gravity_m_s2 is None else float(gravity_m_s2),
        n_per_group=counts,
        jam=jam,
    )


def pressures_vector(p: Mapping[str, float] | Sequence[float]) -> np.ndarray:
    """Eight pressures (kPa) in :data:`PRESSURE_NAMES` order from a mapping or sequence."""
    if isinstance(p, Mapping):
        return np.array([float(p.get(n, 0.0)) for n in PRESSURE_NAMES])
    arr = np.asarray(p, float).ravel()
    if arr.size != 8:
        raise ValueError(f"need eight pressures, got {arr.size}")
    return arr


def pressures_table(p8: Sequence[float]) -> np.ndarray:
    """(group, chamber) view of eight pressures."""
    return np.asarray(p8, float).reshape(4, 2)


# --------------------------------------------------------------------------
# Statics
# --------------------------------------------------------------------------
def actuator_gravity_moments_nm(model: CascadeModel, angles_deg: Sequence[float]) -> np.ndarray:
    """Flexion moment (N m) of the actuator units' weight about each joint."""
    if model.unit_mass_kg == 0.0:
        return np.zeros(3)
    f = model.finger
    joints, _ = f.joint_positions(angles_deg)
    pos = f.pose(angles_deg, model.unit_ref, model.unit_body)
    w = model.unit_mass_kg * model.gravity_m_s2
    return np.array([w * np.sum((pos[:, 0] - joints[j, 0]) * (model.unit_body >= j)) for j in range(3)])


def _strap_compliance(model: CascadeModel) -> np.ndarray:
    """The straps' give per unit span moment (rad per N m): 1 / (k a^2), 0 where no strap holds the span."""
    a = model.strap_arm_m
    with np.errstate(invalid="ignore"):
        c = 1.0 / (model.strap_stiffness_n_per_m * a * a)
    return np.where(np.isfinite(c), c, 0.0)


def _span_compliance(model: CascadeModel) -> np.ndarray:
    """Give of each span per unit span moment (rad per N m): the straps' and the calibrated rest; the joint turns by
    the units' bend (times the span's gain) less this times the moment."""
    return _strap_compliance(model) + np.asarray(model.span_compliance_rad_per_nm, float)


def _span_angles_deg(model: CascadeModel, p8: np.ndarray, m_nm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit angles per group (4,) and span bends (3,) in deg under span moments ``m_nm``."""
    pt = pressures_table(p8)
    # One vectorised call: the unit angle of every group under every span moment.
    pg = np.repeat(pt, 3, axis=0)  # (12, 2): group-major
    mm = np.tile(np.asarray(m_nm, float), 4)
    th = np.asarray(model.unit.angle_deg(pg[:, 0], pg[:, 1], mm), float).reshape(4, 3)  # (group, joint)
    th = model.bends_deg(th, model.group_end_share[:, None])
    counts = model.span_counts()  # (joint, group)
    # the joint lags the units by the span's give: a strap stretched by the moment the actuator drives the finger with
    span = np.asarray(model.span_gain, float) * np.sum(counts * th.T, axis=1) - np.rad2deg(
        _span_compliance(model) * m_nm
    )
    unit_g = np.array([th[g, [j for j, jn in enumerate(JOINTS) if GROUPS[g] in SPANS[jn]][0]] for g in range(4)])
    return unit_g, span


def group_bends_deg(model: CascadeModel, group: int, p_top_kpa, p_bottom_kpa, m_nm) -> np.ndarray:
    """Mean bend (deg) of group ``group``'s units at these pressures (kPa) under the span moment ``m_nm`` (N m):
    the unit model's, or with a jam model its interior and free-end bends averaged over the group (broadcast)."""
    return model.bends_deg(model.unit.angle_deg(p_top_kpa, p_bottom_kpa, m_nm), model.group_end_share[group])


def _required_moments(
    model: CascadeModel, angles_deg: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Span moments that hold the pose, and their parts (spring, finger and actuator gravity)."""
    f = model.finger
    spring = np.array([float(sp.moment_nm(t)) for sp, t in zip(f.springs, angles_deg)])
    g_f = gravity_moments_nm(f, angles_deg)
    g_a = actuator_gravity_moments_nm(model, angles_deg)
    return spring - g_f - g_a, spring, g_f, g_a


@dataclass
class Equilibrium:
    """Static equilibrium of finger and actuator for one set of pressures.

    Angles deg, moments N m (positive = flexion), forces N.
    ``actuator_moments_nm``: the moment the actuator applies about each joint
    (= the bending moment its units carry over that joint's span);
    ``unit_angles_deg`` / ``unit_moments_nm``: per group (CMC, MCP, PIP, DIP);
    ``strap_forces_n``: PIP and DIP strap forces (positive: pulling the finger
    into flexion); ``residual_deg``: span bend minus joint angle.
    """

    pressures_kpa: np.ndarray
    joint_angles_deg: np.ndarray
    unit_angles_deg: np.ndarray
    unit_moments_nm: np.ndarray
    actuator_moments_nm: np.ndarray
    spring_moments_nm: np.ndarray
    finger_gravity_moments_nm: np.ndarray
    actuator_gravity_moments_nm: np.ndarray
    strap_forces_n: np.ndarray
    residual_deg: np.ndarray
    converged: bool
    status: int
    evaluations: int
    continuation_steps: int


def _residual(model: CascadeModel, p8: np.ndarray, th: np.ndarray) -> np.ndarray:
    m, *_ = _required_moments(model, th)
    _, span = _span_angles_deg(model, p8, m)
    return span - th


def _root(model, p8, x0, tol):
    nfev = 0
    best = (np.asarray(x0, float), np.inf)
    for method in ("hybr", "lm"):
        with np.errstate(all="ignore"):
            sol = root(
                lambda t: _residual(model, p8, t), best[0] if np.isfinite(best[1]) else x0, method=method, tol=1e-12
            )
        nfev += int(getattr(sol, "nfev", 0) or 0)
        r = _residual(model, p8, sol.x)
        err = float(np.max(np.abs(r))) if np.all(np.isfinite(r)) else np.inf
        if err < best[1]:
            best = (np.asarray(sol.x, float), err)
        if err < tol:
            break
    return best[0], best[1], nfev


def solve_equilibrium(
    model: CascadeModel,
    pressures_kpa: Sequence[float] | Mapping[str, float],
    *,
    x0_deg: Sequence[float] | None = None,
    tol_deg: float = 1e-6,
    continuation_steps: Sequence[int] = (5, 20),
) -> Equilibrium:
    """Static equilibrium for eight pressures (kPa, :data:`PRESSURE_NAMES` order).

    Tries the root finders from ``x0_deg`` (default: straight), then
    continuation in pressure from zero with 5 and then 20 equal steps.
    ``tol_deg`` bounds the largest span-bend residual.  Never raises for lack
    of convergence: see ``converged`` / ``status``.
    """
    p8 = pressures_vector(pressures_kpa)
    x0 = np.zeros(3) if x0_deg is None else np.asarray(x0_deg, float)
    th, err, nfev = _root(model, p8, x0, tol_deg)
    used = 0
    if not err < tol_deg:
        for steps in continuation_steps:
            tc = np.zeros(3)
            for lam in np.linspace(0.0, 1.0, steps + 1)[1:]:
                tc, err_c, n_c = _root(model, lam * p8, tc, tol_deg)
                nfev += n_c
                if not err_c < tol_deg:
                    break
            used = steps
            if err_c < tol_deg:
                th, err = tc, err_c
                break
    return _equilibrium(model, p8, th, err, tol_deg, nfev, used)


def _equilibrium(model, p8, th, err, tol, nfev, used) -> Equilibrium:
    m, spring, g_f, g_a = _required_moments(model, th)
    unit_g, span = _span_angles_deg(model, p8, m)
    unit_m = np.array([m[[j for j, jn in enumerate(JOINTS) if GROUPS[g] in SPANS[jn]][0]] for g in range(4)])
    finite = np.all(np.isfinite(th)) and np.isfinite(err)
    status = 0 if (finite and err < tol) else (1 if finite else 2)
    return Equilibrium(
        pressures_kpa=np.asarray(p8, float),
        joint_angles_deg=np.asarray(th, float),
        unit_angles_deg=unit_g,
        unit_moments_nm=unit_m,
        actuator_moments_nm=m,
        spring_moments_nm=spring,
        finger_gravity_moments_nm=g_f,
        actuator_gravity_moments_nm=g_a,
        strap_forces_n=(m / model.strap_arm_m)[1:],
        residual_deg=span - th,
        converged=status == 0,
        status=status,
        evaluations=int(nfev),
        continuation_steps=int(used),
    )
