from workflow.reporting.entry import write_table
from workflow.scripts._common import setup_logging

log = setup_logging(snakemake)  # noqa: F821
w, p = snakemake.wildcards, snakemake.params  # noqa: F821
table = w.table if "table" in w.keys() else p.table
suffix = f", patient {w.patient}" if "patient" in w.keys() else ""
write_table(table, snakemake.input.dataset, snakemake.output[0], title_suffix=suffix)  # noqa: F821
log.info("wrote %s", snakemake.output[0])  # noqa: F821
