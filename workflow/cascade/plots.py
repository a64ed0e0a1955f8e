"""Pose plots of the cascade plans (like the paper's Fig. 21), matplotlib Agg."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib
import xarray as xr

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from workflow.cascade.model import CascadeModel
from workflow.cascade.planning import Plan
from workflow.common.constants import GROUPS, JOINTS

__all__ = ["plot_poses", "plot_validation"]

_GROUP_COLOURS = dict(zip(GROUPS, ("tab:blue", "tab:orange", "tab:green", "tab:red")))


def _actuator_nodes(model: CascadeModel, angles_deg: Sequence[float]) -> np.ndarray:
    """Unit centres on the backbone (m), each carried by the body under it."""
    f = model.finger
    pts = f.pose(angles_deg, model.unit_ref, model.unit_body)
    base = np.array([model.base_x_m, model.unit_ref[0, 1]])
    return np.vstack([base, pts])


def plot_poses(model: CascadeModel, plans: Sequence[Plan], out: str | Path, title: str = "") -> None:
    """One panel per exercise: finger at the predicted pose (filled), target pose
    (dashed), the actuator's backbone coloured by group, pressures and angles."""
    n = len(plans)
    fig, axes = plt.subplots(1, n, figsize=(3.2 * n, 3.6), squeeze=False)
    f = model.finger
    for ax, plan in zip(axes[0], plans):
        eq = plan.equilibrium
        for poly in f.outline(plan.target_deg):
            ax.plot(poly[:, 0] * 1e3, poly[:, 1] * 1e3, "--", color="0.6", lw=0.8)
        for poly in f.outline(eq.joint_angles_deg):
            ax.fill(poly[:, 0] * 1e3, poly[:, 1] * 1e3, color="peachpuff", ec="saddlebrown", lw=0.8)
        hand_x = [model.base_x_m * 1e3 - 5, 0]
        ax.fill_between(hand_x, f.dorsal_y_m * 1e3 - 25, f.dorsal_y_m * 1e3, color="0.85")
        nodes = _actuator_nodes(model, eq.joint_angles_deg) * 1e3
        for g, name in enumerate(GROUPS):
            idx = np.flatnonzero(model.unit_group == g) + 1
            seg = nodes[np.r_[idx[0] - 1, idx]]
            ax.plot(
                seg[:, 0],
                seg[:, 1],
                "-o",
                ms=2.5,
                lw=2.0,
                color=_GROUP_COLOURS[name],
                label=f"LA_{name}" if plan is plans[0] else None,
            )
        joints, _ = f.joint_positions(eq.joint_angles_deg)
        ax.plot(joints[:, 0] * 1e3, joints[:, 1] * 1e3, "k.", ms=4)
        p = plan.pressures_kpa.reshape(4, 2)
        txt = "\n".join(f"{g}: {p[i, 0]:.0f}/{p[i, 1]:.0f} kPa" for i, g in enumerate(GROUPS))
        ang = ", ".join(f"{j} {a:.0f}({t:.0f})" for j, a, t in zip(JOINTS, eq.joint_angles_deg, plan.target_deg))
        ax.text(0.02, 0.02, txt, transform=ax.transAxes, fontsize=6.5, va="bottom", family="monospace")
        ax.set_title(
            f"{plan.exercise}: {'reached' if plan.achieved else 'not reached'}\n{ang} deg",
            fontsize=8,
            color="k" if plan.achieved else "firebrick",
        )
        ax.set_aspect("equal")
        ax.set_xlim(model.base_x_m * 1e3 - 8, f.tip_x_m * 1e3 + 20)
        ax.set_ylim(-f.tip_x_m * 1e3 - 10, f.dorsal_y_m * 1e3 + 35)
        ax.tick_params(labelsize=6)
        ax.set_xlabel("x (mm)", fontsize=7)
    axes[0, 0].set_ylabel("y, dorsal (mm)", fontsize=7)
    fig.legend(loc="upper right", fontsize=7, ncol=4)
    fig.suptitle(
        f"Planned poses (reduced-order cascade){': ' + title if title else ''}; "
        "dashed: target, x(y): predicted(target)",
        fontsize=8,
        y=0.995,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=130)
    plt.close(fig)


def plot_validation(ds: xr.Dataset, out: str | Path) -> None:
    """Our pressures beside the paper's, one panel per exercise; a row per table with every planner's, if stored."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ex = list(ds["exercise"].values)
    planner_tables = list(ds["table"].values) if "planner_ours" in ds else []
    rows = 1 + len(planner_tables)
    fig, axes = plt.subplots(rows, len(ex), figsize=(3.0 * len(ex), 3.0 * rows), sharey=True, squeeze=False)
    x = np.arange(8)
    w = 0.8 / (1 + ds.sizes["table"])
    per_table = "table" in ds["ours"].dims
    w = 0.8 / (2 * ds.sizes["table"]) if per_table else w
    for ax, e in zip(axes[0], ex):
        if not per_table:
            ax.bar(x - 0.4 + w / 2, ds["ours"].sel(exercise=e), w, label="ours")
        for k, r in enumerate(ds["table"].values):
            if per_table:
                ax.bar(x - 0.4 + w * (2 * k + 0.5), ds["ours"].sel(table=r, exercise=e), w, label=f"ours vs {r}")
                ax.bar(x - 0.4 + w * (2 * k + 1.5), ds["reference"].sel(table=r, exercise=e), w, label=str(r))
            else:
                ax.bar(x - 0.4 + w * (k + 1.5), ds["reference"].sel(table=r, exercise=e), w, label=str(r))
        reached = bool(ds["ours_achieved"].sel(exercise=e))
        ax.set_title(f"{e} ({'reached' if reached else 'not reached'} by ours)", fontsize=8)
    for row, table in enumerate(planner_tables, start=1):
        planners = list(ds["planner"].values)
        wp = 0.8 / (1 + len(planners))
        for ax, e in zip(axes[row], ex):
            ax.bar(x - 0.4 + wp / 2, ds["reference"].sel(table=table, exercise=e), wp, color="k", label=str(table))
            for k, pl in enumerate(planners):
                med = float(ds["planner_median_rel_error"].sel(planner=pl, table=table))
                ax.bar(
                    x - 0.4 + wp * (k + 1.5),
                    ds["planner_ours"].sel(planner=pl, table=table, exercise=e),
                    wp,
                    label=f"{pl} (median {100 * med:.0f} % off)",
                )
            ax.set_title(f"{e}: planners against {table}", fontsize=8)
    for ax in axes.ravel():
        ax.set_xticks(x, [p[2:] for p in ds["pressure"].values], rotation=90, fontsize=6)
        ax.tick_params(labelsize=6)
    for row in range(rows):
        axes[row, 0].set_ylabel("pressure (kPa)", fontsize=7)
        axes[row, 0].legend(fontsize=6)
    fig.tight_layout()
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=130)
    plt.close(fig)
