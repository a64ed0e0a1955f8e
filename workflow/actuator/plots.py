"""Plots of the actuator sweeps, surrogates and 2D-3D mapping (matplotlib, Agg backend).

* `plot_response`: like the paper's Fig. 11 (and Fig. 17b for 2D): free angle and
  blocked moment per unit over the pressure ratio P_B/P_T, one curve per top
  pressure, FE samples as markers and the surrogate as lines.
* `plot_mapping`: like Fig. 17's use: Table 8's 3D pressures against the mapped
  2D pressures, and the scale per exercise and group.
* `plot_surrogate_cv`: the CV comparison of the regressors.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

__all__ = ["plot_response", "plot_mapping", "plot_surrogate_cv", "plot_moment_check", "plot_unit_stiffness"]


def _save(fig, out: str | Path) -> None:
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)


def plot_response(response: xr.Dataset, surrogate, out: str | Path, *, fea: str = "", n_levels: int = 5) -> None:
    """Angle and moment per unit over P_B/P_T in [0, 1] for up to ``n_levels`` top pressures."""
    pt, pb = response["p_top_kpa"].values, response["p_bottom_kpa"].values
    lower = (pb <= pt + 1e-9) & (pt > 0)
    levels = np.unique(np.round(pt[lower], 6))
    if levels.size > n_levels:
        levels = levels[np.unique(np.linspace(0, levels.size - 1, n_levels).round().astype(int))]
    ratio = np.linspace(0.0, 1.0, 101)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    colours = plt.cm.viridis(np.linspace(0, 0.9, levels.size))
    for (var, target, label), ax in zip(
        [
            ("bending_angle_deg", "angle", "free bending angle per unit (deg)"),
            ("bending_moment_nm", "moment", "blocked moment per unit (N m)"),
        ],
        axes,
    ):
        for lev, c in zip(levels, colours):
            sel = lower & np.isclose(pt, lev)
            ok = sel & (response["status"].values == 0)
            bad = sel & (response["status"].values != 0)
            ax.plot(pb[ok] / pt[ok], response[var].values[ok], "o", color=c, ms=4)
            if bad.any():
                ax.plot(pb[bad] / pt[bad], np.zeros(bad.sum()), "x", color="r", ms=6)
            ax.plot(
                ratio, surrogate.predict(target, lev, ratio * lev), "-", color=c, lw=1.2, label=f"P_T = {lev:.0f} kPa"
            )
        ax.set_xlabel("pressure ratio P_B / P_T")
        ax.set_ylabel(label)
        ax.axhline(0, color="0.7", lw=0.6)
    axes[0].legend(fontsize=7)
    fig.suptitle(
        f"{fea.upper()} FE samples (markers; x = not converged) and {surrogate.regressor} surrogate (lines)", fontsize=9
    )
    fig.tight_layout()
    _save(fig, out)


def plot_mapping(mapping: xr.Dataset, out: str | Path) -> None:
    """3D (Table 8) against mapped 2D pressures per chamber, and the scale per exercise and group."""
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    p3, p2 = mapping["pressure_3d_kpa"], mapping["pressure_2d_kpa"]
    for g, mk in zip(mapping["group"].values, "osD^"):
        for ch, fill in zip(mapping["chamber"].values, ("full", "none")):
            a1.plot(
                p3.sel(group=g, chamber=ch).values,
                p2.sel(group=g, chamber=ch).values,
                mk,
                fillstyle=fill,
                label=f"{g} {ch}",
                ms=6,
            )
    lim = float(np.nanmax([np.nanmax(p3.values), np.nanmax(p2.values) if np.isfinite(p2.values).any() else 0]))
    a1.plot([0, lim], [0, lim], "k:", lw=0.8, label="2D = 3D")
    a1.set_xlabel("3D pressure, Table 8 (kPa)")
    a1.set_ylabel("2D pressure, same ratio and angle (kPa)")
    a1.legend(fontsize=6, ncol=2)
    ex = [str(e) for e in mapping["exercise"].values]
    x = np.arange(len(ex))
    w = 0.2
    for i, g in enumerate(mapping["group"].values):
        s = mapping["scale"].sel(group=g).values
        a2.bar(x + (i - 1.5) * w, np.nan_to_num(s), w, label=str(g))
        for xi, si, st in zip(x, s, mapping["status"].sel(group=g).values):
            if not np.isfinite(si):
                a2.text(xi + (i - 1.5) * w, 0.02, "=" if st == 1 else "out", ha="center", fontsize=6, rotation=90)
    a2.axhline(1.0, color="k", lw=0.6)
    a2.set_xticks(x, ex)
    a2.set_ylabel("scale s = P_2D / P_3D")
    a2.legend(fontsize=7)
    a2.set_title("'=': P_T = P_B (no unique s); 'out': beyond the 2D grid", fontsize=8)
    fig.tight_layout()
    _save(fig, out)


def plot_surrogate_cv(cv: xr.Dataset, out: str | Path) -> None:
    """Mean RMSE (bars, fold min-max as error bars) and mean R^2 (labels) per regressor, FE model and target."""
    feas, targets = list(cv["fea"].values), list(cv["target"].values)
    fig, axes = plt.subplots(len(feas), len(targets), figsize=(4.5 * len(targets), 3.2 * len(feas)), squeeze=False)
    regs = [str(r) for r in cv["regressor"].values]
    x = np.arange(len(regs))
    for i, fea in enumerate(feas):
        for j, t in enumerate(targets):
            ax = axes[i, j]
            rm = cv["rmse"].sel(fea=fea, target=t)
            mean, lo, hi = rm.mean("fold").values, rm.min("fold").values, rm.max("fold").values
            chosen = cv["selected"].sel(fea=fea).values
            ax.bar(x, mean, yerr=[mean - lo, hi - mean], color=np.where(chosen, "C1", "C0"), capsize=2)
            r2 = cv["r2"].sel(fea=fea, target=t).mean("fold").values
            for xi, m, r in zip(x, mean, r2):
                ax.text(xi, m, f"R²={r:.4f}", ha="center", va="bottom", fontsize=6)
            ax.set_yscale("log")
            ax.set_xticks(x, regs, fontsize=7, rotation=20)
            unit = str(cv["target_units"].sel(target=t).values) if "target_units" in cv.coords else ""
            ax.set_ylabel(f"RMSE ({unit})")
            ax.set_title(f"{str(fea).upper()} {t}; chosen: {regs[int(np.argmax(chosen))]}", fontsize=8)
    fig.suptitle(f"{int(cv.attrs.get('folds', cv.sizes['fold']))}-fold CV on shared folds", fontsize=9)
    fig.tight_layout()
    _save(fig, out)


def plot_moment_check(ds: xr.Dataset, out: str | Path) -> Path:
    """Middle unit's rotation against the chain's couple (markers) and each hold's spring (lines), per pair."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    npt = ds.sizes["point"]
    fig, axes = plt.subplots(1, npt, figsize=(4.2 * npt, 3.8), squeeze=False)
    styles = {"face": "-", "backbone": ":"}
    for i, ax in enumerate(axes[0]):
        M, th = ds["chain_moment_nm"][i].values, ds["chain_mid_angle_deg"][i].values
        ax.plot(M, th, "ko", label="chain of %d: middle unit" % ds.attrs.get("chain_units", 5))
        mmax = np.nanmax(np.concatenate([M, ds["blocked_moment_nm"][:, i].values]))
        m = np.linspace(0.0, mmax if np.isfinite(mmax) else 1.0, 20)
        for k, hold in enumerate(ds["end_hold"].values):
            thf, mb = float(ds["free_angle_deg"][i]), float(ds["blocked_moment_nm"][k, i])
            if np.isfinite(thf) and np.isfinite(mb):
                ax.plot(m, thf * (1 - m / mb), styles.get(str(hold), "--"), label=f"spring, {hold} hold")
        ax.set_title(f"P = ({ds.p_top_kpa.values[i]:g}, {ds.p_bottom_kpa.values[i]:g}) kPa", fontsize=9)
        ax.set_xlabel("end moment per unit (N m)")
        ax.set_ylabel("unit rotation (deg)")
        ax.axhline(0.0, color="0.6", lw=0.5)
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.suptitle("A unit inside a chain under an end moment vs the unit model's spring per end hold", fontsize=9)
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def plot_unit_stiffness(ds: xr.Dataset, out: str | Path) -> Path:
    """Bending stiffness of a unit inside the chain (FEA), the stiffness table and the unit model's, against the mean
    pressure (P_T + P_B) / 2, one line per pressure difference |P_T - P_B|."""
    pt, pb = ds["p_top_kpa"].values, ds["p_bottom_kpa"].values
    s, d = 0.5 * (pt + pb), np.abs(pt - pb)
    k = ds["k_nm_per_deg"].values * 1e3
    fit = ds["fit"].values.astype(bool) if "fit" in ds else np.ones(len(k), bool)
    solved = np.all(ds["status"].values == 0, axis=1)
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for c, dd in enumerate(np.unique(d)):
        on = d == dd
        o = np.flatnonzero(on & fit)[np.argsort(s[on & fit])]
        color = f"C{c % 10}"
        name = "P_T = P_B" if dd == 0 else f"|P_T - P_B| = {dd:g} kPa"
        ax.plot(s[o], k[o], "o-", color=color, ms=4, label=f"FEA, {name}")
        held = np.flatnonzero(on & ~fit)
        if held.size:
            ax.plot(s[held], k[held], "o", mfc="none", color=color, ms=7)
        for i in np.flatnonzero(on & ~np.isfinite(k)):
            # every solve converged but the middle unit did not turn: locked by contact across its gaps
            ax.annotate(
                "locked" if solved[i] else "failed",
                (s[i], 0.0),
                fontsize=7,
                color=color,
                rotation=90,
                ha="center",
                va="bottom",
            )
    if "k_table_nm_per_deg" in ds and (~fit).any():
        share = ds.attrs.get("heldout_moment_error_share_max", np.nan)
        ax.plot(
            s[~fit],
            ds["k_table_nm_per_deg"].values[~fit] * 1e3,
            "kx",
            ms=7,
            label=f"table at held-out pairs (open circles: FEA); moment error <= {100 * share:.1f} % of M_b,max",
        )
    if "k_model_nm_per_deg" in ds:
        ax.plot(
            s,
            ds["k_model_nm_per_deg"].values * 1e3,
            "d",
            color="0.4",
            ms=4,
            label="unit model's secant spring (offset estimate near P_T = P_B)",
        )
    ax.set_xlabel("mean pressure (P_T + P_B) / 2 (kPa)")
    ax.set_ylabel("bending stiffness per unit (N mm / deg)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title(
        f"Unit stiffness at end rotations of +-{ds.attrs['delta_deg']:g} deg per unit\n"
        f"(middle unit of a chain of {ds.attrs['chain_units']}, h = {ds.attrs['h_mm']:g} mm)",
        fontsize=8,
    )
    fig.tight_layout()
    _save(fig, out)
    return Path(out)
