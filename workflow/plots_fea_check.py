"""Plots of the FEA check (Fig. 21-like poses) and of the stand-alone actuators (Fig. 22-like), matplotlib Agg."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402

from workflow.finger import JOINTS, Finger  # noqa: E402

__all__ = ["plot_fea_poses", "plot_standalone"]

_COLOURS = {0: "#6fa8dc", 1: "k", 2: "#f6b26b", 3: "#999999"}  # silicone, paper, flesh, bone


def _cells(ax, p: np.ndarray, t: np.ndarray, material: np.ndarray) -> None:
    polys = p[:, t].transpose(2, 1, 0)  # (ncell, 4, 2)
    ax.add_collection(PolyCollection(polys, facecolors=[_COLOURS.get(int(m), "c") for m in material],
                                     edgecolors="none", linewidths=0))


def plot_fea_poses(mesh_p: np.ndarray, mesh_t: np.ndarray, material: np.ndarray, states: Sequence[np.ndarray],
                   ds: xr.Dataset, finger: Finger, out: str | Path, title: str = "") -> None:
    """One panel per exercise: deformed actuator and finger (FEA), target pose of the
    joint chain (dashed), angles reached (target; plan) and the applied pressures."""
    n = len(states)
    fig, axes = plt.subplots(1, n, figsize=(3.4 * n, 3.8), squeeze=False)
    for ax, u, ex in zip(axes[0], states, ds["exercise"].values):
        x = mesh_p + np.asarray(u).reshape(-1, 2).T
        _cells(ax, x, mesh_t, material)
        row = ds.sel(exercise=ex)
        tgt = row["target_angle_deg"].values
        joints, _ = finger.joint_positions(tgt)
        tip = finger.pose(tgt, np.array([[finger.tip_x_m, finger.joints_ref[2, 1]]]), np.array([2]))
        chain = np.vstack([joints, tip]) * 1e3
        ax.plot(chain[:, 0], chain[:, 1], "--o", color="firebrick", ms=2.5, lw=1.0)
        ang = ", ".join(f"{j} {a:.0f}({t:.0f};{q:.0f})" for j, a, t, q in
                        zip(JOINTS, row["angle_deg"].values, tgt, row["predicted_angle_deg"].values))
        p = row["pressure_kpa"].values
        txt = "\n".join(f"{g}: {p[i, 0]:.0f}/{p[i, 1]:.0f}" for i, g in enumerate(ds["group"].values))
        ax.text(0.02, 0.02, txt + " kPa", transform=ax.transAxes, fontsize=6, va="bottom", family="monospace")
        ok = bool(row["achieved"].values)
        conv = "" if bool(row["converged"].values) else f" (stopped at {float(row['load_factor']):.2f})"
        ax.set_title(f"{ex}: {'reached' if ok else 'not reached'}{conv}\n{ang} deg", fontsize=7.5,
                     color="k" if ok else "firebrick")
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.tick_params(labelsize=6)
        ax.set_xlabel("x (mm)", fontsize=7)
    axes[0, 0].set_ylabel("y, dorsal (mm)", fontsize=7)
    fig.suptitle(f"FEA check, 2D plane strain{': ' + title if title else ''}; dashed: target pose, "
                 "angle(target; plan)", fontsize=8, y=0.995)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=130)
    plt.close(fig)


def plot_standalone(ds: xr.Dataset, out: str | Path, title: str = "") -> None:
    """Backbone curves of the stand-alone actuators per exercise and model (Fig. 22-like)."""
    ex = ds["exercise"].values
    fig, axes = plt.subplots(1, len(ex), figsize=(3.4 * len(ex), 3.4), squeeze=False)
    styles = {"2d_mapped": ("tab:blue", "-"), "2d_plan": ("tab:blue", ":"), "3d_plan": ("tab:red", "-")}
    for ax, e in zip(axes[0], ex):
        for m in ds["model"].values:
            row = ds.sel(exercise=e, model=m)
            if not np.any(np.isfinite(row["backbone_x_mm"].values)):
                continue
            c, ls = styles.get(str(m), ("k", "-"))
            conv = "" if bool(row["converged"].values) else f", stopped at {float(row['load_factor']):.2f}"
            ax.plot(row["backbone_x_mm"], row["backbone_y_mm"], ls, color=c,
                    label=f"{m}: tip {float(row['tip_angle_deg']):.0f} deg{conv}")
        ax.set_aspect("equal")
        ax.set_title(str(e), fontsize=8)
        ax.legend(fontsize=6)
        ax.tick_params(labelsize=6)
        ax.set_xlabel("x (mm)", fontsize=7)
    axes[0, 0].set_ylabel("y (mm)", fontsize=7)
    fig.suptitle(f"Stand-alone actuators, backbone curves{': ' + title if title else ''}", fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=130)
    plt.close(fig)
