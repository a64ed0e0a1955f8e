from workflow.actuator.entry import write_surrogate_cv
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
s = snakemake.params.surrogates  # noqa: F821
write_surrogate_cv(
    snakemake.input.response_2d,
    snakemake.input.response_3d,
    snakemake.output.cv,  # noqa: F821
    k=s["k"],
    folds=s["folds"],
    random_state=s["random_state"],
    regressors=s["regressors"],
    config_slice=snakemake.params.config_slice,
    rule=snakemake.rule,  # noqa: F821
    plot=snakemake.output.plot,
    tolerance=snakemake.params.tolerance,
)  # noqa: F821
