"""The bounded quasi-Newton inverse of the FEA check, on doubles of the FEA whose answers are known."""

import numpy as np
import pytest

from workflow.fea_check.inverse import bounded_broyden, tie_matrix

P_MAX = 300.0


def _double(stiff=None, fail_calls=()):
    """A nonlinear stand-in for the FEA: each joint bends with the net (top - bottom) pressure of the groups that
    span it, saturating (tanh), with a cross-coupling the reduced-order chain does not know; it fails above
    ``fail_above`` kPa on any chamber, as a stalled solve does."""
    stiff = np.array([0.55, 0.45, 0.35]) if stiff is None else stiff
    calls = []

    def forward(p):
        calls.append(np.array(p))
        if len(calls) - 1 in fail_calls:
            return np.full(3, np.nan), False
        net = np.array([p[0] - p[1] + p[2] - p[3], p[4] - p[5], p[6] - p[7]])
        y = 110.0 * np.tanh(stiff * net / 110.0)
        y[2] += 0.1 * y[1]  # DIP follows PIP a little
        return y, True

    return forward, calls


def _chain_jacobian():
    """The 'reduced-order chain': the double's small-pressure slopes without the coupling, 30 % too stiff."""
    J = np.zeros((3, 8))
    J[0, [0, 2]], J[0, [1, 3]] = 0.55, -0.55
    J[1, 4], J[1, 5] = 0.45, -0.45
    J[2, 6], J[2, 7] = 0.35, -0.35
    return 1.3 * J


@pytest.mark.parametrize("target", [[90.0, 0.0, 0.0], [90.0, 90.0, 0.0], [0.0, 80.0, 60.0], [-20.0, 10.0, 0.0]])
def test_inverse_reaches_a_reachable_target_within_its_budget_with_cmc_tied_to_mcp(target):
    forward, calls = _double()
    E = tie_matrix(8, [(0, 2), (1, 3)])  # P_CMC = P_MCP
    p0 = np.zeros(8)
    y0, ok0 = forward(p0)
    res = bounded_broyden(forward, p0, y0, ok0, target, _chain_jacobian(), lo=0.0, hi=P_MAX, tol=2.0, budget=6, E=E)
    assert res.reached, res.reason
    # Broyden's update of the chain's (30 % too stiff) Jacobian: 2-5 solves; with the chain's Jacobian kept, 7-9
    assert res.solves <= 6 and len(calls) == res.solves + 1
    p = res.pressures_kpa[res.best]
    assert np.max(np.abs(res.angles_deg[res.best] - target)) <= 2.0
    np.testing.assert_allclose(p[[0, 1]], p[[2, 3]])  # the tie holds
    assert np.all(p >= 0) and np.all(p <= P_MAX)
    # least pressure in the free directions: no group pushes against itself beyond what the target needs
    assert np.all(np.minimum(p[0::2], p[1::2]) < 5.0)


def test_inverse_stops_at_a_bound_and_names_the_chambers_that_block():
    forward, _ = _double(stiff=np.array([0.55, 0.12, 0.35]))  # a weak PIP span: 90 deg needs ~750 kPa
    p0 = np.zeros(8)
    y0, ok0 = forward(p0)
    res = bounded_broyden(
        forward, p0, y0, ok0, [0.0, 90.0, 0.0], _chain_jacobian(), lo=0.0, hi=P_MAX, tol=2.0, budget=10
    )
    assert not res.reached
    # PIP needs more net pressure: its top chamber is at the limit, its bottom one already empty
    assert "bounds block progress" in res.reason and res.blocking == ["P_PIP_T", "P_PIP_B"]
    assert res.solves < 10  # it stopped because of the bound, not the budget
    assert res.pressures_kpa[res.best][4] == pytest.approx(P_MAX)


def test_inverse_backs_off_from_a_failed_forward_solve_and_records_it():
    forward, _ = _double(fail_calls={1})  # the first solve after the start stalls
    p0 = np.zeros(8)
    y0, ok0 = forward(p0)
    res = bounded_broyden(
        forward,
        p0,
        y0,
        ok0,
        [90.0, 0.0, 0.0],
        _chain_jacobian(),
        lo=0.0,
        hi=P_MAX,
        tol=2.0,
        budget=8,
        max_step_kpa=40.0,
    )
    assert res.reached, res.reason
    # the stalled solve is recorded, the next step is half as long and still gets there
    assert res.ok[1] is False and np.isnan(res.angles_deg[1]).all() and res.ok[res.best]
    first, second = (np.max(np.abs(res.pressures_kpa[k] - p0)) for k in (1, 2))
    assert first == pytest.approx(40.0) and second == pytest.approx(20.0)


def test_a_failed_step_inside_the_step_box_is_halved_not_repeated():
    # the first step (about 33 kPa) lies well inside the 100 kPa box: halving the box would give the same step and
    # the same stalled solve again (seen on the FEA: two identical corrections); the step itself is halved
    forward, calls = _double(fail_calls={1})
    p0 = np.zeros(8)
    y0, ok0 = forward(p0)
    res = bounded_broyden(
        forward,
        p0,
        y0,
        ok0,
        [20.0, 0.0, 0.0],
        _chain_jacobian(),
        lo=0.0,
        hi=P_MAX,
        tol=2.0,
        budget=8,
        max_step_kpa=100.0,
    )
    first, second = (np.max(np.abs(res.pressures_kpa[k] - p0)) for k in (1, 2))
    assert first < 50.0 and second == pytest.approx(first / 2)
    assert res.reached, res.reason


def test_inverse_stops_at_its_budget():
    forward, calls = _double()
    p0 = np.zeros(8)
    y0, ok0 = forward(p0)
    res = bounded_broyden(
        forward, p0, y0, ok0, [90.0, 90.0, 60.0], _chain_jacobian(), lo=0.0, hi=P_MAX, tol=1e-6, budget=2
    )
    assert not res.reached and res.solves == 2 and "budget" in res.reason


def test_inverse_keeps_a_tied_group_within_the_tightest_bound_of_its_members():
    forward, _ = _double()
    hi = np.full(8, P_MAX)
    hi[0] = 100.0  # the CMC top chamber bears less: with P_CMC = P_MCP, so does the MCP top chamber
    p0 = np.zeros(8)
    y0, ok0 = forward(p0)
    E = tie_matrix(8, [(0, 2), (1, 3)])
    res = bounded_broyden(
        forward, p0, y0, ok0, [120.0, 0.0, 0.0], _chain_jacobian(), lo=0.0, hi=hi, tol=2.0, budget=6, E=E
    )
    assert not res.reached and all(p[0] <= 100.0 + 1e-9 and p[2] <= 100.0 + 1e-9 for p in res.pressures_kpa)
    assert res.blocking == ["P_CMC_T/P_MCP_T", "P_CMC_B/P_MCP_B"]  # top at its bound, bottom already empty


def test_inverse_says_so_when_its_steps_shrink_after_stalled_solves():
    forward, _ = _double(fail_calls=set(range(1, 20)))  # every solve after the start stalls
    p0 = np.zeros(8)
    y0, ok0 = forward(p0)
    res = bounded_broyden(
        forward, p0, y0, ok0, [90.0, 0.0, 0.0], _chain_jacobian(), lo=0.0, hi=P_MAX, tol=2.0, budget=20
    )
    assert not res.reached and "shrank" in res.reason and res.blocking == []
    assert res.solves < 20 and not any(res.ok[1:])


@pytest.mark.parametrize("target", [[90.0, 0.0, 0.0], [90.0, 90.0, 0.0], [0.0, 80.0, 60.0], [-20.0, 10.0, 0.0]])
def test_the_out_of_reach_test_changes_nothing_for_a_reachable_target(target):
    # a reachable target is reached as without the test, with the same solves
    forward, _ = _double()
    E = tie_matrix(8, [(0, 2), (1, 3)])
    p0 = np.zeros(8)
    y0, ok0 = forward(p0)
    kw = dict(lo=0.0, hi=P_MAX, tol=2.0, budget=6, E=E)
    res = bounded_broyden(forward, p0, y0, ok0, target, _chain_jacobian(), out_of_reach=3.0, **kw)
    ref = bounded_broyden(_double()[0], p0, y0, ok0, target, _chain_jacobian(), **kw)
    assert res.reached, res.reason
    assert res.solves == ref.solves
    np.testing.assert_allclose(res.pressures_kpa[res.best], ref.pressures_kpa[ref.best])


def test_a_target_out_of_reach_inside_the_bounds_costs_no_forward_solve():
    # the chain knows the PIP span is weak (0.12 deg/kPa): 90 deg needs ~750 kPa, 300 kPa give 36 deg at most;
    # the FEA check's TGE2/TGE3/TGE5 plans sit at this: a group at its limit, its joint 50-90 deg short
    forward, calls = _double(stiff=np.array([0.55, 0.12, 0.35]))
    J = _chain_jacobian() / 1.3
    J[1, 4], J[1, 5] = 0.12, -0.12
    p0 = np.zeros(8)
    y0, ok0 = forward(p0)
    res = bounded_broyden(
        forward, p0, y0, ok0, [0.0, 90.0, 0.0], J, lo=0.0, hi=P_MAX, tol=2.0, budget=10, out_of_reach=3.0
    )
    assert not res.reached and res.solves == 0 and len(calls) == 1
    assert "bounds block progress" in res.reason and "misses PIP by 54.0 deg" in res.reason, res.reason
    assert res.blocking == ["P_PIP_B"]  # already empty; its top chamber is not yet at the limit
    # without the test the same inverse spends solves to learn it
    off = bounded_broyden(
        _double(stiff=np.array([0.55, 0.12, 0.35]))[0],
        p0,
        y0,
        ok0,
        [0.0, 90.0, 0.0],
        J,
        lo=0.0,
        hi=P_MAX,
        tol=2.0,
        budget=10,
    )
    assert not off.reached and off.solves >= 1


def test_the_out_of_reach_test_learns_from_the_solves_when_the_chain_is_wrong():
    # the chain thinks the weak PIP span is strong: the first solves show it is not, Broyden's update says so, and
    # the inverse stops on the out-of-reach test before the bounded step shrinks (the test above's stop, sooner)
    forward, _ = _double(stiff=np.array([0.55, 0.12, 0.35]))
    p0 = np.zeros(8)
    y0, ok0 = forward(p0)
    kw = dict(lo=0.0, hi=P_MAX, tol=2.0, budget=10)
    res = bounded_broyden(forward, p0, y0, ok0, [0.0, 90.0, 0.0], _chain_jacobian(), out_of_reach=3.0, **kw)
    off = bounded_broyden(
        _double(stiff=np.array([0.55, 0.12, 0.35]))[0], p0, y0, ok0, [0.0, 90.0, 0.0], _chain_jacobian(), **kw
    )
    assert not res.reached and "linearised response still misses PIP" in res.reason
    assert 1 <= res.solves <= off.solves
