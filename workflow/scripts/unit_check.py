from pathlib import Path

from workflow.actuator import entry_fem
from workflow.common.fidelity_choice import apply_fem_choice
from workflow.common.provenance import open_result
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
i = snakemake.input  # noqa: F821
# fidelity.auto: each model on the mesh the FE study chose, else the config's
choice = open_result(i.fidelity) if "fidelity" in i.keys() else None
per_model, attrs, studied = {}, {}, {}
cases = {Path(f).stem: f for f in (i.cases if "cases" in i.keys() else [])}
for m in p.actuator.get("unit_check", {}).get("models", ["2d", "3d"]):
    per_model[m], f = apply_fem_choice(p.actuator, choice, m)
    attrs.update({f"{k}_{m}": v for k, v in f.items()})
    if f["fidelity"] in cases:  # the study solved these rays on this mesh already
        studied[m] = open_result(cases[f["fidelity"]])
entry_fem.write_unit_check(
    snakemake.output.nc,
    snakemake.output.vtu,
    p.actuator,
    rule=snakemake.rule,  # noqa: F821
    config_slice={"config": p.config_slice, **attrs},
    model_actuators=per_model,
    attrs=attrs,
    studied=studied,
)
