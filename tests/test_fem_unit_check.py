"""The unit-check writer: contract variables, units, CF flags, provenance, .vtu."""

import meshio
import numpy as np
import xarray as xr

from workflow.actuator import entry_fem


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
