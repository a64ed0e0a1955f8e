"""How much does a unit bend inside a long actuator, against the unit model of three chambers?

Not a test: a study (docs/actuator.md, "A unit inside a long actuator"). The paper's reduced-order chain gives
every unit of a group the per-unit free angle of the unit model (three chambers, end rotation / 3; paper section
2.4). Here whole actuators of N equal units, every chamber at (P_T, P_B), hand end clamped, no load (the
stand-alone model of Fig. 22), are cut into their units (:func:`workflow.fem.actuator.unit_bends_deg`), with and
without self-contact, beside the closed-form angle at which the concave side's blocks meet if rigid
(:func:`workflow.fem.actuator.jam_angle_deg`). 2D: seconds to a minute per solve; 3D: minutes to an hour, and the
3D actuators stall where the blocks meet (``--dim 3``).

    OMP_NUM_THREADS=1 python benchmarks/study_long_actuator.py [--dim 2] [--h 2] [--units 3,13]
        [--pressures 20:0,40:0,75:0,75:30] [--contact on,off] [--band 0.1] [--gap 1] [--height 15]
                                                                         -> benchmarks/out/long_actuator_{dim}d[_gap.._height..].csv
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from workflow import fem  # noqa: E402
from workflow.fem._mesh import build_actuator_mesh  # noqa: E402
from workflow.fem.actuator import jam_angle_deg, solve_standalone  # noqa: E402

OUT = ROOT / "benchmarks" / "out"


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dim", type=int, default=2, choices=(2, 3))
    ap.add_argument("--h", type=float, default=2.0, help="element size, mm (the stand-alone meshes: 2D 2, 3D 4)")
    ap.add_argument("--units", default="3,13", help="actuator lengths N, comma-separated")
    ap.add_argument("--pressures", default="20:0,40:0,75:0,75:30", help="(P_T:P_B) kPa pairs, comma-separated")
    ap.add_argument("--contact", default="on,off")
    ap.add_argument("--band", type=float, default=0.1, help="contact band, mm (the stand-alone restart's)")
    ap.add_argument("--max-step", type=float, default=0.05, help="largest load step, without predictor")
    ap.add_argument("--gap", type=float, default=None, help="gap between blocks, mm (Table 6: 1)")
    ap.add_argument("--height", type=float, default=None, help="block height, mm (Table 6: 15)")
    ap.add_argument("--plot", default=None, help="also draw the bends per unit to this .png (e.g. docs/img/...)")
    ap.add_argument("--from-csv", default=None, help="draw from this earlier output instead of solving")
    args = ap.parse_args(argv)
    if args.from_csv:
        df = pd.read_csv(args.from_csv)
        plot(df, args.plot or str(Path(args.from_csv).with_suffix(".png")))
        return df
    act = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())["actuator"]
    geom = {**fem.DEFAULT_GEOMETRY, **act["geometry"]}
    geom.update({k: v for k, v in (("gap", args.gap), ("height", args.height)) if v is not None})
    solver = dict(act["solver"], predictor=False, max_step=args.max_step, max_steps=3000)
    jam = jam_angle_deg(geom)
    print(f"rigid blocks meet on the concave side at {jam:.3f} deg per unit", flush=True)
    rows = []
    for pair in args.pressures.split(","):
        pt, pb = (float(v) for v in pair.split(":"))
        for contact in args.contact.split(","):
            for n in (int(v) for v in args.units.split(",")):
                um = build_actuator_mesh(geom, {"A": n}, h=args.h, dim=args.dim, **fem.layer_options(act))
                t0 = time.perf_counter()
                r = solve_standalone(
                    um,
                    {"A": (pt, pb)},
                    material=act["material"],
                    contact=contact == "on",
                    contact_options={"smoothing_mm": args.band},
                    solver=solver,
                )
                wall = time.perf_counter() - t0
                b = r.unit_bends_deg
                print(
                    f"({pt:g}, {pb:g}) kPa, contact {contact}, N = {n}: status {r.status} at {r.load_factor:.3f}, "
                    f"{r.newton_iterations} its, {wall:.1f} s; unit bends {np.round(b, 2).tolist()} deg",
                    flush=True,
                )
                for k, v in enumerate(b):
                    rows.append(
                        {
                            "dim": args.dim,
                            "gap_mm": geom["gap"],
                            "height_mm": geom["height"],
                            "h_mm": args.h,
                            "p_top_kpa": pt,
                            "p_bottom_kpa": pb,
                            "contact": contact,
                            "n_units": n,
                            "unit": k,
                            "bend_deg": v,
                            "status": r.status,
                            "load_factor": r.load_factor,
                            "wall_time_s": wall,
                            "jam_angle_deg": jam,
                        }
                    )
    df = pd.DataFrame(rows)
    OUT.mkdir(exist_ok=True)
    tag = "".join(f"_{k}{v:g}" for k, v in (("gap", args.gap), ("height", args.height)) if v is not None)
    out = OUT / f"long_actuator_{args.dim}d{tag}.csv"
    df.to_csv(out, index=False)
    print(f"-> {out.relative_to(ROOT)}")
    if args.plot:
        plot(df, args.plot)
    return df


def plot(df: pd.DataFrame, out: str) -> None:
    """One panel per pressure pair: bend per unit along each actuator, with and without contact, and the jam angle."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pairs = df[["p_top_kpa", "p_bottom_kpa"]].drop_duplicates().values
    fig, axes = plt.subplots(1, len(pairs), figsize=(3.3 * len(pairs), 3.2), sharey=True, squeeze=False)
    for ax, (pt, pb) in zip(axes[0], pairs):
        sub = df[(df.p_top_kpa == pt) & (df.p_bottom_kpa == pb)]
        for (contact, n), g in sub.groupby(["contact", "n_units"]):
            style = "-" if contact == "on" else ":"
            colour = "tab:red" if n <= 3 else "tab:blue"
            label = f"{n} units, contact {contact}" + (" (the unit model)" if n == 3 and contact == "on" else "")
            ax.plot(g["unit"] + 1, g["bend_deg"], style, marker=".", color=colour, lw=1.0, label=label)
        jam = float(sub["jam_angle_deg"].iloc[0])
        ax.axhline(jam, color="k", ls="--", lw=0.7)
        ax.text(13, jam, f"rigid blocks meet: {jam:.2f} deg", fontsize=6, va="top", ha="right")
        ax.set_title(f"P_T = {pt:g}, P_B = {pb:g} kPa", fontsize=8)
        ax.set_xlabel("unit, from the clamped end", fontsize=7)
        ax.tick_params(labelsize=6)
    axes[0, 0].set_ylabel("bend per unit (deg)", fontsize=7)
    axes[0, 0].legend(fontsize=5.5)
    d, h = int(df["dim"].iloc[0]), float(df["h_mm"].iloc[0])
    fig.suptitle(f"A unit inside a long actuator ({d}D, h = {h:g} mm, stand-alone, no load)", fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    fig.savefig(out, dpi=130)
    plt.close(fig)
    print(f"-> {out}")


if __name__ == "__main__":
    main()
