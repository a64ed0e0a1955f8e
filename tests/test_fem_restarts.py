"""The one restart mechanism every FE model uses when a solve stalls."""

from types import SimpleNamespace

import pytest

from workflow import fem
from workflow.fem._solve import by_dimension
from workflow.fem._unit import self_contact_pairs

RESTARTS = [{"contact": {"smoothing_mm": 0.05}}, {"solver": {"predictor": False, "max_step": 0.02}}]


def test_separate_restarts_apply_alone_and_cumulative_ones_over_each_other():
    base_c, base_s = {"smoothing_mm": 0.01}, {"max_step": 0.25, "rtol": 1e-6}
    sep = fem.separate_attempts(base_c, base_s, RESTARTS)
    cum = fem.cumulative_attempts(base_c, base_s, RESTARTS)
    assert sep[0] == cum[0] == (base_c, base_s)
    assert sep[1] == cum[1] == ({"smoothing_mm": 0.05}, base_s)
    # the third: small steps on the configured band (alone) or on the widened band (over the previous)
    assert sep[2] == ({"smoothing_mm": 0.01}, {"max_step": 0.02, "rtol": 1e-6, "predictor": False})
    assert cum[2] == ({"smoothing_mm": 0.05}, {"max_step": 0.02, "rtol": 1e-6, "predictor": False})
    assert base_c == {"smoothing_mm": 0.01}  # the configured settings are not changed


def test_first_converged_stops_at_the_first_full_solve_else_keeps_the_furthest():
    def run(outcomes):
        seen = []

        def solve(contact, solver):
            seen.append(contact["smoothing_mm"])
            status, lam = outcomes[len(seen) - 1]
            return SimpleNamespace(status=status, load_factor=lam, reason="")

        res, k = fem.first_converged(fem.cumulative_attempts({"smoothing_mm": 0.01}, {}, RESTARTS), solve)
        return res, k, seen

    res, k, seen = run([(1, 0.3), (0, 1.0), (0, 1.0)])
    assert (res.status, k, seen) == (0, 1, [0.01, 0.05])  # the third attempt is not run
    res, k, seen = run([(1, 0.3), (1, 0.7), (1, 0.5)])
    assert (res.load_factor, k, len(seen)) == (0.7, 1, 3)


def test_the_units_restarts_keep_their_numbers_when_contact_only_ones_are_skipped(monkeypatch):
    """Without contact the two contact-only restarts would repeat the first solve: they are skipped, and the small-
    step restart that converges is still attempt 3; the wall time counts both solves run."""
    from workflow.fem import _config

    calls = []

    def fake_solve_unit(um, p_top, p_bottom, case, contact, **kw):
        calls.append((contact, dict(kw["solver"] or {})))
        ok = len(calls) == 2
        return SimpleNamespace(
            status=0 if ok else 1, load_factor=1.0 if ok else 0.4, reason="", wall_time_s=2.0, newton_iterations=10
        )

    monkeypatch.setattr(_config, "solve_unit", fake_solve_unit)
    act = {"contact": {"enabled": False}, "solver": {"max_step": 0.25}}
    res = _config.solve_unit_from_config(act, 2, 60.0, 0.0, mesh=object())
    assert res.attempt == 3 and res.wall_time_s == 4.0
    assert calls == [(False, {"max_step": 0.25}), (False, {"max_step": 0.02, "predictor": False})]


def test_an_iteration_budget_is_shared_by_a_rays_restarts(monkeypatch):
    """actuator.iteration_budget caps the Newton iterations of all attempts together: each attempt gets what is
    left, and once it is spent no further restart runs (the ray is a failed solve, the furthest attempt kept)."""
    from workflow.fem import _config

    calls = []

    def fake_solve_unit(um, p_top, p_bottom, case, contact, **kw):
        cap = kw["solver"]["max_iterations"]
        calls.append(cap)
        return SimpleNamespace(
            status=2, load_factor=0.1 * len(calls), reason="", wall_time_s=1.0, newton_iterations=min(15, cap)
        )

    monkeypatch.setattr(_config, "solve_unit", fake_solve_unit)
    res = _config.solve_unit_from_config({"iteration_budget": 25}, 2, 60.0, 0.0, mesh=object())
    assert calls == [25, 10]  # the second attempt gets the 10 left; the third and fourth never run
    assert res.status == 2 and res.attempt == 1 and res.wall_time_s == 2.0
    # an attempt's own tighter cap is kept
    calls.clear()
    _config.solve_unit_from_config(
        {"iteration_budget": 100, "solver": {"max_iterations": 12}, "restarts": []}, 2, 60.0, 0.0, mesh=object()
    )
    assert calls == [12]


def test_a_path_stops_when_its_newton_iterations_are_spent():
    """The engine's budget: a 2D unit ray that converges with enough iterations stops with status 2, short of the
    load, and says why when it may use half of them."""
    um = fem.build_unit_mesh(None, h=1.0, dim=2)
    full = fem.solve_unit(um, 60.0, 0.0, "free", True)
    assert full.status == 0
    cut = fem.solve_unit(um, 60.0, 0.0, "free", True, solver={"max_iterations": full.newton_iterations // 2})
    assert cut.status == 2 and "budget" in cut.reason
    assert full.newton_iterations // 2 <= cut.newton_iterations < full.newton_iterations
    assert 0 < cut.load_factor < 1


def test_the_3d_predictor_cuts_back_only_with_the_actual_volume_pressure_in_the_tangent(monkeypatch):
    """In 3D the extrapolated first guess of a step puts the ballooning walls far off incompressibility.  With the
    actual element volume's pressure in the tangent that initial stress makes the 3D unit cut back within its first
    four steps; with the lagged (linearised) one, the default, it does not, and gets further."""
    from workflow.fem import _assembly

    um = fem.build_unit_mesh(None, h=2.0, dim=3)
    out = {}
    for lag in (False, True):
        monkeypatch.setattr(_assembly, "LAGGED_PRESSURE", lag)
        out[lag] = fem.solve_unit(um, 300.0, 0.0, "free", False, solver={"max_steps": 4, "predictor": True})
    assert out[False].cutbacks >= 1
    assert out[True].cutbacks == 0 and out[True].load_factor > out[False].load_factor


def test_a_long_path_logs_its_progress(monkeypatch, caplog):
    """A ray that runs longer than PROGRESS_EVERY_S says how far it is (load, steps, iterations, time) as it goes."""
    import logging

    from workflow.fem import _solve

    monkeypatch.setattr(_solve, "PROGRESS_EVERY_S", 0.0)
    um = fem.build_unit_mesh(None, h=2.0, dim=2)
    with caplog.at_level(logging.INFO, logger="workflow.fem._solve"):
        res = fem.solve_unit(um, 20.0, 0.0, "blocked", False, solver={"max_steps": 3})
    said = [r.getMessage() for r in caplog.records if r.name == "workflow.fem._solve"]
    assert len(said) == len(res.history) >= 1
    assert said[0].startswith("load ") and "Newton iterations" in said[0]


def test_the_contact_band_is_one_per_model_and_a_restart_band_widens_both():
    per_model = {"smoothing_mm": {"2d": 0.01, "3d": 0.02}}
    assert (fem.contact_band(per_model, 2), fem.contact_band(per_model, 3)) == (0.01, 0.02)
    assert fem.contact_band({}, 3) == fem.contact_band(fem.DEFAULT_CONTACT, 3) == 0.02
    restart = fem.separate_attempts(per_model, {}, RESTARTS)[1][0]
    assert (fem.contact_band(restart, 2), fem.contact_band(restart, 3)) == (0.05, 0.05)
    with pytest.raises(ValueError, match="no band for the 3d model"):
        fem.contact_band({"smoothing_mm": {"2d": 0.01}}, 3)
    # the unit's contact pairs take the band of their own model
    for dim, band in ((2, 0.01), (3, 0.02)):
        um = fem.build_unit_mesh(None, h=2.0, dim=dim)
        assert {p.smoothing for p in self_contact_pairs(um, per_model)} == {band}


def test_a_none_in_the_solver_options_takes_the_default_of_the_model_dimension():
    for dim, grow, rtol, utol, predictor in ((2, 6, 1e-6, None, True), (3, 8, 1e-2, 1e-2, False)):
        opts = by_dimension(fem.DEFAULT_SOLVER, dim)
        assert (opts["grow_below_iter"], opts["rtol"], opts["utol"], opts["predictor"]) == (grow, rtol, utol, predictor)
        given = {"grow_below_iter": 10, "rtol": 0.03, "utol": 0.03, "predictor": False}
        assert {k: by_dimension(given, dim)[k] for k in given} == given


def test_the_increment_test_holds_newton_where_the_residual_test_lets_go():
    """With a residual tolerance that every first correction meets, the steps stop after one Newton iteration and
    the angle is off; the increment test alone (last correction <= utol times the step's displacement) brings it
    back to the tight solve's."""
    kw = dict(case="free", contact=False)
    tight = fem.solve_unit({"dim": 2, "h": 2.0}, 60.0, 0.0, solver={"rtol": 1e-10}, **kw)
    loose = fem.solve_unit({"dim": 2, "h": 2.0}, 60.0, 0.0, solver={"rtol": 1.0, "max_step": 0.5}, **kw)
    held = fem.solve_unit({"dim": 2, "h": 2.0}, 60.0, 0.0, solver={"rtol": 1.0, "utol": 1e-6, "max_step": 0.5}, **kw)
    assert tight.status == loose.status == held.status == 0
    # measured: 4.3e-5 of the angle off with the residual test alone, 1e-14 with the increment test
    assert abs(loose.bending_angle_deg - tight.bending_angle_deg) > 1e-5 * abs(tight.bending_angle_deg)
    assert abs(held.bending_angle_deg - tight.bending_angle_deg) < 1e-9 * abs(tight.bending_angle_deg)
    assert held.newton_iterations > loose.newton_iterations
