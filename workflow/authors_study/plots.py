"""The study's figure: per variant and exercise reached or not (colour) with the joint angles the FEA reached."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

__all__ = ["plot_study"]


def plot_study(ds: xr.Dataset, out: str | Path, title: str = "") -> None:
    """Grid variant x exercise: green reached, amber full load but missed, red stalled (shade: load factor)."""
    variants = [str(v) for v in ds["variant"].values]
    exercises = [str(e) for e in ds["exercise"].values]
    fig, (ax, bx) = plt.subplots(
        1, 2, figsize=(3.0 + 2.0 * len(exercises) + 3.5, 1.2 + 0.55 * len(variants)), width_ratios=[len(exercises), 2]
    )
    rgb = np.ones((len(variants), len(exercises), 3))
    for i, v in enumerate(variants):
        for j, e in enumerate(exercises):
            s = ds.sel(variant=v, exercise=e)
            lam = float(s["load_factor"]) if np.isfinite(s["load_factor"]) else np.nan
            if bool(s["reached"]):
                rgb[i, j] = (0.55, 0.8, 0.55)
            elif np.isfinite(lam) and lam >= 1.0 - 1e-9:
                rgb[i, j] = (0.98, 0.8, 0.45)
            elif np.isfinite(lam):
                rgb[i, j] = (0.95, 0.45 + 0.4 * lam, 0.45 + 0.4 * lam)
            else:
                rgb[i, j] = (0.85, 0.85, 0.85)
            ang = s["angle_deg"].values
            txt = " / ".join("-" if not np.isfinite(a) else f"{a:.0f}" for a in ang)
            if np.isfinite(lam) and lam < 1.0 - 1e-9:
                txt += f"\nload {lam:.2f}"
            ax.text(j, i, txt, ha="center", va="center", fontsize=7)
    ax.imshow(rgb, aspect="auto")
    ax.set_xticks(
        range(len(exercises)),
        [
            f"{e}\n" + "/".join(f"{t:.0f}" for t in ds["target_angle_deg"].sel(exercise=e).max("variant").values)
            for e in exercises
        ],
    )
    ax.set_yticks(range(len(variants)), variants)
    ax.set_title("MCP / PIP / DIP reached by the FEA (deg); target under each exercise", fontsize=9)
    y = np.arange(len(variants))
    bx.barh(y - 0.2, ds["max_strap_force_n"].max("exercise").values, height=0.4, label="largest strap force (N)")
    bx.barh(
        y + 0.2,
        100 * ds["moment_share_of_limit"].max("exercise").values,
        height=0.4,
        label="largest moment / limit (%)",
    )
    bx.set_yticks(y, variants)
    bx.invert_yaxis()
    bx.legend(fontsize=7, loc="lower right")
    bx.set_title("loads against the limits", fontsize=9)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
