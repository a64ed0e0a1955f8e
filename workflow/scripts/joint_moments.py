from workflow.musculoskeletal.entry import write_selected_moments
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
write_selected_moments(snakemake.input.source, snakemake.output[0], snakemake.params.backend, rule=snakemake.rule)  # noqa: F821
