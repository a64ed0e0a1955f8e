"""Unit FEA under a prescribed end rotation (case "rotation") and the unit model against it (issue 5 item 4).

Coarse 2D unit (h = 2 mm, contact on) at P_T = 60 kPa: seconds per solve.
"""

import numpy as np
import pytest

from workflow import fem
from workflow.unit_model import UnitModel
from workflow.unit_moment_check import compare, lookup, model_moment_nm

P_T, P_B = 60.0, 0.0


@pytest.fixture(scope="module")
def mesh():
    return fem.build_unit_mesh(None, h=2.0, dim=2)


@pytest.fixture(scope="module")
def ends(mesh):
    """Free angle (total, deg) and the blocked moments of both end holds (N m)."""
    free = fem.solve_unit(mesh, P_T, P_B, "free")
    assert free.converged
    blocked = {hold: fem.solve_unit(mesh, P_T, P_B, "blocked", end_hold=hold) for hold in fem.END_HOLDS}
    assert all(b.converged for b in blocked.values())
    return free.bending_angle_total_deg, {h: b.bending_moment_nm for h, b in blocked.items()}


@pytest.fixture(scope="module")
def curve(mesh, ends):
    """Backbone-held moment at end inclinations -0.1, 0.5, 1.0 of the free angle."""
    theta_f, _ = ends
    out = {}
    for f in (-0.1, 0.5, 1.0):
        r = fem.solve_unit(mesh, P_T, P_B, "rotation", end_angle_deg=f * theta_f, end_hold="backbone")
        assert r.converged, r.reason
        assert r.end_angle_deg == pytest.approx(f * theta_f, abs=1e-9)
        out[f] = r.bending_moment_nm
    return out


def test_clamp_rotation_is_rigid(mesh):
    u = fem.clamp_rotation(mesh, 30.0)
    clamp = mesh.nodes["clamp"]
    x = mesh.mesh.p[:, clamp] + np.array([[u[2 * n] for n in clamp], [u[2 * n + 1] for n in clamp]])
    d0 = np.linalg.norm(mesh.mesh.p[:, clamp, None] - mesh.mesh.p[:, None, clamp], axis=0)
    np.testing.assert_allclose(np.linalg.norm(x[:, :, None] - x[:, None, :], axis=0), d0, atol=1e-12)
    assert fem.clamp_inclination_deg(30.0, 1.0) == pytest.approx(30.0)
    assert fem.clamp_inclination_deg(30.0, 0.5) == pytest.approx(15.0, abs=1e-9)  # symmetric chord


@pytest.mark.parametrize("hold", fem.END_HOLDS)
def test_rotation_at_zero_is_the_blocked_case(mesh, ends, hold):
    r = fem.solve_unit(mesh, P_T, P_B, "rotation", end_angle_deg=0.0, end_hold=hold)
    assert r.bending_moment_nm == pytest.approx(ends[1][hold], rel=1e-9)


def test_backbone_hold_moment_vanishes_at_the_free_angle(ends, curve):
    assert abs(curve[1.0]) < 0.05 * ends[1]["backbone"]


def test_moment_decreases_with_inclination(ends, curve):
    m = [curve[-0.1], ends[1]["backbone"], curve[0.5], curve[1.0]]
    assert np.all(np.diff(m) < 0)


def test_unit_model_agrees_with_the_fea_at_half_the_free_angle(ends, curve):
    """The linear spring built on the same free/blocked runs: within 10 % of M_b (measured: a few %)."""
    theta_f, mb = ends
    model = UnitModel(lookup([P_T], [P_B], [theta_f / 3]), lookup([P_T], [P_B], [mb["backbone"]]), theta_scale_deg=30.0)
    m = model_moment_nm(model, P_T, P_B, 0.5 * theta_f / 3)
    assert abs(m - curve[0.5]) < 0.10 * mb["backbone"]
    # and the model's angle under that FEA moment, per unit
    assert model.angle_deg(P_T, P_B, curve[0.5]) == pytest.approx(0.5 * theta_f / 3, abs=0.1 * theta_f / 3)


@pytest.mark.parametrize("c", [0.0, 0.5, -0.5])
def test_model_moment_inverts_the_unit_model(c):
    model = UnitModel(lookup([100.0], [0.0], [10.0]), lookup([100.0], [0.0], [0.05]), shape_c=c, theta_scale_deg=20.0)
    th = np.array([-1.0, 0.0, 3.0, 7.5, 10.0, 11.0])
    m = model_moment_nm(model, 100.0, 0.0, th)
    np.testing.assert_allclose(model.angle_deg(100.0, 0.0, m), th, atol=1e-10)
    assert m[1] == pytest.approx(0.05) and m[4] == pytest.approx(0.0, abs=1e-12)


def test_compare_dataset():
    """The check's dataset from synthetic FEA arrays: dims, errors, status and the perfect-spring case."""
    pairs, fr = [[100.0, 0.0], [0.0, 100.0]], [0.5, 1.0]
    thf = np.array([10.0, -10.0])
    mb = np.array([[0.05, -0.05]])
    end = thf[:, None] * np.array(fr)[None]
    fea = {"free_angle_deg": thf, "free_status": np.zeros(2, np.int32), "blocked_moment_nm": mb,
           "blocked_status": np.zeros((1, 2), np.int32), "end_angle_deg": end,
           "moment_fea_nm": mb[:, :, None] * (1 - np.array(fr))[None, None], "backbone_angle_deg": end[None],
           "status": np.zeros((1, 2, 2), np.int32), "wall_time_s": np.ones((1, 2, 2))}
    fea["status"][0, 1, 1] = 1
    ds = compare(fea, pairs, fr, ["backbone"])
    assert ds["moment_fea_nm"].dims == ("end_hold", "point", "fraction")
    np.testing.assert_allclose(ds["moment_error_nm"].values[0, 0], 0.0, atol=1e-12)
    assert np.isnan(ds["moment_error_nm"].values[0, 1, 1])
    assert ds.attrs["max_abs_rel_error_backbone"] == pytest.approx(0.0, abs=1e-12)
    assert ds.attrs["failed_rotations_backbone"] == 1
    for name in ("moment_fea_nm", "moment_model_nm", "moment_error_rel", "status"):
        assert "units" in ds[name].attrs and "long_name" in ds[name].attrs
