"""Plots of the DOE and musculoskeletal stages (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

__all__ = ["plot_rsm_r2", "plot_joint_loads"]


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
