"""Figures of the stability maps (matplotlib, Agg backend); data from ``stability.nc``.

* `plot_failures`: status of every FE sample over (P_T, P_B), one panel per method.
* `plot_locking`: free angle and plain/mixed ratio against K/mu0.
* `plot_penetration`: largest contact penetration per method against the bound, and over the plane.
* `plot_coverage`: where the surrogates were sampled, and the cascade's planned pairs.
* `plot_design_feasibility`: RSM prediction variance outside the design sphere, patients, exercises reached.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402

__all__ = ["plot_failures", "plot_locking", "plot_penetration", "plot_coverage", "plot_design_feasibility"]

#: status code -> (marker, colour, label) of the sweep status (SWEEP_SAMPLE_STATUS)
_STATUS_STYLE = {
    0: ("o", "tab:green", "converged"),
    1: ("X", "tab:red", "diverged"),
    2: (".", "0.55", "not reached"),
    3: ("s", "k", "solver error"),
}


def _save(fig, out) -> None:
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def _methods(ds: xr.Dataset) -> list[str]:
    return list(dict.fromkeys(ds["method"].values.tolist()))


def _grid(n: int, ncols: int = 4, size=(3.3, 3.0)):
    ncols = max(1, min(ncols, n))
    nrows = int(np.ceil(n / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(size[0] * ncols, size[1] * nrows + 0.6), squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    return fig, axes.ravel()


def plot_failures(ds: xr.Dataset, out) -> None:
    """Status of every sample over (P_T, P_B), one panel per method; hollow = mirrored copy."""
    methods = _methods(ds)
    fig, axes = _grid(len(methods))
    pmax = float(max(ds["p_top_kpa"].max(), ds["p_bottom_kpa"].max(), 1.0))
    for ax, m in zip(axes, methods):
        on = ds["method"].values == m
        st, mir = ds["status"].values, ds["mirrored"].values
        for code, (mk, col, lab) in _STATUS_STYLE.items():
            for mirrored in (False, True):
                sel = on & (st == code) & (mir == mirrored)
                if sel.any():
                    ax.scatter(
                        ds["p_top_kpa"].values[sel],
                        ds["p_bottom_kpa"].values[sel],
                        marker=mk,
                        s=28,
                        facecolors="none" if mirrored else col,
                        edgecolors=col,
                        linewidths=1.0,
                        label=lab if not mirrored else None,
                    )
        c = ds["failure_count"].sel(fe_method=m).values
        ax.set_title(f"{m}\n{c[0]}/{c.sum()} solved samples converged", fontsize=7.5)
        ax.set_xlim(-0.04 * pmax, 1.04 * pmax)
        ax.set_ylim(-0.04 * pmax, 1.04 * pmax)
        ax.set_aspect("equal")
        ax.set_xlabel("P_T (kPa)", fontsize=8)
        ax.set_ylabel("P_B (kPa)", fontsize=8)
        ax.tick_params(labelsize=7)
    handles = [plt.Line2D([], [], marker=mk, color=col, ls="", label=lab) for mk, col, lab in _STATUS_STYLE.values()]
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.suptitle("Newton failures by method (hollow: mirrored copy of a solved sample)", fontsize=10)
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    _save(fig, out)


def plot_locking(ds: xr.Dataset, out) -> None:
    """Free angle per unit against K/mu0 per formulation, and the locking ratios."""
    k = ds["bulk_ratio"].values
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.6))
    for f, mk in zip(ds["formulation"].values, ("o-", "s--", "^:", "d-.")):
        a.plot(k, ds["locking_angle_deg"].sel(formulation=f).values, mk, label=str(f))
    a.set_xscale("log")
    a.set_xlabel("K / mu0")
    a.set_ylabel("free bending angle per unit (deg)")
    a.axhline(0, color="0.7", lw=0.6)
    a.legend(fontsize=8)
    a.set_title(
        f"2D unit, h = {ds.attrs['locking_h_mm']:g} mm, P_T = {ds.attrs['locking_p_top_kpa']:g} kPa, no contact",
        fontsize=9,
    )
    r = ds["locking_ratio"].values
    b.semilogx(k, r, "o-", color="tab:red", label="volumetric: plain Q1 / mean dilatation")
    if "locking_shear_ratio" in ds:
        b.semilogx(
            k, ds["locking_shear_ratio"].values, "s--", color="tab:blue", label="shear: plain Q1 paper / enhanced paper"
        )
    b.axhline(1, color="0.6", lw=0.8, ls=":")
    b.set_xlabel("K / mu0")
    b.set_ylabel("angle ratio")
    b.set_ylim(min(-0.05, float(np.nanmin(r)) - 0.05), 1.1)
    b.legend(fontsize=7)
    b.set_title("locking ratios (1 = no locking)", fontsize=9)
    fig.tight_layout()
    _save(fig, out)


def plot_penetration(ds: xr.Dataset, out) -> None:
    """Largest penetration per method (bars) against the bound, and penetration over (P_T, P_B)."""
    bound = float(ds.attrs["penetration_bound_mm"])
    mx = ds["max_penetration_by_method"]
    has = np.isfinite(mx.values) & (mx.values > 0)
    methods = [str(m) for m in mx["fe_method"].values[has]]
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.2), gridspec_kw={"width_ratios": [1.1, 1]})
    if methods:
        y = np.arange(len(methods))
        vals = mx.values[has]
        a.barh(y, vals, color=np.where(vals > bound, "tab:red", "tab:blue"))
        a.set_yticks(y, methods, fontsize=7)
        a.set_xscale("log")
    a.axvline(bound, color="k", ls="--", lw=1, label=f"bound {bound:g} mm")
    a.set_xlabel("largest penetration over converged samples (mm)")
    a.legend(fontsize=8)
    pen = ds["max_penetration_mm"].values
    ok = (ds["status"].values == 0) & np.isfinite(pen) & (pen > 0)
    if ok.any():
        sc = b.scatter(
            ds["p_top_kpa"].values[ok],
            ds["p_bottom_kpa"].values[ok],
            c=pen[ok] / bound,
            cmap="viridis",
            s=30,
            vmin=0,
            vmax=max(1.0, float(np.nanmax(pen[ok] / bound))),
        )
        over = ok & (pen > bound)
        b.scatter(
            ds["p_top_kpa"].values[over],
            ds["p_bottom_kpa"].values[over],
            s=80,
            facecolors="none",
            edgecolors="tab:red",
            label="above bound",
        )
        fig.colorbar(sc, ax=b, label="penetration / bound")
        if over.any():
            b.legend(fontsize=8, loc="upper left")
    b.set_xlabel("P_T (kPa)")
    b.set_ylabel("P_B (kPa)")
    b.set_title("all methods with contact (largest value at each point shown last)", fontsize=9)
    fig.suptitle("Contact penetration (penalty contact)", fontsize=10)
    fig.tight_layout()
    _save(fig, out)


def plot_coverage(ds: xr.Dataset, sweeps: Mapping[str, xr.Dataset], out) -> None:
    """Sampled region of each surrogate (hull of converged samples) and the cascade's planned pairs."""
    feas = [str(f) for f in ds["fea"].values]
    fig, axes = plt.subplots(1, len(feas), figsize=(4.6 * len(feas), 4.4), squeeze=False)
    cmap = ListedColormap(["white", "#f4c7c3", "#d9ead3"])  # outside, near a failure, trusted
    for ax, f in zip(axes.ravel(), feas):
        g = ds.sel(fea=f)
        code = np.where(g["coverage_trusted"].values, 2, np.where(g["coverage_in_hull"].values, 1, 0))
        pt, pb = g["grid_p_top_kpa"].values, g["grid_p_bottom_kpa"].values
        ax.pcolormesh(pt, pb, code.T, cmap=cmap, vmin=0, vmax=2, shading="nearest")
        s = sweeps[f]
        okm = s["status"].values == 0
        ax.plot(s["p_top_kpa"].values[okm], s["p_bottom_kpa"].values[okm], "k.", ms=4, label="converged sample")
        if (~okm).any():
            ax.plot(s["p_top_kpa"].values[~okm], s["p_bottom_kpa"].values[~okm], "rx", ms=6, label="failed sample")
        if "query_fea" in ds and ds.sizes.get("query", 0):
            on = ds["query_fea"].values == f
            tr = ds["query_trusted"].values
            ax.plot(
                ds["query_p_top_kpa"].values[on & tr],
                ds["query_p_bottom_kpa"].values[on & tr],
                "o",
                mfc="none",
                mec="tab:blue",
                ms=7,
                label="planned pair, inside",
            )
            if (on & ~tr).any():
                ax.plot(
                    ds["query_p_top_kpa"].values[on & ~tr],
                    ds["query_p_bottom_kpa"].values[on & ~tr],
                    "^",
                    color="tab:orange",
                    ms=8,
                    label="planned pair, flagged",
                )
        ax.set_title(f"{f.upper()} surrogate: {float(g['covered_fraction']):.0%} of the square covered", fontsize=9)
        ax.set_xlabel("P_T (kPa)")
        ax.set_ylabel("P_B (kPa)")
        ax.set_aspect("equal")
        ax.legend(fontsize=7, loc="upper right", framealpha=0.8)
    fig.suptitle(
        "Sampled region (green: hull of converged samples; red: nearest sample failed; white: extrapolation)",
        fontsize=9,
    )
    fig.tight_layout()
    _save(fig, out)


def plot_design_feasibility(ds: xr.Dataset, design: np.ndarray, out) -> None:
    """RSM prediction variance against ||x||, patients in coded space, exercises reached per patient."""
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(14, 4.2), gridspec_kw={"width_ratios": [1.1, 1, 1.1]})
    for d in ds["direction"].values:
        a.semilogy(
            ds["radius"].values, ds["prediction_variance_radial"].sel(direction=d).values, label=f"{d} direction"
        )
    a.axvline(1.0, color="k", ls="--", lw=1, label="design sphere ||x|| = 1")
    a.axvline(float(ds.attrs["ccd_corner_norm"]), color="0.5", ls=":", lw=1, label="CCD corners")
    for p in ds["patient"].values:
        n = float(ds["coded_norm"].sel(patient=p))
        a.axvline(
            n, color="tab:red" if not bool(ds["in_design_range"].sel(patient=p)) else "tab:green", lw=0.8, alpha=0.7
        )
        a.text(n, 0.03, str(p), rotation=90, fontsize=7, va="bottom", ha="right", transform=a.get_xaxis_transform())
    a.set_xlabel("||x|| (coded)")
    a.set_ylabel("scaled prediction variance N Var/sigma^2")
    a.set_title("quadratic RSM: variance outside |x| <= 1", fontsize=9)
    a.legend(fontsize=7, loc="upper center")
    t = np.linspace(0, 2 * np.pi, 200)
    b.plot(np.cos(t), np.sin(t), "k--", lw=1, label="||x|| = 1")
    b.plot(design[:, 0], design[:, 1], "ks", ms=5, mfc="none", label="CCD runs (projected)")
    for p in ds["patient"].values:
        x = ds["x"].sel(patient=p).values
        ok = bool(ds["in_design_range"].sel(patient=p))
        b.plot(x[0], x[1], "o" if ok else "X", color="tab:green" if ok else "tab:red", ms=8)
        b.annotate(str(p), (x[0], x[1]), fontsize=7, xytext=(3, 3), textcoords="offset points")
    b.set_xlabel("depth (coded)")
    b.set_ylabel("length (coded)")
    b.set_aspect("equal")
    lim = max(1.3, float(np.nanmax(np.abs(ds["x"].values))) + 0.2) if ds.sizes["patient"] else 1.3
    b.set_xlim(-lim, lim)
    b.set_ylim(-lim, lim)
    b.legend(fontsize=7, loc="lower right")
    b.set_title("patients (red X: outside the design region)", fontsize=9)
    ach = ds["achieved"].values.astype(float)
    c.imshow(ach, cmap=ListedColormap(["#e06666", "#93c47d"]), vmin=0, vmax=1, aspect="auto")
    c.set_xticks(range(ds.sizes["exercise"]), [str(e) for e in ds["exercise"].values])
    c.set_yticks(range(ds.sizes["patient"]), [str(p) for p in ds["patient"].values])
    for i in range(ach.shape[0]):
        for j in range(ach.shape[1]):
            c.text(j, i, "reached" if ach[i, j] else "no", ha="center", va="center", fontsize=7)
    c.set_title("exercises with feasible pressures (cascade plan)", fontsize=9)
    fig.tight_layout()
    _save(fig, out)
