"""Plots of the DOE and musculoskeletal stages (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

__all__ = ["plot_rsm_r2"]


def plot_rsm_r2(ds: xr.Dataset, out: str | Path) -> None:
    """R^2 of each response and form, the selected form marked, beside the paper's range."""
    names = list(ds["response"].values)
    y = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(7, 0.25 * len(names) + 1.5))
    for k, (form, mk) in enumerate(zip(ds["form"].values, "os^")):
        r2 = ds["r2"].sel(form=form).values
        ax.scatter(r2, y + (k - 1) * 0.2, marker=mk, s=18, label=str(form))
    sel = ds["r2"].where(ds["selected"]).max("form").values
    ax.scatter(sel, y, facecolors="none", edgecolors="k", s=70, label="selected")
    ax.axvspan(0.8344, 0.9998, color="0.9", zorder=0, label="paper: 0.8344-0.9998")
    ax.set_yticks(y, names, fontsize=7)
    ax.set_xlabel("R$^2$")
    ax.set_xlim(min(0.5, float(np.nanmin(ds["r2"].values)) - 0.02), 1.0)
    ax.legend(fontsize=7, loc="lower left")
    ax.set_title("Response-surface fits of joint moments (15 CCD runs)")
    fig.tight_layout()
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)
