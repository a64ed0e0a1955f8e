"""The surrogates' regressors: KNN (the paper's), radial basis functions,
piecewise-linear interpolation and a Gaussian process, each a scikit-learn
pipeline behind a standard scaler.  Inputs (P_T, P_B) kPa.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator, RBFInterpolator
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel
from sklearn.neighbors import KNeighborsRegressor
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.preprocessing import StandardScaler

__all__ = ["REGRESSORS", "RBFRegressor", "LinearInterpRegressor", "make_regressor"]

REGRESSORS = ("knn", "knn_distance", "rbf", "linear", "gp")


class RBFRegressor(RegressorMixin, BaseEstimator):
    """scipy RBFInterpolator as a scikit-learn regressor (thin-plate spline by default)."""

    def __init__(self, kernel: str = "thin_plate_spline", smoothing: float = 0.0):
        self.kernel = kernel
        self.smoothing = smoothing

    def fit(self, X, y):
        self.interp_ = RBFInterpolator(
            np.asarray(X, float), np.asarray(y, float), kernel=self.kernel, smoothing=self.smoothing
        )
        return self

    def predict(self, X):
        return self.interp_(np.asarray(X, float))


class LinearInterpRegressor(RegressorMixin, BaseEstimator):
    """Piecewise-linear interpolation on the Delaunay triangulation; nearest sample outside the hull."""

    def fit(self, X, y):
        self.X_ = np.asarray(X, float)
        self.y_ = np.asarray(y, float)
        self._build()
        return self

    def _build(self):
        self._lin = LinearNDInterpolator(self.X_, self.y_)
        self._near = NearestNDInterpolator(self.X_, self.y_)

    def predict(self, X):
        X = np.asarray(X, float)
        out = self._lin(X)
        bad = np.isnan(out)
        if bad.any():
            out[bad] = self._near(X[bad])
        return out

    # The qhull objects are rebuilt after unpickling rather than stored.
    def __getstate__(self):
        state = self.__dict__.copy()
        state.pop("_lin", None)
        state.pop("_near", None)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        if "X_" in state:
            self._build()


def make_regressor(name: str, *, k: int = 4, random_state: int = 0) -> Pipeline:
    """A fresh, unfitted Pipeline (StandardScaler, model) for regressor ``name``."""
    if name == "knn":
        model = KNeighborsRegressor(n_neighbors=k, weights="uniform")
    elif name == "knn_distance":
        model = KNeighborsRegressor(n_neighbors=k, weights="distance")
    elif name == "rbf":
        model = RBFRegressor()
    elif name == "linear":
        model = LinearInterpRegressor()
    elif name == "gp":
        kernel = ConstantKernel(1.0, (1e-3, 1e3)) * RBF([1.0, 1.0], (1e-2, 1e2)) + WhiteKernel(1e-4, (1e-10, 1e-1))
        model = GaussianProcessRegressor(kernel=kernel, normalize_y=True, random_state=random_state)
    else:
        raise ValueError(f"unknown regressor {name!r}; known: {REGRESSORS}")
    return make_pipeline(StandardScaler(), model)
