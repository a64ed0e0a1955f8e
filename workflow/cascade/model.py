"""Cascade of reduced-order actuator units on a finger: forward model and planning.

Model (planar, the finger's sagittal plane; frame and signs of :mod:`workflow.finger`)
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
* **Equilibrium** of the finger+actuator section at each joint:
  ``spring_X(theta_X) = G_X(theta) + m_X``, where ``G_X`` is the flexion
  moment of gravity about X of the phalanges and of the actuator units distal
  to X (each unit's weight on the backbone, carried by the body under it in the
  straight pose; units beyond the tip by the distal phalanx).  Substituting
  ``m_X`` gives three equations in the three joint angles, solved with
  ``scipy.optimize.root`` (Powell hybrid, then Levenberg-Marquardt, then
  continuation in pressure).  Failure is a status in the result, never an
  exception.

Planning: per exercise, the moments the actuator must supply at the target pose
follow directly (``m*_X = spring_X(theta*_X) - G_X(theta*)``, the paper's Table 7
logic).  Per span, a grid search (no gradients, so piecewise-constant
surrogates such as KNN work) finds the pressures of least sum of squares
whose bend under ``m*_X`` lies within ``tol - margin`` of the
target; the coupled forward model then checks the pose, the angle tolerance and
the active safety limits (``|m_X| <= limit_X``), halving the span goal when the
pose drifts out.  ``P_CMC`` may be tied to ``P_MCP`` as in all the paper's plans.

The unit response object is injected: anything with vectorised
``angle_deg(p_top_kpa, p_bottom_kpa, m_ext_nm)``, ``free_angle_deg(p_top, p_bottom)``
and ``blocked_moment_nm(p_top, p_bottom)`` (per unit; positive = flexion).

Units: SI inside (m, N, rad); pressures kPa, angles deg, moments N m, forces N
at the interfaces.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Protocol, Sequence

import numpy as np
from scipy.optimize import root

from workflow.finger import JOINTS, Finger, gravity_moments_nm

__all__ = [
    "GROUPS",
    "CHAMBERS",
    "PRESSURE_NAMES",
    "SPANS",
    "STATUS_FLAGS",
    "UnitResponse",
    "unit_counts",
    "unit_section",
    "CascadeModel",
    "build_cascade",
    "actuator_gravity_moments_nm",
    "Equilibrium",
    "solve_equilibrium",
    "free_shape",
    "moment_residuals",
    "Plan",
    "plan_exercise",
    "pressures_vector",
    "pressures_table",
    "backbone_polyline",
    "plan_patient",
    "plans_dataset",
    "patient_finger",
    "patient_cascade",
    "plan_options",
    "write_cascade_plan",
]

GROUPS = ("CMC", "MCP", "PIP", "DIP")
CHAMBERS = ("top", "bottom")
PRESSURE_NAMES = tuple(f"P_{g}_{c}" for g in GROUPS for c in ("T", "B"))
#: Groups whose units take up the rotation of each joint (in series).
SPANS = {"MCP": ("CMC", "MCP"), "PIP": ("PIP",), "DIP": ("DIP",)}
#: Forward-solve status codes (CF flag_values / flag_meanings).
STATUS_FLAGS = {0: "converged", 1: "not_converged", 2: "non_finite"}


class UnitResponse(Protocol):
    """What the cascade needs from the actuator surrogate."""

    def angle_deg(self, p_top_kpa, p_bottom_kpa, m_ext_nm): ...

    def free_angle_deg(self, p_top_kpa, p_bottom_kpa): ...

    def blocked_moment_nm(self, p_top_kpa, p_bottom_kpa): ...


# --------------------------------------------------------------------------
# Layout
# --------------------------------------------------------------------------
def unit_counts(segment_lengths_mm: Sequence[float], unit_length_mm: float,
                cmc_units: int = 3, tip_units: int = 1) -> dict[str, int]:
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
    side = d["bot_layer"] * d["width"] * lr + d["depth"] * d["width"] * d["height"] \
        - d["ch_depth"] * d["ch_width"] * d["ch_height"]
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

    @property
    def n_units(self) -> int:
        return int(self.unit_group.size)

    def span_counts(self) -> np.ndarray:
        """(joint, group) number of units of each group in each joint's span."""
        out = np.zeros((3, 4))
        for j, joint in enumerate(JOINTS):
            for g in SPANS[joint]:
                out[j, GROUPS.index(g)] = self.n_per_group[g]
        return out


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
) -> CascadeModel:
    """Lay the actuator on the straight finger (see the module docstring).

    ``actuator_dims_mm``: Table 6 names (depth, gap, width, height, ch_depth,
    ch_width, ch_height, bot_layer, paper_width).  ``cmc_units`` defaults to
    ``round(cmc_length_fraction * L3MC / L_R)`` (the hand part the actuator
    covers; L3MC from the finger's dimensions, 76.8 mm if absent);
    ``units_per_group`` overrides the rule group by group.  ``gravity_m_s2``
    defaults to the finger's.  ``actuator_weight=False`` makes the actuator
    massless.
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
    base_x = -counts["CMC"] * lr
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
    """Extra span rotation per unit moment (rad per N m) from the straps' give."""
    a = model.strap_arm_m
    with np.errstate(invalid="ignore"):
        c = 1.0 / (model.strap_stiffness_n_per_m * a * a)
    return np.where(np.isfinite(c), c, 0.0)


def _span_angles_deg(model: CascadeModel, p8: np.ndarray, m_nm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit angles per group (4,) and span bends (3,) in deg under span moments ``m_nm``."""
    pt = pressures_table(p8)
    # One vectorised call: the unit angle of every group under every span moment.
    pg = np.repeat(pt, 3, axis=0)  # (12, 2): group-major
    mm = np.tile(np.asarray(m_nm, float), 4)
    th = np.asarray(model.unit.angle_deg(pg[:, 0], pg[:, 1], mm), float).reshape(4, 3)  # (group, joint)
    counts = model.span_counts()  # (joint, group)
    span = np.sum(counts * th.T, axis=1) + np.rad2deg(_strap_compliance(model) * m_nm)
    unit_g = np.array([th[g, [j for j, jn in enumerate(JOINTS) if GROUPS[g] in SPANS[jn]][0]]
                       for g in range(4)])
    return unit_g, span


def _required_moments(model: CascadeModel, angles_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
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
            sol = root(lambda t: _residual(model, p8, t), best[0] if np.isfinite(best[1]) else x0,
                       method=method, tol=1e-12)
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


def free_shape(model: CascadeModel, pressures_kpa, m_ext_nm: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Stand-alone actuator (no finger, no gravity): unit angles (deg, per unit)
    and the backbone polyline (m) from the hand end, under a uniform moment."""
    pt = pressures_table(pressures_vector(pressures_kpa))[model.unit_group]
    th = np.asarray(model.unit.angle_deg(pt[:, 0], pt[:, 1], np.full(model.n_units, m_ext_nm)), float)
    return th, backbone_polyline(model, th)


def backbone_polyline(model: CascadeModel, unit_angles_deg: np.ndarray, start=None, heading_rad: float = 0.0) -> np.ndarray:
    """Backbone nodes (N+1, 2) in m: each unit an arc of length L_R bent by its angle."""
    th = np.deg2rad(np.asarray(unit_angles_deg, float))
    L = model.unit_length_m
    p = np.array([model.base_x_m, model.unit_ref[0, 1]]) if start is None else np.asarray(start, float)
    nodes = [p]
    psi = heading_rad
    for t in th:
        # Chord of an arc of length L turning by -t (flexion turns clockwise).
        chord = L if abs(t) < 1e-9 else L * np.sin(t / 2) / (t / 2)
        mid = psi - t / 2
        p = p + chord * np.array([np.cos(mid), np.sin(mid)])
        psi -= t
        nodes.append(p)
    return np.array(nodes)


def moment_residuals(model: CascadeModel, eq: Equilibrium) -> dict[str, np.ndarray]:
    """Out-of-balance of an equilibrium: joint moments (N m) and span bends (deg).

    ``joint_nm``: spring - finger gravity - actuator gravity - actuator moment,
    recomputed from the pose; ``span_deg``: the unit model's bend of each span
    under the carried moment (called directly) minus the joint angle.
    """
    f = model.finger
    th = eq.joint_angles_deg
    spring = np.array([float(sp.moment_nm(t)) for sp, t in zip(f.springs, th)])
    joint = spring - gravity_moments_nm(f, th) - actuator_gravity_moments_nm(model, th) - eq.actuator_moments_nm
    _, span = _span_angles_deg(model, eq.pressures_kpa, eq.actuator_moments_nm)
    return {"joint_nm": joint, "span_deg": span - th}


# --------------------------------------------------------------------------
# Planning
# --------------------------------------------------------------------------
@dataclass
class Plan:
    """Planned pressures for one exercise and what the forward model predicts.

    ``required_moments_nm``: the span moments that hold the target pose (the
    Table-7-like unit moment targets); ``target_unit_angles_deg``: per group,
    the unit angle at the target pose under the planned pressures.
    """

    exercise: str
    target_deg: np.ndarray
    pressures_kpa: np.ndarray
    equilibrium: Equilibrium
    achieved: bool
    reason: str
    required_moments_nm: np.ndarray
    target_unit_angles_deg: np.ndarray


def _span_plan(model, joint: int, m_req: float, target: float, goal: float, p_max: float,
               tie: bool, n_coarse: int = 61) -> tuple[dict[int, float], float]:
    """Least-squares pressures of one span by grid search (no gradients, so a
    piecewise-constant surrogate such as KNN works too).

    Returns {index into the eight pressures: kPa} and the bend error (deg) at
    the target pose.  Feasible: the least sum of squares with
    ``|bend - target| <= goal``; otherwise the pressures closest to the target.
    """
    groups = [GROUPS.index(g) for g in SPANS[JOINTS[joint]]]
    idx = [2 * g + c for g in groups for c in (0, 1)]
    if tie and joint == 0:
        idx = [2, 3]  # MCP's pair drives CMC too
    k = len(idx)
    counts = model.span_counts()[joint]
    comp = np.rad2deg(_strap_compliance(model)[joint] * m_req)

    def bend(P):  # P (n, k) kPa -> span bend error (n,)
        p8 = np.zeros((P.shape[0], 8))
        p8[:, idx] = P
        if tie and joint == 0:
            p8[:, 0:2] = p8[:, 2:4]
        out = np.full(P.shape[0], comp - target)
        for g in range(4):
            if counts[g]:
                th = model.unit.angle_deg(p8[:, 2 * g], p8[:, 2 * g + 1], np.full(P.shape[0], m_req))
                out += counts[g] * np.asarray(th, float)
        return out

    def search(lo, hi, n):
        axes = [np.linspace(l, h, n) for l, h in zip(lo, hi)]
        P = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, k)
        e = bend(P)
        ok = np.abs(e) <= goal
        if np.any(ok):
            i = np.flatnonzero(ok)[np.argmin(np.sum(P[ok] ** 2, axis=1))]
            return P[i], float(e[i]), True
        i = int(np.lexsort((np.sum(P**2, axis=1), np.round(np.abs(e), 9)))[0])
        return P[i], float(e[i]), False

    n = n_coarse if k == 2 else max(9, int(round(n_coarse ** 0.5)))
    step = p_max / (n - 1)
    P, e, feas = search(np.zeros(k), np.full(k, p_max), n)
    for _ in range(3):  # refine around the best point
        lo, hi = np.maximum(P - step, 0.0), np.minimum(P + step, p_max)
        n_f = 21 if k == 2 else 7
        P, e, feas = search(lo, hi, n_f)
        step = step * 2 / (n_f - 1)
    return dict(zip(idx, P)), e


def plan_exercise(
    model: CascadeModel,
    target_deg: Sequence[float],
    *,
    exercise: str = "",
    tol_deg: float = 5.0,
    active_limits_nm: Sequence[float] | None = None,
    p_max_kpa: float = 300.0,
    tie_cmc_mcp: bool = True,
    margin_deg: float = 0.25,
    max_rounds: int = 5,
) -> Plan:
    """Pressures for one exercise (see the module docstring).

    Per span, the pressures of least sum of squares whose bend under the
    target-pose moment is within ``tol - margin`` of the target; then the
    coupled forward model checks the pose.  If a joint lands outside the
    tolerance (the pose, not the target, sets the moments), the plan is
    repeated -- with the moments of the reached pose for spans that cannot
    reach their target, else with half the span goal -- at most ``max_rounds``
    times, and the best round is kept.  Angles deg, moments N m, pressures kPa.
    """
    target = np.asarray(target_deg, float)
    limits = None if active_limits_nm is None else np.abs(np.asarray(active_limits_nm, float))
    m_req, *_ = _required_moments(model, target)
    goal = tol_deg - margin_deg
    # Pose at which the span moments are evaluated: the target, except for
    # joints whose span cannot reach it -- those stay where the forward model
    # puts them, so the other spans plan for the moments they will really see.
    theta_eval = target.copy()
    best = None
    for _ in range(max_rounds):
        m_eval, *_ = _required_moments(model, theta_eval)
        p8 = np.zeros(8)
        span_err = np.zeros(3)
        for j in range(3):
            sol, span_err[j] = _span_plan(model, j, m_eval[j], target[j],
                                          goal, p_max_kpa, tie_cmc_mcp)
            for i, v in sol.items():
                p8[i] = v
        if tie_cmc_mcp:
            p8[0:2] = p8[2:4]
        eq = solve_equilibrium(model, p8, x0_deg=theta_eval)
        e = np.abs(eq.joint_angles_deg - target) if eq.converged else np.full(3, np.inf)
        score = (int(np.sum(e > tol_deg)), float(np.sum(e)))
        if best is None or score < best[2]:
            best = (p8, eq, score)
        if score[0] == 0 or not eq.converged:
            break
        unreachable = np.abs(span_err) > goal
        if np.any(unreachable):
            new_eval = np.where(unreachable, eq.joint_angles_deg, target)
            if np.max(np.abs(new_eval - theta_eval)) < 0.1:
                break
            theta_eval = new_eval
        else:
            goal *= 0.5
    p8, eq, _ = best
    err = eq.joint_angles_deg - target
    reasons = []
    if not eq.converged:
        reasons.append(f"forward model did not converge ({STATUS_FLAGS[eq.status]})")
    for j in np.flatnonzero(np.abs(err) > tol_deg):
        groups = SPANS[JOINTS[j]]
        at_bound = [PRESSURE_NAMES[2 * GROUPS.index(g) + c] for g in groups for c in (0, 1)
                    if p8[2 * GROUPS.index(g) + c] >= p_max_kpa * (1 - 1e-6)]
        reasons.append(
            f"{JOINTS[j]} off target by {err[j]:+.1f} deg (tolerance {tol_deg:g} deg; "
            f"needs {m_req[j]:.3g} N m over {'+'.join('LA_' + g for g in groups)})"
            + (f", {', '.join(at_bound)} at the {p_max_kpa:g} kPa limit" if at_bound else ""))
    if limits is not None:
        for j in np.flatnonzero(np.abs(eq.actuator_moments_nm) > limits):
            reasons.append(f"active safety limit exceeded at {JOINTS[j]} "
                           f"({eq.actuator_moments_nm[j]:.3g} vs {limits[j]:.3g} N m)")
    unit_target, _ = _span_angles_deg(model, p8, m_req)
    return Plan(
        exercise=exercise, target_deg=target, pressures_kpa=p8, equilibrium=eq,
        achieved=not reasons, reason="; ".join(reasons), required_moments_nm=m_req,
        target_unit_angles_deg=unit_target,
    )


# --------------------------------------------------------------------------
# Patient plans as a dataset, and the rule's file-level entry point
# --------------------------------------------------------------------------
def plan_patient(model: CascadeModel, targets: Mapping[str, Sequence[float]], **kw) -> list[Plan]:
    """:func:`plan_exercise` for every exercise of ``targets`` ({name: (MCP, PIP, DIP) deg})."""
    return [plan_exercise(model, t, exercise=name, **kw) for name, t in targets.items()]


def plans_dataset(model: CascadeModel, plans: Sequence[Plan], *, tol_deg: float,
                  active_limits_nm: Sequence[float] | None, notes: Mapping[str, str] | None = None):
    """The contract's ``cascade_plan.nc`` content (without provenance)."""
    import xarray as xr

    ex = [p.exercise for p in plans]
    droop = solve_equilibrium(model, np.zeros(8))
    flag_vals = np.array(sorted(STATUS_FLAGS), dtype="i1")
    lim = np.full(3, np.nan) if active_limits_nm is None else np.asarray(active_limits_nm, float)
    eqs = [p.equilibrium for p in plans]
    ds = xr.Dataset(
        {
            "pressure_kpa": (("exercise", "group", "chamber"), np.array([pressures_table(p.pressures_kpa) for p in plans]),
                             {"units": "kPa", "long_name": "planned chamber pressure"}),
            "target_angle_deg": (("exercise", "joint"), np.array([p.target_deg for p in plans]),
                                 {"units": "degree", "long_name": "target joint angle (Table 1)"}),
            "predicted_angle_deg": (("exercise", "joint"), np.array([e.joint_angles_deg for e in eqs]),
                                    {"units": "degree", "long_name": "joint angle at equilibrium under the planned pressures"}),
            "angle_error_deg": (("exercise", "joint"), np.array([e.joint_angles_deg - p.target_deg for e, p in zip(eqs, plans)]),
                                {"units": "degree", "long_name": "predicted minus target joint angle"}),
            "achieved": ("exercise", np.array([p.achieved for p in plans]),
                         {"long_name": f"every joint within {tol_deg:g} deg of its target, moments within the active limits"}),
            "reason": ("exercise", np.array([p.reason for p in plans], dtype=object),
                       {"long_name": "why the exercise is not reached (empty if reached)"}),
            "status": ("exercise", np.array([e.status for e in eqs], dtype="i1"),
                       {"long_name": "forward-solve status", "flag_values": flag_vals,
                        "flag_meanings": " ".join(STATUS_FLAGS[int(v)] for v in flag_vals)}),
            "actuator_moment_nm": (("exercise", "joint"), np.array([e.actuator_moments_nm for e in eqs]),
                                   {"units": "N m", "long_name": "flexion moment the actuator applies about the joint at equilibrium"}),
            "required_moment_nm": (("exercise", "joint"), np.array([p.required_moments_nm for p in plans]),
                                   {"units": "N m", "long_name": "moment per unit of the joint's span that holds the target pose (Table 7-like)"}),
            "unit_target_angle_deg": (("exercise", "group"), np.array([p.target_unit_angles_deg for p in plans]),
                                      {"units": "degree", "long_name": "unit bending angle at the target pose under the planned pressures (Table 7-like)"}),
            "unit_angle_deg": (("exercise", "group"), np.array([e.unit_angles_deg for e in eqs]),
                               {"units": "degree", "long_name": "unit bending angle at equilibrium"}),
            "unit_moment_nm": (("exercise", "group"), np.array([e.unit_moments_nm for e in eqs]),
                               {"units": "N m", "long_name": "bending moment each unit carries at equilibrium"}),
            "strap_force_n": (("exercise", "strap"), np.array([e.strap_forces_n for e in eqs]),
                              {"units": "N", "long_name": "strap force transmitting the span moment (positive: pulls into flexion)"}),
            "sum_sq_pressure_kpa2": ("exercise", np.array([float(p.pressures_kpa @ p.pressures_kpa) for p in plans]),
                                     {"units": "kPa2", "long_name": "objective: sum of squared pressures"}),
            "active_limit_nm": ("joint", lim, {"units": "N m", "long_name": "active safety limit"}),
            "droop_angle_deg": ("joint", droop.joint_angles_deg,
                                {"units": "degree", "long_name": "joint angle at zero pressure (gravity droop with the actuator on)"}),
            "units_per_group": ("group", np.array([model.n_per_group[g] for g in GROUPS], dtype="i4"),
                                {"units": "1", "long_name": "actuator units per group"}),
            "segment_mass_kg": ("segment", model.finger.masses_kg, {"units": "kg", "long_name": "phalanx mass"}),
        },
        coords={"exercise": ex, "group": list(GROUPS), "chamber": list(CHAMBERS), "joint": list(JOINTS),
                "strap": ["PIP", "DIP"], "segment": ["PP", "MP", "DP"]},
    )
    ds.attrs.update({
        "unit_mass_kg": model.unit_mass_kg,
        "unit_length_mm": model.unit_length_m * 1e3,
        "spans": "; ".join(f"{j}: {'+'.join(g)}" for j, g in SPANS.items()),
        "finger_mass_source": model.finger.mass_source,
        "droop_converged": int(droop.converged),
        **dict(notes or {}),
    })
    return ds


def patient_finger(patient: Mapping[str, Any], loads, moments, ccd, *, cascade_cfg: Mapping[str, Any],
                   anthropometry: Mapping[str, Any]) -> tuple[Finger, str]:
    """The patient's finger model as the plan builds it, and a note on its springs' source.

    ``loads``, ``moments``, ``ccd``: the datasets of ``joint_loads.nc``,
    ``moments.nc`` and ``ccd.nc``; ``cascade_cfg`` the config's ``cascade``
    section (densities, gravity, section points).  Shared by the planning
    and the FEA check, so both see the same finger.
    """
    from workflow import finger as F

    c = cascade_cfg
    finger_name = str(patient.get("finger", "F3"))
    coded = {d: float(v) for d, v in zip(loads["dimension"].values, loads["x"].values)}
    measures = anthropometry["measures"]
    dims = F.patient_dimensions_mm(measures, coded, float(anthropometry.get("coded_unit_sd", 1.0)),
                                   patient.get("measurements_mm"))
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
        *(curve if curve is not None else (None, None)))
    d = dict(c["densities"])
    if patient.get("model", "human") == "dummy":
        # The paper's test finger (Table 10): solid PLA of the same shape; its
        # springs stand in for the passive joint moments, so those stay.
        d.update({k: d.get("pla", 1240.0) for k in ("flesh_proximal", "flesh_middle", "flesh_distal", "bone")})
        spring_note += f"; dummy finger: PLA {d['flesh_proximal']:g} kg/m^3 throughout"
    fing = F.build_finger(
        dims, springs,
        {k: d[k] for k in ("flesh_proximal", "flesh_middle", "flesh_distal", "bone")},
        gravity_m_s2=c["gravity_m_s2"], section_points=c.get("section_points"),
        reference_dims_mm={k: float(v["mean"]) for k, v in measures.items()},
    )
    return fing, spring_note


def patient_cascade(finger: Finger, unit: Any, cascade_cfg: Mapping[str, Any],
                    units_per_group: Mapping[str, int] | None = None) -> CascadeModel:
    """The actuator laid on ``finger`` as the config's ``cascade`` section says (densities, unit counts, straps).

    ``units_per_group`` (e.g. a plan's) overrides the config's counts.  Shared
    by the planning and the FEA check's correction step.
    """
    c, d = cascade_cfg, cascade_cfg["densities"]
    return build_cascade(
        finger, unit, actuator_dims_mm=c["unit_geometry_mm"], silicone_density=d["silicone"],
        paper_density=d["paper"], cmc_length_fraction=c["cmc_length_fraction"], tip_units=c["tip_units"],
        units_per_group=units_per_group or c.get("units_per_group") or None,
        strap_stiffness_n_per_m=c["strap_stiffness_n_per_m"],
    )


def plan_limit(cascade_cfg: Mapping[str, Any], unit: Any = None, material: Any = None):
    """The bound (:class:`workflow.pressure_limit.PressureLimit`, kPa) of every planned pressure.

    The smallest of ``cascade.p_max_kpa``, the silicone's limit ``material``
    and the range the unit's surrogate was sampled on (``unit.p_max_kpa``):
    a plan never stands on an extrapolated unit response.
    """
    from workflow.pressure_limit import PressureLimit, smallest

    sampled = getattr(unit, "p_max_kpa", None)
    return smallest(PressureLimit(float(cascade_cfg["p_max_kpa"]), "cascade.p_max_kpa"), material,
                    None if sampled is None else
                    PressureLimit(float(sampled), "the range the unit surrogate's sweep sampled"))


def plan_options(cascade_cfg: Mapping[str, Any], active_limits_nm: Sequence[float] | None,
                 limit: Any = None) -> dict[str, Any]:
    """Keywords of :func:`plan_exercise` from the config's ``cascade`` section and the patient's active limits (N m).

    ``limit`` (a :func:`plan_limit`) tightens ``cascade.p_max_kpa``.  One
    definition for the plan, the FEA check's correction step and the
    speed-accuracy study's plans, so all three plan alike.
    """
    c = cascade_cfg
    p_max = min(float(c["p_max_kpa"]), np.inf if limit is None else float(limit.kpa))
    return {"tol_deg": float(c["tolerance_deg"]), "p_max_kpa": p_max,
            "tie_cmc_mcp": bool(c["tie_cmc_mcp"]), "margin_deg": float(c["margin_deg"]),
            "active_limits_nm": None if active_limits_nm is None else np.abs(np.asarray(active_limits_nm, float))}


def write_cascade_plan(
    patient_name: str,
    patient: Mapping[str, Any],
    unit: Any,
    *,
    ccd_nc: str,
    moments_nc: str,
    joint_loads_nc: str,
    out_nc: str,
    out_png: str | None,
    cascade_cfg: Mapping[str, Any],
    anthropometry: Mapping[str, Any],
    config_slice: Any,
    rule: str = "cascade_plan",
    sampled_region: Any = None,
    notes: Mapping[str, str] | None = None,
    material_limit: Any = None,
):
    """Build the patient's finger and actuator, plan every exercise, write the plan (and poses plot).

    ``unit`` is the unit response object (see :class:`UnitResponse`);
    ``cascade_cfg`` the config's ``cascade`` section; ``material_limit`` the
    silicone's pressure limit (:func:`workflow.pressure_limit.material_limit`):
    no planned pressure exceeds :func:`plan_limit`, recorded in the attrs
    ``p_limit_kpa`` and ``p_limit_source``.  ``sampled_region`` (a
    `workflow.stability.SampledRegion` of the surrogate's sweep), if given,
    flags planned (P_T, P_B) pairs outside the converged FE samples or nearest
    a failed one: ``pressure_in_sampled_region`` and a warning in the log.
    ``notes`` go into the attrs (e.g. the surrogate's fidelity and why).
    """
    import logging
    import time

    import xarray as xr

    from workflow.provenance import open_result, write_dataset

    log = logging.getLogger(__name__)
    c = cascade_cfg
    loads = open_result(joint_loads_nc)
    fing, spring_note = patient_finger(patient, loads, open_result(moments_nc), open_result(ccd_nc),
                                       cascade_cfg=c, anthropometry=anthropometry)
    finger_name = str(patient.get("finger", "F3"))
    model = patient_cascade(fing, unit, c)
    limits = loads["active_limit_nm"].sel(joint=list(JOINTS)).values
    targets = {str(e): loads["target_angle_deg"].sel(exercise=e, joint=list(JOINTS)).values
               for e in loads["exercise"].values}
    log.info("patient %s: units per group %s, finger masses %s kg (%s); springs: %s", patient_name,
             model.n_per_group, np.round(fing.masses_kg, 4), fing.mass_source, spring_note)
    limit = plan_limit(c, unit, material_limit)
    log.info("patient %s: every planned pressure <= %s", patient_name, limit)
    t0 = time.perf_counter()
    plans = []
    for name, t in targets.items():
        p = plan_exercise(model, t, exercise=name, **plan_options(c, limits, limit))
        if np.any(p.pressures_kpa > limit.kpa):  # the search is bounded: this is a bug, not a plan to write
            raise RuntimeError(f"patient {patient_name} {name}: planned {p.pressures_kpa.max():.1f} kPa above {limit}")
        log.info("%s: %s pressures %s kPa, predicted %s deg (target %s) %s", name,
                 "reached" if p.achieved else "NOT reached", np.round(p.pressures_kpa, 1),
                 np.round(p.equilibrium.joint_angles_deg, 1), t, p.reason)
        plans.append(p)
    ds = plans_dataset(model, plans, tol_deg=c["tolerance_deg"], active_limits_nm=limits,
                       notes={"patient": patient_name, "finger": finger_name, "springs": spring_note,
                              "planning_wall_time_s": round(time.perf_counter() - t0, 3),
                              "p_limit_kpa": limit.kpa, "p_limit_source": limit.source, **dict(notes or {})})
    if sampled_region is not None:
        # the surrogate is an extrapolation outside its samples: flag, do not stop
        from workflow.stability import flag_pressure_table

        ds["pressure_in_sampled_region"], msgs = flag_pressure_table(ds["pressure_kpa"], sampled_region,
                                                                     label=f"patient {patient_name}: ")
        for m in msgs:
            log.warning(m)
    write_dataset(ds, out_nc, rule=rule, config_slice=config_slice,
                  title=f"Cascade pressure plan of patient {patient_name}")
    if out_png:
        from workflow.plots_cascade import plot_poses

        plot_poses(model, plans, out_png, title=f"patient {patient_name}")
    return ds
