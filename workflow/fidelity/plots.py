"""Speed against accuracy chart, matplotlib Agg."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

from workflow.fidelity.analysis import METHOD_GROUPS, group_errors, pareto_front  # noqa: E402

__all__ = ["plot_speed_accuracy"]

_COLOURS = {
    "fem_2d": "tab:blue",
    "fem_3d": "tab:red",
    "surrogate_2d": "tab:cyan",
    "surrogate_3d": "tab:orange",
    "plan": "tab:purple",
    "check": "tab:green",
    "musculoskeletal": "tab:brown",
}


def _label(method: str) -> str:
    for p in ("fem_", "surrogate_", "plan_", "check_", "msk_"):
        if method.startswith(p):
            return method[len(p) :]
    return method


def plot_speed_accuracy(ds: xr.Dataset, out: str | Path) -> None:
    """One panel per quantity group: wall time against error, the Pareto fronts (one per front group) joined and ringed.

    References (error 0) sit on the bottom edge, marked "ref".
    """
    panels = [(t, p, y) for t, p, y in METHOD_GROUPS if np.isfinite(group_errors(ds, p).values).any()]
    n = max(len(panels), 1)
    cols = min(n, 3)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(5.0 * cols, 4.0 * rows), squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    for ax, (title, prefix, ylab) in zip(axes.ravel(), panels):
        e = group_errors(ds, prefix).values
        t = ds["wall_time_s"].values
        ok = np.isfinite(e) & np.isfinite(t) & (t > 0)
        pos = e[ok & (e > 0)]
        floor = (pos.min() / 3.0) if pos.size else 1e-6
        ep = np.where(e > 0, e, floor)
        groups = ds["front_group"].values if "front_group" in ds else np.full(t.size, "", dtype=object)
        front = np.zeros(t.size, bool)
        for g in dict.fromkeys(groups.tolist()):
            rows = groups == g
            front[rows] = pareto_front(np.where(ok & rows, t, np.nan)[rows], np.where(ok & rows, e, np.nan)[rows])
        for i in np.flatnonzero(ok):
            fam = str(ds["family"].values[i])
            ax.scatter(
                t[i],
                ep[i],
                s=28,
                color=_COLOURS.get(fam, "k"),
                zorder=3,
                edgecolors="k" if front[i] else "none",
                linewidths=1.2,
            )
            lab = _label(str(ds["method"].values[i])) + (" (ref)" if e[i] == 0 else "")
            ax.annotate(lab, (t[i], ep[i]), fontsize=5.5, xytext=(3, 2), textcoords="offset points")
        for g, ls in zip(dict.fromkeys(groups[front].tolist()), ("--", ":", "-.", "--")):
            f = np.flatnonzero(front & (groups == g))
            f = f[np.argsort(t[f])]
            ax.step(t[f], ep[f], where="post", color="k", lw=0.8, ls=ls, zorder=2)
            if str(g) in ("2d", "3d"):
                ax.annotate(f"{g} front", (t[f[-1]], ep[f[-1]]), fontsize=6, xytext=(4, -8), textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time per evaluation (s)", fontsize=7)
        ax.set_ylabel(ylab, fontsize=7)
        ax.set_title(title, fontsize=8)
        ax.tick_params(labelsize=6)
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
        fams = sorted({str(ds["family"].values[i]) for i in np.flatnonzero(ok)})
        handles = [plt.Line2D([], [], marker="o", ls="", color=_COLOURS.get(fm, "k"), label=fm) for fm in fams]
        two = {"2d", "3d"} <= set(groups[front].tolist())
        handles.append(
            plt.Line2D(
                [],
                [],
                color="k",
                ls="--",
                lw=0.8,
                label="Pareto fronts (ringed): 2D --, 3D :" if two else "Pareto front (ringed)",
            )
        )
        ax.legend(handles=handles, fontsize=5.5, loc="best")
    fig.suptitle("Speed against accuracy: every fidelity against the finest reference of its quantity", fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.96))
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=130)
    plt.close(fig)
