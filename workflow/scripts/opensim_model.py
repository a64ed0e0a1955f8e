from workflow.musculoskeletal.entry_opensim import write_reference_model
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
write_reference_model(
    snakemake.input.parameters,
    snakemake.input.scaling,
    snakemake.output[0],  # noqa: F821
    fingers=snakemake.params.fingers,  # noqa: F821
    reference_marker=snakemake.params.reference_marker,
)  # noqa: F821
