"""Plots of the FEA check (Fig. 21-like poses) and of the stand-alone actuators (Fig. 22-like), matplotlib Agg."""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402

from workflow.cascade.finger import Finger
from workflow.common.constants import JOINTS

__all__ = ["plot_fea_poses", "plot_standalone"]

_COLOURS = {0: "#6fa8dc", 1: "k", 2: "#f6b26b", 3: "#999999"}  # silicone, paper, flesh, bone


def _cells(ax, p: np.ndarray, t: np.ndarray, material: np.ndarray) -> None:
    polys = p[:, t].transpose(2, 1, 0)  # (ncell, 4, 2)
    ax.add_collection(
        PolyCollection(polys, facecolors=[_COLOURS.get(int(m), "c") for m in material], edgecolors="none", linewidths=0)
    )


def _pose_panel(
    ax, mesh_p, mesh_t, material, u, finger: Finger, target, angles, plan, pressures, groups, head: str, ok: bool
) -> None:
    x = mesh_p + np.asarray(u).reshape(-1, 2).T
    _cells(ax, x, mesh_t, material)
    joints, _ = finger.joint_positions(target)
    tip = finger.pose(target, np.array([[finger.tip_x_m, finger.joints_ref[2, 1]]]), np.array([2]))
    chain = np.vstack([joints, tip]) * 1e3
    ax.plot(chain[:, 0], chain[:, 1], "--o", color="firebrick", ms=2.5, lw=1.0)
    ang = ", ".join(f"{j} {a:.0f}({t:.0f};{q:.0f})" for j, a, t, q in zip(JOINTS, angles, target, plan))
    txt = "\n".join(f"{g}: {pressures[i, 0]:.0f}/{pressures[i, 1]:.0f}" for i, g in enumerate(groups))
    ax.text(0.02, 0.02, txt + " kPa", transform=ax.transAxes, fontsize=6, va="bottom", family="monospace")
    ax.set_title(f"{head}\n{ang} deg", fontsize=7.5, color="k" if ok else "firebrick")
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.tick_params(labelsize=6)
    ax.set_xlabel("x (mm)", fontsize=7)


def plot_fea_poses(
    mesh_p: np.ndarray,
    mesh_t: np.ndarray,
    material: np.ndarray,
    states: Sequence[np.ndarray],
    ds: xr.Dataset,
    finger: Finger,
    out: str | Path,
    title: str = "",
    corrected_states: Sequence[np.ndarray | None] | None = None,
) -> None:
    """One panel per exercise: deformed actuator and finger (FEA), target pose of the
    joint chain (dashed), angles reached (target; plan) and the applied pressures.

    With ``corrected_states`` (the correction step's kept state per exercise,
    None where the plan's own check was kept) a second row shows those.
    """
    n = len(states)
    rows = 2 if corrected_states is not None and any(u is not None for u in corrected_states) else 1
    fig, axes = plt.subplots(rows, n, figsize=(3.4 * n, 3.8 * rows), squeeze=False)
    groups = ds["group"].values
    for k, (u, ex) in enumerate(zip(states, ds["exercise"].values)):
        row = ds.sel(exercise=ex)
        tgt = row["target_angle_deg"].values
        ok = bool(row["achieved"].values)
        conv = "" if bool(row["converged"].values) else f" (stopped at {float(row['load_factor']):.2f})"
        _pose_panel(
            axes[0, k],
            mesh_p,
            mesh_t,
            material,
            u,
            finger,
            tgt,
            row["angle_deg"].values,
            row["predicted_angle_deg"].values,
            row["pressure_kpa"].values,
            groups,
            f"{ex}: {'reached' if ok else 'not reached'}{conv}",
            ok,
        )
        if rows == 2:
            ax = axes[1, k]
            if corrected_states[k] is None:
                ax.axis("off")
                why = textwrap.fill(str(row["correction_reason"].item()), 45)
                ax.text(
                    0.5,
                    0.5,
                    f"{ex}: plan kept\n{why}",
                    ha="center",
                    va="center",
                    fontsize=6.5,
                    transform=ax.transAxes,
                    clip_on=True,
                )
                continue
            b = int(row["correction_best"])
            ok_c = bool(row["achieved_corrected"].values)
            _pose_panel(
                ax,
                mesh_p,
                mesh_t,
                material,
                corrected_states[k],
                finger,
                tgt,
                row["corrected_angle_deg"].values,
                row["iteration_predicted_angle_deg"].isel(iteration=b).values,
                row["corrected_pressure_2d_kpa"].values,
                groups,
                f"{ex} corrected ({b} of {int(row['correction_iterations'])}): {'reached' if ok_c else 'not reached'}",
                ok_c,
            )
    for r in range(rows):
        axes[r, 0].set_ylabel("y, dorsal (mm)", fontsize=7)
    fig.suptitle(
        f"FEA check, 2D plane strain{': ' + title if title else ''}; dashed: target pose, "
        "angle(target; plan)" + ("; lower row: after the correction step" if rows == 2 else ""),
        fontsize=8,
        y=0.995,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=130)
    plt.close(fig)


def plot_standalone(ds: xr.Dataset, out: str | Path, title: str = "") -> None:
    """Backbone curves of the stand-alone actuators per exercise and model (Fig. 22-like)."""
    ex = ds["exercise"].values
    bends = "unit_bend_deg" in ds
    fig, axes = plt.subplots(2 if bends else 1, len(ex), figsize=(3.4 * len(ex), 6.2 if bends else 3.4), squeeze=False)
    styles = {"2d_mapped": ("tab:blue", "-"), "2d_plan": ("tab:blue", ":"), "3d_plan": ("tab:red", "-")}
    if bends:
        _unit_bend_row(axes[1], ds, styles)
    for ax, e in zip(axes[0], ex):
        for m in ds["model"].values:
            row = ds.sel(exercise=e, model=m)
            if not np.any(np.isfinite(row["backbone_x_mm"].values)):
                continue
            c, ls = styles.get(str(m), ("k", "-"))
            conv = "" if bool(row["converged"].values) else f", stopped at {float(row['load_factor']):.2f}"
            ax.plot(
                row["backbone_x_mm"],
                row["backbone_y_mm"],
                ls,
                color=c,
                label=f"{m}: tip {float(row['tip_angle_deg']):.0f} deg{conv}",
            )
        ax.set_aspect("equal")
        ax.set_title(str(e), fontsize=8)
        ax.legend(fontsize=6)
        ax.tick_params(labelsize=6)
        ax.set_xlabel("x (mm)", fontsize=7)
    axes[0, 0].set_ylabel("y (mm)", fontsize=7)
    fig.suptitle(
        f"Stand-alone actuators, backbone curves{' and bend per unit' if bends else ''}{': ' + title if title else ''}",
        fontsize=8,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=130)
    plt.close(fig)


def _unit_bend_row(axes, ds: xr.Dataset, styles: dict) -> None:
    """Each unit's bend along the actuator per exercise and model, against the concave side's jam angle."""
    groups = ds["unit_group"].values
    unit = ds["unit"].values
    edges = [k - 0.5 for k in range(1, len(groups)) if groups[k] != groups[k - 1]]
    for ax, e in zip(axes, ds["exercise"].values):
        for m in ds["model"].values:
            b = ds["unit_bend_deg"].sel(exercise=e, model=m).values
            if np.any(np.isfinite(b)):
                c, ls = styles.get(str(m), ("k", "-"))
                ax.plot(unit, b, ls, color=c, marker=".", ms=3, lw=1.0, label=str(m))
        jam = float(ds["jam_angle_deg"])
        for sign in (1, -1):
            ax.axhline(sign * jam, color="k", ls="--", lw=0.7)
        ax.text(unit[0], jam, f"blocks meet ({jam:.2f} deg)", fontsize=5.5, va="bottom", ha="left")
        for x in edges:
            ax.axvline(x, color="0.7", lw=0.6)
        for g in dict.fromkeys(groups):
            ax.text(
                np.mean(unit[groups == g]),
                1.0,
                str(g),
                transform=ax.get_xaxis_transform(),
                fontsize=6,
                ha="center",
                va="bottom",
            )
        ax.set_xlabel("unit, from the hand end", fontsize=7)
        ax.tick_params(labelsize=6)
    axes[0].set_ylabel("bend per unit (deg)", fontsize=7)
    axes[0].legend(fontsize=6)


def plot_chain_calibration(ds: xr.Dataset, out: str | Path) -> None:
    """Chain against FEA joint angles, before and after the calibration: the fit states and the held-out ones."""
    fig, axes = plt.subplots(1, 2, figsize=(9, 4.2), sharex=True, sharey=True)
    colors = {"MCP": "C0", "PIP": "C1", "DIP": "C2"}
    for ax, role in zip(axes, ("fit", "held_out")):
        sel = ds["role"] == role
        for joint, c in colors.items():
            fea = ds["angle_fea_deg"].sel(joint=joint).where(sel, drop=True)
            for stage, marker, fill in (("before", "o", "none"), ("after", "s", c)):
                chain = ds[f"angle_chain_{stage}_deg"].sel(joint=joint).where(sel, drop=True)
                ax.scatter(fea, chain, marker=marker, facecolors=fill, edgecolors=c, s=18, label=f"{joint} {stage}")
        lo = float(min(ds["angle_fea_deg"].min(), ds["angle_chain_before_deg"].min(), -5))
        hi = float(max(ds["angle_fea_deg"].max(), ds["angle_chain_before_deg"].max(), 5))
        ax.plot([lo, hi], [lo, hi], "k-", lw=0.8)
        for d in (-5, 5):
            ax.plot([lo, hi], [lo + d, hi + d], "k:", lw=0.6)
        err = ds["error_before_deg"].where(sel), ds["error_after_deg"].where(sel)
        ax.set_title(
            f"{role.replace('_', ' ')}: largest |chain - FEA| {float(abs(err[0]).max()):.1f} -> "
            f"{float(abs(err[1]).max()):.1f} deg",
            fontsize=8,
        )
        ax.set_xlabel("FEA joint angle (deg)", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0].set_ylabel("chain joint angle (deg)", fontsize=8)
    axes[0].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=130)
    plt.close(fig)
