"""How wide a gap between blocks the jam-capped chain needs to reach each exercise: an estimate, not a design.

The chain caps every unit at the jam angle gap / (paper/2 + base + block height) (`workflow.actuator.jam`; 3.35 deg
for Table 6's 1 mm gap), so the gap bounds how far a span can turn its joint. Here the gap alone changes: the jam
angle and the unit's pitch (depth + gap, so the length rule lays fewer units over each phalanx), while the unit's
response below the jam stays the 3D unit model's at 1 mm (a wider gap changes it too; that is not modelled). For each
gap, the validation patient's exercises are planned with the paper's rule, as the default run plans them, and the
chain's joint angles and reached exercises printed. The 2D FE what-if with 2.5 mm gaps ([actuator](docs/actuator.md),
"For design") bends the interior units 8.4-9.6 deg, at their new jam angle, where this chain puts them.

    snakemake -c2 results/patients/mean/cascade_plan.nc && python benchmarks/study_gap_chain.py [gap_mm ...]
"""

from __future__ import annotations

import copy
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from workflow.actuator.unit_model import load_unit_model  # noqa: E402
from workflow.cascade.patient import patient_cascade, patient_finger, plan_options  # noqa: E402
from workflow.cascade.planning import plan_exercise  # noqa: E402
from workflow.common.constants import JOINTS  # noqa: E402
from workflow.common.provenance import open_result  # noqa: E402

RES = ROOT / "results"


def main(argv=None) -> None:
    gaps = [float(g) for g in (argv if argv is not None else sys.argv[1:])] or [1.0, 1.5, 2.0, 2.5, 3.0]
    cfg = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    c0 = cfg["cascade"]
    name = c0["validation_patient"]
    loads = open_result(RES / f"patients/{name}/joint_loads.nc")
    finger, _ = patient_finger(
        cfg["patients"][name],
        loads,
        open_result(RES / "musculoskeletal/moments.nc"),
        open_result(RES / "doe/ccd.nc"),
        cascade_cfg=c0,
        anthropometry=cfg["anthropometry"],
    )
    unit = load_unit_model(RES / f"actuator/surrogate_{c0['surrogate']}.joblib", **cfg["surrogates"]["unit_model"])
    targets = {
        str(e): loads["target_angle_deg"].sel(exercise=e, joint=list(JOINTS)).values for e in loads["exercise"].values
    }
    limits = loads["active_limit_nm"].sel(joint=list(JOINTS)).values
    print("| gap (mm) | jam angle (deg) | units CMC/MCP/PIP/DIP | " + " | ".join(targets) + " | reached |")
    print("|---|---|---|" + "---|" * len(targets) + "---|")
    for gap in gaps:
        c = copy.deepcopy(c0)
        c["unit_geometry_mm"]["gap"] = gap
        model = patient_cascade(finger, unit, c)
        opts = plan_options(c, limits)
        plans = [plan_exercise(model, t, exercise=e, **opts) for e, t in targets.items()]
        cells = [" / ".join(f"{a:.0f}" for a in p.equilibrium.joint_angles_deg) for p in plans]
        reached = [p.exercise for p in plans if p.achieved]
        counts = "/".join(str(model.n_per_group[g]) for g in ("CMC", "MCP", "PIP", "DIP"))
        print(
            f"| {gap:g} | {model.jam.jam_deg:.2f} | {counts} | "
            + " | ".join(cells)
            + f" | {', '.join(reached) or 'none'} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
