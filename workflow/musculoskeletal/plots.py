"""Plots of the DOE and musculoskeletal stages (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

from workflow.musculoskeletal.validation import DIMENSIONS

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

__all__ = ["plot_rsm_r2", "plot_joint_loads", "plot_moment_angle", "plot_validation", "plot_missing_reference"]


def plot_rsm_r2(ds: xr.Dataset, out: str | Path) -> None:
    """Unexplained variance 1 - R^2 of each response and form (log axis), the selected form
    marked, beside the paper's range of R^2 (0.8344-0.9998)."""
    names = list(ds["response"].values)
    y = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(7, 0.25 * len(names) + 1.5))
    floor = 1e-7  # a perfect fit would sit at -inf on the log axis
    for k, (form, mk) in enumerate(zip(ds["form"].values, "os^")):
        r2 = ds["r2"].sel(form=form).values
        ax.scatter(np.maximum(1 - r2, floor), y + (k - 1) * 0.2, marker=mk, s=18, label=str(form))
    sel = ds["r2"].where(ds["selected"]).max("form").values
    ax.scatter(np.maximum(1 - sel, floor), y, facecolors="none", edgecolors="k", s=70, label="selected")
    ax.axvspan(1 - 0.9998, 1 - 0.8344, color="0.9", zorder=0, label="paper: R$^2$ 0.8344-0.9998")
    ax.set_xscale("log")
    ax.set_yticks(y, names, fontsize=7)
    ax.set_xlabel("1 - R$^2$ (unexplained variance; smaller is better)")
    ax.legend(fontsize=7, loc="best")
    ax.set_title("Response-surface fits of joint moments (15 CCD runs)")
    fig.tight_layout()
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)


def plot_joint_loads(ds: xr.Dataset, out: str | Path) -> None:
    """Passive moments per exercise and joint with prediction intervals, and the active limits."""
    joints = list(ds["joint"].values)
    exercises = list(ds["exercise"].values)
    fig, axes = plt.subplots(1, len(joints), figsize=(3.2 * len(joints), 3.2), sharey=False)
    for ax, joint in zip(np.atleast_1d(axes), joints):
        m = ds["passive_moment_nm"].sel(joint=joint).values
        lo = ds["passive_moment_lo_nm"].sel(joint=joint).values
        hi = ds["passive_moment_hi_nm"].sel(joint=joint).values
        x = np.arange(len(exercises))
        ax.bar(x, m, color="tab:blue", alpha=0.7, label="passive (95 % PI)")
        ax.errorbar(x, m, yerr=[m - lo, hi - m], fmt="none", ecolor="k", capsize=3)
        ax.set_xticks(x, exercises, fontsize=8)
        ax.set_title(f"{joint}: active limit {float(ds['active_limit_nm'].sel(joint=joint)):.2f} N m", fontsize=9)
        ax.set_ylabel("joint moment [N m]")
    fig.suptitle(f"Patient {ds.attrs.get('patient', '')}: passive joint moments at the exercise targets", fontsize=10)
    fig.tight_layout()
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)


def plot_moment_angle(ds: xr.Dataset, out: str | Path, finger: str | None = None) -> None:
    """Moment (N m) against joint angle (deg) per joint: rows passive / active, one line per CCD run.

    The design centre (marker ``Original``) is drawn black; NaN (not sampled) points are skipped.
    """
    fingers = [str(f) for f in ds["finger"].values]
    finger = finger or ("F3" if "F3" in fingers else fingers[0])
    acts = np.sort(ds["activation"].values)
    joints = [str(j) for j in ds["joint"].values]
    fig, axes = plt.subplots(2, len(joints), figsize=(4.2 * len(joints), 6.4), squeeze=False)
    markers = [str(m) for m in ds["marker"].values] if "marker" in ds.coords else [""] * ds.sizes["run"]
    colours = plt.cm.viridis(np.linspace(0, 0.9, ds.sizes["run"]))
    ang = ds["angle_deg"].values
    for row, (act, label) in enumerate(((acts[0], "passive"), (acts[-1], "active"))):
        for col, j in enumerate(joints):
            ax = axes[row, col]
            for k, run in enumerate(ds["run"].values):
                y = ds["moment_nm"].sel(run=run, finger=finger, joint=j, activation=act).values
                ok = np.isfinite(y)
                centre = markers[k] == "Original"
                ax.plot(
                    ang[ok],
                    y[ok],
                    "-",
                    color="k" if centre else colours[k],
                    lw=1.8 if centre else 0.8,
                    label="design centre" if centre else None,
                    zorder=3 if centre else 2,
                )
            ax.set_title(f"{finger} {j}, {label} (activation {act:g})", fontsize=9)
            ax.set_xlabel("joint angle (deg, + = flexion)")
            ax.set_ylabel("moment to hold the joint (N m)")
            ax.axhline(0, color="0.7", lw=0.6)
            if row == 0 and col == 0:
                ax.legend(fontsize=7)
    fig.suptitle(f"Joint moment-angle curves of the {ds.sizes['run']} CCD runs (other joints at 0 deg)", fontsize=10)
    fig.tight_layout()
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def plot_validation(ds: xr.Dataset, out: str | Path) -> Path:
    """Two panels: |ours| against |theirs| (log-log, one point per response and run), and trends."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 5))
    for kind, marker in (("_P_", "o"), ("_A_", "s")):
        sel = [r for r in ds["response"].values if kind in r]
        if not sel:
            continue
        d = ds.sel(response=sel)
        same = d["sign_agrees"].values
        o, r = np.abs(d["ours"].values), np.abs(d["reference"].values)
        a.scatter(r[same], o[same], marker=marker, s=12, label=f"{'passive' if kind == '_P_' else 'active'}, same sign")
        a.scatter(
            r[~same],
            o[~same],
            marker=marker,
            s=12,
            facecolors="none",
            edgecolors="k",
            label=f"{'passive' if kind == '_P_' else 'active'}, opposite sign",
        )
    if "ours_tone_free" in ds:
        tf = np.abs(ds["ours_tone_free"].values)
        ok = np.isfinite(tf)
        a.scatter(
            np.abs(ds["reference"].values)[ok],
            tf[ok],
            marker="^",
            s=12,
            color="C2",
            label="passive at activation 0 (tone-free)",
        )
    lims = [1e-4, 20]
    a.plot(lims, lims, "k--", lw=0.8)
    a.set(
        xscale="log",
        yscale="log",
        xlim=lims,
        ylim=lims,
        xlabel="|reference| (ARMS export), N m",
        ylabel="|ours|, N m",
        title="Moments at the 15 CCD runs",
    )
    a.legend(fontsize=7)
    f3 = [r for r in ds["response"].values if r.startswith("F3_")]
    d = ds.sel(response=f3)
    norm_o = d["slope_ours"] / np.abs(d["ours"]).mean("run")
    norm_r = d["slope_reference"] / np.abs(d["reference"]).mean("run")
    xpos = np.arange(len(f3))
    for k, dim in enumerate(DIMENSIONS):
        b.scatter(
            xpos + 0.25 * (k - 1), norm_r.sel(dimension=dim), marker="x", color=f"C{k}", label=f"{dim}, reference"
        )
        b.scatter(
            xpos + 0.25 * (k - 1),
            norm_o.sel(dimension=dim),
            marker="o",
            facecolors="none",
            edgecolors=f"C{k}",
            label=f"{dim}, ours",
        )
    b.axhline(0, color="k", lw=0.6)
    b.set_xticks(xpos, f3, rotation=45, ha="right", fontsize=8)
    b.set(ylabel="slope / mean |moment| per coded unit", title="Trends with each dimension (middle finger)")
    b.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def plot_missing_reference(reference_csv: str | Path, out: str | Path) -> Path:
    """A placeholder figure saying the authors' export to compare with is absent."""
    fig, ax = plt.subplots()
    ax.text(0.5, 0.5, f"reference export absent:\n{reference_csv}", ha="center")
    ax.axis("off")
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return Path(out)
