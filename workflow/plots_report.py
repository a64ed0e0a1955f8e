"""Figures that exist only for the run report (matplotlib, Agg backend).

* `plot_moment_angle`: joint moment-angle curves of every CCD run (passive and
  active), the paper's Fig. 7-like view of ``moments.nc``.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

__all__ = ["plot_moment_angle"]


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
                ax.plot(ang[ok], y[ok], "-", color="k" if centre else colours[k], lw=1.8 if centre else 0.8,
                        label="design centre" if centre else None, zorder=3 if centre else 2)
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
