import json
from pathlib import Path

from workflow.common import tracking
from workflow.scripts._common import setup_logging

log = setup_logging(snakemake)  # noqa: F821
sm = snakemake  # noqa: F821
patient = sm.wildcards.patient
metrics = tracking.headline_metrics("results", patient)
metrics.update(tracking.rule_times("results/benchmarks/rules"))
run_id = tracking.log_run(
    uri=sm.params.uri,
    experiment=sm.params.experiment,
    patient=patient,
    params={"patient": sm.params.patient},
    metrics=metrics,
    artifacts=[f for k, f in sm.input.items() if k != "code"],
    config_slice=sm.params.config_slice,
)
log.info("logged MLflow run %s for patient %s (%d metrics) to %s", run_id, patient, len(metrics), sm.params.uri)
Path(sm.output[0]).write_text(json.dumps({"run_id": run_id, "uri": sm.params.uri, "metrics": metrics}, indent=1))
