"""The unit under an end moment: case "rotation", the end hold in use, and the check against a chain.

Coarse 2D meshes (h = 2 mm, contact on) at P_T = 60 kPa: seconds per solve.
"""

import inspect

import numpy as np
import pytest
import yaml

from workflow import fem
from workflow.actuator.moment_check import compare, lookup, model_moment_nm, moment_check, unit_rotations_deg
from workflow.actuator.unit_model import UnitModel
from workflow.settings import REPO_ROOT

P_T, P_B = 60.0, 0.0


@pytest.fixture(scope="module")
def mesh():
    return fem.build_unit_mesh(None, h=2.0, dim=2)


def test_clamp_rotation_is_rigid(mesh):
    u = fem.clamp_rotation(mesh, 30.0)
    clamp = mesh.nodes["clamp"]
    x = mesh.mesh.p[:, clamp] + np.array([[u[2 * n] for n in clamp], [u[2 * n + 1] for n in clamp]])
    d0 = np.linalg.norm(mesh.mesh.p[:, clamp, None] - mesh.mesh.p[:, None, clamp], axis=0)
    np.testing.assert_allclose(np.linalg.norm(x[:, :, None] - x[:, None, :], axis=0), d0, atol=1e-12)
    assert fem.clamp_inclination_deg(30.0, 1.0) == pytest.approx(30.0)
    assert fem.clamp_inclination_deg(30.0, 0.5) == pytest.approx(15.0, abs=1e-9)  # symmetric chord


@pytest.mark.parametrize("hold", fem.END_HOLDS)
def test_rotation_at_zero_is_the_blocked_case(mesh, hold):
    b = fem.solve_unit(mesh, P_T, P_B, "blocked", end_hold=hold)
    r = fem.solve_unit(mesh, P_T, P_B, "rotation", end_angle_deg=0.0, end_hold=hold)
    assert b.converged and r.converged
    assert r.bending_moment_nm == pytest.approx(b.bending_moment_nm, rel=1e-9)


def test_one_end_hold_everywhere():
    """The blocked moment has one definition: the default of every function, the config and the schema."""
    cfg = yaml.safe_load((REPO_ROOT / "config" / "config.yaml").read_text())["actuator"]
    schema = yaml.safe_load((REPO_ROOT / "config" / "schema.yaml").read_text())["properties"]["actuator"]
    assert cfg["end_hold"] == schema["properties"]["end_hold"]["default"] == fem.DEFAULT_END_HOLD == "face"
    for fn in (fem.solve_unit, fem.unit_model, fem.held_end_nodes):
        assert inspect.signature(fn).parameters["end_hold"].default == fem.DEFAULT_END_HOLD
    um = fem.build_unit_mesh(None, h=2.0, dim=2)
    assert np.array_equal(fem.held_end_nodes(um), um.nodes["end"])


def test_unit_rotations_add_up_to_the_backbone_turn():
    um = fem.build_unit_mesh({"n_chambers": 3}, h=2.0, dim=2)
    assert np.allclose(unit_rotations_deg(um, np.zeros(um.mesh.p.size)), 0.0)
    r = fem.solve_unit(um, P_T, P_B, "free", keep_displacement=True)
    rot = unit_rotations_deg(um, r.displacement)
    assert rot.shape == (3,) and np.all(rot > 0)
    # the units tile the backbone: their sum is the turn from its first to its last element
    x = um.mesh.p + r.displacement.reshape(-1, 2).T
    paper = np.flatnonzero(np.abs(um.mesh.p[1]) <= 0.1 + 1e-9)
    cols = np.unique(np.round(um.mesh.p[0, paper], 6))

    def direction(k):
        a = paper[np.isclose(um.mesh.p[0, paper], cols[k])]
        b = paper[np.isclose(um.mesh.p[0, paper], cols[k + 1])]
        d = x[:, b].mean(axis=1) - x[:, a].mean(axis=1)
        return -np.degrees(np.arctan2(d[1], d[0]))

    assert rot.sum() == pytest.approx(direction(len(cols) - 2) - direction(0), rel=1e-9)


@pytest.mark.parametrize("start", [0.0, 31.5])
def test_a_kink_inside_a_unit_is_that_units_bend_alone(start):
    """unit_bends_deg cuts the backbone at the gap centres from the first block's start (the actuator's place in the
    finger model): a backbone straight but for one kink in the middle of chamber 2 puts the whole turn in unit 2."""
    from workflow.fem.actuator import unit_bends_deg

    depth, gap, n = 6.8, 1.0, 5
    length = n * depth + (n - 1) * gap
    s = start + np.linspace(0.0, length, 4 * n * 8 + 1)
    kink = start + 2 * (depth + gap) + depth / 2
    turn = np.radians(10.0)
    ref = np.column_stack([s, np.zeros_like(s)])
    after = s > kink
    cur = ref.copy()
    cur[after, 0] = kink + (s[after] - kink) * np.cos(turn)
    cur[after, 1] = -(s[after] - kink) * np.sin(turn)  # clockwise = positive bend
    bends = unit_bends_deg(cur, ref, n, depth, gap, start_mm=start)
    np.testing.assert_allclose(bends, [0.0, 0.0, 10.0, 0.0, 0.0], atol=1e-9)


def test_chain_check_favours_the_default_hold():
    """Middle unit of a chain of five (coarse) under end moments: the face hold's spring has its stiffness."""
    act = {"mesh": {"h_2d_mm": 2.0}}
    ds = moment_check(act, {"pairs_kpa": [[P_T, P_B]], "fractions": [0.0, 0.5], "chain_units": 5})
    assert ds.attrs["best_end_hold"] == fem.DEFAULT_END_HOLD
    assert abs(np.log(float(ds["compliance_ratio"].sel(end_hold="face")[0]))) < 0.25
    assert float(ds["compliance_ratio"].sel(end_hold="backbone")[0]) > 1.5
    for name in ("chain_moment_nm", "chain_mid_angle_deg", "angle_error_deg", "compliance_ratio"):
        assert "units" in ds[name].attrs and "long_name" in ds[name].attrs


@pytest.mark.parametrize("c", [0.0, 0.5, -0.5])
def test_model_moment_inverts_the_unit_model(c):
    model = UnitModel(lookup([100.0], [0.0], [10.0]), lookup([100.0], [0.0], [0.05]), shape_c=c, theta_scale_deg=20.0)
    th = np.array([-1.0, 0.0, 3.0, 7.5, 10.0, 11.0])
    m = model_moment_nm(model, 100.0, 0.0, th)
    np.testing.assert_allclose(model.angle_deg(100.0, 0.0, m), th, atol=1e-10)
    assert m[1] == pytest.approx(0.05) and m[4] == pytest.approx(0.0, abs=1e-12)


def test_compare_picks_the_hold_with_the_chain_stiffness():
    """Synthetic arrays: a chain whose middle unit follows the 'face' spring exactly."""
    fr = [0.0, 0.5]
    thf = np.array([10.0])
    mb = np.array([[0.05], [0.02]])  # face, backbone
    M = np.array([[0.0, 0.05, 0.025]])
    fea = {
        "free_angle_deg": thf,
        "free_status": np.zeros(1, np.int32),
        "blocked_moment_nm": mb,
        "blocked_status": np.zeros((2, 1), np.int32),
        "blocked_load_factor": np.ones((2, 1)),
        "chain_free_deg": thf,
        "chain_moment_nm": M,
        "chain_mid_angle_deg": thf[0] * (1 - M / 0.05),
        "chain_status": np.zeros((1, 3), np.int32),
        "wall_time_s": np.ones(1),
    }
    ds = compare(fea, [[100.0, 0.0]], fr, ["face", "backbone"])
    assert ds.attrs["best_end_hold"] == "face"
    np.testing.assert_allclose(ds["angle_error_deg"].sel(end_hold="face").values, 0.0, atol=1e-12)
    assert float(ds["compliance_ratio"].sel(end_hold="backbone")[0]) == pytest.approx(2.5)
