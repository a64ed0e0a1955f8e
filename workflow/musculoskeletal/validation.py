"""Our OpenSim moments against the authors' export (the joint moments at the CCD runs).

For every response column of the export (e.g. ``F3_P_MCP_90``: middle finger,
passive, MCP at 90 deg) and each of the 15 CCD runs (matched by coded levels):
our value, theirs, the absolute and relative error, whether the signs agree
and the magnitude ratio |ours|/|theirs|.  Per response: the slope of a linear
fit on the coded depth, length and breadth for both data sets (the trend with
each dimension, fitted to the magnitudes since the export's active moments are
positive; the paper finds breadth has almost no effect) and the R^2 of
the linear and full quadratic response surfaces fitted to our data and theirs.
Moments N m; slopes N m per coded unit.
"""

from __future__ import annotations

import logging
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

__all__ = ["read_reference", "compare", "DIMENSIONS", "FORMS", "summary"]

log = logging.getLogger(__name__)

DIMENSIONS = ("depth", "length", "breadth")
FORMS = ("linear", "quadratic")
_ACT = {"P": 0.01, "A": 1.0}


def read_reference(path: str | Path) -> pd.DataFrame | None:
    """The authors' export (rows with data only), or ``None`` when the file is absent."""
    path = Path(path)
    if not path.is_file():
        return None
    df = pd.read_csv(path).dropna(how="all")
    return df.rename(columns={"Depth": "depth", "Length": "length", "Breadth": "breadth"})


def _design_matrix(x: np.ndarray, form: str) -> np.ndarray:
    """Columns 1, x_i (linear) plus x_i^2 and x_i x_j (quadratic); x is (n, 3) coded."""
    cols = [np.ones(len(x))] + [x[:, i] for i in range(3)]
    if form == "quadratic":
        cols += [x[:, i] ** 2 for i in range(3)]
        cols += [x[:, i] * x[:, j] for i in range(3) for j in range(i + 1, 3)]
    return np.column_stack(cols)


def _fit(x: np.ndarray, y: np.ndarray, form: str) -> tuple[np.ndarray, float]:
    """OLS coefficients and R^2 (NaN if y has NaN or no variance)."""
    X = _design_matrix(x, form)
    if not np.all(np.isfinite(y)) or np.ptp(y) == 0:
        return np.full(X.shape[1], np.nan), float("nan")
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    ss_res = float(np.sum((y - X @ coef) ** 2))
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    return coef, 1.0 - ss_res / ss_tot


def compare(ours: xr.Dataset, design: pd.DataFrame, reference: pd.DataFrame, floor_nm: float = 1e-4) -> xr.Dataset:
    """Validation dataset (dims ``response``, ``run``, ``dimension``, ``form``).

    ``ours``: the ``moments.nc`` layout; ``design``: coded levels per run
    (index = run, columns depth, length, breadth); ``reference``: the export.
    ``rel_error`` is NaN where |reference| < ``floor_nm``.
    """
    runs = list(design.index)
    key = design[list(DIMENSIONS)].round(3)
    ref_key = reference[list(DIMENSIONS)].round(3)
    ref_rows = []
    for run in runs:
        match = np.flatnonzero((ref_key.values == key.loc[run].values).all(axis=1))
        if len(match) != 1:
            raise ValueError(f"run {run}: {len(match)} rows of the reference have coded levels {key.loc[run].tolist()}")
        ref_rows.append(match[0])
    responses = [c for c in reference.columns if c[:1] == "F" and c.count("_") == 3]
    x = design.loc[runs, list(DIMENSIONS)].to_numpy(float)
    nr, nn = len(responses), len(runs)
    ours_v = np.full((nr, nn), np.nan)
    ref_v = np.full((nr, nn), np.nan)
    for i, name in enumerate(responses):
        finger, kind, joint, angle = name.split("_")
        ref_v[i] = reference[name].to_numpy(float)[ref_rows]
        if finger in ours["finger"].values and float(angle) in ours["angle_deg"].values:
            ours_v[i] = (
                ours["moment_nm"]
                .sel(run=runs, finger=finger, joint=joint, angle_deg=float(angle), activation=_ACT[kind])
                .to_numpy()
            )
    # Passive responses also against our tone-free passive curve (activation 0), when present.
    tone_v = np.full((nr, nn), np.nan)
    if "passive_tone_free_moment_nm" in ours:
        for i, name in enumerate(responses):
            finger, kind, joint, angle = name.split("_")
            if kind == "P" and finger in ours["finger"].values and float(angle) in ours["angle_deg"].values:
                tone_v[i] = (
                    ours["passive_tone_free_moment_nm"]
                    .sel(run=runs, finger=finger, joint=joint, angle_deg=float(angle))
                    .to_numpy()
                )
    abs_err = np.abs(ours_v - ref_v)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(np.abs(ref_v) >= floor_nm, (ours_v - ref_v) / np.abs(ref_v), np.nan)
        ratio = np.where(np.abs(ref_v) >= floor_nm, np.abs(ours_v) / np.abs(ref_v), np.nan)
    sign_ok = np.sign(ours_v) == np.sign(ref_v)
    slopes_o = np.full((nr, 3), np.nan)
    slopes_r = np.full((nr, 3), np.nan)
    r2_o = np.full((nr, len(FORMS)), np.nan)
    r2_r = np.full((nr, len(FORMS)), np.nan)
    for i in range(nr):
        # Trends of the magnitudes: the export's active moments are positive
        # where ours (device moment against a contracting finger) are negative.
        slopes_o[i] = _fit(x, np.abs(ours_v[i]), "linear")[0][1:]
        slopes_r[i] = _fit(x, np.abs(ref_v[i]), "linear")[0][1:]
        for k, form in enumerate(FORMS):
            r2_o[i, k] = _fit(x, ours_v[i], form)[1]
            r2_r[i, k] = _fit(x, ref_v[i], form)[1]
    # A trend agrees when both slopes have the same sign, or both are small
    # (below 5 % of the response's mean magnitude per coded unit).
    with warnings.catch_warnings():  # responses we do not model (a finger left out) are all-NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        scale_o = np.nanmean(np.abs(ours_v), axis=1, keepdims=True)
        scale_r = np.nanmean(np.abs(ref_v), axis=1, keepdims=True)
        med = np.nanmedian(ratio, axis=1)
    small_o = np.abs(slopes_o) < 0.05 * scale_o
    small_r = np.abs(slopes_r) < 0.05 * scale_r
    trend_ok = (np.sign(slopes_o) == np.sign(slopes_r)) | (small_o & small_r)
    rd, r_ = ("response", "run"), ("response", "dimension")
    ds = xr.Dataset(
        {
            "ours": (rd, ours_v, {"units": "N m", "long_name": "our OpenSim moment (device flexion moment)"}),
            "reference": (rd, ref_v, {"units": "N m", "long_name": "authors' OpenSim (ARMS) export"}),
            "abs_error": (rd, abs_err, {"units": "N m", "long_name": "|ours - reference|"}),
            "rel_error": (
                rd,
                rel,
                {"units": "1", "long_name": f"(ours - reference)/|reference| (NaN if |reference| < {floor_nm} N m)"},
            ),
            "magnitude_ratio": (rd, ratio, {"units": "1", "long_name": "|ours| / |reference|"}),
            "sign_agrees": (rd, sign_ok, {"long_name": "ours and the reference have the same sign"}),
            "slope_ours": (r_, slopes_o, {"units": "N m", "long_name": "linear-fit slope of |ours| per coded unit"}),
            "slope_reference": (
                r_,
                slopes_r,
                {"units": "N m", "long_name": "linear-fit slope of |reference| per coded unit"},
            ),
            "trend_agrees": (
                r_,
                trend_ok,
                {"long_name": "slopes share their sign (or both < 5 % of the mean per coded unit)"},
            ),
            "r2_ours": (
                ("response", "form"),
                r2_o,
                {"units": "1", "long_name": "R^2 of the response surface fitted to ours"},
            ),
            "r2_reference": (
                ("response", "form"),
                r2_r,
                {"units": "1", "long_name": "R^2 of the response surface fitted to the reference"},
            ),
        },
        coords={"response": responses, "run": runs, "dimension": list(DIMENSIONS), "form": list(FORMS)},
    )
    ds["median_magnitude_ratio"] = (
        ("response",),
        med,
        {"units": "1", "long_name": "median over runs of |ours|/|reference|"},
    )
    with warnings.catch_warnings(), np.errstate(invalid="ignore", divide="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        ratio_tf = np.where(np.abs(ref_v) >= floor_nm, np.abs(tone_v) / np.abs(ref_v), np.nan)
        ds["ours_tone_free"] = (
            rd,
            tone_v,
            {"units": "N m", "long_name": "our passive moment at activation 0 (passive responses)"},
        )
        ds["median_magnitude_ratio_tone_free"] = (
            ("response",),
            np.nanmedian(ratio_tf, axis=1),
            {"units": "1", "long_name": "median over runs of |ours at activation 0| / |reference| (passive responses)"},
        )
        sign_tf = np.where(np.isfinite(tone_v), np.sign(tone_v) == np.sign(ref_v), np.nan)
        ds["sign_agreement_fraction_tone_free"] = (
            ("response",),
            np.nanmean(sign_tf, axis=1),
            {
                "units": "1",
                "long_name": "fraction of runs where our activation-0 passive moment has the reference's sign",
            },
        )
    ds["sign_agreement_fraction"] = (
        ("response",),
        sign_ok.mean(axis=1),
        {"units": "1", "long_name": "fraction of runs with the same sign"},
    )
    return ds


def summary(ds: xr.Dataset) -> str:
    """One line per response: sign agreement, median ratio, slopes (ours / theirs), R^2."""
    lines = [f"{'response':16s} sign  ratio   d(ours/ref)        l(ours/ref)        b(ours/ref)        R2q ours/ref"]
    for r in ds["response"].values:
        d = ds.sel(response=r)
        sl = "  ".join(
            f"{float(d.slope_ours.sel(dimension=k)):+.3g}/{float(d.slope_reference.sel(dimension=k)):+.3g}"
            for k in DIMENSIONS
        )
        tf = ""
        if "median_magnitude_ratio_tone_free" in d and np.isfinite(float(d.median_magnitude_ratio_tone_free)):
            tf = (
                f"  tone-free: sign {float(d.sign_agreement_fraction_tone_free):.2f}"
                f" ratio {float(d.median_magnitude_ratio_tone_free):.3f}"
            )
        lines.append(
            f"{r:16s} {float(d.sign_agreement_fraction):.2f}  {float(d.median_magnitude_ratio):6.3f}  {sl}  "
            f"{float(d.r2_ours.sel(form='quadratic')):.3f}/{float(d.r2_reference.sel(form='quadratic')):.3f}{tf}"
        )
    return "\n".join(lines)
