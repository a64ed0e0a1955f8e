"""The one restart mechanism every FE model uses when a solve stalls."""

from types import SimpleNamespace

from workflow import fem

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
        return SimpleNamespace(status=0 if ok else 1, load_factor=1.0 if ok else 0.4, reason="", wall_time_s=2.0)

    monkeypatch.setattr(_config, "solve_unit", fake_solve_unit)
    act = {"contact": {"enabled": False}, "solver": {"max_step": 0.25}}
    res = _config.solve_unit_from_config(act, 2, 60.0, 0.0, mesh=object())
    assert res.attempt == 3 and res.wall_time_s == 4.0
    assert calls == [(False, {"max_step": 0.25}), (False, {"max_step": 0.02, "predictor": False})]
