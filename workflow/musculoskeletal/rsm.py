"""Response-surface fits of joint moments over the coded finger dimensions.

Three forms are fitted by OLS (statsmodels formulas on a tidy frame of coded
levels), each with its ANOVA:

``linear``        y = b0 + b1 x1 + b2 x2 + b3 x3
``quadratic``     + squares and two-way interactions (the paper's Eq. 1, ten terms)
``quadratic_3fi`` + the three-way interaction x1 x2 x3 (eleven terms)

Selection rule: among the forms whose overall F-test has p < alpha, take the
one with the largest adjusted R^2 (parsimony through the adjustment); when no
form is significant, take the largest adjusted R^2 and mark the response
``significant = False``.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np
import pandas as pd
import statsmodels.formula.api as smf
import xarray as xr

__all__ = ["FORMS", "TERMS", "FORMULAS", "fit_response", "fit_all", "rsm_dataset", "predict"]

FORMS = ("linear", "quadratic", "quadratic_3fi")
TERMS = (
    "1",
    "depth",
    "length",
    "breadth",
    "depth^2",
    "length^2",
    "breadth^2",
    "depth:length",
    "depth:breadth",
    "length:breadth",
    "depth:length:breadth",
)
_LIN = "depth + length + breadth"
_QUAD = _LIN + " + I(depth**2) + I(length**2) + I(breadth**2) + depth:length + depth:breadth + length:breadth"
FORMULAS = {
    "linear": "y ~ " + _LIN,
    "quadratic": "y ~ " + _QUAD,
    "quadratic_3fi": "y ~ " + _QUAD + " + depth:length:breadth",
}
# statsmodels' parameter names -> our fixed term names
_SM_TO_TERM = {
    "Intercept": "1",
    "I(depth ** 2)": "depth^2",
    "I(length ** 2)": "length^2",
    "I(breadth ** 2)": "breadth^2",
}


def _term(name: str) -> str:
    return _SM_TO_TERM.get(name, name)


def fit_response(x: pd.DataFrame, y: np.ndarray, form: str):
    """OLS fit of one response in one form; ``x`` has columns depth, length, breadth."""
    frame = x[["depth", "length", "breadth"]].reset_index(drop=True).assign(y=np.asarray(y, float))
    return smf.ols(FORMULAS[form], data=frame).fit()


def fit_all(x: pd.DataFrame, responses: Mapping[str, np.ndarray]) -> dict[str, dict[str, object]]:
    """Fits of every response in every form: ``{response: {form: results}}``."""
    return {name: {form: fit_response(x, y, form) for form in FORMS} for name, y in responses.items()}


def _select(r2adj: np.ndarray, p: np.ndarray, alpha: float) -> tuple[int, bool]:
    sig = np.isfinite(p) & (p < alpha)
    cand = np.where(sig, r2adj, -np.inf) if sig.any() else np.nan_to_num(r2adj, nan=-np.inf)
    return int(np.argmax(cand)), bool(sig.any())


def rsm_dataset(fits: Mapping[str, Mapping[str, object]], alpha: float = 0.05) -> xr.Dataset:
    """The contract's ``rsm.nc`` from :func:`fit_all`'s result."""
    names = list(fits)
    nr, nf, nt = len(names), len(FORMS), len(TERMS)
    coef = np.full((nr, nf, nt), np.nan)
    tp = np.full((nr, nf, nt), np.nan)
    r2 = np.full((nr, nf), np.nan)
    r2a = np.full((nr, nf), np.nan)
    p = np.full((nr, nf), np.nan)
    dof = np.full((nr, nf), np.nan)
    for i, name in enumerate(names):
        for j, form in enumerate(FORMS):
            res = fits[name][form]
            for k, (pname, val) in enumerate(res.params.items()):
                t = TERMS.index(_term(pname))
                coef[i, j, t] = val
                tp[i, j, t] = res.pvalues.iloc[k]
            r2[i, j], r2a[i, j], p[i, j], dof[i, j] = res.rsquared, res.rsquared_adj, res.f_pvalue, res.df_resid
    selected = np.zeros((nr, nf), bool)
    significant = np.zeros(nr, bool)
    for i in range(nr):
        j, significant[i] = _select(r2a[i], p[i], alpha)
        selected[i, j] = True
    dims2 = ("response", "form")
    ds = xr.Dataset(
        {
            "coef": (("response", "form", "term"), coef, {"units": "N m", "long_name": "regression coefficient"}),
            "term_p_value": (
                ("response", "form", "term"),
                tp,
                {"units": "1", "long_name": "t-test p-value of the term"},
            ),
            "r2": (dims2, r2, {"units": "1", "long_name": "coefficient of determination R^2"}),
            "adj_r2": (dims2, r2a, {"units": "1", "long_name": "adjusted R^2"}),
            "p_value": (dims2, p, {"units": "1", "long_name": "overall F-test p-value"}),
            "df_resid": (dims2, dof, {"units": "1", "long_name": "residual degrees of freedom"}),
            "selected": (dims2, selected, {"long_name": "form chosen by the selection rule"}),
            "significant": ("response", significant, {"long_name": f"selected form has overall p < {alpha}"}),
        },
        coords={"response": names, "form": list(FORMS), "term": list(TERMS)},
    )
    ds.attrs["selection_rule"] = (
        f"among forms with overall F-test p < {alpha}, the largest adjusted R^2; "
        "if none is significant, the largest adjusted R^2 (significant = False)"
    )
    ds.attrs["formulas"] = "; ".join(f"{k}: {v}" for k, v in FORMULAS.items())
    return ds


def predict(res, x: Mapping[str, float], alpha: float = 0.05) -> tuple[float, float, float]:
    """Prediction and (1 - alpha) prediction interval of a fit at coded levels ``x``, N m."""
    frame = pd.DataFrame({k: [float(x[k])] for k in ("depth", "length", "breadth")})
    sf = res.get_prediction(frame).summary_frame(alpha=alpha)
    return float(sf["mean"].iloc[0]), float(sf["obs_ci_lower"].iloc[0]), float(sf["obs_ci_upper"].iloc[0])
