import json

import numpy as np
import xarray as xr
from xarray.testing import assert_identical

from workflow import provenance


def test_roundtrip_keeps_data_attrs_and_provenance(tmp_path):
    ds = xr.Dataset(
        {"a": ("x", np.array([1.0, np.nan, 3.0]), {"units": "N m", "long_name": "a"}),
         "ok": ("x", np.array([True, False, True])),
         "status": ("x", np.array([0, 1, 0], dtype="i4"), {"flag_values": [0, 1], "flag_meanings": "converged failed"})},
        coords={"x": [1, 2, 3]},
    )
    path = provenance.write_dataset(ds, tmp_path / "d.nc", rule="test", config_slice={"k": 1}, title="t")
    with xr.open_dataset(path) as back:
        back = back.load()
    for key in ("config_sha256", "git_commit", "created_utc", "rule", "package_versions", "Conventions", "history"):
        assert key in back.attrs
    assert json.loads(back.attrs["package_versions"])["xarray"] == xr.__version__
    expected = ds.assign_attrs(back.attrs)
    assert_identical(back, expected)
    assert not (tmp_path / "d.nc.part").exists()


def test_config_hash_depends_only_on_the_slice():
    a = provenance.config_sha256({"patient": {"p1": {"coded": {"depth": 0}}}})
    b = provenance.config_sha256({"patient": {"p1": {"coded": {"depth": 0}}}})
    c = provenance.config_sha256({"patient": {"p1": {"coded": {"depth": 0.1}}}})
    assert a == b != c
    assert provenance.config_sha256({"a": 1, "b": 2}) == provenance.config_sha256({"b": 2, "a": 1})


def test_code_files_follow_the_imports_of_the_modules_a_rule_uses():
    unit = provenance.code_files("fem")
    assert "workflow/fem/_solve.py" in unit and "workflow/fem/_linsolve.py" in unit  # relative imports, transitively
    assert "workflow/fem/_coupled.py" not in unit  # the finger-actuator model does not rerun the unit sweeps
    check = provenance.code_files("fea_check")
    for f in ("workflow/fem/_coupled.py", "workflow/fem/_finger2d.py", "workflow/fem/__init__.py", "workflow/cascade.py"):
        assert f in check
    assert "workflow/mapping.py" in check  # imported lazily inside a function
    assert "workflow/provenance.py" in unit


def test_code_files_names_an_unknown_module():
    import pytest

    with pytest.raises(FileNotFoundError, match="workflow.no_such_module"):
        provenance.code_files("no_such_module")
