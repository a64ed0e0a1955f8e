from pathlib import Path

from workflow.actuator.entry_fem import write_shard
from workflow.common.fidelity_choice import apply_fem_choice
from workflow.common.provenance import open_result
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
fea = snakemake.wildcards.fea  # noqa: F821
# fidelity.auto: the element size and contact the FE study chose for this model, else the config's
choice = open_result(snakemake.input.fidelity) if "fidelity" in snakemake.input.keys() else None  # noqa: F821
actuator, fidelity = apply_fem_choice(p.actuator, choice, fea)
# the FE study's case on the chosen mesh: the sweep takes from it the P_B = 0 ray it solved on these load steps
cases = {Path(f).stem: f for f in (snakemake.input.cases if "cases" in snakemake.input.keys() else [])}  # noqa: F821
studied = open_result(cases[fidelity["fidelity"]]) if fidelity["fidelity"] in cases else None
write_shard(
    snakemake.output[0],
    fea=fea,
    shard=int(snakemake.wildcards.shard),  # noqa: F821
    sweep_cfg=p.sweep,
    actuator_cfg=actuator,
    config_slice={"config": p.config_slice, **fidelity},
    rule=snakemake.rule,
    attrs=fidelity,
    studied=studied,
)  # noqa: F821
