import json

import numpy as np
import xarray as xr
from xarray.testing import assert_identical

from workflow.common import provenance


def test_roundtrip_keeps_data_attrs_and_provenance(tmp_path):
    ds = xr.Dataset(
        {
            "a": ("x", np.array([1.0, np.nan, 3.0]), {"units": "N m", "long_name": "a"}),
            "ok": ("x", np.array([True, False, True])),
            "status": (
                "x",
                np.array([0, 1, 0], dtype="i4"),
                {"flag_values": [0, 1], "flag_meanings": "converged failed"},
            ),
        },
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
    assert "workflow/fem/coupled.py" not in unit  # the finger-actuator model does not rerun the unit sweeps
    check = provenance.code_files("scripts.fea_check")  # a rule's adapter: its entry point and all it imports
    for f in (
        "workflow/fem/coupled.py",
        "workflow/fem/finger2d.py",
        "workflow/fem/__init__.py",
        "workflow/cascade/model.py",
        "workflow/fea_check/entry.py",
        "workflow/actuator/mapping.py",
    ):
        assert f in check
    assert "workflow/common/provenance.py" in unit
    # the FE sweep's inputs hold the sweep and the engine, not the fitting code downstream of it
    shard = provenance.code_files("scripts.sweep_shard")
    assert "workflow/actuator/sweep.py" in shard and "workflow/fem/_contact.py" in shard
    assert not {"workflow/actuator/surrogates.py", "workflow/actuator/mapping.py", "workflow/actuator/entry.py"} & set(
        shard
    )


def test_code_files_names_an_unknown_module():
    import pytest

    with pytest.raises(FileNotFoundError, match="workflow.no_such_module"):
        provenance.code_files("no_such_module")


# --- A damaged or foreign input: one line naming the file, what is wrong and the fix ----------------------
def _response(tmp_path, drop=()):
    ds = xr.Dataset(
        {
            v: ("point", np.zeros(3))
            for v in (
                "bending_angle_deg",
                "bending_moment_nm",
                "status",
                "converged",
                "mirrored",
                "newton_iterations",
                "wall_time_s",
            )
        },
        coords={"p_top_kpa": ("point", [0.0, 150.0, 300.0]), "p_bottom_kpa": ("point", np.zeros(3))},
    )
    return provenance.write_dataset(
        ds.drop_vars(list(drop)),
        tmp_path / "results" / "actuator" / "response_3d.nc",
        rule="sweep_merge",
        config_slice={},
        title="t",
    )


def _one_line(err, path, *needles):
    msg = str(err.value)
    assert (
        "\n" not in msg and msg.startswith(str(path)) and msg.endswith("delete it and rerun: Snakemake recomputes it")
    )
    for needle in needles:
        assert needle in msg


def test_truncated_netcdf_is_named_with_the_fix(tmp_path):
    import pytest

    path = _response(tmp_path)
    assert provenance.open_result(path)["converged"].size == 3
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(provenance.CorruptInputError) as err:
        provenance.open_result(path)
    _one_line(err, path, "not a readable netCDF file")
    path.write_bytes(b"")
    with pytest.raises(OSError):  # CorruptInputError is an OSError: callers catching those still do
        provenance.open_result(path)


def test_netcdf_without_the_contracts_variables_is_named(tmp_path):
    import pytest

    path = _response(tmp_path, drop=("converged", "mirrored"))
    with pytest.raises(provenance.CorruptInputError) as err:
        provenance.open_result(path)
    _one_line(err, path, "converged, mirrored")
    assert provenance.open_result(path, required_vars=("status",))["status"].size == 3  # the caller's own list
    with pytest.raises(FileNotFoundError):
        provenance.open_result(tmp_path / "absent.nc")


def test_garbage_foreign_or_other_version_joblib_is_named(tmp_path):
    import joblib
    import pytest

    from workflow.actuator import surrogates

    cases = {
        "garbage.joblib": (b"\x80\x04 not a pickle at all", "not a readable joblib file"),
        "foreign.joblib": ({"weights": [1, 2]}, "holds dict, not a surrogate"),
        "old.joblib": (
            {"surrogate": surrogates.Surrogate("3d", "knn", {}, 300.0, 0), "sklearn_version": "0.1"},
            "fitted with scikit-learn 0.1",
        ),
    }
    for name, (content, needle) in cases.items():
        path = tmp_path / name
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            joblib.dump(content, path)
        with pytest.raises(provenance.CorruptInputError) as err:
            surrogates.load_surrogate(path)
        _one_line(err, path, needle)
