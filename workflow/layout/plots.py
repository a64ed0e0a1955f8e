"""The layout design's figure: every candidate on the chain (exercises reached against mean pressure) and the FEA's
verdict on the best few and on the length rule's default."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

__all__ = ["plot_layouts"]


def plot_layouts(ds: xr.Dataset, out: str | Path) -> None:
    """Left: the chain's candidates; right: per checked layout the exercises reached on the chain and by the FEA."""
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2))
    n = ds["search_n_reached"].values
    rng = np.random.default_rng(0)
    sc = ax.scatter(
        ds["search_mean_pressure_kpa"].values,
        n + rng.uniform(-0.15, 0.15, n.size),
        c=ds["search_units"].values.sum(axis=1),
        s=10,
        cmap="viridis",
    )
    fig.colorbar(sc, ax=ax, label="units in all")
    ax.set_xlabel("mean planned pressure (kPa)")
    ax.set_ylabel("exercises reached on the chain")
    ax.set_title("candidates on the chain", fontsize=9)
    how = ds["checked_label"].values if "checked_label" in ds else [f"rank {k}" for k in ds["checked"].values]
    chosen = ds.attrs.get("chosen", "")
    labels = [
        f"{'/'.join(str(v) for v in u)} ({h}){', chosen' if h == chosen else ''}"
        for u, h in zip(ds["checked_units"].values, how)
    ]
    y = np.arange(len(labels))
    bx.barh(y - 0.2, ds["chain_reached"].sum("exercise").values, height=0.4, label="chain")
    bx.barh(y + 0.2, ds["fea_reached"].sum("exercise").values, height=0.4, label="FEA")
    bx.set_yticks(y, labels)
    bx.invert_yaxis()
    bx.set_xlabel("exercises reached")
    bx.set_title("checked by FEA: the chain's best and the default\n(units CMC/MCP/PIP/DIP)", fontsize=9)
    bx.legend(fontsize=8)
    fig.suptitle(f"Layout design, patient {ds.attrs.get('patient', '')}", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
