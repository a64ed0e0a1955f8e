"""The unit-check writer: contract variables, units, CF flags, provenance, .vtu."""

import meshio
import numpy as np
import pytest
import xarray as xr

from workflow.actuator import entry_fem
from workflow.common.fidelity_choice import FemCase, case_actuator
from workflow.common.provenance import open_result
from workflow.fem._config import unit_check, unit_mesh_from_config
from workflow.fidelity.entry_fem import write_fem_case


def test_unit_check_dataset_follows_the_contract(tmp_path):
    actuator = {
        "mesh": {"h_2d_mm": 2.0},
        "unit_check": {"models": ["2d"], "p_top_kpa": [10.0, 30.0]},
        "solver": {"initial_step": 0.25},
    }
    nc, vtu = tmp_path / "unit_check.nc", tmp_path / "unit_3d_300kpa.vtu"
    entry_fem.write_unit_check(nc, vtu, actuator, rule="unit_check", config_slice={"actuator": actuator})
    ds = xr.open_dataset(nc)
    assert list(ds["model"].values) == ["2d"]
    assert list(ds["case"].values) == ["free", "blocked"]
    np.testing.assert_allclose(ds["p_top_kpa"], [10.0, 30.0])
    for name in ("bending_angle_deg", "bending_moment_nm", "max_penetration_mm", "wall_time_s", "status"):
        assert "units" in ds[name].attrs and "long_name" in ds[name].attrs
    assert ds["max_penetration_mm"].dims == ("model", "p_top_kpa", "case")
    assert ds["wall_time_s"].dims == ("model", "p_top_kpa", "case")
    assert (ds["status"] == 0).all()
    assert ds["status"].attrs["flag_meanings"].split()[0] == "converged"
    ang = ds["bending_angle_deg"].sel(model="2d").values
    mom = ds["bending_moment_nm"].sel(model="2d").values
    assert np.all(ang > 0) and ang[1] > ang[0]
    assert np.all(mom > 0) and mom[1] > mom[0]
    for key in ("config_sha256", "git_commit", "created_utc", "rule", "package_versions"):
        assert key in ds.attrs
    m = meshio.read(vtu)
    assert "displacement" in m.point_data and m.points.shape[1] == 3


ACT = {
    "mesh": {"h_2d_mm": 2.0},
    "unit_check": {"models": ["2d"], "p_top_kpa": [10.0, 30.0]},
    "solver": {"initial_step": 0.25},
}


@pytest.fixture(scope="module")
def studied_case(tmp_path_factory):
    """The FE study's case of the 2D unit on the check's mesh, with the study's Newton budget."""
    path = tmp_path_factory.mktemp("study") / "fem_2d_h2_contact.nc"
    write_fem_case(
        "fem_2d_h2_contact", path, actuator=ACT, config_slice={}, p_top_kpa=[10.0, 30.0], iteration_budget=1200
    )
    return open_result(path)


def test_the_unit_check_takes_the_studied_case_instead_of_solving_it_again(studied_case, tmp_path, monkeypatch):
    """The study's case runs the check's own rays (its Newton budget only ends a ray early): a case that reached
    every point is read, not solved again, and its values are the ones a solve gives, to the last digit."""
    case = studied_case
    act = case_actuator(ACT, FemCase("2d", 2.0, True))
    solved, _ = unit_check(act, ("2d",), [10.0, 30.0])  # what the check solves without the study
    for name in ("bending_angle_deg", "bending_moment_nm", "newton_iterations", "status"):
        np.testing.assert_array_equal(case[name].values, solved[name].sel(model="2d").values)

    def no_solve(*args, **kwargs):
        raise AssertionError("solved again")

    monkeypatch.setattr(entry_fem, "unit_check", no_solve)
    nc, vtu = tmp_path / "unit_check.nc", tmp_path / "unit_3d_300kpa.vtu"
    entry_fem.write_unit_check(nc, vtu, ACT, config_slice={}, model_actuators={"2d": act}, studied={"2d": case})
    ds = xr.open_dataset(nc)
    assert ds["bending_angle_deg"].dims == ("model", "p_top_kpa")
    assert ds["status"].dims == ("model", "p_top_kpa", "case")
    np.testing.assert_array_equal(ds["bending_moment_nm"].sel(model="2d").values, solved["bending_moment_nm"][0])
    assert "fem_2d_h2_contact" in ds.attrs["unit_check_source_2d"]
    for name in ("bending_angle_deg", "bending_moment_nm", "max_penetration_mm", "wall_time_s", "status"):
        for key in ("units", "long_name"):  # as the contract has them
            assert ds[name].attrs[key] == solved[name].attrs[key]
    assert ds["status"].attrs["flag_meanings"] == solved["status"].attrs["flag_meanings"]


def test_a_studied_case_that_failed_or_differs_is_solved_again(studied_case):
    case = studied_case
    act = case_actuator(ACT, FemCase("2d", 2.0, True))
    assert entry_fem.studied_unit_check(case, act, "2d", [10.0, 30.0]) is not None
    failed = case.copy()
    failed["status"] = failed["status"].where(failed["p_top_kpa"] < 20.0, 1)
    assert entry_fem.studied_unit_check(failed, act, "2d", [10.0, 30.0]) is None
    assert entry_fem.studied_unit_check(case, act, "2d", [10.0, 60.0]) is None  # other points
    assert entry_fem.studied_unit_check(case, act, "2d", [10.0, 30.0, 60.0]) is None  # more points
    finer = case_actuator(ACT, FemCase("2d", 1.0, True))
    assert entry_fem.studied_unit_check(case, finer, "2d", [10.0, 30.0]) is None  # another mesh
    # the 3D check writes the deformed unit: a 3D case without the free ray's displacement cannot stand in for it
    as3d = case.assign_attrs(model="3d", h_mm=4.0)
    act3 = case_actuator(dict(ACT, mesh={"h_3d_mm": 4.0}), FemCase("3d", 4.0, True))
    assert entry_fem.studied_unit_check(as3d, act3, "3d", [10.0, 30.0]) is None
    n = unit_mesh_from_config(act3, 3).mesh.p.size
    known = entry_fem.studied_unit_check(as3d.assign(displacement_mm=("dof", np.zeros(n))), act3, "3d", [10.0, 30.0])
    assert known is not None and known[1][1].size == n


SWEEP = {"p_max_kpa": 30.0, "n_ratios": 2, "n_pressures": 3, "n_shards": 2}


def test_the_sweep_reads_its_first_ray_from_a_study_case_that_landed_on_its_samples(tmp_path, monkeypatch):
    """A study case that shares the sweep's P_B = 0 ray lands its steps on the sweep's samples too and keeps both
    paths: the shard built from them equals the shard solved here to the last digit, and the study's own points
    keep their values; a case on another config, or one whose ray stopped, is solved again."""
    from workflow.actuator import fe_solver

    path = tmp_path / "fem_2d_h2_contact.nc"
    write_fem_case(
        "fem_2d_h2_contact",
        path,
        actuator=ACT,
        config_slice={},
        p_top_kpa=[10.0, 30.0],
        iteration_budget=1200,
        sweep=SWEEP,
    )
    case = open_result(path)
    assert case["path_lam"].dims == ("case", "step")
    np.testing.assert_allclose(case.attrs["path_stops"], [1 / 3, 2 / 3, 1.0], rtol=0, atol=0)
    act = case_actuator(ACT, FemCase("2d", 2.0, True))
    solved, _ = unit_check(act, ("2d",), [10.0, 30.0])  # the study's points on their own path: the same values
    np.testing.assert_allclose(case["bending_angle_deg"], solved["bending_angle_deg"].sel(model="2d"), rtol=1e-6)

    fresh = entry_fem.write_shard(
        tmp_path / "solved.nc", fea="2d", shard=0, sweep_cfg=SWEEP, actuator_cfg=act, config_slice={}
    )
    real = fe_solver.make_solver

    def no_first_ray(fea, actuator):
        solve = real(fea, actuator)

        def guarded(direction, scales):
            assert float(direction[1]) > 0.0, "the P_B = 0 ray was solved again"
            return solve(direction, scales)

        return guarded

    scales = np.array([1 / 3, 2 / 3, 1.0])
    assert fe_solver.studied_ray(case, act, "2d", (30.0, 0.0), scales) is not None
    monkeypatch.setattr(entry_fem, "make_solver", no_first_ray)
    read = entry_fem.write_shard(
        tmp_path / "read.nc", fea="2d", shard=0, sweep_cfg=SWEEP, actuator_cfg=act, config_slice={}, studied=case
    )
    assert "fem_2d_h2_contact" in read.attrs["rays_read_from_study"]
    assert "rays_read_from_study" not in fresh.attrs
    names = ("bending_angle_deg", "bending_moment_nm", "status", "newton_iterations")
    for name in names + ("max_penetration_mm", "overlap_depth_mm", "min_pocket_area_mm2"):
        np.testing.assert_array_equal(read[name].values, fresh[name].values)
    np.testing.assert_allclose(read["wall_time_s"].sum(), float(case["path_wall_time_s"].sum()), rtol=1e-12)

    # a sweep with a Newton budget below the study's might have stopped where the study's ray went on
    assert fe_solver.studied_ray(case, dict(act, iteration_budget=1200), "2d", (30.0, 0.0), scales) is not None
    assert fe_solver.studied_ray(case, dict(act, iteration_budget=1199), "2d", (30.0, 0.0), scales) is None
    stiffer = dict(act, contact=dict(act["contact"], penalty_factor=300.0))
    assert fe_solver.studied_ray(case, stiffer, "2d", (30.0, 0.0), scales) is None  # another config
    assert fe_solver.studied_ray(case, act, "2d", (30.0, 10.0), scales) is None  # another ray
    assert fe_solver.studied_ray(case, act, "2d", (30.0, 0.0), scales[1:]) is None  # other samples
    stopped = case.copy()
    stopped["path_status"] = stopped["path_status"].where(stopped["case"] == "free", 1)
    assert fe_solver.studied_ray(stopped, act, "2d", (30.0, 0.0), scales) is None
    # the unit check reading this case keeps the check's variables only
    known = entry_fem.studied_unit_check(case, act, "2d", [10.0, 30.0])
    assert known is not None and not any(str(k).startswith("path_") for k in known[0].data_vars)


def test_only_the_coarser_contact_cases_share_the_sweep_ray():
    from workflow.common.fidelity_choice import case_sweep, fem_cases, shares_sweep_ray

    cases = fem_cases(
        [
            {"model": "2d", "h_mm": [1.0, 0.5, 0.25], "contact": True},
            {"model": "2d", "h_mm": [1.0], "contact": False},
            {"model": "3d", "h_mm": [2.0, 1.4, 1.0], "contact": True},
        ]
    )
    share = {c.name for c in cases if shares_sweep_ray(c, cases)}
    assert share == {"fem_2d_h1_contact", "fem_2d_h0.5_contact", "fem_3d_h2_contact", "fem_3d_h1.4_contact"}
    # what the rule passes the case: the sweep only where a sweep can read the ray from it
    sweep, pts = {"p_max_kpa": 300.0, "n_ratios": 11, "n_pressures": 10, "n_shards": 11}, [60.0, 180.0, 300.0]
    assert case_sweep(cases[0], cases, sweep, pts, True) == {"p_max_kpa": 300.0, "n_pressures": 10}
    assert case_sweep(cases[0], cases, sweep, pts, False) == {}  # fidelity.auto off: no sweep reads the study
    assert case_sweep(cases[2], cases, sweep, pts, True) == {}  # the finest
    assert case_sweep(cases[0], cases, dict(sweep, n_pressures=4), pts, True) == {}  # 60 kPa not a sample


def test_the_study_lands_on_the_sweep_samples_only_where_its_ray_can_be_the_sweeps():
    from workflow.common.rays import shared_stops

    assert shared_stops([60.0, 180.0, 300.0], {"p_max_kpa": 300.0, "n_pressures": 10}) == tuple(np.arange(1, 11) / 10)
    assert shared_stops([60.0, 180.0, 300.0], {"p_max_kpa": 300.0, "n_pressures": 4}) == ()  # 60 kPa not a sample
    assert shared_stops([60.0, 180.0, 300.0], {"p_max_kpa": 250.0, "n_pressures": 10}) == ()  # another end pressure
    assert shared_stops([60.0, 180.0, 300.0], {}) == ()
