from workflow.musculoskeletal.entry_opensim import write_run
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
write_run(
    snakemake.input.model,
    snakemake.input.scaling,
    int(snakemake.wildcards.run),  # noqa: F821
    snakemake.output[0],
    fingers=p.fingers,
    angle_step_deg=p.angle_step_deg,  # noqa: F821
    activations=p.activations,
    include_gravity=p.include_gravity,
    rule=snakemake.rule,
    config_slice=p.config_slice,
)  # noqa: F821
