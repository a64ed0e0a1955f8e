"""Surrogates of a unit's response over (P_T, P_B): cross-validation, choice, fit, save.

The paper fits its FE samples with k-nearest-neighbour regression (k = 4) and
reports 5-fold CV scores (section 3.1).  Here the same KNN model and, on the same
folds, other regressors and interpolators are scored:

``knn``           KNN, uniform weights, k from config (the paper's model)
``knn_distance``  KNN with inverse-distance weights (exact at the samples)
``rbf``           scipy RBFInterpolator, thin-plate spline (smooth, exact at the samples)
``linear``        scipy LinearNDInterpolator on the Delaunay triangulation (nearest
                  sample outside the convex hull)
``gp``            Gaussian process, anisotropic RBF kernel plus white noise

Each is a scikit-learn Pipeline (StandardScaler, model) fitted on the training
split only.  Targets: ``angle`` (free bending angle per unit, deg) and
``moment`` (blocked moment per unit, N m), fitted separately.

The CV uses every converged sample, mirrored ones included (they are data the
surrogate is trained on; a mirror sits elsewhere in the (P_T, P_B) plane, so it
does not stand in for its held-out twin).

Choice (`SELECTION_RULE`): the regressor with the smallest mean over folds and
both targets of the RMSE divided by the target's standard deviation over the
samples; the choice is made per FE model and recorded in ``surrogate_cv.nc``.
"""

from __future__ import annotations

import logging
import time
import warnings
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Callable, Mapping, Sequence

import joblib
import numpy as np
import sklearn
import xarray as xr
from sklearn.model_selection import KFold
from sklearn.pipeline import Pipeline

from workflow.actuator.regressors import REGRESSORS, make_regressor
from workflow.common.fidelity_choice import cheapest_within
from workflow.common.provenance import corrupt_input, load_joblib

__all__ = [
    "TARGETS",
    "SELECTION_RULE",
    "training_data",
    "cross_validate",
    "surrogate_cv",
    "select_regressor",
    "Surrogate",
    "fit_surrogate",
    "save_surrogate",
    "load_surrogate",
    "density_study",
    "as_callables",
]

log = logging.getLogger(__name__)

#: target name -> (response variable, units)
TARGETS = {"angle": ("bending_angle_deg", "degree"), "moment": ("bending_moment_nm", "N m")}
SELECTION_RULE = (
    "smallest mean over folds and targets (angle, moment) of RMSE / standard deviation of the target; "
    "chosen per FE model"
)


def training_data(response: xr.Dataset) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Converged samples of a response dataset: X = (P_T, P_B) in kPa, y per target."""
    ok = (
        (response["status"].values == 0)
        & np.isfinite(response["bending_angle_deg"].values)
        & np.isfinite(response["bending_moment_nm"].values)
    )
    X = np.column_stack([response["p_top_kpa"].values[ok], response["p_bottom_kpa"].values[ok]])
    Y = {t: response[var].values[ok].astype(float) for t, (var, _) in TARGETS.items()}
    return X, Y


def cross_validate(
    X: np.ndarray,
    Y: Mapping[str, np.ndarray],
    *,
    regressors: Sequence[str] = REGRESSORS,
    k: int = 4,
    folds: int = 5,
    random_state: int = 0,
) -> xr.Dataset:
    """K-fold CV of every regressor on the same (shuffled, seeded) folds.

    Returns a Dataset on (regressor, target, fold) with ``r2``, ``mae``,
    ``rmse``, ``fit_time_s``, ``predict_time_s``.  A regressor that fails on a
    fold scores NaN there (logged), it does not stop the comparison.
    """
    targets = list(Y)
    shape = (len(regressors), len(targets), folds)
    out = {m: np.full(shape, np.nan) for m in ("r2", "mae", "rmse", "fit_time_s", "predict_time_s")}
    splitter = KFold(n_splits=folds, shuffle=True, random_state=random_state)
    for f, (tr, te) in enumerate(splitter.split(X)):
        for i, name in enumerate(regressors):
            for j, t in enumerate(targets):
                y = np.asarray(Y[t], float)
                model = make_regressor(name, k=k, random_state=random_state)
                try:
                    t0 = time.perf_counter()
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")  # GP bound warnings on near-noise-free data
                        model.fit(X[tr], y[tr])
                    t1 = time.perf_counter()
                    pred = model.predict(X[te])
                    t2 = time.perf_counter()
                except Exception:  # noqa: BLE001 - a failing candidate scores NaN
                    log.exception("CV: %s on %s failed in fold %d", name, t, f)
                    continue
                err = pred - y[te]
                ss_tot = np.sum((y[te] - y[te].mean()) ** 2)
                out["r2"][i, j, f] = 1.0 - np.sum(err**2) / ss_tot if ss_tot > 0 else np.nan
                out["mae"][i, j, f] = np.mean(np.abs(err))
                out["rmse"][i, j, f] = np.sqrt(np.mean(err**2))
                out["fit_time_s"][i, j, f] = t1 - t0
                out["predict_time_s"][i, j, f] = t2 - t1
    dims = ("regressor", "target", "fold")
    ds = xr.Dataset(
        {m: (dims, v) for m, v in out.items()},
        coords={"regressor": list(regressors), "target": targets, "fold": np.arange(folds)},
    )
    ds["target_std"] = ("target", np.array([np.std(np.asarray(Y[t], float)) for t in targets]))
    ds["n_samples"] = ((), np.int32(X.shape[0]))
    return ds


def select_regressor(cv: xr.Dataset, tolerance: float | None = None) -> tuple[str, xr.DataArray, str]:
    """One FE model's CV results -> (chosen name, score per regressor, why).

    Without ``tolerance``: `SELECTION_RULE`.  With it (``fidelity.auto``): the
    regressor with the shortest prediction time whose score is within
    ``tolerance`` (model no more than needed), else the best score.
    """

    score = (cv["rmse"] / cv["target_std"]).mean(("fold", "target"), skipna=False)
    if np.all(np.isnan(score.values)):
        raise ValueError("no regressor completed every fold")
    names = [str(r) for r in score["regressor"].values]
    if tolerance is None:
        best = names[int(np.nanargmin(score.values))]
        return best, score, f"{best}: {SELECTION_RULE} (score {float(score.sel(regressor=best)):.4g})"
    t = cv["predict_time_s"].mean(("fold", "target")).values
    ch = cheapest_within("surrogate", names, t, score.values, float(tolerance), unit="RMSE/std")
    return ch.method, score, ch.reason


def surrogate_cv(
    responses: Mapping[str, xr.Dataset],
    *,
    regressors: Sequence[str] = REGRESSORS,
    k: int = 4,
    folds: int = 5,
    random_state: int = 0,
    tolerance: float | None = None,
) -> xr.Dataset:
    """CV of every regressor for every FE model (``{'2d': ds, '3d': ds}``) -> ``surrogate_cv.nc`` content.

    Dims ``fea``, ``regressor``, ``target``, ``fold``; adds ``score`` (fea,
    regressor), ``selected`` (fea, regressor), ``choice_reason`` (fea) and the
    rule in the attrs; ``tolerance``: see :func:`select_regressor`.
    """
    parts, reasons = [], []
    for fea, resp in responses.items():
        X, Y = training_data(resp)
        log.info("CV %s: %d converged samples of %d, %d folds", fea, X.shape[0], resp.sizes["point"], folds)
        if X.shape[0] < max(folds, k + 1):
            raise ValueError(
                f"{fea} sweep: {X.shape[0]} converged samples of {resp.sizes['point']}, too few for "
                f"{folds}-fold cross-validation of a {k}-nearest-neighbour surrogate; the sweep's "
                "status variable says where its rays stopped"
            )
        cv = cross_validate(X, Y, regressors=regressors, k=k, folds=folds, random_state=random_state)
        best, score, why = select_regressor(cv, tolerance)
        cv["score"] = score
        cv["selected"] = ("regressor", cv["regressor"].values == best)
        reasons.append(why)
        log.info(
            "CV %s: chosen %s (%s); scores %s",
            fea,
            best,
            why,
            dict(zip(score["regressor"].values, score.values.round(5))),
        )
        parts.append(cv.expand_dims(fea=[fea]))
    ds = xr.concat(parts, dim="fea")
    ds["choice_reason"] = ("fea", np.array(reasons, dtype=object))
    ds["chosen"] = (
        "fea",
        np.array(
            [str(ds["regressor"].values[ds["selected"].sel(fea=f).values][0]) for f in ds["fea"].values], dtype=object
        ),
    )
    per_target = "deg for target angle, N m for target moment (see target_units)"
    ds = ds.assign_coords(target_units=("target", [TARGETS[t][1] for t in ds["target"].values]))
    attrs = {
        "r2": ("1", "coefficient of determination on the held-out fold"),
        "mae": (per_target, "mean absolute error on the held-out fold"),
        "rmse": (per_target, "root mean squared error on the held-out fold"),
        "fit_time_s": ("s", "wall time to fit on the training folds"),
        "predict_time_s": ("s", "wall time to predict the held-out fold"),
        "target_std": (per_target, "standard deviation of the target over the converged samples"),
        "n_samples": ("1", "converged samples used"),
        "score": ("1", "selection score: mean over folds and targets of rmse / target_std"),
        "selected": ("1", "regressor chosen for this FE model by the selection rule"),
        "chosen": ("1", "name of the chosen regressor"),
        "choice_reason": ("1", "why this regressor (rule, scores, tolerance)"),
    }
    for name, (units, long_name) in attrs.items():
        ds[name].attrs.update({"units": units, "long_name": long_name})
    ds.attrs["selection_rule"] = (
        SELECTION_RULE
        if tolerance is None
        else (
            f"fidelity.auto: the fastest prediction among the regressors whose score (mean RMSE/std) is within "
            f"{tolerance:g}, else the best score"
        )
    )
    ds.attrs["k_neighbours"] = int(k)
    ds.attrs["folds"] = int(folds)
    ds.attrs["random_state"] = int(random_state)
    return ds


@dataclass
class Surrogate:
    """A fitted surrogate of one FE model: angle and moment over (P_T, P_B) in kPa.

    Vectorised: every method broadcasts ``p_top_kpa`` and ``p_bottom_kpa``
    against each other and returns an array of the broadcast shape.
    """

    fea: str
    regressor: str
    models: dict[str, Pipeline]
    p_max_kpa: float
    n_samples: int
    meta: dict = field(default_factory=dict)

    def predict(self, target: str, p_top_kpa, p_bottom_kpa) -> np.ndarray:
        pt, pb = np.broadcast_arrays(np.asarray(p_top_kpa, float), np.asarray(p_bottom_kpa, float))
        X = np.column_stack([pt.ravel(), pb.ravel()])
        return np.asarray(self.models[target].predict(X), float).reshape(pt.shape)

    def angle_deg(self, p_top_kpa, p_bottom_kpa) -> np.ndarray:
        """Free bending angle per unit, deg."""
        return self.predict("angle", p_top_kpa, p_bottom_kpa)

    def moment_nm(self, p_top_kpa, p_bottom_kpa) -> np.ndarray:
        """Blocked moment per unit, N m."""
        return self.predict("moment", p_top_kpa, p_bottom_kpa)


def fit_surrogate(response: xr.Dataset, regressor: str, *, fea: str, k: int = 4, random_state: int = 0) -> Surrogate:
    """Fit ``regressor`` on all converged samples of ``response`` (both targets)."""
    X, Y = training_data(response)
    models = {}
    for t, y in Y.items():
        m = make_regressor(regressor, k=k, random_state=random_state)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            models[t] = m.fit(X, y)
    p_max = float(max(response["p_top_kpa"].max(), response["p_bottom_kpa"].max()))
    return Surrogate(
        fea=fea,
        regressor=regressor,
        models=models,
        p_max_kpa=p_max,
        n_samples=int(X.shape[0]),
        meta={"k": int(k), "random_state": int(random_state)},
    )


def save_surrogate(surrogate: Surrogate, path: str | Path) -> Path:
    """Write a fitted surrogate with joblib (atomically: temporary name, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    joblib.dump({"surrogate": surrogate, "sklearn_version": sklearn.__version__}, tmp)
    tmp.replace(path)
    return path


def load_surrogate(path: str | Path) -> Surrogate:
    """Load a surrogate written by `save_surrogate` (trusted files only: joblib unpickles).

    A damaged file, one that holds no surrogate of this version, or one fitted
    with another scikit-learn (its models may predict differently) raises
    `workflow.common.provenance.CorruptInputError`, naming the file and the fix.
    """
    obj = load_joblib(path)
    s = obj.get("surrogate") if isinstance(obj, dict) else None
    if not isinstance(s, Surrogate) or any(not hasattr(s, f.name) for f in fields(Surrogate)):
        raise corrupt_input(
            path,
            f"holds {type(s if s is not None else obj).__name__}, not a surrogate "
            "written by this version of the workflow",
        )
    if obj.get("sklearn_version") != sklearn.__version__:
        raise corrupt_input(
            path,
            f"fitted with scikit-learn {obj.get('sklearn_version')}, this is "
            f"{sklearn.__version__} (its models may predict differently)",
        )
    return s


def as_callables(surrogate: Surrogate) -> tuple[Callable, Callable]:
    """(free_angle_deg, blocked_moment_nm) callables for `workflow.actuator.unit_model.UnitModel`."""
    return surrogate.angle_deg, surrogate.moment_nm


def density_study(
    response: xr.Dataset,
    designs: Sequence[tuple[int, int]],
    *,
    regressors: Sequence[str] = ("knn",),
    k: int = 4,
    random_state: int = 0,
) -> xr.Dataset:
    """How dense a sweep the surrogates need: fit on coarser sub-grids of a dense sweep, test on the rest.

    ``response`` is a merged sweep (points carry ``ratio`` and ``scale`` of their
    solved ray).  Each design (n_ratios, n_pressures) keeps the points whose ray
    ratio is on linspace(0, 1, n_ratios) and whose scale is on the multiples of
    1/n_pressures (mirrors included); it must be a sub-grid of the dense one.
    Returns ``rmse``, ``mae``, ``max_abs_error`` and ``n_train`` on
    (design, regressor, target), measured on the dense points left out.
    """
    ok = response["status"].values == 0
    ratio, scale = response["ratio"].values, response["scale"].values
    X = np.column_stack([response["p_top_kpa"].values, response["p_bottom_kpa"].values])
    names = [f"{nr}x{npr}" for nr, npr in designs]
    shape = (len(designs), len(regressors), len(TARGETS))
    out = {m: np.full(shape, np.nan) for m in ("rmse", "mae", "max_abs_error")}
    n_train = np.zeros(len(designs), dtype=np.int32)
    for i, (nr, npr) in enumerate(designs):
        on_r = np.isclose(ratio[:, None], np.linspace(0.0, 1.0, nr)[None, :], atol=1e-9).any(axis=1)
        on_s = np.isclose(scale[:, None], (np.arange(1, npr + 1) / npr)[None, :], atol=1e-9).any(axis=1)
        train = ok & on_r & on_s
        test = ok & ~(on_r & on_s)
        n_train[i] = int(train.sum())
        if not (np.unique(ratio[on_r]).size == nr and np.unique(scale[on_s]).size == npr):
            raise ValueError(f"design {nr}x{npr} is not a sub-grid of the sweep")
        if test.sum() == 0 or train.sum() < max(k, 3):
            continue
        for j, name in enumerate(regressors):
            for t, (var, _) in enumerate(TARGETS.values()):
                y = response[var].values
                m = make_regressor(name, k=k, random_state=random_state)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    m.fit(X[train], y[train])
                err = m.predict(X[test]) - y[test]
                out["rmse"][i, j, t] = np.sqrt(np.mean(err**2))
                out["mae"][i, j, t] = np.mean(np.abs(err))
                out["max_abs_error"][i, j, t] = np.max(np.abs(err))
    dims = ("design", "regressor", "target")
    ds = xr.Dataset(
        {m: (dims, v) for m, v in out.items()},
        coords={"design": names, "regressor": list(regressors), "target": list(TARGETS)},
    )
    ds["n_train"] = ("design", n_train)
    return ds
