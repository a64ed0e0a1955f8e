# Stage tracking: one MLflow run per workflow run and patient (the run ledger).


rule track_patient:
    input:
        unpack(get_tracking_inputs),
        code=code_files("scripts.track_patient"),
    output:
        "results/tracking/{patient}.json",
    log:
        "logs/tracking/{patient}.log",
    benchmark:
        "results/benchmarks/rules/track_patient_{patient}.tsv"
    conda:
        "../envs/project.yaml"
    params:
        uri=config["tracking"]["uri"],
        experiment=config["tracking"]["experiment"],
        config_slice=patient_cfg,
        patient=get_patient,
    script:
        "../workflow/scripts/track_patient.py"
