from workflow.fidelity.entry_fem import write_fem_case
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
write_fem_case(
    snakemake.wildcards.case,
    snakemake.output[0],
    actuator=p.actuator,  # noqa: F821
    config_slice=p.config_slice,
    p_top_kpa=p.p_top_kpa,
    iteration_budget=p.iteration_budget,
    sweep=p.sweep,
    rule=snakemake.rule,
)  # noqa: F821
