"""Unit model under an external moment, calibration hook and inverse queries.

theta_f and M_b below are a TEST DOUBLE (smooth analytic functions with the
unit's symmetries), not actuator results.
"""

from __future__ import annotations

import numpy as np
import pytest
from _doubles import double_angle as free  # noqa: E402
from _doubles import double_moment as blocked
from _doubles import double_response

from workflow.actuator import unit_inverse, unit_model
from workflow.actuator.unit_model import UnitModel


def k_diagonal(p):
    """Analytic limit of M_b / theta_f at P_T = P_B = p for the double."""
    return 2.0e-3 * (1 + 0.2 * p / 600) * 250.0 / (12.0 * (1 - 0.4 * p / 600))


@pytest.fixture
def model():
    return UnitModel(free, blocked, p_max_kpa=300.0)


@pytest.mark.parametrize("c", [0.0, 0.4, -0.5])
def test_the_two_ends_are_exact(model, c):
    m = model.with_shape(c) if c else model
    pt = np.array([300.0, 200.0, 50.0, 0.0])
    pb = np.array([0.0, 60.0, 10.0, 120.0])
    np.testing.assert_allclose(m.angle_deg(pt, pb, 0.0), free(pt, pb), rtol=1e-12)
    np.testing.assert_allclose(m.angle_deg(pt, pb, blocked(pt, pb)), 0.0, atol=1e-10)


def test_linear_spring_between_the_ends(model):
    pt, pb = 250.0, 40.0
    np.testing.assert_allclose(model.angle_deg(pt, pb, 0.5 * blocked(pt, pb)), 0.5 * free(pt, pb))
    # a resisting moment reduces the angle, an assisting one increases it
    assert model.angle_deg(pt, pb, 0.001) < free(pt, pb) < model.angle_deg(pt, pb, -0.001)


def test_shape_term_bends_the_curve(model):
    pt, pb = 250.0, 40.0
    mid = 0.5 * blocked(pt, pb)
    assert model.with_shape(0.5).angle_deg(pt, pb, mid) > model.angle_deg(pt, pb, mid)


def test_top_bottom_symmetry(model):
    rng = np.random.default_rng(0)
    pt, pb = rng.uniform(0, 300, 50), rng.uniform(0, 300, 50)
    m = rng.uniform(-0.05, 0.05, 50)
    np.testing.assert_allclose(model.angle_deg(pb, pt, -m), -model.angle_deg(pt, pb, m), atol=1e-9)


def test_stiffness_near_the_diagonal_is_the_limit(model):
    for p in (0.0, 100.0, 250.0):
        k = model.stiffness_nm_per_deg(p, p)
        assert np.isfinite(k)
        # offset pair at +-5 kPa: the tanh curvature error is ~(10/250)^2/3
        assert k == pytest.approx(k_diagonal(p), rel=2e-3) if p > 0 else k > 0
    # continuity across the floor that switches to the offset estimate
    np.testing.assert_allclose(
        model.stiffness_nm_per_deg(100.0, 99.999), model.stiffness_nm_per_deg(100.0, 100.0), rtol=5e-3
    )
    # at P_T = P_B the unit bends only under the external moment: theta = -M / k
    np.testing.assert_allclose(model.angle_deg(150.0, 150.0, 0.01), -0.01 / k_diagonal(150.0), rtol=5e-3)


def test_vectorised_broadcasting(model):
    out = model.angle_deg(np.linspace(0, 300, 5)[:, None], np.linspace(0, 300, 4)[None, :], 0.002)
    assert out.shape == (5, 4)
    assert model.free_angle_deg(np.zeros((2, 3)), 0.0).shape == (2, 3)


def test_fit_shape_recovers_c_and_verify(model):
    truth = model.with_shape(0.3)
    rng = np.random.default_rng(1)
    pt, pb = rng.uniform(100, 300, 12), rng.uniform(0, 60, 12)
    m = rng.uniform(0.1, 0.9, 12) * blocked(pt, pb)
    fea = truth.angle_deg(pt, pb, m)  # stands for FEA runs at prescribed end moments
    fitted = unit_model.fit_shape(model, pt, pb, m, fea)
    assert fitted.shape_c == pytest.approx(0.3, abs=1e-9)
    assert unit_model.verify(fitted, pt, pb, m, fea)["max_abs_error_deg"] < 1e-9
    assert unit_model.verify(model, pt, pb, m, fea)["max_abs_error_deg"] > 0.1


def test_pressures_on_ray(model):
    res = unit_inverse.pressures_on_ray(model, [5.0, -4.0, 50.0], [0.005, 0.0, 0.0], [0.2, np.inf, 0.0])
    assert list(res["status"]) == [0, 0, 1]
    pt, pb = res["p_top_kpa"], res["p_bottom_kpa"]
    assert pb[0] / pt[0] == pytest.approx(0.2)
    assert pt[1] == 0.0 and pb[1] > 0
    np.testing.assert_allclose(model.angle_deg(pt[:2], pb[:2], [0.005, 0.0]), [5.0, -4.0], atol=1e-4)
    assert np.isnan(pt[2]) and np.isnan(pb[2])


def test_min_norm_against_brute_force(model):
    target, m = 4.0, 0.003
    res = unit_inverse.min_norm_pressures(model, target, m)
    assert res["status"] == 0
    pt, pb = float(res["p_top_kpa"]), float(res["p_bottom_kpa"])
    assert model.angle_deg(pt, pb, m) == pytest.approx(target, abs=1e-3)
    g = np.linspace(0, 300, 601)
    PT, PB = np.meshgrid(g, g, indexing="ij")
    th = model.angle_deg(PT, PB, m)
    near = np.abs(th - target) < 0.02
    brute = np.hypot(PT, PB)[near].min()
    assert np.hypot(pt, pb) <= brute + 0.5
    # unreachable target
    assert unit_inverse.min_norm_pressures(model, 40.0, 0.0)["status"] == 1


def test_on_a_fitted_surrogate():
    from workflow.actuator import surrogates

    resp = double_response(6, 8, n_shards=1)
    s = surrogates.fit_surrogate(resp, "rbf", fea="3d")
    um = UnitModel.from_surrogate(s)
    assert um.p_max_kpa == 300.0
    pt, pb = np.array([280.0, 120.0]), np.array([30.0, 200.0])
    np.testing.assert_allclose(um.angle_deg(pt, pb, 0.0), s.angle_deg(pt, pb))
    np.testing.assert_allclose(um.angle_deg(pt, pb, s.moment_nm(pt, pb)), 0.0, atol=1e-9)


def test_finite_everywhere_on_a_knn_surrogate():
    """The cascade needs a finite angle at every pressure pair, also on KNN's flat stretches."""
    from workflow.actuator import surrogates

    resp = double_response(6, 5, n_shards=1)
    um = UnitModel.from_surrogate(surrogates.fit_surrogate(resp, "knn", fea="3d", k=4))
    g = np.linspace(0, 300, 31)
    th = um.angle_deg(g[:, None], g[None, :], 0.004)
    assert np.all(np.isfinite(th))
    assert np.all(um.stiffness_nm_per_deg(g[:, None], g[None, :]) > 0)


def test_verification_points_and_dataset(model):
    pts = unit_model.verification_points(model, [150.0, 300.0], [0.0, 30.0], fractions=(0.0, 0.5, 1.0))
    assert pts["m_ext_nm"].shape == (6,)
    np.testing.assert_allclose(pts["predicted_deg"][pts["fraction"] == 1.0], 0.0, atol=1e-10)
    np.testing.assert_allclose(pts["predicted_deg"][pts["fraction"] == 0.0], free([150.0, 300.0], [0.0, 30.0]))
    # FEA stand-in: a curve bent with c = 0.2; one run failed
    fea = model.with_shape(0.2).angle_deg(pts["p_top_kpa"], pts["p_bottom_kpa"], pts["m_ext_nm"])
    status = np.array([0, 0, 0, 0, 1, 0])
    ds = unit_model.verification_dataset(model, pts["p_top_kpa"], pts["p_bottom_kpa"], pts["m_ext_nm"], fea, status)
    assert np.isnan(ds["error_deg"].values[4])
    mid = pts["fraction"] == 0.5
    assert np.all(np.abs(ds["error_deg"].values[mid & (status == 0)]) > 0.01)  # the linear spring misses the bend
    assert ds.attrs["max_abs_error_deg"] > 0.01
    for v in ds.data_vars:
        assert ds[v].attrs["units"] and ds[v].attrs["long_name"]
