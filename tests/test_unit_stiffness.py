"""A unit's bending stiffness inside a chain, at prescribed end rotations (workflow/actuator/stiffness.py).

Coarse 2D chain of three chambers (h = 2 mm, no contact): a second or two per solve.
"""

import numpy as np
import pytest

from workflow import fem
from workflow.actuator.moment_check import chain_mesh
from workflow.actuator.stiffness import (
    SOLVES,
    StiffnessTable,
    compare_model,
    heldout_errors,
    rotation_stiffness,
    stiffness_dataset,
)
from workflow.actuator.unit_model import UnitModel

J = {name: k for k, (name, _, _) in enumerate(SOLVES)}


@pytest.fixture(scope="module")
def chain():
    return chain_mesh(fem.build_unit_mesh(None, h=2.0, dim=2), chain_units=3)


@pytest.fixture(scope="module")
def study(chain):
    pairs = [[0.0, 0.0], [50.0, 50.0], [20.0, 0.0]]
    return rotation_stiffness(chain, pairs, delta_deg=1.0, solve_kwargs={"contact": False})


def test_every_solve_converges(study):
    assert (study["status"] == 0).all() and np.allclose(study["load_factor"], 1.0)


def test_co_pressurised_chain_is_mirror_symmetric(study):
    # P_T = P_B: no free angle, no blocked moment, and the moment-angle curve odd about the blocked state;
    # a top/bottom asymmetry (pressure on one side only, a sign error in the hold) breaks this
    m, th = study["moment_nm"][1], study["mid_angle_deg"][1]
    scale = abs(m[J["plus"]])
    assert abs(th[J["free"]]) < 1e-9 and abs(m[J["blocked"]]) < 1e-9 * scale
    assert m[J["plus"]] == pytest.approx(-m[J["minus"]], rel=1e-8)
    assert th[J["plus"]] == pytest.approx(-th[J["minus"]], rel=1e-8)
    assert m[J["plus"]] < 0 < th[J["plus"]]  # rotating further in the P_T sense takes a negative couple


def test_moment_is_straight_about_the_blocked_state_at_small_pressure(study):
    # 20 kPa on one side, no contact: M is linear in the rotation about the blocked state, so the blocked
    # moment is the mean of the two held rotations' (second difference under 1 % of the change)
    m = study["moment_nm"][2]
    assert m[J["minus"]] > m[J["blocked"]] > m[J["plus"]]
    assert abs(m[J["plus"]] + m[J["minus"]] - 2 * m[J["blocked"]]) < 0.01 * (m[J["minus"]] - m[J["plus"]])


def test_co_pressurising_stiffens_the_unit(study):
    # both chambers at 50 kPa make an interior unit stiffer than at rest, without contact by 13 % (the walls'
    # pretension; with contact the pressed walls across the gaps add far more, see docs/actuator.md)
    k = study["k_nm_per_deg"]
    assert np.all(k > 0) and k[1] > 1.08 * k[0]


def test_model_comparison_and_dataset(study):
    # a unit model whose secant is twice the FEA's at the one-sided pair: error +1 there; the dataset carries both
    k_fea = dict(zip(map(tuple, study["pairs_kpa"]), study["k_nm_per_deg"]))

    def angle(pt, pb):
        return np.asarray(pt, float) - np.asarray(pb, float) + 0.0

    def moment(pt, pb):
        pt, pb = np.broadcast_arrays(np.asarray(pt, float), np.asarray(pb, float))
        k = np.array([k_fea.get((a, b), 0.0) for a, b in zip(pt.ravel(), pb.ravel())]).reshape(pt.shape)
        return 2.0 * k * angle(pt, pb)

    cmp = compare_model(study, UnitModel(angle, moment))
    assert cmp["k_model_rel_error"][2] == pytest.approx(1.0, rel=1e-12)
    ds = stiffness_dataset(study, delta_deg=1.0, h_mm=2.0, chain_units=3, model=cmp)
    assert ds.sizes == {"pair": 3, "solve": len(SOLVES)}
    assert ds["k_nm_per_deg"].attrs["units"] == "N m / degree" and "k_model_rel_error" in ds


def test_bad_inputs_are_named(chain):
    with pytest.raises(ValueError, match="delta_deg"):
        rotation_stiffness(chain, [[0.0, 0.0]], delta_deg=0.0)
    with pytest.raises(ValueError, match="chain cut at gap centres"):
        rotation_stiffness(fem.build_unit_mesh(None, h=2.0, dim=2), [[0.0, 0.0]])


def test_stiffness_table_is_exact_at_its_pairs_symmetric_and_never_extrapolates():
    # log k linear in the folded pressures is reproduced everywhere inside the hull; a locked pair (NaN) is left out
    g = np.array([0.0, 100.0, 200.0, 300.0])
    P = np.array([(a, b) for a in g for b in g if a >= b])

    def k_of(a, b):
        return np.exp(-3.0 + 0.01 * np.maximum(a, b) + 0.004 * np.minimum(a, b))

    k = k_of(P[:, 0], P[:, 1])
    k[(P[:, 0] == 300.0) & (P[:, 1] == 300.0)] = np.nan  # locked
    table = StiffnessTable(P[:, 0], P[:, 1], k)
    q = np.array([[50.0, 0.0], [150.0, 60.0], [250.0, 120.0], [120.0, 250.0]])
    assert np.allclose(table(q[:, 0], q[:, 1]), k_of(q[:, 0], q[:, 1]), rtol=1e-12)
    assert table(60.0, 150.0) == pytest.approx(table(150.0, 60.0), rel=1e-14)
    assert np.isnan(table(350.0, 0.0)) and np.isnan(table(-10.0, 0.0))
    assert np.isnan(table(290.0, 290.0))  # beyond the last finite pair on the diagonal: no value, not a guess
    # a failed pair inside the grid is left out, not kept as a NaN vertex: its neighbours' triangles cover it
    k3 = k_of(P[:, 0], P[:, 1])
    k3[(P[:, 0] == 200.0) & (P[:, 1] == 100.0)] = np.nan
    assert StiffnessTable(P[:, 0], P[:, 1], k3)(200.0, 100.0) == pytest.approx(k_of(200.0, 100.0), rel=1e-12)
    with pytest.raises(ValueError, match="three pairs"):
        StiffnessTable([0.0, 100.0, 200.0], [0.0, 0.0, 0.0], [1.0, 2.0, 3.0])  # collinear


def test_unit_model_takes_the_measured_stiffness_inside_its_window_only():
    # secant k = 2 everywhere; the measurement 5 where |theta_f| < 1.5 deg, blended into the secant up to 3 deg
    def angle(pt, pb):
        return 0.1 * (np.asarray(pt, float) - np.asarray(pb, float))

    def moment(pt, pb):
        return 2.0 * angle(pt, pb)

    spring = UnitModel(angle, moment)
    measured = UnitModel(angle, moment, measured_stiffness=lambda pt, pb: np.full(np.shape(pt), 5.0))
    pt, pb = np.array([100.0, 100.0, 100.0, 100.0]), np.array([100.0, 90.0, 80.0, 0.0])  # theta_f 0, 1, 2, 10 deg
    w = 2.0 * (1.0 - 2.0 / 3.0)  # the blend's weight at 2 deg
    assert np.allclose(measured.stiffness_nm_per_deg(pt, pb), [5.0, 5.0, 5.0**w * 2.0 ** (1 - w), 2.0])
    # continuous at the window's edge
    edge = measured.stiffness_nm_per_deg(100.0, 100.0 - np.array([29.999, 30.001]))
    assert abs(edge[0] - edge[1]) < 1e-3
    # where the table has no value inside the window (outside its pairs) the secant (or its offset estimate) stays
    gap = UnitModel(angle, moment, measured_stiffness=lambda pt, pb: np.where(np.asarray(pt) > 90.0, np.nan, 5.0))
    assert np.allclose(gap.stiffness_nm_per_deg(pt, pb), 2.0)
    assert np.allclose(spring.stiffness_nm_per_deg(pt[1:], pb[1:]), 2.0)
    # at P_T = P_B the angle under a moment is -M / k_measured
    assert measured.angle_deg(150.0, 150.0, 1.0) == pytest.approx(-0.2)


def test_stiffness_table_reproduces_heldout_fea_pairs(chain):
    # the table from a coarse grid (three pairs, no contact) predicts the chain's stiffness at three pairs it was not
    # built on: moment error over the +-1 deg window under 0.2 % of the grid's largest blocked moment, k within 2 %
    fit = [[0.0, 0.0], [60.0, 0.0], [60.0, 60.0]]
    held = [[30.0, 0.0], [30.0, 30.0], [60.0, 30.0]]
    res = rotation_stiffness(chain, fit + held, delta_deg=1.0, solve_kwargs={"contact": False})
    P, k = res["pairs_kpa"], res["k_nm_per_deg"]
    assert np.isfinite(k).all()
    table = StiffnessTable(P[:3, 0], P[:3, 1], k[:3])
    m_max = float(np.abs(res["moment_nm"][:3, J["blocked"]]).max())
    e = heldout_errors(table, P[3:, 0], P[3:, 1], k[3:], 1.0, m_max)
    assert np.all(np.abs(e["rel_error"]) < 0.02)
    assert np.all(e["moment_error_share"] < 0.002)
    # and a table with the wrong trend (k halved at 60 kPa) fails the same check
    wrong = StiffnessTable(P[:3, 0], P[:3, 1], k[:3] * np.array([1.0, 0.5, 0.5]))
    assert np.abs(heldout_errors(wrong, P[3:, 0], P[3:, 1], k[3:], 1.0, m_max)["rel_error"]).max() > 0.1


def _study_result(extra=()):
    """A stiffness study's result on the grid 0/100/200 kPa (P_T >= P_B) and ``extra`` pairs, k = exp(0.01 P_T +
    0.002 P_B) N m/deg, every solve converged (what `rotation_stiffness` returns)."""
    g = np.array([0.0, 100.0, 200.0])
    P = np.array([(a, b) for a in g for b in g if a >= b] + list(extra))
    n = (len(P), len(SOLVES))
    return {
        "pairs_kpa": P,
        "k_nm_per_deg": np.exp(0.01 * P[:, 0] + 0.002 * P[:, 1]),
        "moment_nm": np.zeros(n),
        "mid_angle_deg": np.zeros(n),
        "status": np.zeros(n, dtype=np.int8),
        "load_factor": np.ones(n),
        "wall_time_s": np.zeros(n),
    }


def test_table_from_a_study_dataset_uses_its_fit_pairs_only():
    res = _study_result(extra=[[150.0, 50.0]])
    P = res["pairs_kpa"]
    res["k_nm_per_deg"][-1] = 99.0  # a held-out pair far off the trend: used, it would move the table there
    fit = np.arange(len(P)) < len(P) - 1
    ds = stiffness_dataset(res, delta_deg=3.0, h_mm=1.0, chain_units=5, fit=fit)
    table = StiffnessTable.from_study(ds)
    assert table(150.0, 50.0) == pytest.approx(np.exp(1.5 + 0.1), rel=1e-12)


def test_the_fea_checks_2d_chain_takes_the_table_of_a_study_file(tmp_path):
    # fea_check.unit_stiffness: the check reads unit_stiffness.nc and its 2D unit takes the table inside the
    # study's window only; no file (the switch off) leaves the unit model as it was
    from workflow.common.provenance import write_dataset
    from workflow.fea_check.entry import with_measured_stiffness

    res = _study_result()
    nc = tmp_path / "unit_stiffness.nc"
    write_dataset(
        stiffness_dataset(res, delta_deg=3.0, h_mm=1.0, chain_units=5), nc, rule="t", config_slice={}, title="t"
    )

    def angle(pt, pb):
        return 0.1 * (np.asarray(pt, float) - np.asarray(pb, float))

    unit = UnitModel(angle, lambda pt, pb: 2.0 * angle(pt, pb))
    assert with_measured_stiffness(unit, None) is unit
    measured = with_measured_stiffness(unit, nc)
    assert measured.stiffness_nm_per_deg(100.0, 100.0) == pytest.approx(np.exp(1.2), rel=1e-12)
    assert measured.stiffness_nm_per_deg(100.0, 0.0) == pytest.approx(2.0)  # 10 deg off the diagonal: the secant
    assert unit.stiffness_nm_per_deg(100.0, 100.0) != pytest.approx(np.exp(1.2))
