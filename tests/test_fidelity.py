"""Speed against accuracy and the cheapest fidelity, on small synthetic tables."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from workflow.common import fidelity_choice, scheduling
from workflow.fidelity import analysis as FD
from workflow.fidelity.entry import fem_table


def test_fem_case_names_round_trip_and_cases_are_listed_once():
    c = fidelity_choice.FemCase("2d", 0.5, True)
    assert c.name == "fem_2d_h0.5_contact" and fidelity_choice.FemCase.parse(c.name) == c
    cases = fidelity_choice.fem_cases(
        [
            {"model": "2d", "h_mm": [2.0, 1.0], "contact": True},
            {"model": "2d", "h_mm": [1.0], "contact": True},
            {"model": "3d", "h_mm": [4.0], "contact": False},
        ]
    )
    assert [x.name for x in cases] == ["fem_2d_h2_contact", "fem_2d_h1_contact", "fem_3d_h4_nocontact"]
    with pytest.raises(ValueError, match="not an FE case"):
        fidelity_choice.FemCase.parse("fem_2d_coarse")


def test_fem_case_queue_priority_starts_the_longest_cases_first_and_before_every_other_job():
    # the default study's cases in the order their times put them in the cold run the estimate was fitted to (3D 1 mm
    # 411 s, 1.4 mm 187 s, 2D 0.25 mm 149 s, 3D 2 mm 67 s, 2D 0.5 mm 40 s, ...; the latest: 296 / 143 / 156 / 43 /
    # 42 s, two neighbours swapped); every case above 10, which puts the study before every other rule (0)
    names = [
        "fem_3d_h1_contact",
        "fem_3d_h1.4_contact",
        "fem_2d_h0.25_contact",
        "fem_3d_h2_contact",
        "fem_2d_h0.5_contact",
        "fem_3d_h2_nocontact",
        "fem_2d_h1_contact",
        "fem_2d_h0.5_nocontact",
        "fem_2d_h1_nocontact",
    ]
    prio = [scheduling.fem_case_priority(fidelity_choice.FemCase.parse(n)) for n in names]
    assert prio == sorted(prio, reverse=True) and len(set(prio)) == len(prio)
    assert min(prio) > 10
    # the sweeps, which every plan waits for, after the study and ahead of the studies nothing waits for (0), below
    # the checks; the 3D shards in the order of their rays' cost (shard 0: P_B = 0, the longest solved), above the 2D ones
    p3 = [scheduling.sweep_shard_priority("3d", k, 6) for k in range(6)]
    p2 = [scheduling.sweep_shard_priority("2d", k, 11) for k in range(11)]
    assert p3 == sorted(p3, reverse=True) and p3[0] > p3[-1] > max(p2) >= min(p2) > 0
    assert max(p3) < scheduling.CHECK_PRIORITY < min(prio)


def test_pareto_front_keeps_exactly_the_undominated_methods():
    t = np.array([1.0, 2.0, 3.0, 2.5, 0.5])
    e = np.array([0.3, 0.1, 0.05, 0.2, np.nan])
    # 2.5 s / 0.2 is dominated by 2 s / 0.1; NaN error is never on the front
    np.testing.assert_array_equal(FD.pareto_front(t, e), [True, True, True, False, False])
    # ties: equal on both is not domination
    np.testing.assert_array_equal(FD.pareto_front(np.array([1.0, 1.0]), np.array([0.1, 0.1])), [True, True])


def test_cheapest_within_tolerance_else_the_most_accurate():
    names = ["coarse", "mid", "fine"]
    ch = fidelity_choice.cheapest_within("s", names, [1.0, 5.0, 50.0], [0.2, 0.05, 0.0], 0.1)
    assert ch.method == "mid" and ch.met_tolerance and "coarse" in ch.reason  # the faster one outside is named
    ch = fidelity_choice.cheapest_within(
        "s", names, [1.0, 5.0, 50.0], [0.2, 0.05, 0.0], 0.1, converged=[True, False, True]
    )
    assert ch.method == "fine"  # a method that did not converge is never taken
    ch = fidelity_choice.cheapest_within("s", names, [1.0, 5.0, 50.0], [0.5, 0.3, np.nan], 0.1)
    assert ch.method == "mid" and not ch.met_tolerance and "no method within" in ch.reason


def _case(name, angles, moments, wall=1.0, status=(0, 0, 0)):
    p = np.array([60.0, 180.0, 300.0])
    st = np.array([[s, s] for s in status])
    return xr.Dataset(
        {
            "bending_angle_deg": ("p_top_kpa", np.asarray(angles, float)),
            "bending_moment_nm": ("p_top_kpa", np.asarray(moments, float)),
            "status": (("p_top_kpa", "case"), st),
            "case_wall_time_s": ((), wall),
        },
        coords={"p_top_kpa": p, "case": ["free", "blocked"]},
        attrs={"case": name},
    )


def test_fem_table_measures_every_case_against_the_finest_converged_case_with_contact():
    cases = [
        _case("fem_2d_h2_contact", [8, 20, 28], [0.05, 0.12, 0.20], wall=1),
        _case("fem_2d_h1_contact", [9, 21, 30], [0.05, 0.13, np.nan], wall=4, status=(0, 0, 1)),
        _case("fem_2d_h2_nocontact", [8, 18, 21], [0.05, 0.10, 0.14], wall=0.5),
        _case("fem_3d_h4_contact", [3, 6, 9], [0.02, 0.07, 0.12], wall=10),
    ]
    t = fem_table(cases)
    e = t["error"]
    # angle_300: the 1 mm case is the reference; 2 mm is 28/30 - 1 off
    assert float(e.sel(case="fem_2d_h1_contact", quantity="angle_300")) == 0.0
    assert float(e.sel(case="fem_2d_h2_contact", quantity="angle_300")) == pytest.approx(2 / 30)
    assert float(e.sel(case="fem_2d_h2_nocontact", quantity="angle_300")) == pytest.approx(9 / 30)
    # moment_300: 1 mm did not get there, so 2 mm is the finest that did (its own reference)
    assert str(t["reference_case"].sel(case="fem_2d_h2_nocontact", quantity="moment_300").values) == "fem_2d_h2_contact"
    assert np.isnan(float(e.sel(case="fem_2d_h1_contact", quantity="moment_300")))
    # 3D has its own reference, never the 2D one
    assert float(e.sel(case="fem_3d_h4_contact", quantity="angle_60")) == 0.0
    assert not bool(t["converged"].sel(case="fem_2d_h1_contact"))


def test_fem_choice_picks_the_cheapest_case_within_tolerance(tmp_path):
    from workflow.fidelity.entry import write_fem_choice

    files = []
    for c in (
        _case("fem_2d_h2_contact", [8, 20, 28], [0.05, 0.12, 0.20], wall=1),
        _case("fem_2d_h1_contact", [8.5, 21, 29.5], [0.05, 0.13, 0.21], wall=4),
        _case("fem_2d_h0.5_contact", [8.6, 21.3, 30], [0.051, 0.13, 0.21], wall=20),
    ):
        path = tmp_path / f"{c.attrs['case']}.nc"
        c.to_netcdf(path)
        files.append(path)
    ds = write_fem_choice(files, tmp_path / "fem.nc", tolerance=0.03, config_slice={})
    assert str(ds["chosen_case"].sel(model_choice="2d").values) == "fem_2d_h1_contact"
    act, attrs = fidelity_choice.apply_fem_choice({"mesh": {"h_2d_mm": 2.0}, "contact": {"enabled": False}}, ds, "2d")
    assert act["mesh"]["h_2d_mm"] == 1.0 and act["contact"]["enabled"] is True
    assert attrs["fidelity"] == "fem_2d_h1_contact" and "within" in attrs["fidelity_reason"]
    # separate bounds: a tight one on the moment (1 mm is 2 % off at 60 kPa) moves the choice to the finest
    strict = write_fem_choice(
        files, tmp_path / "fem_strict.nc", tolerance={"angle": 0.03, "moment": 0.01}, config_slice={}
    )
    assert str(strict["chosen_case"].sel(model_choice="2d").values) == "fem_2d_h0.5_contact"
    assert "blocked moment" in str(strict["choice_reason"].sel(model_choice="2d").values)
    act, attrs = fidelity_choice.apply_fem_choice({"mesh": {"h_2d_mm": 2.0}}, None, "2d")
    assert act["mesh"]["h_2d_mm"] == 2.0 and attrs["fidelity"] == "config"


def test_check_choice_takes_the_coarsest_mesh_whose_angles_stay_close():
    a2 = [[30.0, 10, 0], [37.0, 12, 0], [38.0, 12.5, 0], [38.5, 12.6, 0]]  # TGE2 by mesh
    a1 = [[9.0, 0, 1], [10.5, 0, 1], [9.8, 0, 1], [9.6, 0, 1]]  # TGE1 by mesh
    study = xr.Dataset(
        {
            "angle_deg": (("h_mm", "exercise", "joint"), np.stack([a1, a2], axis=1)),
            "status": (("h_mm", "exercise"), np.zeros((4, 2), int)),
            "wall_time_s": (("h_mm", "exercise"), np.array([[10.0] * 2, [20] * 2, [40] * 2, [90] * 2])),
        },
        coords={"h_mm": [3.0, 2.5, 2.0, 1.5], "exercise": ["TGE1", "TGE2"]},
    )
    h, why = fidelity_choice.check_choice(study, 2.0, 2.0)
    assert h == 2.5 and "TGE1, TGE2" in why
    h, _ = fidelity_choice.check_choice(study, 1.0, 2.0)  # TGE1 is 0.9 deg off at 2.5 mm, TGE2 1.5: 2 mm
    assert h == 2.0
    # a mesh whose contact penetrates beyond the bound is no valid check, however close its angles
    study["max_penetration_mm"] = (("h_mm", "exercise"), np.array([[0.05] * 2, [0.05, 0.2], [0.04] * 2, [0.03] * 2]))
    h, why = fidelity_choice.check_choice(study, 2.0, 2.0, penetration_bound_mm=0.1)
    assert h == 2.0 and "penetration <= 0.1 mm" in why
    h, _ = fidelity_choice.check_choice(None, 2.0, 1.75)
    assert h == 1.75


def test_loads_method_trusts_the_surfaces_only_where_the_study_found_them_accurate():
    from workflow.musculoskeletal.direct import loads_method

    study = xr.Dataset(
        {
            "rel_error": (("method", "point", "quantity"), np.array([[[0.01], [0.30]], [[0.0], [0.0]]])),
            "wall_time_s": (("method", "point"), [[0.01, 0.01], [2.0, 2.0]]),
            "inside_design": ("point", [True, False]),
        },
        coords={"method": ["msk_rsm_selected", "msk_opensim"]},
    )
    m, why = loads_method(study, {"depth": 0.1, "length": 0.2, "breadth": 0.0}, 0.05, model_available=True)
    assert m == "rsm" and "inside" in why
    m, why = loads_method(study, {"depth": 1.5, "length": 0.0, "breadth": 0.0}, 0.05, model_available=True)
    assert m == "opensim_direct" and "outside" in why
    m, _ = loads_method(study, {"depth": 1.5, "length": 0.0, "breadth": 0.0}, 0.05, model_available=False)
    assert m == "rsm"


def test_regressor_choice_with_a_tolerance_takes_the_fastest_good_enough():
    from workflow.actuator.surrogates import select_regressor

    regs, targets, folds = ["knn", "rbf", "gp"], ["angle", "moment"], 2
    rmse = np.array([0.2, 0.02, 0.01])[:, None, None] * np.ones((3, 2, folds))
    pt = np.array([1e-4, 1e-3, 1e-2])[:, None, None] * np.ones((3, 2, folds))
    cv = xr.Dataset(
        {
            "rmse": (("regressor", "target", "fold"), rmse),
            "predict_time_s": (("regressor", "target", "fold"), pt),
            "target_std": ("target", [1.0, 1.0]),
        },
        coords={"regressor": regs, "target": targets, "fold": np.arange(folds)},
    )
    assert select_regressor(cv)[0] == "gp"  # the best score without a tolerance
    best, _, why = select_regressor(cv, tolerance=0.05)
    assert best == "rbf" and "knn" in why


def test_speed_accuracy_dataset_marks_the_front_per_quantity():
    ds = FD.speed_accuracy_dataset(
        ["a", "b", "c"],
        ["q1", "q2"],
        [1.0, 2.0, 3.0],
        np.array([[0.5, 0.1], [0.2, 0.3], [0.0, np.nan]]),
        family=["x"] * 3,
        error_units={"q1": "1", "q2": "kPa"},
        reference={"q1": "c", "q2": "a"},
    )
    np.testing.assert_array_equal(ds["pareto"].sel(quantity="q1").values, [True, True, True])
    np.testing.assert_array_equal(ds["pareto"].sel(quantity="q2").values, [True, False, False])
    assert str(ds["error_units"].sel(quantity="q2").values) == "kPa"
    # a method of another front group (another model's reference) never dominates
    ds = FD.speed_accuracy_dataset(
        ["2d_fast", "3d_slow", "3d_slower"],
        ["q"],
        [1.0, 5.0, 9.0],
        np.array([[0.01], [0.05], [0.02]]),
        family=["x"] * 3,
        error_units={"q": "1"},
        reference={"q": ""},
        front_group=["2d", "3d", "3d"],
    )
    np.testing.assert_array_equal(ds["pareto"].sel(quantity="q").values, [True, True, True])


def test_richardson_recovers_an_order_and_refuses_growing_differences():
    # f = 3 + 0.2 h^2 on unequal ratios: order 2 and the limit exactly
    h = np.array([1.0, 4.0 / 3.0, 2.0])
    r = FD.richardson(h, 3.0 + 0.2 * h**2)
    assert r.asymptotic and r.order == pytest.approx(2.0, rel=1e-8) and r.limit == pytest.approx(3.0, rel=1e-10)
    # differences that grow under refinement (the 3D unit's blocked moment at 300 kPa on the systematic family,
    # docs/fea.md): Celik's absolute value alone would call this order 2.78 and extrapolate; it is not asymptotic
    r = FD.richardson(h, [0.376137, 0.368426, 0.362519])
    assert not r.asymptotic and r.order < 0 and np.isnan(r.gci_fine) and r.limit == 0.376137
    # equal ratios: growing differences get the negative order of the signed equation
    r = FD.richardson([1.0, 2.0, 4.0], [1.0, 1.2, 1.3])
    assert not r.asymptotic and r.order == pytest.approx(-1.0, rel=1e-8)


def test_coarsest_first_mesh_search_solves_the_finest_then_stops_at_the_first_mesh_within_tolerance():
    # meshes 3 / 2.5 / 2 / 1.5 mm (index 0 coarsest); TGE1 and TGE2 angles per mesh
    angles = {0: [[9.0, 0, 1], [37.0, 12, 0]], 1: [[10.5, 0, 1], [38.0, 12.5, 0]], 2: [[9.8, 0, 1], [38.3, 12.6, 0]]}
    angles[3] = [[9.6, 0, 1], [38.5, 12.6, 0]]
    solved = []

    def solve(i, bad=(), pen=0.01):
        solved.append(i)
        status = np.array([1 if i in bad else 0, 0])
        return np.array(angles[i], float), status, np.full(2, pen)

    # the coarsest is 1.5 deg off (TGE2): within 2 deg, so 2.5 and 2 mm are never solved
    ang, status, pen, stop = fidelity_choice.search_meshes(4, 2, solve, "coarsest_first", tolerance_deg=2.0)
    assert solved == [3, 0] and stop[0] == 0 and abs(stop[1] - 1.5) < 1e-12 and stop[2] == [1, 2]
    assert np.all(status[1:3] == fidelity_choice.NOT_SOLVED) and np.isnan(ang[1:3]).all()
    study = xr.Dataset(
        {
            "angle_deg": (("h_mm", "exercise", "joint"), ang),
            "status": (("h_mm", "exercise"), status),
            "wall_time_s": (("h_mm", "exercise"), np.where(np.isnan(ang[..., 0]), np.nan, 10.0)),
        },
        coords={"h_mm": [3.0, 2.5, 2.0, 1.5], "exercise": ["TGE1", "TGE2"]},
    )
    h, why = fidelity_choice.check_choice(study, 2.0, 2.0)
    assert h == 3.0 and "2.5, 2 mm not solved" in why
    # 1 deg: the coarsest misses (TGE2 1.5 deg), 2.5 mm misses (TGE1 0.9, TGE2 0.5: within) -> stops at 2.5 mm
    solved.clear()
    *_, stop = fidelity_choice.search_meshes(4, 2, solve, "coarsest_first", tolerance_deg=1.0)
    assert solved == [3, 0, 1] and stop[0] == 1
    # a coarse mesh that did not converge, or penetrates beyond the bound, is passed over
    solved.clear()
    *_, stop = fidelity_choice.search_meshes(4, 2, lambda i: solve(i, bad=(0,)), "coarsest_first", tolerance_deg=2.0)
    assert solved == [3, 0, 1] and stop[0] == 1
    solved.clear()
    *_, stop = fidelity_choice.search_meshes(
        4, 2, lambda i: solve(i, pen=0.2), "coarsest_first", tolerance_deg=2.0, penetration_bound_mm=0.1
    )
    assert solved == [3, 0, 1, 2] and stop is None
    # a failed finest is no reference: every mesh is solved; "all" solves every mesh, coarsest first
    solved.clear()
    *_, stop = fidelity_choice.search_meshes(4, 2, lambda i: solve(i, bad=(3,)), "coarsest_first", tolerance_deg=2.0)
    assert solved == [3, 0, 1, 2] and stop is None
    solved.clear()
    *_, stop = fidelity_choice.search_meshes(4, 2, solve, "all", tolerance_deg=2.0)
    assert solved == [0, 1, 2, 3] and stop is None
    with pytest.raises(ValueError, match="coarsest_first"):
        fidelity_choice.mesh_order(4, "finest_first")
