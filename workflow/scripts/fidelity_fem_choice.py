from workflow.fidelity.entry import write_fem_choice
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
write_fem_choice(
    list(snakemake.input.cases),
    snakemake.output[0],
    tolerance=p.tolerance,  # noqa: F821
    config_slice=p.config_slice,
    rule=snakemake.rule,
)  # noqa: F821
