# Stage musculoskeletal: joint moments at the CCD runs, response surfaces, patient loads.


rule joint_moments_table:
    input:
        ccd="results/doe/ccd.nc",
        table=config["musculoskeletal"]["table_path"],
        code=code_files("musculoskeletal.table_backend", "musculoskeletal.moments", "pipeline"),
    output:
        "results/musculoskeletal/moments_table.nc",
    log:
        "logs/musculoskeletal/joint_moments_table.log",
    benchmark:
        "results/benchmarks/rules/joint_moments_table.tsv"
    script:
        "../workflow/scripts/joint_moments_table.py"


rule joint_moments:
    input:
        source=moments_source(),
        code=code_files("pipeline"),
    output:
        "results/musculoskeletal/moments.nc",
    params:
        backend=config["musculoskeletal"]["backend"],
    log:
        "logs/musculoskeletal/joint_moments.log",
    benchmark:
        "results/benchmarks/rules/joint_moments.tsv"
    script:
        "../workflow/scripts/joint_moments.py"


rule rsm:
    input:
        ccd="results/doe/ccd.nc",
        moments="results/musculoskeletal/moments.nc",
        code=code_files("musculoskeletal.rsm", "musculoskeletal.moments", "pipeline", "plots"),
    output:
        rsm="results/musculoskeletal/rsm.nc",
        plot=report("results/musculoskeletal/rsm_r2.png", caption="../report/rsm.rst", category="Musculoskeletal"),
    params:
        exercises=config["exercises"],
        alpha=config["rsm"]["alpha"],
    log:
        "logs/musculoskeletal/rsm.log",
    benchmark:
        "results/benchmarks/rules/rsm.tsv"
    script:
        "../workflow/scripts/rsm.py"


rule patient_loads:
    input:
        unpack(get_msk_choice),
        ccd="results/doe/ccd.nc",
        moments="results/musculoskeletal/moments.nc",
        rsm="results/musculoskeletal/rsm.nc",
        code=code_files("musculoskeletal.patient_loads", "musculoskeletal.rsm", "musculoskeletal.moments", "doe", "pipeline", "plots"),
    output:
        loads="results/patients/{patient}/joint_loads.nc",
        plot=report(
            "results/patients/{patient}/joint_loads.png",
            caption="../report/joint_loads.rst",
            category="Patients",
            subcategory="{patient}",
        ),
    params:
        patient=get_patient,
        exercises=config["exercises"],
        anthropometry=config["anthropometry"],
        prediction_alpha=config["rsm"]["prediction_alpha"],
        tolerance=config["fidelity"]["tolerance"]["msk_rel"],
        scaling=config["scaling"],
        config_slice=lambda wc: patient_cfg(wc) | ({"fidelity": {"tolerance": config["fidelity"]["tolerance"]["msk_rel"],
                                                                 "scaling": config["scaling"]}} if config["fidelity"]["auto"] else {}),
    log:
        "logs/patients/{patient}/patient_loads.log",
    benchmark:
        "results/benchmarks/rules/patient_loads_{patient}.tsv"
    script:
        "../workflow/scripts/patient_loads.py"
