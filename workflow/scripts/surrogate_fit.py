from workflow.actuator.entry import write_surrogate
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
s = snakemake.params.surrogates  # noqa: F821
write_surrogate(
    snakemake.input.response,
    snakemake.input.cv,
    snakemake.output.model,  # noqa: F821
    fea=snakemake.wildcards.fea,
    k=s["k"],
    random_state=s["random_state"],  # noqa: F821
    plot=snakemake.output.plot,
)  # noqa: F821
