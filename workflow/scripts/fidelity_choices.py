from workflow.common.html import write_html
from workflow.reporting.entry import fidelity_choices_table
from workflow.scripts._common import setup_logging

log = setup_logging(snakemake)  # noqa: F821
i = snakemake.input  # noqa: F821
table = fidelity_choices_table(i.unit_check, i.cv, list(i.responses), list(i.loads), i.get("fea_check"))
write_html(
    snakemake.output[0],
    "Fidelity used per stage",
    [("stage, fidelity used and why", table)],  # noqa: F821
    [f"fidelity.auto = {snakemake.config['fidelity']['auto']}"],
)  # noqa: F821
log.info("wrote %s", snakemake.output[0])  # noqa: F821
