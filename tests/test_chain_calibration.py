"""The chain calibrated to the FEA: fitted to a double of the FEA (the chain itself with known span gains and
compliances, the test double only), it recovers them and predicts a held-out list; the unit is the analytic
stand-in of test_cascade."""

from __future__ import annotations

import numpy as np
import pytest
from test_cascade import model

from workflow.cascade import calibration as CAL
from workflow.cascade import model as C
from workflow.cascade import planning

FIT = np.array(
    [
        [40, 0, 40, 0, 40, 0, 40, 0],
        [80, 0, 80, 0, 80, 0, 80, 0],
        [0, 40, 0, 40, 0, 40, 0, 40],
        [70, 0, 70, 0, 0, 0, 0, 0],
        [0, 0, 0, 0, 70, 0, 0, 0],
        [0, 0, 0, 0, 0, 0, 70, 0],
        [60, 60, 60, 60, 60, 60, 60, 60],
    ],
    float,
)
HELD_OUT = np.array(
    [
        [55, 89, 55, 89, 55, 89, 50, 50],
        [72, 0, 72, 0, 0, 56, 60, 60],
        [73, 0, 73, 0, 73, 0, 60, 60],
        [73, 0, 73, 0, 73, 0, 73, 0],
        [50, 86, 50, 86, 55, 0, 55, 0],
    ],
    float,
)
GAIN, COMPLIANCE = np.array([0.55, 0.8, 0.9]), np.array([3.0, -1.0, 0.5])


def fea_double():
    """The 'FEA': the chain with span gains and compliances the paper's chain does not have."""
    return CAL.calibrated(model(), GAIN, COMPLIANCE)


def test_calibration_recovers_the_doubles_gains_and_predicts_the_held_out_list():
    truth = fea_double()
    P = np.vstack([FIT * s for s in (0.5, 1.0)])  # two load factors of each ramp
    A, ok = CAL.chain_angles(truth, P)
    assert ok.all()
    chain = model()
    before, _ = CAL.chain_angles(chain, HELD_OUT)
    target, _ = CAL.chain_angles(truth, HELD_OUT)
    assert np.max(np.abs(before - target)) > 5.0  # the paper's chain misses the 'FEA' by more than the tolerance
    cal = CAL.fit_chain(chain, P, A)
    assert cal.status > 0 and cal.rms_after_deg < 1e-3 < cal.rms_before_deg
    np.testing.assert_allclose(cal.gain, GAIN, rtol=1e-3)
    np.testing.assert_allclose(cal.compliance_rad_per_nm, COMPLIANCE, atol=1e-2)
    after, ok = CAL.chain_angles(CAL.calibrated(chain, cal.gain, cal.compliance_rad_per_nm), HELD_OUT)
    assert ok.all() and np.max(np.abs(after - target)) < 0.05


def test_a_calibrated_chain_plans_what_the_double_then_reaches():
    # planned on the calibrated chain, the double of the FEA reaches the pose; planned on the paper's chain it does not
    truth = fea_double()
    target = C.solve_equilibrium(truth, np.array([150, 0, 150, 0, 120, 0, 0, 0], float)).joint_angles_deg
    plain = planning.plan_exercise(model(), target, tol_deg=2.0)
    cal = planning.plan_exercise(CAL.calibrated(model(), GAIN, COMPLIANCE), target, tol_deg=2.0)
    assert plain.achieved and cal.achieved
    miss = lambda p: np.max(np.abs(C.solve_equilibrium(truth, p.pressures_kpa).joint_angles_deg - target))  # noqa: E731
    assert miss(cal) <= 2.0 < miss(plain)


def test_bad_calibration_data_is_refused():
    with pytest.raises(ValueError, match="expected"):
        CAL.fit_chain(model(), np.zeros((3, 7)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="too few"):
        CAL.fit_chain(model(), np.zeros((1, 8)), np.zeros((1, 3)))


def test_path_states_take_the_ramps_converged_states_nearest_the_load_factors():
    from workflow.fea_check.calibration import path_states

    hist = [{"phase": "gravity", "lam": 1.0, "joint_angles_deg": np.zeros(3)}] + [
        {"phase": "pressure", "lam": lam, "joint_angles_deg": np.full(3, 10 * lam)} for lam in (0.1, 0.3, 0.45, 0.8)
    ]
    p8 = np.arange(8.0)
    P, A, lam = path_states(hist, p8, (0.25, 0.5, 0.75, 1.0))
    np.testing.assert_allclose(lam, [0.3, 0.45, 0.8])  # nothing past the last state (0.8 < 1)
    np.testing.assert_allclose(P, lam[:, None] * p8)
    np.testing.assert_allclose(A[:, 0], 10 * lam)
    _, _, lam = path_states(hist[:2], p8, (0.25, 0.5))  # stopped before the first point: its last state
    np.testing.assert_allclose(lam, [0.1])


def test_a_bad_fit_set_is_refused_before_any_fea():
    import pandas as pd

    from workflow.common.constants import PRESSURE_NAMES
    from workflow.fea_check.entry_calibration import calibration_sets

    t8 = pd.DataFrame([np.full(8, 100.0)], index=pd.Index(["TGE1"], name="exercise"), columns=PRESSURE_NAMES)
    half = lambda p3: (p3 / 2, None)  # noqa: E731
    sets, held = calibration_sets({"fit_pressures_2d_kpa": [[10] * 8, [20] * 8]}, t8, half, 100.0)
    assert list(sets) == ["fit_1", "fit_2", "TGE1"] and held == ["TGE1"]
    np.testing.assert_allclose(sets["TGE1"], 50.0)
    with pytest.raises(ValueError, match=r"fit_pressures_2d_kpa\[1\].*within 0 and 100"):
        calibration_sets({"fit_pressures_2d_kpa": [[10] * 8, [150] + [0] * 7]}, t8, half, 100.0)


def test_the_calibration_stage_fits_the_fea_states_and_judges_the_held_out_sets(monkeypatch):
    # the FEA replaced by the double (its ramps' states at four load factors); the stage fits on the fit sets only,
    # recovers the double's parameters and records every state, the sets' statuses and the held-out errors
    from types import SimpleNamespace

    from workflow.fea_check import calibration as FCAL

    truth = fea_double()

    def fake_gravity(fea, solver):
        return SimpleNamespace(status=0, load_factor=1.0, joint_angles_deg=np.zeros(3), wall_time_s=0.0, reason="")

    def fake_check(fea, name, p42, solver, gravity=None):
        p8 = np.asarray(p42, float).ravel()
        hist = [
            {"phase": "pressure", "lam": lam, "joint_angles_deg": CAL.chain_angles(truth, lam * p8)[0][0]}
            for lam in (0.25, 0.5, 0.75, 1.0)
        ]
        res = SimpleNamespace(status=0, load_factor=1.0, history=hist, newton_iterations=7)
        return SimpleNamespace(result=res, angle_deg=hist[-1]["joint_angles_deg"], wall_time_s=0.1)

    monkeypatch.setattr(FCAL, "gravity_state", fake_gravity)
    monkeypatch.setattr(FCAL, "check_exercise", fake_check)
    sets = {f"fit_{k}": p for k, p in enumerate(FIT, start=1)} | {f"TGE{k}": p for k, p in enumerate(HELD_OUT, 1)}
    held = [f"TGE{k}" for k in range(1, 6)]
    ds, cal = FCAL.run_chain_calibration(None, model(), sets, held, solver={})
    np.testing.assert_allclose(cal.gain, GAIN, rtol=1e-3)
    assert ds.sizes["state"] == 4 * len(sets) and int((ds["role"] == "held_out").sum()) == 4 * len(held)
    assert ds.attrs["max_error_held_out_before_deg"] > 5.0 > 0.05 > ds.attrs["max_error_held_out_after_deg"]
    assert list(ds["set_status"].values) == [0] * len(sets) and "flag_meanings" in ds["set_status"].attrs
    np.testing.assert_allclose(ds["span_gain"].values, cal.gain)
