"""2D -> 3D pressure mapping: exact scale on analytic doubles, flags, round trip, dataset.

theta_3D and theta_2D are TEST DOUBLES: theta_2D(P) = theta_3D(P / a), so the
exact scale is s = a for every pair (the ratio is kept).
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from workflow.actuator import entry, mapping, surrogates, sweep
from workflow.common.provenance import write_dataset
from workflow.settings import REPO_ROOT

TABLE8 = REPO_ROOT / "resources" / "table08_planned_pressures_3d.csv"


def theta_3d(pt, pb):
    pt, pb = np.asarray(pt, float), np.asarray(pb, float)
    return 12.0 * np.tanh((pt - pb) / 250.0) * (1.0 - 0.2 * (pt + pb) / 600.0)


def theta_2d_of(a):
    return lambda pt, pb: theta_3d(np.asarray(pt, float) / a, np.asarray(pb, float) / a)


def test_exact_scale_and_ratio_on_table8():
    planned = mapping.read_planned_pressures(TABLE8)
    ds = mapping.mapping_dataset(planned, theta_3d, theta_2d_of(0.8), p_max_2d_kpa=300.0, p_max_3d_kpa=300.0)
    assert dict(ds.sizes) == {"exercise": 5, "group": 4, "chamber": 2}
    eq = ds["status"] == 1
    # Table 8 has P_T = P_B for DIP in TGE1-3: no unique scale
    assert sorted(map(str, ds["exercise"].values[np.any(eq.values, axis=1)])) == ["TGE1", "TGE2", "TGE3"]
    assert np.all(np.isnan(ds["scale"].where(eq)).values[eq.values])
    assert all(r.startswith("P_T = P_B") for r in ds["reason"].values[eq.values])
    ok = ds["status"] == 0
    assert int(ok.sum()) == 17
    np.testing.assert_allclose(ds["scale"].values[ok.values], 0.8, rtol=1e-7)
    np.testing.assert_allclose(
        ds["pressure_2d_kpa"].values[ok.values], 0.8 * ds["pressure_3d_kpa"].values[ok.values], rtol=1e-7
    )
    np.testing.assert_allclose(ds["angle_2d_deg"].values[ok.values], ds["angle_3d_deg"].values[ok.values], atol=1e-7)
    np.testing.assert_allclose(ds["pressure_3d_kpa"].sel(exercise="TGE4", group="PIP").values, [291.84, 0.0])


def test_pairs_outside_the_2d_grid_are_flagged():
    pt = np.array([100.0, 150.0, 250.0, 0.0])
    pb = np.array([0.0, 20.0, 0.0, 280.0])
    r = mapping.map_pairs(pt, pb, theta_3d, theta_2d_of(1.5), p_max_2d_kpa=300.0)
    # the 2D pair would need 1.5 x the 3D pressures: > 300 kPa for the last two
    assert list(r["status"]) == [0, 0, 2, 2]
    np.testing.assert_allclose(r["scale"][:2], 1.5, rtol=1e-7)
    assert np.all(np.isnan(r["p_top_2d_kpa"][2:]))


def test_round_trip():
    pt = np.array([291.84, 215.31, 159.61, 0.0, 60.0])
    pb = np.array([0.0, 0.0, 259.95, 120.0, 30.0])
    fwd = mapping.map_pairs(pt, pb, theta_3d, theta_2d_of(0.7), p_max_2d_kpa=300.0)
    back = mapping.map_pairs(
        fwd["p_top_2d_kpa"], fwd["p_bottom_2d_kpa"], theta_2d_of(0.7), theta_3d, p_max_2d_kpa=300.0
    )
    np.testing.assert_allclose(back["p_top_2d_kpa"], pt, atol=1e-6)
    np.testing.assert_allclose(back["p_bottom_2d_kpa"], pb, atol=1e-6)
    np.testing.assert_allclose(fwd["scale"] * back["scale"], 1.0, rtol=1e-8)


def _fitted(a, fea, regressor):
    """A surrogate fitted on a sweep of the double theta_2d_of(a)."""

    def solve(direction, scales):
        pt, pb = scales * direction[0], scales * direction[1]
        n = scales.size
        th = theta_2d_of(a)(pt, pb)
        return pt, pb, th, 0.001 * th, np.zeros(n, int), np.ones(n, int), np.zeros(n)

    resp = sweep.merge_shards(
        [sweep.run_shard(solve, shard=0, n_shards=1, p_max_kpa=300.0, n_ratios=11, n_pressures=12)],
        n_ratios=11,
        n_pressures=12,
    )
    return surrogates.fit_surrogate(resp, regressor, fea=fea)


@pytest.mark.parametrize("regressor, tol", [("rbf", 0.01), ("knn", 0.15)])
def test_on_fitted_surrogates(regressor, tol):
    s3, s2 = _fitted(1.0, "3d", regressor), _fitted(0.8, "2d", regressor)
    planned = mapping.read_planned_pressures(TABLE8)
    ds = mapping.mapping_dataset(
        planned, s3.angle_deg, s2.angle_deg, p_max_2d_kpa=s2.p_max_kpa, p_max_3d_kpa=s3.p_max_kpa
    )
    ok = ds["status"].values == 0
    assert ok.sum() == 17
    np.testing.assert_allclose(ds["scale"].values[ok], 0.8, rtol=tol)


def test_dataset_roundtrip(tmp_path):
    planned = mapping.read_planned_pressures(TABLE8)
    ds = mapping.mapping_dataset(planned, theta_3d, theta_2d_of(0.8), p_max_2d_kpa=300.0, p_max_3d_kpa=300.0)
    path = write_dataset(ds, tmp_path / "m.nc", rule="mapping_2d3d", config_slice={}, title="t")
    back = xr.load_dataset(path)
    np.testing.assert_allclose(back["pressure_2d_kpa"].values, ds["pressure_2d_kpa"].values)
    np.testing.assert_array_equal(back["reason"].values.astype(str), ds["reason"].values.astype(str))
    assert back["status"].attrs["flag_meanings"] == "mapped equal_pressures outside_2d_grid"


def test_mapped_2d_pressures_stay_under_the_silicone_limit(tmp_path):
    """A weaker 2D unit needs 1.1 x the 3D pressure: within the 2D sweep (300 kPa), never beyond the material limit."""
    from workflow.actuator.pressure_limit import PressureLimit

    paths = {
        fea: surrogates.save_surrogate(_fitted(a, fea, "rbf"), tmp_path / f"surrogate_{fea}.joblib")
        for a, fea in ((1.0, "3d"), (1.1, "2d"))
    }
    free = entry.write_mapping(TABLE8, paths["3d"], paths["2d"], tmp_path / "free.nc", config_slice={})
    assert float(free["pressure_2d_kpa"].max()) > 250.0
    limit = PressureLimit(250.0, "actuator.material.p_limit_kpa: test")
    ds = entry.write_mapping(TABLE8, paths["3d"], paths["2d"], tmp_path / "m.nc", config_slice={}, material_limit=limit)
    assert float(ds["pressure_2d_kpa"].max()) <= 250.0
    assert int((ds["status"] == 2).sum()) > int((free["status"] == 2).sum())  # not reached within 250 kPa
    assert ds.attrs["p_max_2d_kpa"] == 250.0 and ds.attrs["p_limit_source"] == limit.source
    # under Table 7's moments too: same bound, every mapped pair's 3D angle under load reproduced by the 2D unit
    t7 = REPO_ROOT / "resources" / "table07_unit_targets.csv"
    ld = entry.write_mapping(
        TABLE8, paths["3d"], paths["2d"], tmp_path / "l.nc", config_slice={}, material_limit=limit, unit_moments_csv=t7
    )
    assert float(np.nanmax(ld["pressure_2d_loaded_kpa"])) <= 250.0
    assert ld["unit_moment_nm"].sel(exercise="TGE3", group="PIP") == pytest.approx(7.71e-3)
    # both doubles have the same spring (M_b = 0.001 theta_f): the moment cancels, and where both maps find a pair
    # it is the free map's; under the moments most pairs need more than 250 kPa (status 2), none is beyond it
    ok = ((ld["status_loaded"] == 0) & (ld["status"] == 0)).values
    assert ok.sum() >= 2
    np.testing.assert_allclose(ld["scale_loaded"].values[ok], ld["scale"].values[ok], rtol=0.02)
    assert set(np.unique(ld["status_loaded"].values)) <= {0, 1, 2}


def test_loaded_map_matches_the_angles_under_the_units_moment():
    # linear doubles: theta_f3 = g (P_T - P_B), theta_f2(P) = theta_f3(P / a); springs k3 and a weaker k2.
    # Under an end moment M the 2D scale s solves g s dP / a - M / k2 = g dP - M / k3 exactly:
    # s = a (1 + M (1/k2 - 1/k3) / (g dP)); at M = 0 it is the free-angle map's s = a.
    from workflow.actuator.unit_model import UnitModel

    g, a, k3, k2 = 0.1, 0.6, 0.01, 0.004

    def unit(angle):
        return UnitModel(angle, lambda pt, pb, k=(k3 if angle is th3 else k2): k * angle(pt, pb), p_max_kpa=1e6)

    def th3(pt, pb):
        return g * (np.asarray(pt, float) - np.asarray(pb, float))

    def th2(pt, pb):
        return th3(np.asarray(pt, float) / a, np.asarray(pb, float) / a)

    u3, u2 = unit(th3), unit(th2)
    pt, pb, m = np.array([200.0, 150.0, 100.0]), np.array([0.0, 50.0, 0.0]), np.array([0.02, 0.01, 0.0])
    r = mapping.map_pairs(pt, pb, u3.angle_deg, u2.angle_deg, p_max_2d_kpa=1e4, m_ext_nm=m)
    expected = a * (1.0 + m * (1.0 / k2 - 1.0 / k3) / (g * (pt - pb)))
    assert list(r["status"]) == [0, 0, 0]
    np.testing.assert_allclose(r["scale"], expected, rtol=1e-7)
    assert r["scale"][0] > 1.1 * a  # a weaker 2D unit needs more pressure under load
    np.testing.assert_allclose(r["angle_2d_deg"], r["angle_3d_deg"], atol=1e-7)
    np.testing.assert_allclose(r["angle_3d_deg"], th3(pt, pb) - m / k3)
    free = mapping.map_pairs(pt, pb, th3, th2, p_max_2d_kpa=1e4)
    assert free["scale"][2] == pytest.approx(r["scale"][2], rel=1e-9)


def test_table7_moments_per_exercise_and_group():
    m = mapping.read_unit_moments(REPO_ROOT / "resources" / "table07_unit_targets.csv", ["TGE3", "TGE9"])
    assert m.shape == (2, 4)
    np.testing.assert_allclose(m[0], [1.28e-3, 1.28e-3, 7.71e-3, -1.37e-4])  # CMC, MCP, PIP, DIP
    assert np.isnan(m[1]).all()  # an exercise the table lacks
