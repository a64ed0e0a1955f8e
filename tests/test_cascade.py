"""Cascade forward model and planning, against an analytic unit stand-in.

The stand-in (test double only) is a unit that bends ``c (P_T - P_B)`` when
free and is a linear torsional spring of stiffness ``k0 + k1 (P_T + P_B)``
about that angle: swapping the pressures negates angle and moment, equal
pressures give no bend, and the blocked moment is stiffness x free angle
(about 8.7 deg and 0.2 N m at 300 kPa, the magnitudes of the 3D unit at that pressure).
"""

from __future__ import annotations

import numpy as np
import pytest
from _doubles import DENSITIES, mean_finger

from workflow.cascade import entry, kinematics, planning, plans_data, stiffness
from workflow.cascade import finger as F
from workflow.cascade import model as C

ACTUATOR = dict(
    depth=6.8, gap=1, width=20, height=15, ch_depth=2.8, ch_width=14, ch_height=13, bot_layer=2, paper_width=0.2
)
LIMITS = (5.4, 4.1, 1.1)  # N m, the size of the mean finger's active moments


class LinearUnit:
    def __init__(self, c=0.029, k0=0.01, k1=4.3e-5):
        self.c, self.k0, self.k1 = c, k0, k1  # deg/kPa, N m/deg, N m/(deg kPa)

    def free_angle_deg(self, pt, pb):
        return self.c * (np.asarray(pt, float) - np.asarray(pb, float))

    def stiffness(self, pt, pb):
        return self.k0 + self.k1 * (np.asarray(pt, float) + np.asarray(pb, float))

    def blocked_moment_nm(self, pt, pb):
        return self.free_angle_deg(pt, pb) * self.stiffness(pt, pb)

    def angle_deg(self, pt, pb, m):
        return self.free_angle_deg(pt, pb) - np.asarray(m, float) / self.stiffness(pt, pb)

    def stiffness_nm_per_deg(self, pt, pb):
        return self.stiffness(pt, pb)


def springs():
    return [
        F.JointSpring.from_points([90], [0.058]),
        F.JointSpring.from_points([90, 100], [0.0189, 0.0285]),
        F.JointSpring.from_points([80], [0.00324]),
    ]


def model(unit=None, densities=DENSITIES, **kw):
    f = mean_finger(springs=springs(), densities=densities)
    return C.build_cascade(f, unit or LinearUnit(), actuator_dims_mm=ACTUATOR, **kw)


def test_layout_counts_units_from_segment_lengths():
    m = model()
    assert m.n_per_group == {"CMC": 5, "MCP": 6, "PIP": 4, "DIP": 4}
    assert m.unit_length_m == pytest.approx(7.8e-3)
    # Table 6 unit: two sides of (base layer + block - pocket) plus paper.
    vol = 2 * (2 * 20 * 7.8 + 6.8 * 20 * 15 - 2.8 * 14 * 13)
    assert m.unit_mass_kg == pytest.approx((1240 * vol + 800 * 0.2 * 20 * 7.8) * 1e-9)
    assert m.n_per_group == C.unit_counts([50.6, 30.6, 26.5], 7.8, 5, 1)


def test_equal_pressures_give_a_straight_actuator():
    m = model()
    for p in (0.0, 120.0, 300.0):
        th, nodes = kinematics.free_shape(m, [p] * 8)
        np.testing.assert_allclose(th, 0.0, atol=1e-12)
        np.testing.assert_allclose(nodes[:, 1], nodes[0, 1], atol=1e-12)
        assert nodes[-1, 0] - nodes[0, 0] == pytest.approx(m.n_units * m.unit_length_m)
    # Top only bends it towards the palm (clockwise), bottom only the other way.
    th, nodes = kinematics.free_shape(m, [300, 0] * 4)
    assert np.all(th > 8) and nodes[-1, 1] < nodes[0, 1]
    th_b, _ = kinematics.free_shape(m, [0, 300] * 4)
    np.testing.assert_allclose(th_b, -th)


def test_zero_pressure_gives_the_gravity_droop_of_the_springs():
    # A massless actuator whose units are (almost) limp at zero pressure carries
    # no moment: the finger hangs where its springs hold its own weight.
    limp = LinearUnit(k0=1e-7)
    m = model(unit=limp, actuator_weight=False)
    eq = C.solve_equilibrium(m, np.zeros(8))
    droop, ok = F.gravity_droop_deg(m.finger)
    assert eq.converged and ok
    np.testing.assert_allclose(eq.joint_angles_deg, droop, atol=0.05)
    assert droop[0] > 10  # a real droop, not a trivial zero
    # With the actuator's weight and stiffness the finger still droops, into flexion.
    eq2 = C.solve_equilibrium(model(), np.zeros(8))
    assert eq2.converged and np.all(eq2.joint_angles_deg > 0)


@pytest.mark.parametrize(
    "p", [[0] * 8, [286, 0, 286, 0, 0, 217, 187, 187], [290, 0] * 4, [0, 200] * 4, [150, 260, 150, 260, 215, 0, 215, 0]]
)
def test_moment_balance_residual_below_tolerance(p):
    m = model()
    eq = C.solve_equilibrium(m, p)
    assert eq.converged
    r = kinematics.moment_residuals(m, eq)
    assert np.max(np.abs(r["joint_nm"])) < 1e-9
    assert np.max(np.abs(r["span_deg"])) < 1e-6
    # Independent statics: each span carries the spring moment minus the weights'
    # flexion moments, computed here from the poses of the bodies.
    f = m.finger
    th = eq.joint_angles_deg
    joints, _ = f.joint_positions(th)
    coms = f.pose(th, f.coms_ref, np.arange(3))
    units = f.pose(th, m.unit_ref, m.unit_body)
    g = 9.81
    for j in range(3):
        grav = np.sum(f.masses_kg[j:] * g * (coms[j:, 0] - joints[j, 0]))
        grav += np.sum(m.unit_mass_kg * g * (units[:, 0] - joints[j, 0]) * (m.unit_body >= j))
        assert f.springs[j].moment_nm(th[j]) - grav == pytest.approx(eq.actuator_moments_nm[j], abs=1e-12)
    # Every unit of a span bends by the unit model's angle under the span moment.
    unit = LinearUnit()
    pt = np.asarray(p, float).reshape(4, 2)
    span_of_group = [0, 0, 1, 2]
    for g_ in range(4):
        expect = unit.angle_deg(pt[g_, 0], pt[g_, 1], eq.actuator_moments_nm[span_of_group[g_]])
        assert eq.unit_angles_deg[g_] == pytest.approx(expect, abs=1e-9)


def test_top_pressure_flexes_and_bottom_pressure_extends():
    m = model()
    zero = C.solve_equilibrium(m, np.zeros(8)).joint_angles_deg
    flex = C.solve_equilibrium(m, [200, 0] * 4).joint_angles_deg
    ext = C.solve_equilibrium(m, [0, 200] * 4).joint_angles_deg
    assert np.all(flex > zero) and np.all(ext < zero)


def test_inverse_plan_reaches_a_reachable_target():
    m = model()
    p_known = np.array([220, 0, 220, 0, 150, 0, 0, 60], float)
    target = C.solve_equilibrium(m, p_known).joint_angles_deg
    plan = planning.plan_exercise(m, target, tol_deg=5.0, active_limits_nm=LIMITS)
    assert plan.achieved, plan.reason
    assert np.max(np.abs(plan.equilibrium.joint_angles_deg - target)) <= 5.0
    np.testing.assert_allclose(plan.pressures_kpa[0:2], plan.pressures_kpa[2:4])  # CMC tied to MCP
    assert np.all((plan.pressures_kpa >= 0) & (plan.pressures_kpa <= 300))
    # Least squares: no more pressure than the pressures that made the target.
    assert plan.pressures_kpa @ plan.pressures_kpa <= p_known @ p_known + 1e-6
    # A tighter tolerance needs more pressure and still lands inside it.
    tight = planning.plan_exercise(m, target, tol_deg=1.0, active_limits_nm=LIMITS)
    assert tight.achieved and np.max(np.abs(tight.equilibrium.joint_angles_deg - target)) <= 1.0
    assert tight.pressures_kpa @ tight.pressures_kpa > plan.pressures_kpa @ plan.pressures_kpa


def test_stiffness_planner_co_pressurises_to_hold_the_pose_stiffer():
    # the double's unit stiffens with P_T + P_B: the least-pressure plan never co-pressurises; asked for spans
    # stiffer than their load, the stiffness planner does, at the same pose within the tolerance
    m = model()
    target = C.solve_equilibrium(m, np.array([120, 0, 120, 0, 100, 0, 0, 40], float)).joint_angles_deg
    least = planning.plan_exercise(m, target, tol_deg=5.0, active_limits_nm=LIMITS)
    k_least = [stiffness.span_stiffness_nm_per_deg(m, j, least.pressures_kpa)[0] for j in range(3)]
    load = stiffness.load_stiffness_nm_per_deg(m, np.asarray(target))
    margin = 1.5 * max(k / lo for k, lo in zip(k_least, load))  # more than the least-pressure plan gives anywhere
    stiff = planning.plan_exercise(
        m, target, tol_deg=5.0, active_limits_nm=LIMITS, planner="stiffness", stiffness_margin=margin
    )
    assert least.achieved and stiff.achieved, (least.reason, stiff.reason)
    co = np.minimum(least.pressures_kpa[0::2], least.pressures_kpa[1::2])
    assert np.all(co == 0)  # least pressure: one chamber of a group at most
    assert np.any(np.minimum(stiff.pressures_kpa[0::2], stiff.pressures_kpa[1::2]) > 0)  # co-pressurised
    k_stiff = [stiffness.span_stiffness_nm_per_deg(m, j, stiff.pressures_kpa)[0] for j in range(3)]
    assert all(ks > kl for ks, kl in zip(k_stiff, k_least))
    assert np.max(np.abs(stiff.equilibrium.joint_angles_deg - target)) <= 5.0
    assert stiff.pressures_kpa.max() <= 300.0
    with pytest.raises(ValueError, match="planner"):
        planning.plan_exercise(m, target, planner="stiffest")


def test_paper_rule_gives_each_unit_its_angle_under_its_moment_and_co_pressurises_straight_groups():
    # the paper's rule on the straight pose (TGE1): each span's units start on the 300 kPa curve where their free
    # angle is the unit's target (the straps' give under the span's extension moment asks a little extension:
    # mirrored, the bottom at 300 kPa), and the top pressure alone then moves until each unit gives that angle under
    # the span's moment, the bottom held
    m = model()
    unit = LinearUnit()
    plan = planning.plan_exercise(m, [0, 0, 0], tol_deg=5.0, active_limits_nm=LIMITS, planner="paper")
    p = plan.pressures_kpa.reshape(4, 2)
    np.testing.assert_allclose(p[:, 1], 300.0)  # the bottom held at the limit
    assert np.all(p[:, 0] > 0) and np.all(p[:, 0] < 300)  # co-pressurised, the top below: an extension moment
    m_req = plan.required_moments_nm
    give = np.rad2deg(C._strap_compliance(m) * m_req)
    a, k0, k1, b = unit.c, unit.k0, unit.k1, 300.0
    for j, g in ((0, 1), (1, 2), (2, 3)):  # MCP span (CMC tied to MCP), PIP, DIP
        theta_u = give[j] / m.span_counts()[j].sum()
        assert theta_u <= 0
        # (b), the double in closed form: a (t - b) - m / (k0 + k1 (t + b)) = theta_u, a quadratic in t
        roots = np.roots(
            [a * k1, a * k0 - theta_u * k1, -a * b * k0 - a * k1 * b**2 - m_req[j] - theta_u * (k0 + k1 * b)]
        )
        t_exact = roots[(roots.real > 0) & (roots.real < 300)].real
        assert p[g, 0] == pytest.approx(float(t_exact[0]), abs=0.02)
    assert plan.achieved, plan.reason
    np.testing.assert_allclose(plan.equilibrium.joint_angles_deg, 0.0, atol=0.5)
    # the least-pressure plan of the same pose pressurises one chamber of a group at most
    least = planning.plan_exercise(m, [0, 0, 0], tol_deg=5.0, active_limits_nm=LIMITS)
    assert np.all(np.minimum(least.pressures_kpa[0::2], least.pressures_kpa[1::2]) == 0)


class BiasedUnit(LinearUnit):
    """The double with a free angle 0.05 deg off on the diagonal, as a fitted surrogate may be."""

    def free_angle_deg(self, pt, pb):
        return super().free_angle_deg(pt, pb) + 0.05


def test_paper_rule_takes_the_closest_pressures_where_no_pressure_meets_the_target():
    # a straight span with no moment on a unit whose free angle is never 0 at the limit's top pressure: (a) takes
    # the closest (300/300 kPa), not the top alone (which would flex the span by 35 deg), and (b) then lowers the
    # top to where the unit is straight: 300 - 0.05 / c
    m = model(unit=BiasedUnit())
    sol, err = planning._span_plan_paper(m, 2, 0.0, 0.0, 300.0, True)
    assert sol[7] == pytest.approx(300.0) and sol[6] == pytest.approx(300.0 - 0.05 / 0.029, abs=0.01)
    assert abs(err) < 1e-6
    # a span asked for more than the top alone gives under its moment: the closest of both lines, not (a) kept
    sol, err = planning._span_plan_paper(model(), 1, 0.3, 20.0 * 4, 300.0, True)
    assert sol[4] == pytest.approx(300.0) and sol[5] == pytest.approx(0.0) and err < 0


def test_paper_rule_on_a_calibrated_chain_bends_each_span_exactly():
    # the rule divides the span's target by the span's gain and adds its give: every span exactly on target
    from workflow.cascade import calibration as CAL

    m = CAL.calibrated(model(), [0.6, 0.8, 0.9], [1.0, -0.5, 0.3])
    target = np.array([30.0, 20.0, 0.0])
    m_req, *_ = C._required_moments(m, target)
    for j in range(3):
        sol, err = planning._span_plan_paper(m, j, m_req[j], target[j], 300.0, True)
        assert abs(err) < 1e-3, (j, sol, err)


def test_paper_rule_bends_every_span_exactly_under_its_moment_within_the_limit():
    # a flexion target: each span's units bend by exactly their share under the span moment at the planned pose
    # (the rule solves for it, not within a goal), co-pressurised from the limit's top-pressure curve
    m = model()
    unit = LinearUnit()
    target = C.solve_equilibrium(m, np.array([200, 0, 200, 0, 150, 0, 0, 0], float)).joint_angles_deg
    target[2] = 0.0
    plan = planning.plan_exercise(m, target, tol_deg=5.0, active_limits_nm=LIMITS, planner="paper", p_max_kpa=280.0)
    p = plan.pressures_kpa.reshape(4, 2)
    assert np.all(p <= 280.0) and np.all(p > 0)  # every group co-pressurised, none above the limit
    assert np.any(p == 280.0)
    m_req = plan.required_moments_nm
    give = np.rad2deg(C._strap_compliance(m) * m_req)
    counts = m.span_counts()
    for j in range(3):
        bend = sum(counts[j][g] * unit.angle_deg(p[g, 0], p[g, 1], m_req[j]) for g in range(4)) - give[j]
        assert bend == pytest.approx(target[j], abs=0.01)
    assert plan.achieved, plan.reason
    assert np.max(np.abs(plan.equilibrium.joint_angles_deg - target)) <= 5.0


def test_planner_comparison_scores_each_planner_against_a_table():
    # a table equal to the paper planner's own pressures is 0 % off for it and not for the least-pressure planner
    import pandas as pd

    from workflow.cascade import validation
    from workflow.common.constants import PRESSURE_NAMES

    m = model()
    targets = {"TGE1": [0, 0, 0], "TGE2": [60, 0, 0], "TGE3": [60, 40, 0]}
    by = {pl: planning.plan_patient(m, targets, active_limits_nm=LIMITS, planner=pl) for pl in planning.PLANNERS}
    ds = plans_data.plans_dataset(m, by["least_pressure"], tol_deg=5.0, active_limits_nm=LIMITS).merge(
        plans_data.planners_dataset(by)
    )
    assert list(ds["planner"].values) == list(planning.PLANNERS)
    np.testing.assert_allclose(
        ds["planner_pressure_kpa"].sel(planner="least_pressure").values, ds["pressure_kpa"].values
    )
    table = pd.DataFrame(
        [p.pressures_kpa for p in by["paper"]], index=pd.Index(list(targets), name="exercise"), columns=PRESSURE_NAMES
    )
    out = validation.compare_planners(ds, {"table08": table})
    med = out["planner_median_rel_error"].sel(table="table08")
    assert float(med.sel(planner="paper")) == pytest.approx(0.0, abs=1e-12)
    assert float(out["planner_worst_rel_error"].sel(planner="paper", table="table08")) == pytest.approx(0.0, abs=1e-12)
    assert float(med.sel(planner="least_pressure")) > 0.1
    reached = out["planner_reached"].sel(table="table08")
    np.testing.assert_array_equal(reached.sel(planner="paper").values, [p.achieved for p in by["paper"]])


def test_unreachable_target_is_marked_with_a_reason():
    m = model()
    plan = planning.plan_exercise(m, [90, 100, 80], tol_deg=5.0, active_limits_nm=LIMITS)
    assert not plan.achieved
    assert "PIP" in plan.reason and "300 kPa limit" in plan.reason
    # A safety limit below what the plan needs is reported too.
    plan2 = planning.plan_exercise(m, [0, 0, 0], tol_deg=5.0, active_limits_nm=(1e-4, 1e-4, 1e-4))
    assert not plan2.achieved and "safety limit" in plan2.reason


def test_heavier_finger_needs_more_pressure():
    light = planning.plan_exercise(model(), [0, 0, 0], tol_deg=5.0, active_limits_nm=LIMITS)
    heavy = planning.plan_exercise(
        model(densities={k: 2 * v for k, v in DENSITIES.items()}), [0, 0, 0], tol_deg=5.0, active_limits_nm=LIMITS
    )
    assert light.achieved and heavy.achieved
    assert heavy.pressures_kpa @ heavy.pressures_kpa > 1.2 * (light.pressures_kpa @ light.pressures_kpa)
    # Holding the finger straight against gravity takes the bottom (extending) chambers.
    assert heavy.pressures_kpa[3] > light.pressures_kpa[3] > 0
    assert heavy.pressures_kpa[2] == 0


def test_non_convergence_is_reported_not_raised():
    class Broken(LinearUnit):
        def angle_deg(self, pt, pb, m):
            return np.full(np.shape(m), np.nan)

    eq = C.solve_equilibrium(model(unit=Broken()), [100, 0] * 4)
    assert not eq.converged and eq.status != 0


def test_springs_from_loads_use_points_or_a_scaled_curve():
    targets = np.array([[0, 0, 0], [90, 0, 0], [90, 90, 0], [90, 100, 80], [0, 100, 80]], float)
    passive = np.array([[0, 0, 0], [0.05, 0, 0], [0.05, 0.016, 0], [0.05, 0.024, 0.003], [0, 0.024, 0.003]])
    sp, note = F.springs_from_loads(targets, passive)
    assert "patient points" in note
    for j, (a, m) in enumerate([(90, 0.05), (100, 0.024), (80, 0.003)]):
        assert sp[j].moment_nm(a) == pytest.approx(m) and sp[j].moment_nm(0) == 0
    assert sp[1].moment_nm(90) == pytest.approx(0.016)
    # A full curve (OpenSim backend) lends its shape, scaled through the patient's point.
    ang = np.arange(0, 105, 5.0)
    curve = np.vstack([1e-5 * ang**2, 4e-6 * ang**2, 6e-7 * ang**2])
    sp2, note2 = F.springs_from_loads(targets, passive, ang, curve)
    assert "scaled" in note2
    assert sp2[0].moment_nm(90) == pytest.approx(0.05)
    assert sp2[0].moment_nm(45) == pytest.approx(0.05 / 4, rel=1e-6)  # quadratic shape kept


def test_plan_dataset_roundtrip_and_validation(tmp_path):
    import xarray as xr

    from workflow.cascade.validation import compare_pressures, read_pressure_table
    from workflow.common.provenance import write_dataset

    m = model()
    targets = {"TGE1": [0, 0, 0], "TGE2": [90, 0, 0], "TGE4": [90, 100, 80]}
    plans = planning.plan_patient(m, targets, tol_deg=5.0, active_limits_nm=LIMITS)
    ds = plans_data.plans_dataset(m, plans, tol_deg=5.0, active_limits_nm=LIMITS)
    path = write_dataset(ds, tmp_path / "plan.nc", rule="test", config_slice={}, title="t")
    back = xr.load_dataset(path)
    for v in ("pressure_kpa", "target_angle_deg", "predicted_angle_deg", "achieved", "reason"):
        assert v in back
    assert back["pressure_kpa"].dims == ("exercise", "group", "chamber")
    np.testing.assert_allclose(back["pressure_kpa"].values, ds["pressure_kpa"].values)
    assert list(back["reason"].values) == [p.reason for p in plans]
    assert back["status"].attrs["flag_meanings"].split()[0] == "converged"
    # Validation against a table: errors per pressure, relative only above the floor.
    csv = tmp_path / "ref.csv"
    csv.write_text("exercise," + ",".join(C.PRESSURE_NAMES) + "\nTGE1,100,5,100,200,0,50,20,20\n")
    val = compare_pressures(back, {"ref": read_pressure_table(csv)}, rel_floor_kpa=10.0)
    ours = back["pressure_kpa"].sel(exercise="TGE1").values.ravel()
    ref = np.array([100, 5, 100, 200, 0, 50, 20, 20.0])
    np.testing.assert_allclose(val["abs_error"].sel(table="ref", exercise="TGE1"), np.abs(ours - ref))
    rel = val["rel_error"].sel(table="ref", exercise="TGE1").values
    assert np.isnan(rel[1]) and np.isnan(rel[4]) and rel[3] == pytest.approx(abs(ours[3] - 200) / 200)
    assert np.all(np.isnan(val["reference"].sel(exercise="TGE2")))
    assert bool(val["paper_reached"].sel(paper_set="dummy", exercise="TGE2"))
    assert not bool(val["paper_reached"].sel(paper_set="fea_2d", exercise="TGE4"))


def test_write_cascade_plan_from_stage_files(tmp_path, caplog):
    """The rule's entry point on minimal upstream files (contract layouts)."""
    import xarray as xr
    from _doubles import MEASURES, SECTION

    joints = ["MCP", "PIP", "DIP"]
    ex = ["TGE1", "TGE2"]
    xr.Dataset(
        {"depth": ("run", [0.0, 1.0])}, coords={"run": [9, 12], "marker": ("run", ["Original", "DM"])}
    ).to_netcdf(tmp_path / "ccd.nc")
    mom = np.full((2, 1, 3, 3, 2), np.nan)
    mom[0, 0, 0, 1, 0] = 0.05
    xr.Dataset(
        {"moment_nm": (("run", "finger", "joint", "angle_deg", "activation"), mom)},
        coords={
            "run": [9, 12],
            "finger": ["F3"],
            "joint": joints,
            "angle_deg": [80.0, 90.0, 100.0],
            "activation": [0.01, 1.0],
        },
    ).to_netcdf(tmp_path / "moments.nc")
    xr.Dataset(
        {
            "x": ("dimension", [0.0, 0.0, 0.0]),
            "target_angle_deg": (("exercise", "joint"), [[0, 0, 0], [90, 0, 0]]),
            "passive_moment_nm": (("exercise", "joint"), [[0, 0, 0], [0.05, 0, 0]]),
            "active_limit_nm": ("joint", list(LIMITS)),
        },
        coords={"exercise": ex, "joint": joints, "dimension": ["depth", "length", "breadth"]},
    ).to_netcdf(tmp_path / "loads.nc")
    # PIP and DIP have no sample above 0 deg in these loads: the entry point must say so.
    cfg = {
        "tolerance_deg": 5.0,
        "margin_deg": 0.25,
        "tie_cmc_mcp": True,
        "p_max_kpa": 300.0,
        "strap_stiffness_n_per_m": 240e3,
        "gravity_m_s2": 9.81,
        "densities": {**DENSITIES, "silicone": 1240.0, "paper": 800.0},
        "section_points": str(SECTION),
        "cmc_length_fraction": 0.5,
        "tip_units": 1,
        "units_per_group": {},
        "unit_geometry_mm": ACTUATOR,
    }
    anth = {"coded_unit_sd": 1.0, "measures": {k: {"mean": m, "sd": s} for k, (m, s) in MEASURES.items()}}
    kw = dict(
        ccd_nc=tmp_path / "ccd.nc",
        moments_nc=tmp_path / "moments.nc",
        joint_loads_nc=tmp_path / "loads.nc",
        cascade_cfg=cfg,
        anthropometry=anth,
        config_slice={"c": 1},
    )
    with pytest.raises(ValueError, match="PIP"):
        entry.write_cascade_plan("p", {"finger": "F3"}, LinearUnit(), out_nc=tmp_path / "x.nc", out_png=None, **kw)
    xr.Dataset(
        {
            "x": ("dimension", [0.0, 0.0, 0.0]),
            "target_angle_deg": (("exercise", "joint"), [[0, 0, 0], [90, 100, 80]]),
            "passive_moment_nm": (("exercise", "joint"), [[0, 0, 0], [0.05, 0.0285, 0.0032]]),
            "active_limit_nm": ("joint", list(LIMITS)),
        },
        coords={"exercise": ex, "joint": joints, "dimension": ["depth", "length", "breadth"]},
    ).to_netcdf(tmp_path / "loads.nc")
    # a surrogate sampled only up to 100 kPa: planned pairs beyond it are flagged and logged
    from workflow.actuator.sampled_region import SampledRegion

    region = SampledRegion(np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0], [100.0, 100.0]]), np.empty((0, 2)))
    with caplog.at_level("WARNING", logger="workflow.cascade"):
        ds = entry.write_cascade_plan(
            "p",
            {"finger": "F3"},
            LinearUnit(),
            out_nc=tmp_path / "plan.nc",
            out_png=tmp_path / "poses.png",
            sampled_region=region,
            **kw,
        )
    back = xr.load_dataset(tmp_path / "plan.nc")
    assert back.attrs["rule"] == "cascade_plan" and "config_sha256" in back.attrs
    assert (tmp_path / "poses.png").stat().st_size > 10_000
    assert bool(ds["achieved"].sel(exercise="TGE1")) and not bool(ds["achieved"].sel(exercise="TGE2"))
    assert list(ds["units_per_group"].values) == [5, 6, 4, 4]
    p = back["pressure_kpa"]
    outside = (p.max("chamber") > 100.0).values
    assert outside.any() and np.array_equal(~back["pressure_in_sampled_region"].values, outside)
    assert sum("outside the sampled region" in r.getMessage() for r in caplog.records) == int(outside.sum())
    # the silicone's limit and the surrogate's sampled range bound every planned pressure, and the plan says which
    from workflow.actuator.pressure_limit import PressureLimit

    assert float(p.max()) == pytest.approx(300.0)  # TGE2 is out of reach: its spans sit at cascade.p_max_kpa
    sampled = LinearUnit()
    sampled.p_max_kpa = 200.0
    for unit, material, bound, source in (
        (LinearUnit(), PressureLimit(150.0, "material"), 150.0, "material"),
        (sampled, PressureLimit(300.0, "material"), 200.0, "sampled"),
    ):
        ds = entry.write_cascade_plan(
            "p", {"finger": "F3"}, unit, out_nc=tmp_path / "lim.nc", out_png=None, material_limit=material, **kw
        )
        assert float(ds["pressure_kpa"].max()) == pytest.approx(bound)
        assert ds.attrs["p_limit_kpa"] == bound and source in ds.attrs["p_limit_source"]


def test_untying_cmc_from_mcp_never_needs_more_pressure():
    m = model()
    target = C.solve_equilibrium(m, [250, 0, 150, 0, 80, 0, 0, 40]).joint_angles_deg
    tied = planning.plan_exercise(m, target, tol_deg=3.0, active_limits_nm=LIMITS)
    free = planning.plan_exercise(m, target, tol_deg=3.0, active_limits_nm=LIMITS, tie_cmc_mcp=False)
    assert tied.achieved and free.achieved, (tied.reason, free.reason)
    assert np.max(np.abs(free.equilibrium.joint_angles_deg - target)) <= 3.0
    # The untied grid is coarser, so allow its resolution (a few kPa) in the comparison.
    assert free.pressures_kpa @ free.pressures_kpa <= 1.02 * (tied.pressures_kpa @ tied.pressures_kpa) + 100.0


def test_dummy_finger_is_solid_pla_with_the_same_springs(config):
    """The dummy finger (the paper's PLA finger, section 4) changes the masses, not the springs."""
    import xarray as xr

    from workflow.cascade.patient import patient_finger

    ex, joints = ["TGE1", "TGE4"], ["MCP", "PIP", "DIP"]
    loads = xr.Dataset(
        {
            "x": (("dimension",), np.zeros(3)),
            "target_angle_deg": (("exercise", "joint"), [[0.0, 0.0, 0.0], [90.0, 100.0, 80.0]]),
            "passive_moment_nm": (("exercise", "joint"), [[0.0, 0.0, 0.0], [0.05, 0.025, 0.02]]),
        },
        coords={"dimension": ["depth", "length", "breadth"], "exercise": ex, "joint": joints},
    )
    moments = xr.Dataset(coords={"finger": ["F2"]})  # no curve for F3: the patient's points alone
    ccd = xr.Dataset({"marker": (("run",), ["Original"])}, coords={"run": [9]})
    c = dict(config["cascade"], section_points=None)
    human, _ = patient_finger(
        {"finger": "F3"}, loads, moments, ccd, cascade_cfg=c, anthropometry=config["anthropometry"]
    )
    dummy, note = patient_finger(
        {"finger": "F3", "model": "dummy"}, loads, moments, ccd, cascade_cfg=c, anthropometry=config["anthropometry"]
    )
    assert "PLA" in note
    d = c["densities"]
    # every slice of the proximal segment is flesh+bone (4000/2000) in the human, PLA in the dummy
    assert d["pla"] / d["flesh_proximal"] < dummy.masses_kg[0] / human.masses_kg[0] < d["pla"] / d["bone"]
    for a in (30.0, 90.0):
        assert [s.moment_nm(a) for s in dummy.springs] == [s.moment_nm(a) for s in human.springs]


def test_jam_caps_an_interior_units_bend_smoothly_and_oddly():
    from workflow.actuator.jam import JamModel, capped_bend_deg, free_end_weights

    jam = JamModel.from_geometry(ACTUATOR)
    assert jam.jam_deg == pytest.approx(np.degrees(1.0 / 17.1))  # gap / (paper/2 + base + block height)
    th = np.linspace(-30.0, 30.0, 6001)
    c = capped_bend_deg(th, jam.jam_deg, 0.1)
    np.testing.assert_allclose(c, -capped_bend_deg(-th, jam.jam_deg, 0.1), atol=1e-12)  # extension mirrors flexion
    assert np.all(np.diff(c) > 0)  # monotone: the plans' inverse stays unique
    far = np.abs(th) > jam.jam_deg + 3.0
    np.testing.assert_allclose(c[far], np.sign(th[far]) * (jam.jam_deg + 0.1 * (np.abs(th[far]) - jam.jam_deg)))
    below = np.abs(th) < jam.jam_deg - 2.0
    np.testing.assert_allclose(c[below], th[below], atol=1e-3)
    w = free_end_weights(6, 2.0)
    np.testing.assert_allclose(w, np.exp(-np.array([4, 3, 2, 1, 0, 0]) / 2.0))
    assert np.all(free_end_weights(6, 0.0) == 0.0)
    for bad in (1.5, 0.0):  # a zero slope: flat past the jam, no unique inverse
        with pytest.raises(ValueError, match="slope"):
            JamModel(3.35, slope=bad)


def test_chain_with_the_jam_bends_less_and_plans_agree_with_it():
    # every unit of the chain capped at the jam: the same pressures flex the finger less; each span's bend in the
    # paper rule's plan is the jam-capped units' (the planner and the chain use one unit response)
    from workflow.actuator.jam import JamModel

    jam = JamModel.from_geometry(ACTUATOR, decay_units=2.0)  # with the free end's layer, as the actuator alone
    free, capped = model(), model(jam=jam)
    p = np.array([250, 0, 250, 0, 200, 0, 200, 0], float)
    assert np.all(C.solve_equilibrium(capped, p).joint_angles_deg < C.solve_equilibrium(free, p).joint_angles_deg)
    # a group's mean bend: the interior cap for the CMC group, far from the free end; the unit model's at the tip
    share = capped.group_end_share
    assert share[0] < 1e-3 and share[3] > 0.5
    th = LinearUnit().free_angle_deg(250.0, 0.0)  # 7.25 deg, past the 3.35 deg jam
    # the CMC group, far from the free end: the closed form J + s (theta - J), not the unit model's theta
    assert C.group_bends_deg(capped, 0, 250.0, 0.0, 0.0) == pytest.approx(
        jam.jam_deg + 0.1 * (th - jam.jam_deg), abs=0.01
    )
    target = C.solve_equilibrium(capped, np.array([150, 0, 150, 0, 100, 0, 60, 0], float)).joint_angles_deg
    plan = planning.plan_exercise(capped, target, tol_deg=5.0, active_limits_nm=LIMITS, planner="paper")
    assert plan.achieved, plan.reason
    # the rule solves each span's bend exactly on the jam-capped units (on the raw unit model it would miss by ~3 deg)
    assert np.max(np.abs(plan.equilibrium.joint_angles_deg - target)) <= 0.05
    # the whole actuator drawn free: the free end's units bend more than the interior's at one pressure
    th_units, _ = kinematics.free_shape(capped, [250, 0] * 4)
    assert th_units[-1] == pytest.approx(th) and th_units[-1] > 1.9 * th_units[capped.n_units // 2]


def test_the_default_chain_caps_its_units_at_table_6s_jam_angle(config):
    from workflow.cascade.patient import jam_model

    jam = jam_model(config["cascade"])
    assert jam.jam_deg == pytest.approx(3.3506, abs=1e-4) and jam.slope == 0.1 and jam.decay_units == 0.0
    assert jam_model({**config["cascade"], "jam": {"use": False}}) is None


def test_a_jammed_span_is_stiffer_by_the_jams_slope():
    from workflow.actuator.jam import JamModel, capped_bend_deg, capped_bend_slope

    th = np.linspace(-20, 20, 4001)
    fd = np.gradient(capped_bend_deg(th, 3.35, 0.1), th)
    np.testing.assert_allclose(capped_bend_slope(th, 3.35, 0.1)[1:-1], fd[1:-1], atol=2e-3)
    jam = JamModel.from_geometry(ACTUATOR)
    free, capped = model(), model(jam=jam)
    p = np.array([[300, 0, 300, 0, 300, 0, 300, 0], [20, 0, 20, 0, 20, 0, 20, 0]], float)
    k0 = stiffness.span_stiffness_nm_per_deg(free, 1, p)  # PIP span: four units in series and the strap
    k1 = stiffness.span_stiffness_nm_per_deg(capped, 1, p)
    assert k1[0] > 3.0 * k0[0]  # 8.7 deg free at 300 kPa: past the jam, the units follow a tenth
    assert k1[1] == pytest.approx(k0[1], rel=1e-6)  # 0.58 deg at 20 kPa: below it, unchanged
    # under a span moment the stiffness is the chain's own: the span bend's change per moment, by finite differences
    for pp, m in ((p[0], 0.15), (p[0], 0.0), ([100, 0] * 4, -0.05)):
        pp = np.asarray(pp, float)
        dm = 1e-6
        bend = [C._span_angles_deg(capped, pp, np.full(3, mm))[1][1] for mm in (m - dm, m + dm)]
        k_fd = 2 * dm / abs(bend[1] - bend[0])  # N m per degree of the span, the strap's give included
        assert stiffness.span_stiffness_nm_per_deg(capped, 1, pp[None, :], m)[0] == pytest.approx(k_fd, rel=1e-3)
