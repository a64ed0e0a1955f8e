"""Surrogates: CV on shared folds, selection rule, fit/save/load.

Data come from a TEST DOUBLE solver (smooth analytic function with the unit's
symmetries), so the scores below are a plumbing check, not actuator results.
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from _doubles import double_response as response

from workflow.actuator import surrogates
from workflow.common.provenance import write_dataset


@pytest.fixture(scope="module")
def cv():
    return surrogates.surrogate_cv({"2d": response(), "3d": response(5, 6)}, k=4, folds=5, random_state=3)


def test_cv_dataset_layout(cv, tmp_path):
    assert dict(cv.sizes) == {"fea": 2, "regressor": 5, "target": 2, "fold": 5}
    assert list(cv["target"].values) == ["angle", "moment"]
    for v in ("r2", "mae", "rmse", "fit_time_s", "predict_time_s"):
        assert np.all(np.isfinite(cv[v].values)), v
        assert cv[v].attrs["units"] and cv[v].attrs["long_name"]
    assert np.all(cv["rmse"] >= cv["mae"])  # holds for every fold by Cauchy-Schwarz
    path = write_dataset(cv, tmp_path / "cv.nc", rule="surrogate_cv", config_slice={}, title="t")
    back = xr.load_dataset(path)
    np.testing.assert_array_equal(back["chosen"].values.astype(str), cv["chosen"].values.astype(str))
    np.testing.assert_allclose(back["r2"].values, cv["r2"].values)


def test_scores_on_the_double(cv):
    r2 = cv["r2"].mean("fold")
    # the paper's model: coarse but well correlated on a smooth response
    assert float(r2.sel(fea="2d", regressor="knn", target="angle")) > 0.9
    # a smooth interpolant must beat 4-NN averaging on a smooth function
    rmse = cv["rmse"].mean("fold").sel(fea="2d", target="angle")
    assert float(rmse.sel(regressor="rbf")) < 0.5 * float(rmse.sel(regressor="knn"))


def test_selection_rule_picks_the_smallest_score(cv):
    for fea in cv["fea"].values:
        c = cv.sel(fea=fea)
        score = (c["rmse"] / c["target_std"]).mean(("fold", "target"))
        expected = str(score["regressor"].values[int(np.argmin(score.values))])
        assert str(c["chosen"].values) == expected
        assert bool(c["selected"].sel(regressor=expected))
        assert int(c["selected"].sum()) == 1


def test_same_folds_same_scores(seed):
    X, Y = surrogates.training_data(response(4, 5))
    a = surrogates.cross_validate(X, Y, regressors=("knn", "linear"), folds=5, random_state=seed)
    b = surrogates.cross_validate(X, Y, regressors=("linear",), folds=5, random_state=seed)
    # the linear interpolator scores the same whether or not KNN ran beside it: the folds are shared
    np.testing.assert_allclose(a["rmse"].sel(regressor="linear"), b["rmse"].sel(regressor="linear"))
    c = surrogates.cross_validate(X, Y, regressors=("linear",), folds=5, random_state=seed + 1)
    assert not np.allclose(c["rmse"].values, b["rmse"].values)


def test_knn_is_the_mean_of_four_nearest_in_scaled_space():
    X, Y = surrogates.training_data(response(4, 5))
    m = surrogates.make_regressor("knn", k=4).fit(X, Y["angle"])
    q = np.array([[123.0, 45.0]])
    Z = (X - X.mean(0)) / X.std(0)
    zq = (q - X.mean(0)) / X.std(0)
    nearest = np.argsort(np.linalg.norm(Z - zq, axis=1))[:4]
    np.testing.assert_allclose(m.predict(q), Y["angle"][nearest].mean())


@pytest.mark.parametrize("name", ["knn_distance", "rbf", "linear"])
def test_interpolators_reproduce_samples(name):
    X, Y = surrogates.training_data(response(4, 5))
    m = surrogates.make_regressor(name).fit(X, Y["moment"])
    np.testing.assert_allclose(m.predict(X), Y["moment"], atol=1e-9)


def test_failed_points_not_trained_on():
    r = response(4, 5)
    status = r["status"].values.copy()
    status[[2, 7]] = 1
    r["status"].values[:] = status
    X, _ = surrogates.training_data(r)
    assert X.shape[0] == r.sizes["point"] - 2


@pytest.mark.parametrize("name", ["knn", "linear", "rbf"])
def test_fit_save_load_roundtrip(tmp_path, name):
    r = response(5, 6)
    s = surrogates.fit_surrogate(r, name, fea="3d", k=4)
    path = surrogates.save_surrogate(s, tmp_path / "s.joblib")
    back = surrogates.load_surrogate(path)
    pt = np.linspace(0, 300, 7)[:, None]
    pb = np.linspace(0, 300, 5)[None, :]
    a = s.angle_deg(pt, pb)
    assert a.shape == (7, 5)
    np.testing.assert_array_equal(back.angle_deg(pt, pb), a)
    np.testing.assert_array_equal(back.moment_nm(pt, pb), s.moment_nm(pt, pb))
    assert back.p_max_kpa == 300.0 and back.regressor == name


def test_density_study_error_falls_with_density():
    dense = response(11, 12)
    st = surrogates.density_study(dense, [(3, 3), (6, 6), (11, 4)], regressors=("knn", "rbf"))
    rm = st["rmse"].sel(target="angle")
    assert float(rm.sel(design="6x6", regressor="rbf")) < float(rm.sel(design="3x3", regressor="rbf"))
    assert float(rm.sel(design="6x6", regressor="knn")) < float(rm.sel(design="3x3", regressor="knn"))
    # 3x3 trains on 3 rays x 3 scales (+ 2 x 3 mirrors)
    assert int(st["n_train"].sel(design="3x3")) == 15
    with pytest.raises(ValueError, match="sub-grid"):
        surrogates.density_study(dense, [(4, 3)])
