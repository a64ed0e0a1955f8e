"""Finger model: geometry, masses, springs and the gravity droop."""

from __future__ import annotations

import numpy as np
import pytest
from _doubles import DENSITIES, MEASURES, SECTION, linear_springs, mean_finger, measures  # noqa: F401
from scipy.optimize import brentq

from workflow.cascade import finger as F


def test_coded_levels_shift_by_one_sd_and_measurements_win():
    dims = F.patient_dimensions_mm(
        measures(), {"depth": 0.5, "length": -1.0, "breadth": 0.0}, measurements_mm={"L3PP": 55.0}
    )
    assert dims["D3MCP"] == pytest.approx(25.5 + 0.5 * 2.85)
    assert dims["L3MP"] == pytest.approx(30.6 - 2.74)
    assert dims["B3PP"] == pytest.approx(18.6)
    assert dims["L3PP"] == 55.0


def test_spring_interpolates_monotone_and_continues_linearly():
    sp = F.JointSpring.from_points([90, 100], [0.0189, 0.0285])
    a = np.linspace(-30, 130, 321)
    m = sp.moment_nm(a)
    assert sp.moment_nm(0.0) == 0.0
    assert np.all(np.diff(m) > 0)
    assert sp.moment_nm(90) == pytest.approx(0.0189) and sp.moment_nm(100) == pytest.approx(0.0285)
    # Linear beyond the samples with the nearest interval's secant slope.
    assert sp.moment_nm(120) - sp.moment_nm(110) == pytest.approx(0.0096, rel=1e-9)
    assert sp.moment_nm(-20) == pytest.approx(-20 * 0.0189 / 90)
    # Energy is the integral of the moment over the angle in rad.
    e = sp.energy_j(95.0)
    quad = np.trapezoid(sp.moment_nm(np.linspace(0, 95, 20001)), np.deg2rad(np.linspace(0, 95, 20001)))
    assert e == pytest.approx(quad, rel=1e-6)
    with pytest.raises(ValueError):
        F.JointSpring.from_points([80, 90], [0.02, 0.01])


@pytest.mark.parametrize("section", [True, False])
def test_masses_follow_densities_and_volume(section):
    f = mean_finger(section_points=SECTION if section else None)
    m = f.masses_kg
    # Elliptic cylinder bound: the proximal phalanx, 4000/2000 kg/m^3, is the heaviest.
    assert m[0] > m[1] > 0 and m[0] > m[2] > 0
    if not section:
        # Closed form: pi/4 d b L with flesh around a bone core of half the depth and breadth.
        a_o = np.pi / 4 * 17.3 * np.interp(np.linspace(0, 1, 10001), [0, 0.5, 1], [18.6, 18.6, 19.4]).mean()
        expect = (4000 * 0.75 + 2000 * 0.25) * a_o * 50.6 * 1e-9
        assert m[0] == pytest.approx(expect, rel=2e-3)
    # Doubling every density doubles every mass.
    f2 = mean_finger(section_points=SECTION if section else None, densities={k: 2 * v for k, v in DENSITIES.items()})
    np.testing.assert_allclose(f2.masses_kg, 2 * m, rtol=1e-12)
    # A longer finger (coded length +1) is heavier.
    dims = F.patient_dimensions_mm(measures(), {"depth": 0, "length": 1, "breadth": 0})
    f3 = F.build_finger(
        dims,
        linear_springs(),
        DENSITIES,
        section_points=SECTION if section else None,
        reference_dims_mm={k: v for k, (v, _) in MEASURES.items()},
    )
    assert np.all(f3.masses_kg > m)


def test_section_points_give_the_dummy_finger_moment_arms():
    f = mean_finger()
    arms = f.dorsal_y_m - f.joints_ref[:, 1]
    np.testing.assert_allclose(arms * 1e3, [10.14, 8.43, 5.67], atol=0.01)
    assert f.tip_x_m * 1e3 == pytest.approx(50.6 + 30.6 + 26.5)


def test_gravity_moment_of_horizontal_finger_is_weight_times_lever():
    f = mean_finger()
    g = F.gravity_moments_nm(f, [0, 0, 0])
    w = f.masses_kg * 9.81
    com = f.coms_ref
    assert g[2] == pytest.approx(w[2] * (com[2, 0] - f.joints_ref[2, 0]))
    assert g[0] == pytest.approx(np.sum(w * com[:, 0]))
    # Hanging straight down (MCP at 90 deg, others 0) the weight has no lever about MCP
    # beyond the small dorsal/palmar offsets of the centres of mass.
    # (5 % with the authors' section points, 12 % with the elliptic fallback, whose
    # joint centres sit at half the joint depth)
    g90 = F.gravity_moments_nm(f, [90, 0, 0])
    assert abs(g90[0]) < 0.15 * g[0]


def test_gravity_droop_matches_single_joint_closed_form():
    # Stiff PIP and DIP: the finger droops as one body about MCP, where a linear
    # spring k balances W r cos(theta) -- solved here independently.
    k = 0.058 / 90
    f = mean_finger(springs=[F.JointSpring.linear(k), F.JointSpring.linear(100.0), F.JointSpring.linear(100.0)])
    w = f.masses_kg * 9.81
    com = f.coms_ref
    wr_x = np.sum(w * com[:, 0])
    wr_y = np.sum(w * com[:, 1])

    def bal(t):
        tr = np.deg2rad(t)
        return k * t - (wr_x * np.cos(tr) + wr_y * np.sin(tr))

    expect = brentq(bal, 0, 90)
    th, ok = F.gravity_droop_deg(f)
    assert ok
    assert th[0] == pytest.approx(expect, abs=1e-3)
    assert abs(th[1]) < 1e-2 and abs(th[2]) < 1e-2
    assert 10 < th[0] < 80  # it really droops


def test_gravity_droop_balances_every_joint_and_grows_with_weight():
    f = mean_finger()
    th, ok = F.gravity_droop_deg(f)
    assert ok and np.all(th > 0)
    res = [sp.moment_nm(t) for sp, t in zip(f.springs, th)] - F.gravity_moments_nm(f, th)
    assert np.max(np.abs(res)) < 1e-10
    heavy = mean_finger(densities={k: 1.5 * v for k, v in DENSITIES.items()})
    th2, _ = F.gravity_droop_deg(heavy)
    # MCP carries the whole finger: it droops more. A distal joint can droop
    # less, as the drooped chain turns its segment's lever arm away (fallback sections).
    assert th2[0] > th[0] and th2.sum() > th.sum()


def test_spring_from_curve_with_tone_offset_is_zero_at_zero_and_monotone():
    """OpenSim's passive curve has a muscle-tone offset at 0 deg; the spring must not inherit it."""
    ca = np.arange(0.0, 95.0, 5.0)
    cm = 1e-3 * (ca - 45.0)  # -0.045 N m at 0 deg, crosses zero at 45 deg
    curve = np.vstack([cm, cm, cm])
    targets = np.array([[90.0, 90.0, 80.0]])
    loads = np.array([[0.05, 0.02, 0.02]])
    springs, _ = F.springs_from_loads(targets, loads, ca, curve)
    for sp, a_max, m_pat in zip(springs, targets[0], loads[0]):
        assert sp.moment_nm(0.0) == pytest.approx(0.0, abs=1e-12)
        m = sp.moment_nm(ca)
        assert np.all(np.diff(m) >= -1e-12)
        # scaled by patient / curve at the largest target: (cm - cm0) * m_pat / cm(a_max)
        assert sp.moment_nm(a_max) == pytest.approx(1e-3 * a_max * m_pat / (1e-3 * (a_max - 45.0)))
