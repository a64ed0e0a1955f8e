from workflow.authors_study.entry import write_authors_study
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
o = snakemake.output  # noqa: F821
write_authors_study(
    dict(zip(p.variants, snakemake.input.checks)),  # noqa: F821
    p.changes,
    patient=p.patient,
    out_nc=o.nc,
    out_png=o.plot,
    out_html=o.table,
    config_slice=p.config_slice,
    rule=snakemake.rule,  # noqa: F821
)
